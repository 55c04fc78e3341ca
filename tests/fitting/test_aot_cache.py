"""The exported-program cache (fitting/_aot.py) checks a file before deserialising it: a damaged file never
reaches ``jax.export.deserialize`` (which can abort the process) and never changes the answer."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from jaxlimb import _jaxcache as jc
from jaxlimb import _programs as pg
from jaxlimb.errors import CacheRepairWarning
from jaxlimb.fitting import _aot


def _core(x):  # noqa: ANN001, ANN202 - a module-level function: stable across processes
    return {"y": 0.5 * x + jnp.sin(x), "n": jnp.sum(x)}


def _template(x):  # noqa: ANN001, ANN202
    return {"y": x, "n": x}


@pytest.fixture
def folder(tmp_path, monkeypatch):
    monkeypatch.setattr(_aot, "_cache_dir", lambda: tmp_path)
    monkeypatch.setattr(pg, "_folder", lambda: None)  # the exports alone (no stored executable to load instead)
    monkeypatch.setattr(jc, "_WARNED", set())
    return tmp_path


def _run(x):  # noqa: ANN001, ANN202
    out = _aot.ExportedCore(_core, "tests.fitting.test_aot_cache._core", _template)(x)  # a new process's core
    return {k: np.asarray(v) for k, v in out.items()}


@pytest.mark.parametrize("where", ["payload", "header", "truncate", "junk"])
def test_damaged_export_is_replaced_with_the_same_answer(folder, monkeypatch, where):
    x = jnp.linspace(0.0, 1.0, 7)
    first = _run(x)
    (path,) = folder.glob("*.bin")
    good = path.read_bytes()
    assert jc.unseal(good) is not None
    data = bytearray(good)
    if where == "payload":  # e.g. an exponent bit of a constant: 1.0 -> 0.5 gave exit 0 and another answer
        data[-40] ^= 0x10
    elif where == "header":
        data[5] ^= 0x01
    elif where == "truncate":
        data = data[: len(data) // 2]
    else:
        data = bytearray(b"\x00junk" * 100)
    path.write_bytes(bytes(data))
    seen = []
    real = jax.export.deserialize
    monkeypatch.setattr(jax.export, "deserialize", lambda b: (seen.append(bytes(b)), real(b))[1])
    with pytest.warns(CacheRepairWarning, match="exported-program cache entry .* failed its check"):
        again = _run(x)
    assert all(jc.seal(s) == good for s in seen)  # only checked bytes were ever deserialised
    for k in first:
        np.testing.assert_array_equal(again[k], first[k])
    assert path.read_bytes() != bytes(data) and jc.unseal(path.read_bytes()) is not None  # exported again
    monkeypatch.setattr(jc, "_WARNED", set())
    third = _run(x)  # loaded from the repaired file, quietly (a warning is an error under pytest's filters)
    np.testing.assert_array_equal(third["y"], first["y"])


def test_the_export_folder_keeps_the_least_recently_used_entries_within_the_limit(folder, monkeypatch):
    """Every version of the sources exports its own cores: the folder is bounded like the stored executables."""
    import os

    from jaxlimb import _programs

    _run(jnp.linspace(0.0, 1.0, 7))
    (old,) = folder.glob("*.bin")
    monkeypatch.setattr(_programs, "MAX_BYTES", int(old.stat().st_size * 1.5))
    os.utime(old, (1, 1))  # long unused
    _run(jnp.linspace(0.0, 1.0, 9))  # another shape: another entry, over the limit
    assert not old.exists() and len(list(folder.glob("*.bin"))) == 1
