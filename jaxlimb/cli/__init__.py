"""The ``jaxlimb`` command.

Each sub-command lives in its own module ``jaxlimb/cli/_<name>.py`` that defines
``register(subparsers)``; the parser it adds sets ``func`` to a callable
``run(args) -> int``.  This module owns the error contract of docs/design.md:

* exit 0 on success;
* exit 2 for unusable input (:class:`~jaxlimb.errors.LimbInputError`, bad arguments);
* exit 3 for a failed check (:class:`~jaxlimb.errors.CheckFailed`);
* with ``--json`` the error goes to stdout as
  ``{"status": "error", "check": NAME, "message": TEXT}``, otherwise one line
  on stderr -- never a traceback (set ``JAXLIMB_DEBUG=1`` to see one);
* stderr carries only one-line messages: a Python warning is printed as one
  ``jaxlimb: warning: ...`` line (NumPy/JAX ``RuntimeWarning`` noise is dropped unless
  ``JAXLIMB_DEBUG`` is set) and OpenCV's own ``[ WARN ]`` logging is silenced (the
  image readers report every failure themselves);
* a closed stdout (``jaxlimb ... --json | head -c 1``) ends the command quietly
  with exit 141 (128 + SIGPIPE, as the POSIX tools do);
* SIGINT (Ctrl-C) ends the command with one ``interrupted`` message and exit 130, SIGTERM
  with one ``terminated`` message and exit 143 (128 + the signal); outputs stay whole and
  resumable (files are written atomically or one whole line at a time);
* a standard stream closed at start (``<&-``, ``2>&-``) is opened on ``/dev/null``, so no
  file the command opens can take its place and no message fails for want of it.

The exit codes and what every command guarantees are tabled in ``docs/guarantees.md``.
"""

from __future__ import annotations

import argparse
import contextlib
import importlib
import json
import os
import signal
import sys
import warnings
from collections.abc import Callable, Iterator, Sequence

# Sub-command modules, in the order they appear in --help.
_COMMANDS = (
    "_demo",
    "_locate",
    "_navigate",
    "_track",
    "_los",
    "_posterior",
    "_montecarlo",
    "_compare",
    "_gradcheck",
    "_figures",
)


_STATE = {"json": False}  # whether the current invocation asked for --json (set by main)


class _Parser(argparse.ArgumentParser):
    """ArgumentParser whose usage errors follow the one-line / JSON contract (exit 2)."""

    def error(self, message: str) -> None:  # type: ignore[override]
        if _STATE["json"]:
            print(json.dumps({"status": "error", "check": "bad_arguments", "message": message}))
        else:
            print(f"jaxlimb: error: {message} (see `{self.prog} --help`)", file=sys.stderr)
        raise SystemExit(2)


def build_parser() -> argparse.ArgumentParser:
    from .. import __version__

    parser = _Parser(prog="jaxlimb", description="Limb-based optical navigation with differentiable JAX models.",
                     epilog=PROGRESS_HELP)
    parser.add_argument("--version", action="version", version=f"jaxlimb {__version__}")
    parser.add_argument("-q", "--quiet", action="store_true", help=_QUIET_HELP)
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", parser_class=_Parser)
    sub.required = True
    for name in _COMMANDS:
        importlib.import_module(f"{__name__}.{name}").register(sub)
    _add_quiet(sub)
    return parser


PROGRESS_HELP = ("Progress: the long commands (locate and los locate on many frames, los build-db, montecarlo, "
                 "posterior, compare, track) draw progress bars on stderr when stderr is a terminal, also with "
                 "--json (stdout carries only the result); --quiet (before or after the command) silences them; "
                 "JAXLIMB_PROGRESS=1 draws them also when stderr is not a terminal (a log file), "
                 "JAXLIMB_PROGRESS=0 never.")
_QUIET_HELP = "no progress bars on stderr (messages, warnings and errors are still printed)"


def _add_quiet(sub: argparse._SubParsersAction) -> None:
    """``--quiet`` on every sub-command too (``jaxlimb locate ... --quiet``); its default is left to the top level."""
    for p in sub.choices.values():
        nested = [a for a in p._actions if isinstance(a, argparse._SubParsersAction)]
        if nested:
            _add_quiet(nested[0])
        elif not any("--quiet" in a.option_strings for a in p._actions):
            p.add_argument("-q", "--quiet", action="store_true", default=argparse.SUPPRESS, help=_QUIET_HELP)


