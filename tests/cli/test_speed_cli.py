"""Compile once (persistent cache, lazy imports) and the resumable Monte-Carlo command."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np

from jaxlimb.cli import main


def _run(code: str, env: dict[str, str] | None = None) -> str:
    e = {**os.environ, **(env or {})}
    return subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True, env=e).stdout


def test_help_does_not_import_jax():
    out = _run("import sys\nfrom jaxlimb.cli import main\n"
               "try:\n    main(['--help'])\nexcept SystemExit:\n    pass\n"
               "print('JAX' if 'jax' in sys.modules else 'NOJAX')")
    assert out.strip().endswith("NOJAX")


def test_locate_imports_no_heavy_optional_package():
    """The modules of ``jaxlimb locate`` load none of the packages other commands use (plots, SPICE, meshes,
    Dask, optimistix, SciPy's linalg/optimize packages): their import would be paid by every process."""
    heavy = ("matplotlib", "astropy", "trimesh", "optimistix", "lineax", "dask", "spiceypy", "emcee", "diffrax",
             "scipy.linalg", "scipy.optimize", "tqdm", "mkdocs")
    out = _run("import sys\nimport jaxlimb.cli._locate, jaxlimb.pipeline\n"
               f"print(*[m for m in {heavy!r} if m in sys.modules])")
    assert out.split() == []


def test_process_entry_freezes_the_collector_and_main_does_not():
    """``entry`` (the command's process) freezes JAX's objects for the garbage collector once JAX has started
    (and all at the end); :func:`main` in a session (tests, notebooks) freezes nothing."""
    code = ("import contextlib, gc, io, sys\nfrom jaxlimb import cli\n"
            "seen = []\norig = cli.start_command_jax\n"
            "cli.start_command_jax = lambda: (orig(), seen.append(gc.get_freeze_count()))\n"
            "sys.argv = ['jaxlimb', 'montecarlo', '--n', '2', '--radius', '20', '--batch', '2', '--json']\n"
            "with contextlib.redirect_stdout(io.StringIO()):\n    code = cli.{fn}()\n"
            "print(code, seen[0] if seen else -1, gc.get_freeze_count())")
    out = _run(code.format(fn="entry"), {"JAXLIMB_CACHE_DIR": "off"}).split()
    assert out[0] == "0"
    started, ended = int(out[1]), int(out[2])
    assert started > 10_000 and ended >= started  # JAX's module objects, then everything left at the end
    assert _run(code.format(fn="main"), {"JAXLIMB_CACHE_DIR": "off"}).split()[1:] == ["0", "0"]


def test_solver_names_match_the_registry():
    from jaxlimb._solver_names import SOLVER_NAMES
    from jaxlimb.fitting import SOLVERS

    assert set(SOLVER_NAMES) == set(SOLVERS)


def test_cache_dir_override_and_off(tmp_path):
    code = "from jaxlimb._jaxcache import cache_dir; print(cache_dir())"
    assert _run(code, {"JAXLIMB_CACHE_DIR": str(tmp_path / "c")}).strip() == str(tmp_path / "c")
    assert _run(code, {"JAXLIMB_CACHE_DIR": "off"}).strip() == "None"
    env = {k: v for k, v in os.environ.items() if k not in ("JAXLIMB_CACHE_DIR", "JAXLIMB_CACHE")}
    env["XDG_CACHE_HOME"] = str(tmp_path / "xdg")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True, env=env).stdout
    assert out.strip() == str(tmp_path / "xdg" / "jaxlimb" / "jax")
    env["JAXLIMB_CACHE"] = str(tmp_path / "root")  # one root for every jaxlimb cache
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True, env=env).stdout
    assert out.strip() == str(tmp_path / "root" / "jax")


def test_command_fills_the_cache_and_reuses_it(tmp_path):
    cache = tmp_path / "cache"
    env = {**os.environ, "JAXLIMB_CACHE_DIR": str(cache)}
    cmd = [sys.executable, "-m", "jaxlimb.cli", "montecarlo", "--n", "4", "--radius", "30", "--batch", "4", "--json"]
    first = json.loads(subprocess.run(cmd, capture_output=True, text=True, check=True, env=env).stdout)
    entries = sorted(p.name for p in cache.iterdir() if p.name.endswith("-cache"))
    assert entries, "no program was written to the persistent cache"
    second = json.loads(subprocess.run(cmd, capture_output=True, text=True, check=True, env=env).stdout)
    assert second["rms"] == first["rms"]  # same seeds, same answer, programs from the cache
    assert sorted(p.name for p in cache.iterdir() if p.name.endswith("-cache")) == entries  # nothing recompiled


