"""Many frames per call: the runner behind ``jaxlimb locate`` / ``jaxlimb los locate`` on many images.

Images.  Each ``IMAGE`` argument is a file, a directory (its image files, sorted by name), a
glob pattern (``'frames/*.png'``, quoted so that the shell does not expand it; sorted), or
``@LIST`` (a text file with one image path per line; blank lines and ``#`` comments skipped;
relative paths are taken from the current directory).  A frame named twice is processed once.

Output.  One JSON object per frame and per line (JSON Lines), the command's ``--json`` object
plus ``"image": PATH`` and ``"run_settings"`` (a digest of the command, its options and the
contents of its camera, hints, database/mesh and kernel files); a frame that fails gives its
error object (``{"status": "error", "check", "message", "image"}``) and the run goes on.  On
stdout, or with ``--out FILE.jsonl`` appended to FILE, each line written whole and flushed to
disk (:func:`jaxlimb._io.append_whole`: a short write is completed, a failed one -- a full disk,
an interrupt -- is cut back off the file, and a full disk stops the run with exit 2, check
``write_failed``).  A progress bar (tqdm) goes to stderr (:func:`jaxlimb.cli.show_progress`: when it is a terminal,
unless ``--quiet``), and a one-line summary at the end.

One writer.  ``--out FILE`` is locked for the whole run, resume included
(:func:`jaxlimb._io.exclusive_output`): a second run writing the same FILE is refused at once
(exit 2, check ``output_busy``) naming the process that holds it.  A FIFO, a device or anything
else that is not a regular file is refused as ``--out`` before any work.

Resume.  ``--resume`` (with ``--out``) skips the frames FILE already holds (any status: an
error is an answer too, except ``internal_error``, which is retried); a partial last line left
by a crash is cut off first.  FILE must have been written by the same command with the same
settings (every record's ``run_settings``); a file of another command, camera, hints or options,
or a line that is not such a record, is refused (exit 2) rather than mixed.  Without ``--resume``
an existing non-empty FILE is refused (exit 2) rather than mixed with a new run.

Exit code (of the frames processed by this call): 0 when every frame is ok; else the worst of
1 (an internal error), 2 (a frame was unusable input, e.g. unreadable or wrong size) and 3 (a
check failed), in that order.

Dask.  ``--workers N`` (a ``LocalCluster``) or ``--scheduler ADDRESS`` (a running cluster) measures
chunks of frames as Dask tasks (:mod:`jaxlimb.analysis.distributed`); the records still arrive
in order and are written by this process, one line per frame, so ``--resume`` works the same.

Speed.  Every frame runs in the same process, so the compiled programs are reused (frames of
one camera share them: pixel sets are padded to size buckets) and the compilation is paid once
per call (or loaded from the persistent cache, :mod:`jaxlimb._jaxcache`).
"""

from __future__ import annotations

import argparse
import glob
import hashlib
import json
import os
import sys
from collections.abc import Callable, Iterable
from pathlib import Path
from typing import Any

IMAGE_SUFFIXES = frozenset({".png", ".tif", ".tiff", ".fits", ".fit", ".fts", ".jpg", ".jpeg", ".jp2", ".img",
                            ".vic", ".vicar", ".xml", ".lbl", ".pgm", ".bmp"})
"""Files a directory argument contributes (case-insensitive suffixes)."""
_SEVERITY = {0: 0, 3: 1, 2: 2, 1: 3}  # exit code -> rank; the worst rank wins


def add_batch_arguments(p: argparse.ArgumentParser) -> None:
    """The options of the many-frame mode (``--out``, ``--resume``)."""
    p.add_argument("--out", metavar="FILE.jsonl", default=None,
                   help="many frames: append one JSON line per frame to FILE (default: stdout)")
    p.add_argument("--resume", action="store_true",
                   help="many frames: skip the frames --out FILE already holds (continue an interrupted run)")
    from .._validate import Range, arg_number

    p.add_argument("--workers", type=arg_number(Range(1, 1024), integer=True), default=None,
                   help="many frames: measure chunks of frames on a Dask LocalCluster of N worker processes")
    p.add_argument("--scheduler", metavar="ADDRESS", default=None,
                   help="many frames: measure chunks of frames on a running Dask cluster (e.g. tcp://node:8786)")


