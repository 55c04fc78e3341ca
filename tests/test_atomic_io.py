"""Files are written atomically: a failure leaves the old file intact and no temporary behind."""

import json
import os

import pytest

from jaxlimb._io import atomic_open, write_json_atomic


def test_write_and_mode(tmp_path):
    p = tmp_path / "sub" / "a.json"
    write_json_atomic(p, {"x": 1})
    assert json.loads(p.read_text()) == {"x": 1}
    assert oct(os.stat(p).st_mode & 0o777) != "0o600"


def test_failure_keeps_old_file(tmp_path):
    p = tmp_path / "a.json"
    write_json_atomic(p, {"old": True})
    with pytest.raises(RuntimeError):
        with atomic_open(p) as fh:
            fh.write('{"new": tru')
            raise RuntimeError("interrupted")
    assert json.loads(p.read_text()) == {"old": True}
    assert sorted(x.name for x in tmp_path.iterdir()) == ["a.json"]


def _dead_pid() -> int:
    pid = 4_000_000
    while True:
        try:
            os.kill(pid, 0)
        except ProcessLookupError:
            return pid
        except PermissionError:
            pass
        pid -= 1


def test_next_write_removes_the_temporary_of_a_killed_writer(tmp_path):
    """A writer killed mid-write leaves ``.NAME.PID-XXXX.tmp``; the next write of NAME removes it,
    but never a live writer's temporary nor another file's."""
    p = tmp_path / "a.json"
    dead = tmp_path / f".a.json.{_dead_pid()}-k1ll3d.tmp"
    live = tmp_path / f".a.json.{os.getppid()}-w0rk1ng.tmp"  # our parent process: alive
    other = tmp_path / f".b.json.{_dead_pid()}-x.tmp"
    for t in (dead, live, other):
        t.write_text("half")
    write_json_atomic(p, {"x": 1})
    assert not dead.exists() and live.exists() and other.exists()
    assert json.loads(p.read_text()) == {"x": 1}


def test_sweep_removes_every_dead_writers_temporary_of_a_directory(tmp_path):
    """A killed Monte Carlo leaves ``.chunk_NNNNNN.npz.PID-XXXX.tmp`` files; the next run sweeps them."""
    from jaxlimb._io import sweep_dead_temporaries

    dead = [tmp_path / f".chunk_00000{i}.npz.{_dead_pid()}-k1ll3d.tmp" for i in range(3)]
    live = tmp_path / f".chunk_000009.npz.{os.getppid()}-w0rk1ng.tmp"
    keep = tmp_path / "chunk_000001.npz"
    for t in (*dead, live, keep):
        t.write_text("x")
    assert sorted(sweep_dead_temporaries(tmp_path)) == sorted(dead)
    assert live.exists() and keep.exists() and not any(t.exists() for t in dead)
    assert sweep_dead_temporaries(tmp_path / "missing") == []
