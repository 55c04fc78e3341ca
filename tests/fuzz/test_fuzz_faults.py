"""Faults a user's machine produces: nothing lost, nothing duplicated, never an answer that differs.

* disk full (a fault-injecting ``os.write``: short writes, then ``ENOSPC``): whole lines only, exit 2
  ``write_failed``, and ``--resume`` completes the run;
* one writer per ``--out``: a second run is refused naming the holder; two runs started together, or two
  ``--resume`` of one partial file, leave every frame once;
* kill -9, SIGTERM and SIGINT mid-run: exit 137/143/130 with at most one message, and ``--resume`` gives
  the records of an uninterrupted run;
* the environment: ``JAX_PLATFORMS`` naming a platform that is not there, closed stdin/stderr,
  ``JAXLIMB_CACHE`` naming a file: exit 2 with one line, or the run as usual -- never a Python error;
* a damaged cache (a flipped bit in every entry, junk entries, JAX's ``-atime`` files deleted, its lock
  held by a stopped process): the same answer, one warning per cache, no wait on the lock;
* Dask workers start with their stderr on ``/dev/null`` (a Ctrl-C during their start printed a traceback each).

The many-frame runs are ``los locate --no-refine`` (no JAX start: a process takes ~1 s).
"""

from __future__ import annotations

import errno
import json
import os
import signal
import subprocess
import sys
import time

import pytest

from ._cli import assert_refused, run_cli
from ._hostile import CACHED_PROGRAM, damage_cache, stopped_lock_holder

N_FRAMES = 40
_CMD = [sys.executable, "-m", "jaxlimb.cli"]


def _env(**extra: str) -> dict[str, str]:
    env = {k: v for k, v in os.environ.items() if k != "JAXLIMB_DEBUG"}
    env.update(extra)
    return env


@pytest.fixture(scope="module")
def run(inputs, tmp_path_factory):
    """Frames (links to a few distinct images), a database, and the records of an uninterrupted run."""
    d = tmp_path_factory.mktemp("faults")
    (d / "frames").mkdir()
    sources = [inputs["moon.png"], inputs["noise.png"], inputs["black.png"]]
    for i in range(N_FRAMES):
        (d / "frames" / f"f{i:03d}.png").symlink_to(sources[i % 3])
    db = d / "db.npz"
    assert run_cli(["los", "build-db", inputs["mesh.obj"], "--out", db, "--step-deg", "30", "--template-size", "64",
                    "--json", "--no-progress"]).code == 0
    argv = ["los", "locate", str(d / "frames"), "--db", str(db), "--camera", str(inputs["camera.json"]), "--no-refine"]
    ref = d / "ref.jsonl"
    assert run_cli([*argv, "--out", ref]).code in (0, 2, 3)
    return {"dir": d, "argv": argv, "ref": _records(ref)}


def _records(path) -> list[dict]:  # noqa: ANN001
    return [{k: v for k, v in json.loads(s).items() if k != "locate_seconds"} for s in path.read_text().splitlines()]


def _assert_same_as_uninterrupted(path, run) -> None:  # noqa: ANN001
    recs = _records(path)
    images = [r["image"] for r in recs]
    assert len(images) == len(set(images)) == N_FRAMES, "a frame lost or duplicated"
    assert sorted(recs, key=lambda r: r["image"]) == sorted(run["ref"], key=lambda r: r["image"])


# ----------------------------------------------------------------------------- disk full
class _FillingDisk:
    """``os.write`` of a disk that takes 7 bytes per call and is full from call ``full_at`` on."""

    def __init__(self, full_at: int) -> None:
        self.real, self.calls, self.full_at = os.write, 0, full_at

    def __call__(self, fd: int, data) -> int:  # noqa: ANN001
        self.calls += 1
        if self.calls >= self.full_at:
            raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))
        return self.real(fd, bytes(data[:7]))


def test_disk_full_mid_run_stops_typed_and_resume_completes(run, monkeypatch):
    out = run["dir"] / "full.jsonl"
    disk = _FillingDisk(full_at=250)  # a few records in, mid-record
    monkeypatch.setattr(os, "write", disk)
    res = run_cli([*run["argv"], "--out", out, "--json"])
    monkeypatch.undo()
    assert res.code == 2 and disk.calls >= 250
    assert_refused(res, 2, str(out), check="write_failed")
    partial = out.read_bytes()
    assert partial.endswith(b"\n") and 0 < partial.count(b"\n") < N_FRAMES  # whole lines only
    res = run_cli([*run["argv"], "--out", out, "--resume"])
    assert res.code in (0, 2, 3) and "Traceback" not in res.err
    _assert_same_as_uninterrupted(out, run)