def is_many(images: list[str], args: argparse.Namespace) -> bool:
    """Whether the call is a many-frame run (several images, a directory, a glob, @LIST, or --out)."""
    if any(not s.strip() for s in images):  # Path("") is the current directory: never a frame by accident
        from ..errors import ImageReadError

        raise ImageReadError("IMAGE is an empty path")
    if len(images) != 1 or args.out is not None or args.resume or args.workers is not None or args.scheduler:
        return True
    spec = images[0]
    return spec.startswith("@") or Path(spec).is_dir() or (glob.has_magic(spec) and not Path(spec).exists())


def one_per_frame(paths: list[str]) -> list[str]:
    """One file per frame: a detached PDS3 label (``X.LBL``) beside its image (``X.IMG``) is read with the image,
    and a PDS4 label (``X.xml``) names its data files (``X.IMG``, ``X.dat`` ...): the pair is one frame."""
    stems: dict[tuple[str, str], set[str]] = {}
    for p in paths:
        q = Path(p)
        stems.setdefault((str(q.parent), q.stem.lower()), set()).add(q.suffix.lower())

    def keep(p: str) -> bool:
        q = Path(p)
        sfx = stems[(str(q.parent), q.stem.lower())]
        if ".xml" in sfx:
            return q.suffix.lower() == ".xml"
        return not (q.suffix.lower() == ".lbl" and ".img" in sfx)

    return [p for p in paths if keep(p)]


def expand_images(specs: Iterable[str]) -> list[str]:
    """The image paths named by ``specs`` (module docstring), in order, without repeats.

    Raises
    ------
    ConfigError
        An unreadable list file, a glob that matches nothing, a directory without images.
    """
    from ..errors import ConfigError

    out: list[str] = []
    for spec in specs:
        if spec.startswith("@"):
            try:
                lines = Path(spec[1:]).read_text().splitlines()
            except (OSError, UnicodeDecodeError) as e:
                raise ConfigError(f"cannot read the image list {spec[1:]!r}: {getattr(e, 'strerror', None) or e}") from None
            out += [s.strip() for s in lines if s.strip() and not s.strip().startswith("#")]
        elif Path(spec).is_dir():
            found = sorted(str(p) for p in Path(spec).iterdir() if p.is_file() and p.suffix.lower() in IMAGE_SUFFIXES)
            if not found:
                raise ConfigError(f"directory {spec!r} holds no image files ({', '.join(sorted(IMAGE_SUFFIXES))})")
            out += one_per_frame(found)
        elif glob.has_magic(spec) and not Path(spec).exists():
            found = sorted(glob.glob(spec))
            if not found:
                raise ConfigError(f"pattern {spec!r} matches no file")
            out += one_per_frame(found)
        else:
            out.append(spec)
    if not out:
        raise ConfigError("no images to process")
    return list(dict.fromkeys(out))


# ------------------------------------------------------------------------------------ output file
#: Arguments that say how a run is carried out, not what it answers (left out of ``run_settings``).
_RUN_ONLY = frozenset({"image", "out", "resume", "workers", "scheduler", "json", "no_progress", "quiet",
                       "figure"})
#: Files up to this size enter ``run_settings`` by content; larger ones by size and modification time.
_HASH_CONTENT_BYTES = 64 << 20


def run_settings(args: argparse.Namespace) -> str:
    """Digest of what decides a run's answers: the command, its options, and the contents of the files
    they name (camera, hints, database or mesh, kernels); 16 hex digits."""
    items = {k: _setting(v) for k, v in sorted(vars(args).items()) if k not in _RUN_ONLY and not callable(v)}
    return hashlib.sha256(json.dumps(items, sort_keys=True, default=repr).encode()).hexdigest()[:16]


