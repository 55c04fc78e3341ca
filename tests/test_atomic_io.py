"""Files are written atomically: a failure leaves the old file intact and no temporary behind; appended
records are whole or absent (short writes, a full disk, an interrupt); one writer per output; JSON input
files are what they claim."""

import errno
import fcntl
import json
import os
import signal
import subprocess
import sys

import pytest

from jaxlimb._io import append_whole, atomic_open, exclusive_output, loads_strict, read_json_file, write_json_atomic
from jaxlimb.errors import ConfigError, OutputBusyError, OutputWriteError


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


# ----------------------------------------------------------------------------- whole appended records
class FaultyWrites:
    """``os.write`` of a disk that writes ``short`` bytes per call and fails with ``fail`` on call number ``at``."""

    def __init__(self, short: int = 3, at: int | None = None, fail: BaseException | None = None) -> None:
        self.real, self.short, self.at, self.fail, self.calls = os.write, short, at, fail, 0

    def __call__(self, fd: int, data) -> int:  # noqa: ANN001
        self.calls += 1
        if self.at is not None and self.calls == self.at:
            raise self.fail
        return self.real(fd, bytes(data[: self.short]))


def _appended(tmp_path, monkeypatch, writes: FaultyWrites, records: list[bytes]) -> tuple[bytes, BaseException | None]:
    p = tmp_path / "out.jsonl"
    fd = os.open(p, os.O_WRONLY | os.O_APPEND | os.O_CREAT, 0o644)
    monkeypatch.setattr(os, "write", writes)
    err = None
    try:
        for rec in records:
            append_whole(fd, rec, str(p))
    except BaseException as e:  # noqa: BLE001 - what the writer raised is the point
        err = e
    finally:
        monkeypatch.undo()
        os.close(fd)
    return p.read_bytes(), err


def test_short_writes_are_completed(tmp_path, monkeypatch):
    recs = [b'{"a": 1}\n', b'{"b": 22}\n', b'{"c": 333}\n']
    data, err = _appended(tmp_path, monkeypatch, FaultyWrites(short=2), recs)
    assert err is None and data == b"".join(recs)


@pytest.mark.parametrize("code", [errno.ENOSPC, errno.EIO, errno.EDQUOT])
def test_a_full_disk_mid_record_is_cut_back_and_typed(tmp_path, monkeypatch, code):
    """The 2nd record fails after 3 of its bytes: the file keeps the 1st record whole, nothing of the 2nd."""
    recs = [b'{"a": 1}\n', b'{"b": 22}\n']
    per = -(-len(recs[0]) // 3)  # calls the first record takes at 3 bytes per call
    data, err = _appended(tmp_path, monkeypatch, FaultyWrites(short=3, at=per + 2, fail=OSError(code, os.strerror(code))),
                          recs)
    assert isinstance(err, OutputWriteError) and err.exit_code == 2 and err.check == "write_failed"
    assert "out.jsonl" in str(err) and errno.errorcode[code] in str(err)
    assert data == recs[0]


def test_an_interrupt_mid_record_leaves_no_half_line(tmp_path, monkeypatch):
    recs = [b'{"a": 1}\n', b'{"b": 22}\n']
    data, err = _appended(tmp_path, monkeypatch, FaultyWrites(short=4, at=5, fail=KeyboardInterrupt()), recs)
    assert isinstance(err, KeyboardInterrupt) and data == recs[0]


def test_atomic_write_on_a_full_disk_is_typed_and_leaves_nothing(tmp_path, monkeypatch):
    p = tmp_path / "a.json"
    write_json_atomic(p, {"old": True})

    def full(fd):  # noqa: ANN001
        raise OSError(errno.ENOSPC, "No space left on device")

    monkeypatch.setattr(os, "fsync", full)
    with pytest.raises(OutputWriteError, match="No space left"):
        write_json_atomic(p, {"new": True})
    assert json.loads(p.read_text()) == {"old": True} and sorted(x.name for x in tmp_path.iterdir()) == ["a.json"]


# ----------------------------------------------------------------------------- one writer per output
def test_second_writer_is_refused_naming_the_holder(tmp_path):
    p = tmp_path / "out.jsonl"
    with exclusive_output(p):
        with pytest.raises(OutputBusyError, match=rf"pid {os.getpid()} on host"):
            with exclusive_output(p):
                pass
    with exclusive_output(p):  # released: the next writer gets it
        pass


def test_a_stopped_holder_is_named_as_stopped_and_a_dead_one_frees_the_lock(tmp_path):
    p = tmp_path / "out.jsonl"
    code = ("import sys; from jaxlimb._io import exclusive_output\n"
            "with exclusive_output(sys.argv[1]):\n    print('locked', flush=True); sys.stdin.read()\n")
    with subprocess.Popen([sys.executable, "-c", code, str(p)], stdin=subprocess.PIPE, stdout=subprocess.PIPE) as holder:
        try:
            assert holder.stdout.readline().strip() == b"locked"
            os.kill(holder.pid, signal.SIGSTOP)
            with pytest.raises(OutputBusyError, match=rf"pid {holder.pid} on host .*stopped"):
                with exclusive_output(p):
                    pass
        finally:
            holder.kill()  # SIGKILL: no clean-up ran, the kernel releases the flock
            holder.wait(timeout=30)
    with exclusive_output(p):
        pass


# ----------------------------------------------------------------------------- strict JSON files
@pytest.mark.parametrize(("text", "match"), [
    ('{"body": "moon", "body": "earth"}', "key 'body' twice"),
    ("[" * 200_000 + "]" * 200_000, "200000 deep"),
    ('{"rows": ' + "9" * 5000 + "}", "5000 digits"),
    ('{"rows": 1,}', "not valid JSON"),
])
def test_json_that_is_not_what_it_claims_is_refused(text, match, tmp_path):
    p = tmp_path / "f.json"
    p.write_text(text)
    with pytest.raises(ConfigError, match=match):
        read_json_file(p, "camera file")


def test_json_with_a_byte_order_mark_and_brackets_in_strings_is_read(tmp_path):
    p = tmp_path / "f.json"
    p.write_bytes(b"\xef\xbb\xbf" + json.dumps({"note": "[[[{{", "v": [1, [2]]}).encode())
    assert read_json_file(p, "hints file") == {"note": "[[[{{", "v": [1, [2]]}
    assert loads_strict('"x"', "f") == "x"


def test_fcntl_lock_of_the_output_is_the_one_the_cli_takes(tmp_path):
    """A writer holding the lock by hand (another tool, an older jaxlimb) refuses jaxlimb too."""
    p = tmp_path / "out.jsonl"
    fd = os.open(tmp_path / ".out.jsonl.lock", os.O_RDWR | os.O_CREAT)
    try:
        fcntl.flock(fd, fcntl.LOCK_EX)
        with pytest.raises(OutputBusyError, match="holder unknown"):
            with exclusive_output(p):
                pass
    finally:
        os.close(fd)