# ----------------------------------------------------------------------------- one writer
def test_second_writer_of_a_many_frame_output_is_refused_naming_the_holder(run):
    from jaxlimb._io import exclusive_output

    out = run["dir"] / "busy.jsonl"
    with exclusive_output(out):  # a run in progress
        for extra in ([], ["--resume"]):
            res = run_cli([*run["argv"], "--out", out, *extra, "--json"])
            assert_refused(res, 2, f"pid {os.getpid()}", check="output_busy")
    assert not out.exists() or out.stat().st_size == 0


#: ``_CMD`` exec'd with SIGINT at its default: a suite started in the background (``nohup``, ``&``) passes SIGINT
#: ignored to its children, and a Python started so keeps ignoring it, as a command should (no ``preexec_fn``: a
#: fork of the JAX-threaded worker).
_CMD_SIGINT = [sys.executable, "-c", "import os, signal, sys; signal.signal(signal.SIGINT, signal.SIG_DFL); "
               "os.execv(sys.executable, [sys.executable, '-m', 'jaxlimb.cli', *sys.argv[1:]])"]


def _start(run, out, *extra: str, **env: str) -> subprocess.Popen:  # noqa: ANN001
    return subprocess.Popen([*_CMD_SIGINT, *run["argv"], "--out", str(out), *extra], stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True, env=_env(**env))


def _wait_lines(path, n: int, proc: subprocess.Popen, timeout: float = 120.0) -> None:  # noqa: ANN001
    t_end = time.monotonic() + timeout
    while time.monotonic() < t_end and proc.poll() is None:
        if path.exists() and path.read_bytes().count(b"\n") >= n:
            return
        time.sleep(0.005)


def test_two_writers_started_together_leave_every_frame_once(run):
    out = run["dir"] / "two.jsonl"
    a, b = _start(run, out), _start(run, out)
    results = [(p.wait(timeout=300), *p.communicate()) for p in (a, b)]
    codes = sorted(code for code, _, _ in results)
    refused = [err for code, _, err in results if code == 2 and "--resume" not in err and "pid" in err]
    assert len(refused) == 1 or codes.count(2) == 1, results  # one ran; the other was refused (lock or file)
    assert all("Traceback" not in err for _, _, err in results)
    _assert_same_as_uninterrupted(out, run)


@pytest.mark.parametrize("sig", [signal.SIGKILL, signal.SIGTERM, signal.SIGINT])
def test_interrupted_run_resumed_equals_an_uninterrupted_one(run, sig):
    out = run["dir"] / f"sig{int(sig)}.jsonl"
    proc = _start(run, out)
    _wait_lines(out, 5, proc)
    proc.send_signal(signal.SIGSTOP)  # held still: the frames it has written are all it will have written
    if proc.poll() is not None or out.read_bytes().count(b"\n") >= N_FRAMES:
        proc.send_signal(signal.SIGCONT)
        proc.wait(timeout=120)
        pytest.skip("the run ended before the signal (machine too fast for this frame count)")
    proc.send_signal(sig)
    proc.send_signal(signal.SIGCONT)
    code = proc.wait(timeout=120)
    _, err = proc.communicate()
    assert code == {signal.SIGKILL: -9, signal.SIGTERM: 143, signal.SIGINT: 130}[sig], err
    if sig != signal.SIGKILL:  # one message, naming the signal
        lines = err.splitlines()
        assert len(lines) == 1 and lines[0].startswith("jaxlimb: error:") and sig.name in lines[0], lines
    partial = out.read_bytes()
    assert partial.count(b"\n") < N_FRAMES
    if sig == signal.SIGKILL:  # two --resume together on the killed run's file: one continues it
        a, b = _start(run, out, "--resume"), _start(run, out, "--resume")
        for p in (a, b):
            p.wait(timeout=300)
            assert "Traceback" not in p.communicate()[1]
    else:
        res = run_cli([*run["argv"], "--out", out, "--resume"])
        assert res.code in (0, 2, 3) and "Traceback" not in res.err
    _assert_same_as_uninterrupted(out, run)