def _setting(value: Any) -> Any:
    if isinstance(value, (list, tuple)):
        return [_setting(v) for v in value]
    if isinstance(value, str) and value and os.path.isfile(value):
        try:
            st = os.stat(value)
            if st.st_size > _HASH_CONTENT_BYTES:
                return {"file_size": st.st_size, "mtime_ns": st.st_mtime_ns}
            return {"file_sha256": hashlib.sha256(Path(value).read_bytes()).hexdigest()}
        except OSError:
            return value  # unreadable: the command reports it itself
    return value


def _done_frames(path: Path, settings: str) -> set[str]:
    """Frames already answered in ``path`` by a run with these ``settings`` (a partial last line is cut off
    the file first); a file of another command or settings, or a line that is not a record, is refused."""
    from ..errors import ConfigError

    if not path.exists():
        return set()
    data = path.read_bytes()
    end = data.rfind(b"\n") + 1
    if end < len(data):  # a partial last line: the write that a crash interrupted
        with open(path, "r+b") as fh:
            fh.truncate(end)
    done: set[str] = set()
    for n, line in enumerate(data[:end].splitlines(), 1):
        if not line.strip():
            continue
        try:
            rec = json.loads(line)
        except (json.JSONDecodeError, UnicodeDecodeError):
            rec = None
        if not isinstance(rec, dict) or not isinstance(rec.get("image"), str):
            raise ConfigError(f"--resume: line {n} of {str(path)!r} is not a frame record of a jaxlimb run; "
                              "this file cannot be continued (choose a new --out)")
        if rec.get("run_settings") != settings:
            raise ConfigError(f"--resume: {str(path)!r} was written by another command or with other settings "
                              "(camera, hints, options or files; line " f"{n}); continue it with the same ones, "
                              "or choose a new --out")
        if rec.get("check") != "internal_error":
            done.add(rec["image"])
    return done


class _LineWriter:
    """JSON Lines to stdout, or appended to a file one whole line at a time (flushed to disk)."""

    def __init__(self, path: Path | None) -> None:
        self._path = path
        self._fd = None if path is None else os.open(path, os.O_WRONLY | os.O_APPEND | os.O_CREAT, 0o666)

    def write(self, rec: dict[str, Any]) -> None:
        from .._io import WRITE_ERRNOS, append_whole, write_error
        from . import json_default

        line = json.dumps(rec, allow_nan=False, default=json_default) + "\n"
        if self._fd is None:
            try:
                sys.stdout.write(line)
                sys.stdout.flush()
            except OSError as e:
                if e.errno in WRITE_ERRNOS:
                    raise write_error("<stdout>", e) from None
                raise
            return
        append_whole(self._fd, line.encode(), str(self._path))

    def close(self) -> None:
        if self._fd is not None:
            os.close(self._fd)
            self._fd = None


def check_out(args: argparse.Namespace) -> Path | None:
    """Validate ``--out`` / ``--resume`` before any work (exit 2 on a bad combination)."""
    from ..errors import ConfigError

    if args.out is None:
        if args.resume:
            raise ConfigError("--resume needs --out FILE.jsonl (the output of the run to continue)")
        return None
    path = Path(args.out)
    if path.is_dir():
        raise ConfigError(f"--out {args.out!r} is a directory; give a file name (e.g. results.jsonl)")
    if path.exists() and not path.is_file():
        raise ConfigError(f"--out {args.out!r} is not a regular file (a FIFO, socket or device); give a file name")
    if not path.parent.is_dir():
        raise ConfigError(f"--out {args.out!r}: directory {str(path.parent)!r} does not exist")
    if path.exists() and path.stat().st_size > 0 and not args.resume:
        raise ConfigError(f"--out {args.out!r} already exists: pass --resume to continue that run, or choose a new file")
    if not os.access(path.parent, os.W_OK) or (path.exists() and not os.access(path, os.W_OK)):
        raise ConfigError(f"--out {args.out!r} is not writable")
    return path


