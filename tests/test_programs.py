"""Stored executables (jaxlimb/_programs.py): a later process loads the compiled program instead of tracing and
lowering it, gets the same numbers, and never loads a damaged entry or one traced under other settings."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from jaxlimb import _jaxcache as jc
from jaxlimb import _programs as pg
from jaxlimb.errors import CacheRepairWarning

TRACES = {"n": 0}
SETTING = {"scale": 2.0}


def _fn(p, x):  # noqa: ANN001, ANN202 - module level: described the same in every process
    TRACES["n"] += 1
    return {"y": p["a"] * jnp.sin(x) + SETTING["scale"], "s": (jnp.sum(x * x), jnp.linalg.inv(p["m"]))}


@pytest.fixture
def folder(tmp_path, monkeypatch):
    monkeypatch.setattr(pg, "_folder", lambda: tmp_path)
    monkeypatch.setattr(jc, "_WARNED", set())
    monkeypatch.setattr(pg, "_SETTINGS", {"scale": lambda: repr(SETTING["scale"])})
    TRACES["n"] = 0
    return tmp_path


def _args():
    return {"a": 1.5, "m": np.eye(3) * 2.0}, jnp.linspace(0.0, 1.0, 9)


def _run():  # a new process's function: nothing in memory
    out = pg.StoredJit(_fn)(*_args())
    return jax.tree_util.tree_map(np.asarray, out)


def test_a_later_process_loads_the_executable_without_tracing_and_gets_the_same_numbers(folder):
    plain = jax.tree_util.tree_map(np.asarray, jax.jit(_fn)(*_args()))
    TRACES["n"] = 0
    first = _run()
    assert TRACES["n"] == 1 and len(list(folder.glob("*.bin"))) == 1
    again = _run()
    assert TRACES["n"] == 1  # loaded: not traced again
    for a, b, c in zip(jax.tree_util.tree_leaves(plain), jax.tree_util.tree_leaves(first),
                       jax.tree_util.tree_leaves(again)):
        np.testing.assert_array_equal(b, a)
        np.testing.assert_array_equal(c, a)
    pg.StoredJit(_fn)({"a": 1.5, "m": np.eye(3)}, jnp.linspace(0.0, 1.0, 17))  # another shape: another program
    assert TRACES["n"] == 2 and len(list(folder.glob("*.bin"))) == 2


def test_a_trace_setting_is_part_of_the_key(folder, monkeypatch):
    first = _run()
    monkeypatch.setitem(SETTING, "scale", 3.0)
    other = _run()
    assert TRACES["n"] == 2  # traced again under the other setting, not loaded
    np.testing.assert_allclose(other["y"] - first["y"], 1.0)


@pytest.mark.parametrize("where", ["payload", "truncate"])
def test_a_damaged_entry_is_compiled_again_with_the_same_answer(folder, where):
    first = _run()
    (path,) = folder.glob("*.bin")
    data = bytearray(path.read_bytes())
    if where == "payload":
        data[-100] ^= 0x10
    else:
        data = data[: len(data) // 2]
    path.write_bytes(bytes(data))
    with pytest.warns(CacheRepairWarning, match="compiled-program cache entry .* failed its check"):
        again = _run()
    np.testing.assert_array_equal(again["y"], first["y"])
    assert jc.unseal(path.read_bytes()) is not None  # stored again


def test_an_executable_that_cannot_run_is_deleted_and_the_jit_answers(folder, tmp_path):
    """A stored executable that loads but lacks one of its functions fails only when it runs (``NOT_FOUND:
    Function ... not found``): the guarded call waits for its first results, deletes the entry, says so once and
    answers with the function's jit from then on; other runtime errors are not swallowed."""
    entry = tmp_path / "broken.bin"
    entry.write_bytes(b"x")
    calls = {"compiled": 0, "fallback": 0}

    def broken(*args):  # noqa: ANN002, ANN202
        calls["compiled"] += 1
        raise jax.errors.JaxRuntimeError("NOT_FOUND: Function wrapped_broadcast not found (type id: 1)")

    def fallback(x):  # noqa: ANN001, ANN202
        calls["fallback"] += 1
        return {"y": x + 1.0}

    f = pg.guarded_call(broken, jax.tree_util.tree_structure({"y": 0}), fallback, entry)
    with pytest.warns(CacheRepairWarning, match="cannot run .*wrapped_broadcast.*deleted"):
        assert float(f(jnp.asarray(1.0))["y"]) == 2.0
    assert not entry.exists() and float(f(jnp.asarray(2.0))["y"]) == 3.0 and calls == {"compiled": 1, "fallback": 2}

    def other_error(*args):  # noqa: ANN002, ANN202
        raise jax.errors.JaxRuntimeError("INTERNAL: something else")

    with pytest.raises(jax.errors.JaxRuntimeError, match="INTERNAL"):
        pg.guarded_call(other_error, jax.tree_util.tree_structure({"y": 0}), fallback)(jnp.asarray(1.0))