def show_progress(args: argparse.Namespace) -> bool:
    """Whether a command draws progress bars (on stderr): never with ``--quiet`` (or ``los``'s ``--no-progress``);
    else ``JAXLIMB_PROGRESS=1`` always and ``0`` never; else only when stderr is a terminal -- a bar in a log file or
    a pipe is noise."""
    if getattr(args, "quiet", False) or getattr(args, "no_progress", False):
        return False
    forced = os.environ.get("JAXLIMB_PROGRESS", "").strip().lower()
    if forced in ("1", "yes", "on", "always"):
        return True
    if forced in ("0", "no", "off", "never"):
        return False
    try:
        return sys.stderr is not None and sys.stderr.isatty()
    except (AttributeError, ValueError, OSError):  # a closed or replaced stream
        return False


def emit_json(obj: object) -> None:
    """Print one JSON object on stdout (the ``--json`` output of every command).

    The output is strict JSON: a non-finite float (NaN, inf) is written as ``null``.
    """
    print(json.dumps(finite_json(obj), allow_nan=False, default=json_default))


def finite_json(obj: object) -> object:
    """``obj`` with every non-finite float (also NumPy scalars) replaced by ``None``."""
    import math

    if isinstance(obj, dict):
        return {k: finite_json(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [finite_json(v) for v in obj]
    if isinstance(obj, float) and not math.isfinite(obj):
        return None
    if type(obj).__module__ == "numpy" and getattr(obj, "ndim", None) == 0:
        return finite_json(obj.item())  # type: ignore[attr-defined]
    return obj


@contextlib.contextmanager
def warnings_to_stderr(*categories: type[Warning]) -> Iterator[None]:
    """Show warnings of ``categories`` raised in the block as one ``jaxlimb: warning: ...`` line
    each on stderr (every one, not only the first of its kind); other warnings recorded in the
    block are not shown (the CLI prints one-line messages, never Python's warning format), except a
    cache's :class:`~jaxlimb.errors.CacheRepairWarning`, which is always shown."""
    from ..errors import CacheRepairWarning

    categories = (*categories, CacheRepairWarning)
    with warnings.catch_warnings(record=True) as caught:
        for c in categories:
            warnings.simplefilter("always", c)
        yield
    for w in caught:
        if issubclass(w.category, categories):
            print(f"jaxlimb: warning: {' '.join(str(w.message).split())}", file=sys.stderr)


def figure_path(path: str | None, flag: str) -> str | None:
    """Check an output picture path (``--figure``, ``--plot``) before any computation:
    a known extension, a directory that exists and accepts a file (exit 2 otherwise)."""
    from .._validate import FIGURE_SUFFIXES, output_file

    if path is not None:
        output_file(path, flag, suffixes=FIGURE_SUFFIXES)
    return path


def try_save(save: Callable[[], object], flag: str) -> str | None:
    """Run a picture writer after the result is computed; return ``None`` or the one-line error.

    The caller still prints its result (adding the error to it) and then reports the error
    with :func:`report_after_result`: a computed result is never lost to a figure that fails.
    """
    try:
        save()
    except Exception as e:  # matplotlib/OS errors of many types; the result must survive them
        if os.environ.get("JAXLIMB_DEBUG"):
            raise
        return " ".join(f"could not write {flag}: {type(e).__name__}: {e}".split())
    return None


def report_after_result(error: str | None) -> int:
    """Exit code after the result was printed: 0, or 2 with ``error`` as one stderr line."""
    if error is None:
        return 0
    print(f"jaxlimb: error: {error}", file=sys.stderr)
    return 2


def json_default(o: object) -> object:
    """``json.dumps``'s ``default`` for the commands' output: NumPy scalars and arrays as Python values."""
    import numpy as np

    if isinstance(o, np.generic):
        return o.item()
    if isinstance(o, np.ndarray):
        return o.tolist()
    if hasattr(o, "__array__"):
        return np.asarray(o).tolist()
    raise TypeError(f"not JSON serialisable: {type(o).__name__}")


_EXIT_BROKEN_PIPE = 141  # 128 + SIGPIPE
EXIT_INTERRUPTED = 130  # 128 + SIGINT
EXIT_TERMINATED = 143  # 128 + SIGTERM


class Terminated(BaseException):
    """SIGTERM received: raised in the main thread by the CLI's handler, so ``finally`` blocks
    (locks, partial records, Dask clusters) run as for Ctrl-C."""


def _on_sigterm(signum: int, frame: object) -> None:
    del signum, frame
    signal.signal(signal.SIGTERM, signal.SIG_DFL)  # a second SIGTERM ends the process at once
    raise Terminated()


@contextlib.contextmanager
def _sigterm_raises() -> Iterator[None]:
    """SIGTERM raises :class:`Terminated` in the block (main thread only; the old handler is restored)."""
    try:
        old = signal.signal(signal.SIGTERM, _on_sigterm)
    except ValueError:  # not the main thread: leave signals alone
        yield
        return
    try:
        yield
    finally:
        signal.signal(signal.SIGTERM, old)


def _reopen_closed_std_streams() -> None:
    """Open ``/dev/null`` on a closed fd 0, 1 or 2 (and give ``sys`` a stream on it), so a file the command
    opens never takes a standard fd, and a message to a closed stream is dropped rather than an error."""
    for fd, name, mode in ((0, "stdin", "r"), (1, "stdout", "w"), (2, "stderr", "w")):
        try:
            os.fstat(fd)
            if getattr(sys, name) is not None:
                continue
        except OSError:
            got = os.open(os.devnull, os.O_RDWR)
            if got != fd:
                os.dup2(got, fd)
                os.close(got)
        setattr(sys, name, open(fd, mode, closefd=False, encoding="utf-8", errors="replace"))


def _one_line_warning(message, category, filename, lineno, file=None, line=None) -> None:  # noqa: ANN001
    """``warnings.showwarning`` of the CLI: one ``jaxlimb: warning:`` line, no source line."""
    if issubclass(category, RuntimeWarning) and not os.environ.get("JAXLIMB_DEBUG"):
        return  # numeric noise of NumPy/JAX (nan in a masked pixel, ...): never a user message
    text = " ".join(str(message).split())
    print(f"jaxlimb: warning: {text}", file=sys.stderr if file is None else file)


def _quiet_opencv() -> None:
    """Silence OpenCV's ``[ WARN ]`` logging (it writes to the stderr fd from C++), and bound the images its
    decoders accept to :data:`jaxlimb._image_bounds.MAX_IMAGE_PIXELS` (formats whose header jaxlimb does not read)."""
    os.environ.setdefault("OPENCV_LOG_LEVEL", "ERROR")  # read when cv2 is first imported
    os.environ.setdefault("OPENCV_IO_MAX_IMAGE_PIXELS", str(1 << 28))  # = _image_bounds.MAX_IMAGE_PIXELS
    cv2 = sys.modules.get("cv2")
    if cv2 is not None:
        with contextlib.suppress(AttributeError):
            cv2.utils.logging.setLogLevel(cv2.utils.logging.LOG_LEVEL_ERROR)


def _stdout_closed() -> int:
    """stdout's reader went away: point fd 1 at /dev/null so the exit flush is silent."""
    with contextlib.suppress(OSError, ValueError):
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())
    return _EXIT_BROKEN_PIPE


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of the ``jaxlimb`` command; returns the exit code.

    JAX is imported only after the arguments are parsed (``jaxlimb --help`` does not pay for
    it); the persistent compilation cache is switched on before the first compilation
    (:mod:`jaxlimb._jaxcache`: ``JAXLIMB_CACHE_DIR``, ``off`` to disable).  A closed stdout
    ends the command quietly (exit 141).
    """
    _reopen_closed_std_streams()
    _quiet_opencv()
    try:
        with _sigterm_raises():
            code = _main(argv)
            sys.stdout.flush()
        return code
    except BrokenPipeError:
        return _stdout_closed()
    except Terminated:  # after _main returned (while flushing)
        return EXIT_TERMINATED
    except OSError as e:  # stdout on a full device (`> /dev/full`): its last flush
        from .._io import write_error

        _report(False, "write_failed", str(write_error("<stdout>", e)))
        _stdout_closed()
        return 2


def entry() -> int:
    """The ``jaxlimb`` command as a process (the console script and ``python -m jaxlimb.cli``): :func:`main`,
    with Python's cyclic garbage collector told (``gc.freeze``) that the objects which live until the
    process ends -- JAX's and the imported modules', frozen once JAX has started -- need no tracing.

    Why: a process that has imported JAX holds ~10^6 objects the collector tracks.  Without the freeze
    every full collection during the run, and the collections of the interpreter's shutdown, walk them
    all: measured on a 2-core CPU, ``python -c "import jax; jax.numpy.zeros(1)"`` spends 0.4-0.6 s of its
    ~1.2 s after its last statement (0.2 s with the freeze), and ``locate --body sun`` 0.2 s in
    collections during its run.  Frozen objects are still freed by reference counting; only cycles among
    them are left to the process's end.  :func:`main` called in a Python session (tests, notebooks) does
    not freeze anything.
    """
    import gc

    _STATE["process"] = True
    code = main()
    gc.freeze()  # the objects made after JAX started: the shutdown's collections skip them too
    return code


def _main(argv: Sequence[str] | None) -> int:
    from ..errors import JaxlimbError

    argv = list(sys.argv[1:] if argv is None else argv)
    want_json = "--json" in argv
    _STATE["json"] = want_json
    try:
        args = build_parser().parse_args(argv)
        needs_jax = getattr(args, "needs_jax", True)  # a sub-command may declare it runs without JAX
        if callable(needs_jax):  # ... or decide from its arguments
            needs_jax = needs_jax(args)
        with warnings.catch_warnings():
            warnings.simplefilter("default")
            warnings.simplefilter("ignore", ResourceWarning)  # Python's own default: a file freed by an interrupt
            warnings.showwarning = _one_line_warning
            precheck = getattr(args, "precheck", None)  # cheap input checks before JAX starts (image bombs)
            if precheck is not None:
                precheck(args)
            if needs_jax:
                host_devices = getattr(args, "host_devices", None)
                _request_host_devices(host_devices(args) if host_devices else 1)
                start_command_jax()
            return int(args.func(args) or 0)
    except BrokenPipeError:
        raise
    except OSError as e:
        from .._io import WRITE_ERRNOS, write_error

        if e.errno not in WRITE_ERRNOS or os.environ.get("JAXLIMB_DEBUG"):
            return _internal_error(want_json, e)
        err = write_error(e.filename or "<stdout>", e)
        _report(want_json, err.check, str(err))  # type: ignore[attr-defined]
        return 2
    except JaxlimbError as e:
        _report(want_json, e.check, str(e))
        return e.exit_code
    except KeyboardInterrupt:
        _report(want_json, "interrupted", "interrupted (SIGINT)")
        _last_message()
        return EXIT_INTERRUPTED
    except Terminated:
        _report(want_json, "terminated", "terminated (SIGTERM)")
        _last_message()
        return EXIT_TERMINATED
    except SystemExit as e:
        return int(e.code) if isinstance(e.code, int) else 2
    except Exception as e:  # last resort: never a traceback unless asked for
        return _internal_error(want_json, e)


def _internal_error(want_json: bool, e: Exception) -> int:
    if os.environ.get("JAXLIMB_DEBUG"):
        raise e
    _report(want_json, "internal_error", f"{type(e).__name__}: {e}")
    return 1


def _request_host_devices(n: int) -> None:
    """Ask XLA for ``n`` CPU devices (``--xla_force_host_platform_device_count``) before JAX starts.

    Only for a command that splits its batches over devices (``montecarlo``); a no-op when JAX
    is already running in this process or the user's ``XLA_FLAGS`` already set the count.
    """
    if n <= 1 or "jax" in sys.modules:
        return
    flags = os.environ.get("XLA_FLAGS", "")
    if "xla_force_host_platform_device_count" not in flags:
        os.environ["XLA_FLAGS"] = f"{flags} --xla_force_host_platform_device_count={n}".strip()


def start_command_jax() -> None:
    """Start JAX for a command (float64, compilation cache); in the command's own process, freeze its objects."""
    from .._jaxcache import start_jax

    start_jax()  # LAPACK kernels before JAX (no scipy.linalg package import), float64, compilation cache
    _check_backend()
    if _STATE.get("process"):  # the command's own process (entry): JAX's objects live until its end
        import gc

        gc.freeze()


def _last_message() -> None:
    """After the one message of an interrupted command process: nothing more on stderr (the shutdown of a
    half-started Dask cluster, interrupted library threads).  A command run in a Python session is left alone."""
    if not _STATE.get("process"):
        return
    with contextlib.suppress(OSError, ValueError, AttributeError):
        sys.stderr.flush()
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, 2)
        os.close(devnull)


def _check_backend() -> None:
    """JAX's backend starts (``JAX_PLATFORMS=cuda`` on a machine without CUDA does not): else exit 2, one line."""
    import jax

    from ..errors import ConfigError

    try:
        jax.devices()
    except Exception as e:  # noqa: BLE001 - RuntimeError, or an AssertionError when no platform asked for exists
        first = next((ln.strip() for ln in str(e).splitlines() if ln.strip()), "no such platform on this machine")
        raise ConfigError(f"JAX cannot start a backend (JAX_PLATFORMS={os.environ.get('JAX_PLATFORMS', '')!r}): "
                          f"{first}") from None


def _report(want_json: bool, check: str, message: str) -> None:
    message = " ".join(str(message).split())  # one line
    if want_json:
        print(json.dumps({"status": "error", "check": check, "message": message}))
    else:
        print(f"jaxlimb: error: {message}", file=sys.stderr)


if __name__ == "__main__":  # pragma: no cover
    raise SystemExit(main())
