"""Small file helpers shared by every reader and writer: atomic writes, whole appended lines, the
writer's lock, stale temporaries, and strict JSON input files.

* :func:`atomic_path` / :func:`atomic_open`: a file appears whole or not at all (temporary + rename);
* :func:`append_whole`: one record appended whole or not at all (short writes completed, a failure
  cut back to the previous end of the file);
* :func:`exclusive_output`: one writer per output file (``flock``), a second one refused at once with
  the holder's process id and host;
* :func:`read_json_file`: a JSON file that is what it claims -- no duplicate keys, bounded nesting and
  integer length, a UTF-8 byte-order mark accepted.

A write that fails for want of space or because the device fails (``ENOSPC``, ``EDQUOT``, ``EFBIG``,
``EIO``, ``EROFS``) raises :class:`~jaxlimb.errors.OutputWriteError` (CLI exit 2), never a bare ``OSError``.
"""

from __future__ import annotations

import contextlib
import errno
import glob
import itertools
import json
import os
import re
import socket
import tempfile
from collections.abc import Iterator
from pathlib import Path
from typing import IO, Any

#: ``errno`` values of a write that failed for want of space or a failing device (not a programming error).
WRITE_ERRNOS = frozenset({errno.ENOSPC, errno.EDQUOT, errno.EFBIG, errno.EIO, errno.EROFS})
#: Deepest nesting of arrays/objects accepted in a JSON input file (camera, hints, attitude files nest 3 deep).
MAX_JSON_DEPTH = 64
#: Most digits accepted in a JSON integer (a 64-bit integer has 20).
MAX_JSON_INT_DIGITS = 100
#: Largest JSON input file read (camera, hints and attitude files are a few hundred bytes).
MAX_JSON_BYTES = 16 << 20


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
    except BaseException as e:
        with contextlib.suppress(FileNotFoundError):
            tmp_path.unlink()
        if isinstance(e, OSError) and e.errno in WRITE_ERRNOS:
            raise write_error(path, e) from None
        raise


def write_error(path: str | os.PathLike[str], e: OSError) -> Exception:
    """The :class:`~jaxlimb.errors.OutputWriteError` of a failed write of ``path`` (one line, the OS reason)."""
    from .errors import OutputWriteError

    code = errno.errorcode.get(e.errno or 0, "?")
    return OutputWriteError(f"cannot write {str(path)!r}: {e.strerror or e} ({code})")


def append_whole(fd: int, data: bytes, name: str, *, sync: bool = True) -> None:
    """Append ``data`` to the file open on ``fd`` (``O_APPEND``) whole, or leave the file as it was.

    ``os.write`` may write less than asked (a full disk that frees space, a signal): the rest is
    written until all is out.  Any failure -- ``ENOSPC``/``EIO`` (raised as
    :class:`~jaxlimb.errors.OutputWriteError` naming ``name``), an interrupt, an exception of a signal
    handler -- cuts the file back to its length before the call, so a reader (``--resume``) never sees
    half a record.  The caller must be the file's only writer (:func:`exclusive_output`).
    """
    start = os.fstat(fd).st_size
    view = memoryview(data)
    try:
        while view:
            n = os.write(fd, view)
            if n <= 0:  # a write of nothing: treat as a full device rather than loop for ever
                raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))
            view = view[n:]
        if sync:
            os.fsync(fd)
    except BaseException as e:
        with contextlib.suppress(OSError):
            os.ftruncate(fd, start)
        if isinstance(e, OSError) and e.errno in WRITE_ERRNOS:
            raise write_error(name, e) from None
        raise


@contextlib.contextmanager
def atomic_open(path: str | os.PathLike[str], mode: str = "w") -> Iterator[IO[Any]]:
    """Open a temporary file for writing and atomically move it onto ``path``."""
    with atomic_path(path) as tmp, open(tmp, mode) as fh:
        yield fh
        fh.flush()
        os.fsync(fh.fileno())


def read_json_file(path: str | os.PathLike[str], what: str) -> Any:
    """Parse a JSON file strictly (:func:`loads_strict`); a missing/unreadable file or bad JSON is a
    :class:`~jaxlimb.errors.ConfigError`.

    ``what`` names the file in the message (``"camera file"``, ``"hints file"``...).
    """
    from .errors import ConfigError

    from ._validate import input_file

    p = input_file(path, what, error=ConfigError)  # a directory is a directory, not "missing"
    try:
        if p.stat().st_size > MAX_JSON_BYTES:
            raise ConfigError(f"{what} {str(p)!r} is {p.stat().st_size} bytes: not a jaxlimb JSON file "
                              f"(at most {MAX_JSON_BYTES >> 20} MiB)")
        raw = p.read_bytes()
    except OSError as e:
        raise ConfigError(f"cannot read {what} {str(p)!r}: {e.strerror or e}") from None
    try:
        text = raw.decode("utf-8-sig")  # a byte-order mark is accepted (and dropped)
    except UnicodeDecodeError:
        raise ConfigError(f"{what} {str(p)!r} is not valid JSON: it is not UTF-8 text (a binary file?)") from None
    return loads_strict(text, f"{what} {str(p)!r}")