def test_inside_another_transformation_and_without_a_cache_it_is_plain_jit(folder, monkeypatch):
    f = pg.StoredJit(_fn)
    p, x = _args()
    y = jax.jit(lambda x: f(p, x)["y"])(x)  # tracer arguments
    assert not list(folder.glob("*.bin"))
    monkeypatch.setattr(pg, "_folder", lambda: None)
    np.testing.assert_array_equal(np.asarray(f(p, x)["y"]), np.asarray(y))
    assert not list(folder.glob("*.bin"))


def test_an_argument_without_a_stable_description_is_not_stored(folder):
    f = pg.StoredJit(_fn, static_non_arrays=True)
    f({"a": 1.5, "m": np.eye(3), "f": object()}, jnp.ones(3))  # an object printed with its address
    assert not list(folder.glob("*.bin"))


def test_a_closure_is_never_stored(folder):
    scale = 4.0
    f = pg.StoredJit(lambda p, x: _fn(p, x)["y"] * scale)  # the captured value is not in any key
    f(*_args())
    assert not list(folder.glob("*.bin"))


def test_the_least_recently_used_entries_are_evicted_beyond_the_limit(folder, monkeypatch):
    _run()
    (old,) = folder.glob("*.bin")
    monkeypatch.setattr(pg, "MAX_BYTES", int(old.stat().st_size * 1.5))
    import os

    os.utime(old, (1, 1))  # long unused
    pg.StoredJit(_fn)({"a": 1.5, "m": np.eye(3)}, jnp.linspace(0.0, 1.0, 17))  # another program: over the limit
    assert not old.exists() and len(list(folder.glob("*.bin"))) == 1


def test_the_functions_a_warm_locate_calls_are_stored():
    """What a later ``jaxlimb locate`` process would otherwise trace and lower again (the profile's columns, its
    Fisher matrix, the glow and brightening score columns; the fit cores: tests/cli/test_speed_cli.py)."""
    from jaxlimb.models import lunar_lambert, profile_columns
    from jaxlimb.pipeline import sigmoid
    from jaxlimb.pipeline.profile import glow, model_error

    for f in (sigmoid._columns, sigmoid._predict_jit, model_error._signed_profile,
              glow.glow_columns, lunar_lambert.brightening_column, profile_columns.glow_column,
              profile_columns._padded_parts):
        assert isinstance(f, pg.StoredJit), f


def test_past_half_the_kernels_map_limit_every_compiled_program_is_dropped(folder, monkeypatch):
    jitted = jax.jit(_fn)
    stored = pg.StoredJit(_fn)
    loads = {"n": 0}
    real_load = pg.load_program
    monkeypatch.setattr(pg, "load_program", lambda *a: (loads.__setitem__("n", loads["n"] + 1), real_load(*a))[1])
    want = np.asarray(jitted(*_args())["y"])
    stored(*_args())
    TRACES["n"] = 0
    monkeypatch.setattr(pg, "mapped_regions", lambda: (49, 100))
    assert not pg.bound_compiled_programs()
    jitted(*_args()), stored(*_args())
    assert TRACES["n"] == 0 and loads["n"] == 0  # below half the limit: both still in memory
    monkeypatch.setattr(pg, "mapped_regions", lambda: (50, 100))
    assert pg.bound_compiled_programs()
    np.testing.assert_array_equal(np.asarray(jitted(*_args())["y"]), want)
    assert TRACES["n"] == 1  # JAX's cache dropped: traced again
    np.testing.assert_array_equal(np.asarray(stored(*_args())["y"]), want)
    assert loads["n"] == 1 and TRACES["n"] == 1  # the loaded executable dropped: loaded again from its entry


def test_the_process_map_count_is_read_where_proc_tells_it():
    counts = pg.mapped_regions()
    if counts is None:
        pytest.skip("no /proc on this system")
    used, limit = counts
    assert 0 < used < limit


def _fn_apart(a, m, x):  # noqa: ANN001, ANN202 - a function no other test compiles
    return {"y": a * jnp.cos(x) + jnp.trace(m)}


def test_a_stored_program_is_compiled_apart_from_jaxs_persistent_cache(folder, monkeypatch):
    """An executable loaded from JAX's persistent cache serialises without its functions (a later load fails with
    ``NOT_FOUND: Function ... not found``), and ``enable_compilation_cache(False)`` is read once per process: the
    stored program's compilation must not consult that cache however early the process used it."""
    from jax._src import compilation_cache as cc

    jax.jit(lambda x: x + 1.0)(jnp.ones(3))  # the process has decided whether it uses the cache
    before = cc.is_cache_used(jax.devices()[0].client)
    seen: list[bool] = []
    real = cc.is_cache_used
    monkeypatch.setattr(cc, "is_cache_used", lambda b: (seen.append(real(b)), seen[-1])[1])
    stored = pg.StoredJit(_fn_apart)
    want = np.asarray(jax.jit(_fn_apart)(1.5, np.eye(3), jnp.linspace(0.0, 1.0, 9))["y"])
    seen.clear()
    stored(1.5, np.eye(3), jnp.linspace(0.0, 1.0, 9))
    assert seen and not any(seen)  # compiled, not looked up nor stored
    assert real(jax.devices()[0].client) == before  # the process's setting is back
    stored.forget_loaded()
    np.testing.assert_array_equal(np.asarray(stored(1.5, np.eye(3), jnp.linspace(0.0, 1.0, 9))["y"]), want)
