"""Dask scale-out: chunks as tasks, atomic chunk files, kill + resume = uninterrupted."""

from __future__ import annotations

import json
import math
import os
import signal
import subprocess
import sys
import time

import numpy as np
import pytest

from jaxlimb.analysis.distributed import chunked, close_client, make_client, run_monte_carlo_distributed
from jaxlimb.analysis.montecarlo import MonteCarloOptions, run_monte_carlo
from jaxlimb.errors import LimbInputError


def gaussian_trial(seed: int, i: int) -> dict[str, float]:
    rng = np.random.default_rng(seed)
    return {"x": float(rng.standard_normal()), "i": float(i)}


def test_two_worker_cluster_equals_in_process_and_resumes(tmp_path):
    opt = MonteCarloOptions(n_trials=23, chunk_size=4, seed=9, out_dir=str(tmp_path / "d"), progress=False)
    client = make_client(workers=2, processes=False)
    try:
        assert len(client.scheduler_info()["workers"]) == 2
        res = run_monte_carlo_distributed(gaussian_trial, opt, client, progress=False)
        assert res.chunks_run == 6 and res.chunks_skipped == 0
        (tmp_path / "d" / "chunk_000002.npz").unlink()  # a chunk lost: only it is recomputed
        again = run_monte_carlo_distributed(gaussian_trial, opt, client, progress=False)
        assert again.chunks_run == 1 and again.chunks_skipped == 5
    finally:
        close_client(client)
    ref = run_monte_carlo(gaussian_trial, MonteCarloOptions(n_trials=23, chunk_size=4, seed=9, progress=False))
    np.testing.assert_array_equal(res.values["x"], ref.values["x"])
    np.testing.assert_array_equal(again.values["x"], ref.values["x"])


def test_bad_workers_and_chunks():
    with pytest.raises(LimbInputError, match="workers"):
        make_client(workers=0)
    assert list(chunked([1, 2, 3, 4, 5], 2)) == [[1, 2], [3, 4], [5]]
    from jaxlimb.analysis.distributed import TASKS_PER_WORKER, default_chunk

    for n, w in ((200, 2), (200, 1), (1000, 3), (5, 4), (10**6, 2)):
        c = default_chunk(n, w)
        assert 1 <= c <= 50
        assert c == 50 or math.ceil(n / c) >= 0.75 * min(n, TASKS_PER_WORKER * w)  # enough tasks to balance the workers


SMALL_CAMERA = {"focal_length_mm": 16.0 * 500 / 2592, "pixel_pitch_mm": 0.0022, "rows": 400, "cols": 500,
                "principal_point_rc": [199.5, 249.5]}


def _cmd(cam, out, *extra):
    return [sys.executable, "-m", "jaxlimb.cli", "montecarlo", "--pipeline", "--camera", str(cam), "--range-km", "30000",
            "--phase-deg", "30", "--n", "6", "--batch", "1", "--seed", "4", "--out", str(out), "--json", *extra]


def test_killed_pipeline_run_resumed_gives_the_same_result_file(tmp_path):
    """A two-worker run killed mid-run (the client and its workers) and resumed in one process writes the result
    file of one uninterrupted run, byte for byte (a resume on a cluster: the first test, in process)."""
    cam = tmp_path / "cam.json"
    cam.write_text(json.dumps(SMALL_CAMERA))
    env = {**os.environ, "JAXLIMB_CACHE_DIR": str(tmp_path / "jaxcache")}
    ref = tmp_path / "ref"
    subprocess.run(_cmd(cam, ref), check=True, capture_output=True, env=env, timeout=300)
    out = tmp_path / "killed"
    p = subprocess.Popen(_cmd(cam, out, "--workers", "2"), stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
                         env=env, start_new_session=True)
    t0 = time.monotonic()
    while len(list(out.glob("chunk_*.npz"))) < 2 and p.poll() is None and time.monotonic() - t0 < 240:
        time.sleep(0.2)
    os.killpg(p.pid, signal.SIGKILL)  # the client and its workers, mid-run
    p.wait()
    done = len(list(out.glob("chunk_*.npz")))
    assert not (out / "result.json").exists() and done >= 2
    r = subprocess.run(_cmd(cam, out, "--resume"), check=True, capture_output=True, text=True, env=env, timeout=300)
    summary = json.loads(r.stdout)
    assert summary["chunks_resumed"] >= 2 and summary["chunks_run"] + summary["chunks_resumed"] == 6
    assert (out / "result.json").read_bytes() == (ref / "result.json").read_bytes()
    assert summary["n_ok"] == 6 and summary["summary"]["all"]["row"]["rms"] < 0.2


