"""The ``jaxlimb`` command.

Each sub-command lives in its own module ``jaxlimb/cli/_<name>.py`` that defines
``register(subparsers)``; the parser it adds sets ``func`` to a callable
``run(args) -> int``.  This module owns the error contract of DESIGN.md:

* exit 0 on success;
* exit 2 for unusable input (:class:`~jaxlimb.errors.LimbInputError`, bad arguments);
* exit 3 for a failed check (:class:`~jaxlimb.errors.CheckFailed`);
* with ``--json`` the error goes to stdout as
  ``{"status": "error", "check": NAME, "message": TEXT}``, otherwise one line
  on stderr -- never a traceback (set ``JAXLIMB_DEBUG=1`` to see one).
"""

from __future__ import annotations

import argparse
import contextlib
import importlib
import json
import os
import sys
import warnings
from collections.abc import Iterator, Sequence

# Sub-command modules, in the order they appear in --help.
_COMMANDS = (
    "_demo",
    "_locate",
    "_navigate",
    "_los",
    "_posterior",
    "_montecarlo",
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
            print(f"{self.prog}: error: {message}", file=sys.stderr)
        raise SystemExit(2)


def build_parser() -> argparse.ArgumentParser:
    parser = _Parser(prog="jaxlimb", description="Limb-based optical navigation with differentiable JAX models.")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", parser_class=_Parser)
    sub.required = True
    for name in _COMMANDS:
        importlib.import_module(f"{__name__}.{name}").register(sub)
    return parser


def emit_json(obj: object) -> None:
    """Print one JSON object on stdout (the ``--json`` output of every command)."""
    print(json.dumps(obj, allow_nan=False, default=_json_default))


@contextlib.contextmanager
def warnings_to_stderr(*categories: type[Warning]) -> Iterator[None]:
    """Show warnings of ``categories`` raised in the block as one ``jaxlimb: warning: ...`` line
    each on stderr (every one, not only the first of its kind); other warnings recorded in the
    block are not shown (the CLI prints one-line messages, never Python's warning format)."""
    with warnings.catch_warnings(record=True) as caught:
        for c in categories:
            warnings.simplefilter("always", c)
        yield
    for w in caught:
        if issubclass(w.category, categories):
            print(f"jaxlimb: warning: {' '.join(str(w.message).split())}", file=sys.stderr)


def _json_default(o: object) -> object:
    import numpy as np

    if isinstance(o, np.generic):
        return o.item()
    if isinstance(o, np.ndarray):
        return o.tolist()
    if hasattr(o, "__array__"):
        return np.asarray(o).tolist()
    raise TypeError(f"not JSON serialisable: {type(o).__name__}")


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of the ``jaxlimb`` command; returns the exit code.

    JAX is imported only after the arguments are parsed (``jaxlimb --help`` does not pay for
    it); the persistent compilation cache is switched on before the first compilation
    (:mod:`jaxlimb._jaxcache`: ``JAXLIMB_CACHE_DIR``, ``off`` to disable).
    """
    from ..errors import JaxlimbError

    argv = list(sys.argv[1:] if argv is None else argv)
    want_json = "--json" in argv
    _STATE["json"] = want_json
    try:
        args = build_parser().parse_args(argv)
        if getattr(args, "needs_jax", True):  # a sub-command may declare it runs without JAX
            _start_jax()
        with warnings.catch_warnings():
            warnings.simplefilter("default")
            return int(args.func(args) or 0)
    except JaxlimbError as e:
        _report(want_json, e.check, str(e))
        return e.exit_code
    except KeyboardInterrupt:
        _report(want_json, "interrupted", "interrupted")
        return 130
    except SystemExit as e:
        return int(e.code) if isinstance(e.code, int) else 2
    except Exception as e:  # last resort: never a traceback unless asked for
        if os.environ.get("JAXLIMB_DEBUG"):
            raise
        _report(want_json, "internal_error", f"{type(e).__name__}: {e}")
        return 1


def _start_jax() -> None:
    import jax

    from .._jaxcache import enable_compile_cache

    jax.config.update("jax_enable_x64", True)
    enable_compile_cache()


def _report(want_json: bool, check: str, message: str) -> None:
    message = " ".join(str(message).split())  # one line
    if want_json:
        print(json.dumps({"status": "error", "check": check, "message": message}))
    else:
        print(f"jaxlimb: error: {message}", file=sys.stderr)


if __name__ == "__main__":  # pragma: no cover
    raise SystemExit(main())