# ----------------------------------------------------------------------------- the environment
def test_hostile_environment_is_one_line_or_a_normal_run(inputs, tmp_path):
    missing = str(inputs["missing"])
    a_file = tmp_path / "not-a-dir"
    a_file.write_text("x")
    env_off = {"JAXLIMB_CACHE_DIR": "off"}
    sh = ["sh", "-c"]
    procs = {
        "cuda": subprocess.Popen([*_CMD, "locate", str(inputs["moon.png"]), "--json"], stdout=subprocess.PIPE,
                                 stderr=subprocess.PIPE, text=True, env=_env(JAX_PLATFORMS="cuda", **env_off)),
        "closed": subprocess.Popen([*sh, f'exec "$@" <&- 2>&-', "sh", *_CMD, "locate", missing, "--json"],
                                   stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=_env(**env_off)),
        "cache-file": subprocess.Popen([*_CMD, "locate", missing, "--json"], stdout=subprocess.PIPE,
                                       stderr=subprocess.PIPE, text=True,
                                       env={**_env(JAXLIMB_CACHE=str(a_file)), "JAXLIMB_CACHE_DIR": ""}),
        "stdout-full": subprocess.Popen([*sh, 'exec "$@" > /dev/full', "sh", *_CMD, "los", "build-db",
                                         str(inputs["mesh.obj"]), "--out", str(tmp_path / "db.npz"), "--step-deg", "30",
                                         "--template-size", "64", "--no-progress", "--json"],
                                        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=_env()),
    }
    out = {k: (p.wait(timeout=300), *p.communicate()) for k, p in procs.items()}
    code, stdout, stderr = out["cuda"]
    assert code == 2 and json.loads(stdout)["check"] == "bad_config" and "JAX_PLATFORMS='cuda'" in stdout, out["cuda"]
    code, stdout, stderr = out["closed"]
    assert code == 2 and json.loads(stdout)["check"] == "bad_image" and stderr == "", out["closed"]
    code, stdout, stderr = out["cache-file"]
    assert code == 2 and json.loads(stdout)["check"] == "bad_image", out["cache-file"]
    assert "Traceback" not in stderr and all(ln.startswith("jaxlimb: warning:") for ln in stderr.splitlines())
    code, stdout, stderr = out["stdout-full"]  # the database is written; its summary cannot be
    assert code == 2 and stderr.startswith("jaxlimb: error: cannot write '<stdout>'") and len(stderr.splitlines()) == 1
    assert (tmp_path / "db.npz").is_file()


# ----------------------------------------------------------------------------- a damaged cache


def test_damaged_cache_gives_the_same_answer_without_waiting_on_its_lock(tmp_path):
    cache = tmp_path / "cache"
    env = _env(JAXLIMB_CACHE_DIR=str(cache))
    first = json.loads(subprocess.run([sys.executable, "-c", CACHED_PROGRAM], capture_output=True, text=True, env=env,
                                      check=True).stdout)
    assert first["warnings"] == []
    entries = damage_cache(cache)
    assert len(entries) >= 3
    with stopped_lock_holder(cache / ".lockfile"):  # JAX's own cache waited 10 s per access on it
        second = json.loads(subprocess.run([sys.executable, "-c", CACHED_PROGRAM], capture_output=True, text=True,
                                           env=env, check=True).stdout)
    assert (second["y"], second["n"], second["z"]) == (first["y"], first["n"], first["z"])  # bit for bit
    assert 1 <= len(second["warnings"]) <= 2 and all("failed its check" in w for w in second["warnings"])
    assert second["s"] < first["s"] + 15.0  # no 10-s lock timeouts (JAX's own cache waited on every access)
    assert all(p.exists() and len(p.read_bytes()) > 0 for p in entries if p.suffix == ".bin")  # exported again


# ----------------------------------------------------------------------------- Dask workers' start
def test_worker_processes_start_with_stderr_on_dev_null(capfd):
    from jaxlimb.analysis.distributed import _workers_start_quietly

    with _workers_start_quietly():
        subprocess.run([sys.executable, "-c", "import sys; sys.stderr.write('worker traceback\\n')"], check=True)
    subprocess.run([sys.executable, "-c", "import sys; sys.stderr.write('parent message\\n')"], check=True)
    err = capfd.readouterr().err
    assert "worker traceback" not in err and "parent message" in err
