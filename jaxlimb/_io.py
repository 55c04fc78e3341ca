"""Small file helpers shared by every writer: atomic writes, the writer's lock, stale temporaries."""

from __future__ import annotations

import contextlib
import glob
import json
import os
import tempfile
from collections.abc import Iterator
from pathlib import Path
from typing import IO, Any


def _umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask


@contextlib.contextmanager
def atomic_path(path: str | os.PathLike[str]) -> Iterator[Path]:
    """Yield a temporary path beside ``path``; rename it onto ``path`` on success.

    The rename is atomic on POSIX, so readers see either the old file or the whole
    new one, never a half-written file.  On an exception the temporary is removed
    and ``path`` is untouched.  The temporary's name carries the writer's process id
    (``.NAME.PID-XXXX.tmp``): a writer that was killed (SIGKILL, power loss) leaves its
    temporary behind, and the next write of ``path`` removes it (:func:`remove_dead_temporaries`).
    """
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    remove_dead_temporaries(path)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.{os.getpid()}-", suffix=".tmp", dir=path.parent)
    os.close(fd)
    tmp_path = Path(tmp)
    os.chmod(tmp_path, 0o666 & ~_umask())  # mkstemp makes 0600; give the file the usual mode
    try:
        yield tmp_path
        os.replace(tmp_path, path)
    except BaseException:
        with contextlib.suppress(FileNotFoundError):
            tmp_path.unlink()
        raise


@contextlib.contextmanager
def atomic_open(path: str | os.PathLike[str], mode: str = "w") -> Iterator[IO[Any]]:
    """Open a temporary file for writing and atomically move it onto ``path``."""
    with atomic_path(path) as tmp, open(tmp, mode) as fh:
        yield fh
        fh.flush()
        os.fsync(fh.fileno())


def read_json_file(path: str | os.PathLike[str], what: str) -> Any:
    """Parse a JSON file; a missing/unreadable file or bad JSON is a :class:`~jaxlimb.errors.ConfigError`.

    ``what`` names the file in the message (``"camera file"``, ``"hints file"``...).
    """
    from .errors import ConfigError

    from ._validate import input_file

    p = input_file(path, what, error=ConfigError)  # a directory is a directory, not "missing"
    try:
        text = p.read_text(encoding="utf-8")
    except OSError as e:
        raise ConfigError(f"cannot read {what} {str(p)!r}: {e.strerror or e}") from None
    except UnicodeDecodeError:
        raise ConfigError(f"{what} {str(p)!r} is not valid JSON: it is not UTF-8 text (a binary file?)") from None
    try:
        return json.loads(text)
    except json.JSONDecodeError as e:
        raise ConfigError(f"{what} {str(p)!r} is not valid JSON: {e.msg} at line {e.lineno}") from None


def write_json_atomic(path: str | os.PathLike[str], obj: Any) -> None:
    """Write ``obj`` as indented JSON to ``path`` atomically."""
    with atomic_open(path, "w") as fh:
        json.dump(obj, fh, indent=2, sort_keys=False)
        fh.write("\n")


def stale_temporaries(path: str | os.PathLike[str]) -> list[Path]:
    """The temporaries :func:`atomic_path` leaves beside ``path`` when its writer is killed."""
    p = Path(path)
    return sorted(p.parent.glob(f".{glob.escape(p.name)}.*.tmp")) if p.parent.is_dir() else []


def _writer_pid(tmp: Path, name: str) -> int | None:
    """The process id in a temporary's name ``.NAME.PID-XXXX.tmp`` (None for other names)."""
    pid = tmp.name[len(name) + 2 : -len(".tmp")].split("-", 1)[0]
    return int(pid) if pid.isdigit() else None


def _alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:  # another user's live process
        return True
    return True


def remove_dead_temporaries(path: str | os.PathLike[str]) -> list[Path]:
    """Remove the temporaries of ``path`` whose writer process no longer exists; return them.

    A live writer's temporary (its process still runs) is left alone, so concurrent atomic
    writers of one file never remove each other's work.
    """
    p = Path(path)
    removed = []
    for tmp in stale_temporaries(p):
        pid = _writer_pid(tmp, p.name)
        if pid is not None and pid != os.getpid() and not _alive(pid):
            with contextlib.suppress(OSError):
                tmp.unlink()
                removed.append(tmp)
    return removed


def sweep_dead_temporaries(directory: str | os.PathLike[str]) -> list[Path]:
    """:func:`remove_dead_temporaries` for every file of ``directory`` (a killed run's leftovers)."""
    d = Path(directory)
    if not d.is_dir():
        return []
    names = {t.name[1:-len(".tmp")].rsplit(".", 1)[0] for t in d.glob(".*.tmp")}
    return [t for name in sorted(names) for t in remove_dead_temporaries(d / name)]


@contextlib.contextmanager
def exclusive_output(path: str | os.PathLike[str]) -> Iterator[Path]:
    """Hold the writer's lock of ``path`` for the whole block (computation and write).

    The lock is ``flock`` on a hidden lock file ``.NAME.lock`` beside ``path``; a second
    writer of the same ``path`` is refused at once with
    :class:`~jaxlimb.errors.OutputBusyError` (no database is silently lost to a race).
    Under the lock, the temporaries of an earlier writer that was killed mid-write
    (:func:`remove_dead_temporaries`, and untagged ones of older versions) are removed.
    The lock file is removed on exit.
    """
    import fcntl

    from .errors import OutputBusyError

    p = Path(path)
    lock = p.parent / f".{p.name}.lock"
    while True:
        fd = os.open(lock, os.O_RDWR | os.O_CREAT, 0o666 & ~_umask())
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            os.close(fd)
            raise OutputBusyError(f"another jaxlimb process is writing {str(p)!r} (lock {str(lock)!r} is held); "
                                  "wait for it or choose another output") from None
        try:
            same = os.fstat(fd).st_ino == os.stat(lock).st_ino  # not unlinked by the previous holder meanwhile
        except FileNotFoundError:
            same = False
        if same:
            break
        os.close(fd)
    try:
        remove_dead_temporaries(p)
        for tmp in stale_temporaries(p):  # untagged ones (older versions): only a lock holder may remove them
            if _writer_pid(tmp, p.name) is None:
                with contextlib.suppress(OSError):
                    tmp.unlink()
        yield p
    finally:
        with contextlib.suppress(OSError):
            lock.unlink()
        os.close(fd)