_STRINGS = re.compile(r'"(?:[^"\\]|\\.)*"')
_NOT_BRACKETS = re.compile(r"[^\[\]{}]+")
_STEP = {"[": 1, "{": 1, "]": -1, "}": -1}


def loads_strict(text: str, what: str) -> Any:
    """``json.loads`` of a file that is what it claims, else :class:`~jaxlimb.errors.ConfigError` naming ``what``.

    Refused: invalid JSON; an object with the same key twice (JSON takes the last one silently: a
    second ``"body"`` would change the answer); nesting deeper than :data:`MAX_JSON_DEPTH`; an integer
    of more than :data:`MAX_JSON_INT_DIGITS` digits.  Checked before any value is built, so no input
    reaches Python's recursion or integer-size limits.
    """
    from .errors import ConfigError

    text = text.removeprefix("\ufeff")
    depth = _max_depth(text)
    if depth > MAX_JSON_DEPTH:
        raise ConfigError(f"{what} nests arrays/objects {depth} deep; at most {MAX_JSON_DEPTH} are accepted")

    def pairs(items: list[tuple[str, Any]]) -> dict[str, Any]:
        out: dict[str, Any] = {}
        for k, v in items:
            if k in out:
                raise ConfigError(f"{what} has the key {k!r} twice in one object; each key may appear once")
            out[k] = v
        return out

    def integer(digits: str) -> int:
        n = len(digits.lstrip("-"))
        if n > MAX_JSON_INT_DIGITS:
            raise ConfigError(f"{what} holds an integer of {n} digits; at most {MAX_JSON_INT_DIGITS} are accepted")
        return int(digits)

    try:
        return json.loads(text, object_pairs_hook=pairs, parse_int=integer)
    except json.JSONDecodeError as e:
        raise ConfigError(f"{what} is not valid JSON: {e.msg} at line {e.lineno}") from None
    except RecursionError:  # pragma: no cover - the depth check comes first
        raise ConfigError(f"{what} nests arrays/objects too deep") from None


def _max_depth(text: str) -> int:
    """Deepest nesting of ``[``/``{`` in JSON ``text`` (brackets inside strings not counted)."""
    brackets = _NOT_BRACKETS.sub("", _STRINGS.sub("", text))
    return max(itertools.accumulate(map(_STEP.__getitem__, brackets)), default=0)


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

    The lock is ``flock`` on a hidden lock file ``.NAME.lock`` beside ``path``, which holds the
    holder's process id and host; a second writer of the same ``path`` is refused at once with
    :class:`~jaxlimb.errors.OutputBusyError` naming that holder (and saying when it is stopped).
    The kernel releases a ``flock`` when its holder dies, so a killed writer never leaves a lock
    that refuses the next run.  Under the lock, the temporaries of an earlier writer that was
    killed mid-write (:func:`remove_dead_temporaries`, and untagged ones of older versions) are
    removed.  The lock file is removed on exit.
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
            holder = _lock_holder(fd)
            os.close(fd)
            raise OutputBusyError(f"another jaxlimb process ({holder}) is writing {str(p)!r} (lock {str(lock)!r}); "
                                  "wait for it to end or choose another output") from None
        try:
            same = os.fstat(fd).st_ino == os.stat(lock).st_ino  # not unlinked by the previous holder meanwhile
        except FileNotFoundError:
            same = False
        if same:
            break
        os.close(fd)
    with contextlib.suppress(OSError):  # who holds it, for the message of a refused second writer
        os.ftruncate(fd, 0)
        os.pwrite(fd, f"{os.getpid()} {socket.gethostname()}\n".encode(), 0)
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


def _lock_holder(fd: int) -> str:
    """``"pid 123 on host h"`` (``", stopped"`` when that process is stopped) from a held lock file."""
    try:
        pid_s, host = os.pread(fd, 256, 0).decode("utf-8", "replace").split()[:2]
        pid = int(pid_s)
    except (OSError, ValueError):
        return "holder unknown"
    text = f"pid {pid} on host {host}"
    if host == socket.gethostname():
        state = process_state(pid)
        if state == "T":
            text += ", stopped (SIGSTOP/Ctrl-Z): resume it with `kill -CONT` or end it"
    return text


def process_state(pid: int) -> str | None:
    """The state letter of local process ``pid`` (``R``, ``S``, ``T`` stopped, ``Z`` zombie...), or ``None``
    when it does not exist or cannot be read (``/proc`` on Linux)."""
    try:
        stat = Path(f"/proc/{pid}/stat").read_text()
    except OSError:
        return None if not _alive(pid) else "?"
    return stat[stat.rindex(")") + 2 :].split(" ", 1)[0]