MC = ["montecarlo", "--n", "30", "--radius", "40", "--batch", "10", "--seed", "5", "--json"]


def test_montecarlo_out_resume_and_truncated_chunk(tmp_path, capsys):
    out = tmp_path / "study"
    assert main([*MC, "--out", str(out)]) == 0
    ref = json.loads(capsys.readouterr().out)
    assert ref["status"] == "ok" and ref["chunks_run"] == 3 and ref["compile_s"] >= 0 and ref["fit_s"] > 0
    assert sorted(p.name for p in out.glob("chunk_*.npz")) == [f"chunk_{i:06d}.npz" for i in range(3)]
    # an existing study is not overwritten without --resume (exit 2, before any work)
    assert main([*MC, "--out", str(out)]) == 2
    assert "--resume" in json.loads(capsys.readouterr().out)["message"]
    # resume: nothing recomputed, the same answer
    assert main([*MC, "--out", str(out), "--resume"]) == 0
    res = json.loads(capsys.readouterr().out)
    assert res["chunks_resumed"] == 3 and res["chunks_run"] == 0 and res["rms"] == ref["rms"]
    # a truncated chunk (a crash of the machine mid-write) is recomputed, with a message naming it
    bad = out / "chunk_000001.npz"
    bad.write_bytes(bad.read_bytes()[:100])
    assert main([*MC, "--out", str(out), "--resume"]) == 0
    cap = capsys.readouterr()
    res = json.loads(cap.out)
    assert res["chunks_run"] == 1 and res["chunks_resumed"] == 2 and res["rms"] == ref["rms"]
    assert "chunk_000001.npz" in cap.err and "Traceback" not in cap.err
    # other settings into the same directory are refused
    assert main([*MC[:-1], "--sigma", "3", "--json", "--out", str(out), "--resume"]) == 2


def test_montecarlo_result_does_not_depend_on_the_batch(capsys):
    assert main([*MC]) == 0
    a = json.loads(capsys.readouterr().out)
    assert main([*MC[:5], "--batch", "30", *MC[7:]]) == 0
    b = json.loads(capsys.readouterr().out)
    for k in a["rms"]:
        np.testing.assert_allclose(a["rms"][k], b["rms"][k], rtol=1e-9)


def test_resume_without_out_is_bad_input(capsys):
    assert main([*MC, "--resume"]) == 2
    assert "--out" in json.loads(capsys.readouterr().out)["message"]


def test_chunk_file_error_names_the_file(tmp_path):
    import pytest

    from jaxlimb.analysis.montecarlo import load_monte_carlo
    from jaxlimb.errors import ConfigError

    assert main([*MC, "--out", str(tmp_path / "s")]) == 0
    p = Path(tmp_path / "s" / "chunk_000000.npz")
    p.write_bytes(b"PK\x03\x04garbage")
    with pytest.raises(ConfigError, match="chunk_000000.npz"):
        load_monte_carlo(tmp_path / "s")


FIT_SCRIPT = """
import json, sys
import jax
jax.config.update("jax_enable_x64", True)
from jaxlimb._jaxcache import enable_compile_cache
enable_compile_cache()
import numpy as np
from jaxlimb.fitting import compile_count, fit
from jaxlimb.models import CIRCLE, CircleParams
rr, cc = np.mgrid[0:120, 0:120]
coords = np.stack([rr.ravel(), cc.ravel()], -1).astype(float)
truth = CircleParams(60.3, 59.6, 40.0, 3.0, 200.0, 20.0)
z = np.asarray(CIRCLE.intensity(truth, coords)) + np.random.default_rng(0).normal(0, 5, coords.shape[0])
r = fit(CIRCLE, coords, z, truth.replace(r0=60.8, radius=40.4))
print(json.dumps({"x": np.asarray(r.params.to_vector()).tolist(), "cov": np.asarray(r.covariance).tolist(),
                  "traces": compile_count()}))
"""