def test_worker_environment_shares_the_cores(monkeypatch):
    from jaxlimb.analysis.distributed import worker_environment

    for k in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "OPENCV_FOR_THREADS_NUM", "XLA_FLAGS",
              "MALLOC_MMAP_THRESHOLD_", "MALLOC_TRIM_THRESHOLD_"):
        monkeypatch.delenv(k, raising=False)
    one_core_each = worker_environment(2, cores=2)
    assert one_core_each["XLA_FLAGS"] == "--xla_cpu_multi_thread_eigen=false"
    assert one_core_each["OMP_NUM_THREADS"] == one_core_each["OPENCV_FOR_THREADS_NUM"] == "1"
    malloc = {"MALLOC_MMAP_THRESHOLD_": str(64 << 20), "MALLOC_TRIM_THRESHOLD_": str(128 << 20)}
    assert worker_environment(1, cores=2) == malloc and worker_environment(2, cores=8) == malloc  # cores to spare
    assert one_core_each["MALLOC_MMAP_THRESHOLD_"] == malloc["MALLOC_MMAP_THRESHOLD_"]  # not Dask's 128 KiB
    monkeypatch.setenv("MALLOC_TRIM_THRESHOLD_", "65536")
    assert worker_environment(1, cores=2)["MALLOC_TRIM_THRESHOLD_"] == "65536"  # the user's, passed on
    monkeypatch.setenv("XLA_FLAGS", "--xla_cpu_multi_thread_eigen=true")
    monkeypatch.setenv("OMP_NUM_THREADS", "2")
    kept = worker_environment(2, cores=2)
    assert "XLA_FLAGS" not in kept and "OMP_NUM_THREADS" not in kept  # the user's choice wins


def test_worker_preload_starts_jax_and_freezes_at_teardown():
    """:mod:`jaxlimb.analysis.dask_worker` in a fresh process: setup starts JAX (float64, the locate
    pipeline) in a thread; teardown freezes the collector's objects (a quick process exit)."""
    code = ("import gc, sys\nfrom jaxlimb.analysis import dask_worker as d\n"
            "print('jax' in sys.modules)\nd.dask_setup(None)\nd.dask_setup(None)\n"
            "assert len(d._STARTED) == 1\nd._STARTED[0].join()\nimport jax\n"
            "print(jax.config.jax_enable_x64, 'jaxlimb.pipeline' in sys.modules)\n"
            "n = gc.get_freeze_count()\nx = [[] for _ in range(1000)]\nd.dask_teardown(None)\n"
            "print(n > 10_000, gc.get_freeze_count() >= n + 1000)")
    env = {**os.environ, "JAXLIMB_CACHE_DIR": "off"}
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True, env=env).stdout
    assert out.split() == ["False", "True", "True", "True", "True"]


def test_local_cluster_workers_load_the_preload():
    client = make_client(workers=1)
    try:
        assert all(client.run(lambda: "jaxlimb.analysis.dask_worker" in sys.modules).values())
    finally:
        close_client(client)


def test_resume_keeps_the_chunks_of_the_study_whatever_the_workers(tmp_path):
    """The default chunk size depends on the number of workers; ``--resume`` takes the study's own (a study
    started with 2 workers resumes with 1 or 3 instead of being refused as "another study")."""
    import argparse

    from jaxlimb.analysis.distributed import default_chunk
    from jaxlimb.analysis.montecarlo import prepare_study, study_chunk_size
    from jaxlimb.cli._mc_pipeline import study
    from jaxlimb.geometry.camera import Camera

    cam = Camera.from_dict(SMALL_CAMERA)
    out = tmp_path / "study"
    args = dict(range_km=30000.0, phase_deg=30.0, sigma=10.0, n=200, seed=4, out=str(out), json=True, batch=None,
                families=None, body="moon", profile=None)
    _, started, _ = study(argparse.Namespace(**args, workers=2, resume=False), cam)
    prepare_study(started)  # writes the manifest
    assert study_chunk_size(out) == started.chunk_size == default_chunk(200, 2)
    for w in (None, 1, 3):
        assert default_chunk(200, w or 1) != started.chunk_size
        _, resumed, _ = study(argparse.Namespace(**args, workers=w, resume=True), cam)
        assert resumed.chunk_size == started.chunk_size
        assert prepare_study(resumed) == list(range(started.n_chunks))  # accepted as the same study
    _, explicit, _ = study(argparse.Namespace(**{**args, "batch": 7}, workers=1, resume=True), cam)
    assert explicit.chunk_size == 7  # --batch still wins (and a mismatch is then refused by the manifest)
    assert study_chunk_size(tmp_path / "none") is None


def test_first_task_waits_for_the_preload_imports():
    """A worker's first task began while the preload thread imported ``jaxlimb.pipeline``: the two threads
    importing the package at once saw a partially initialised ``jaxlimb.geometry.ellipsoid`` (ImportError in
    2 of 3 such processes).  ``LocateTrial`` waits for the preload (:func:`dask_worker.wait_started`)."""
    code = ("import time\nfrom jaxlimb.analysis import dask_worker as d\nfrom jaxlimb.analysis.pipeline_study import LocateTrial\n"
            "slow = d.start_jax\nd.start_jax = lambda: (time.sleep(4.0), slow())\n"  # a preload still importing
            "d.dask_setup(None)\nLocateTrial(range_km=400000.0)._base()\n"
            "assert not d._STARTED[0].is_alive(), 'the trial ran before the preload had finished'\nprint('ok')\n")
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300)
    assert r.returncode == 0 and r.stdout.strip() == "ok", r.stderr[-2000:]