# ------------------------------------------------------------------------------------ the loop
def _error_record(e: BaseException) -> tuple[dict[str, Any], int]:
    from ..errors import JaxlimbError

    if isinstance(e, JaxlimbError):
        return {"status": "error", "check": e.check, "message": " ".join(str(e).split())}, e.exit_code
    if os.environ.get("JAXLIMB_DEBUG"):
        raise e
    return {"status": "error", "check": "internal_error", "message": f"{type(e).__name__}: {' '.join(str(e).split())}"}, 1


def _one_frame(path: str, read: Callable[[str], Any], measure: Callable[[str, Any], dict[str, Any]]) -> tuple[dict[str, Any], int]:
    try:
        return {**measure(path, read(path)), "image": path}, 0
    except Exception as e:  # noqa: BLE001 - a bad frame never stops the run
        rec, code = _error_record(e)
        return {**rec, "image": path}, code


def _frame_chunk(paths: list[str], read: Callable[[str], Any],
                 measure: Callable[[str, Any], dict[str, Any]]) -> list[tuple[dict[str, Any], int]]:
    """A Dask task: the records of a chunk of frames (the worker sets up JAX as the command does)."""
    from ..analysis.dask_worker import wait_started
    from . import start_command_jax

    wait_started()  # a worker's preload thread may still be importing the package
    start_command_jax()
    return [_one_frame(p, read, measure) for p in paths]


def _records(todo: list[str], args: argparse.Namespace, read: Callable[[str], Any],
             measure: Callable[[str, Any], dict[str, Any]]) -> Any:
    """``(record, exit code)`` per frame, in order: in this process, or chunks of frames on Dask."""
    if args.workers is None and args.scheduler is None:
        for path in todo:
            yield _one_frame(path, read, measure)
        return
    from functools import partial

    from ..analysis.distributed import close_client, make_client, map_chunks

    client = make_client(args.scheduler, args.workers or 2)
    try:
        n_workers = max(1, len(client.scheduler_info().get("workers", {})))
        size = max(1, min(16, -(-len(todo) // (4 * n_workers))))
        for chunk in map_chunks(partial(_frame_chunk, read=read, measure=measure), todo, client, size):
            yield from chunk
    finally:
        close_client(client)


def run_frames(images: list[str], args: argparse.Namespace, read: Callable[[str], Any],
               measure: Callable[[str, Any], dict[str, Any]]) -> int:
    """Run ``measure(path, read(path))`` over the frames and stream JSON Lines (module docstring)."""
    from .._io import exclusive_output

    out = check_out(args)
    paths = expand_images(images)
    if out is None:
        return _run_locked(paths, args, read, measure, None)
    with exclusive_output(out):  # one writer for the whole run, the resume's reading included
        if out.exists() and not out.is_file():  # replaced meanwhile
            check_out(args)
        return _run_locked(paths, args, read, measure, out)


def _run_locked(paths: list[str], args: argparse.Namespace, read: Callable[[str], Any],
                measure: Callable[[str, Any], dict[str, Any]], out: Path | None) -> int:
    from tqdm.auto import tqdm

    from . import show_progress

    settings = run_settings(args)
    done = _done_frames(out, settings) if (out is not None and args.resume) else set()
    todo = [p for p in paths if p not in done]
    writer = _LineWriter(out)
    worst, counts = 0, {"ok": 0, "error": 0}
    bar = tqdm(total=len(todo), unit="frame", desc="frames", file=sys.stderr, disable=not show_progress(args))
    try:
        for rec, code in _records(todo, args, read, measure):
            writer.write({**rec, "run_settings": settings})
            counts["ok" if code == 0 else "error"] += 1
            worst = max(worst, code, key=_SEVERITY.__getitem__)
            bar.update(1)
    finally:
        bar.close()
        writer.close()
    skipped = f", {len(paths) - len(todo)} already in {args.out}" if done else ""
    print(f"jaxlimb: {len(todo)} frames: {counts['ok']} ok, {counts['error']} failed{skipped}", file=sys.stderr)
    return worst


__all__ = ["IMAGE_SUFFIXES", "add_batch_arguments", "check_out", "expand_images", "is_many", "one_per_frame", "run_frames", "run_settings"]