def test_fit_core_is_traced_once_per_machine(tmp_path):
    """The exported fit core (fitting/_aot.py): a second process loads it instead of tracing, same numbers."""
    env = {"JAXLIMB_CACHE_DIR": str(tmp_path / "c")}
    first = json.loads(_run(FIT_SCRIPT, env))
    assert first["traces"] == 1 and list((tmp_path / "c" / "exported").glob("*.bin"))
    stored = list((tmp_path / "c" / "programs").glob("*.bin"))  # its executable (jaxlimb/_programs.py)
    assert stored
    second = json.loads(_run(FIT_SCRIPT, env))  # loads the executable: a LAPACK call in it runs (no crash)
    assert second["traces"] == 0  # loaded: no trace
    assert list((tmp_path / "c" / "programs").glob("*.bin")) == stored  # nothing compiled again
    # same numbers to rounding: identical on a quiet machine, but one run under heavy load (load ~10, three
    # other processes) saw a difference that failed a bit-for-bit comparison
    np.testing.assert_allclose(second["x"], first["x"], rtol=1e-13, atol=1e-13)
    np.testing.assert_allclose(second["cov"], first["cov"], rtol=1e-11, atol=0)
    off = json.loads(_run(FIT_SCRIPT, {"JAXLIMB_CACHE_DIR": "off"}))
    np.testing.assert_allclose(off["x"], first["x"], rtol=0, atol=1e-12)


def test_montecarlo_splits_the_batch_over_cpu_devices_with_the_same_answer(tmp_path):
    """``--devices 2``: the seeds are split over two XLA CPU devices; the study is the same."""
    env = {**os.environ, "JAXLIMB_CACHE_DIR": str(tmp_path / "cache")}
    env.pop("XLA_FLAGS", None)
    cmd = [sys.executable, "-m", "jaxlimb.cli", *MC[:5], "--batch", "15", *MC[7:]]
    one, two = (json.loads(subprocess.run([*cmd, "--devices", d], capture_output=True, text=True, check=True,
                                          env=env).stdout) for d in ("1", "2"))
    assert (one["devices"], two["devices"]) == (1, 2)
    for k in one["rms"]:
        np.testing.assert_allclose(two["rms"][k], one["rms"][k], rtol=1e-9)


def test_host_device_request_respects_the_users_xla_flags(monkeypatch):
    from jaxlimb import cli

    monkeypatch.setattr(cli.sys, "modules", {k: v for k, v in sys.modules.items() if k != "jax"})
    monkeypatch.setenv("XLA_FLAGS", "--xla_force_host_platform_device_count=3")
    cli._request_host_devices(2)
    assert os.environ["XLA_FLAGS"] == "--xla_force_host_platform_device_count=3"
    monkeypatch.setenv("XLA_FLAGS", "--xla_cpu_enable_fast_math=false")
    cli._request_host_devices(2)
    assert os.environ["XLA_FLAGS"] == "--xla_cpu_enable_fast_math=false --xla_force_host_platform_device_count=2"


def test_lapack_kernels_without_the_scipy_linalg_package():
    """The command line's start-up loads SciPy's Cython BLAS/LAPACK alone; linear algebra still works."""
    code = ("import sys; from jaxlimb._jaxcache import preload_lapack_kernels; assert preload_lapack_kernels(); "
            "import jax, jax.numpy as jnp; jax.config.update('jax_enable_x64', True); "
            "a = jnp.array([[4.0, 1.0], [1.0, 3.0]]); c = jnp.linalg.cholesky(a); "
            "print('scipy.linalg' in sys.modules, float(c[1, 1]), float(jnp.linalg.solve(a, jnp.ones(2))[0])); "
            "import scipy.linalg; print(float(scipy.linalg.cho_factor(a)[0][0, 0]))")
    first, second = _run(code).split("\n")[:2]
    loaded, c11, x0 = first.split()
    assert loaded == "False" and abs(float(c11) - 11 ** 0.5 / 2) < 1e-12 and abs(float(x0) - 2 / 11) < 1e-12
    assert float(second) == 2.0
