"""Run ``jaxlimb`` in-process and check the error contract of docs/design.md on the result.

The contract every hostile case must meet:

* no traceback, anywhere;
* the documented exit code (2: unusable input, 3: failed check), never 0;
* with ``--json``: stdout is exactly one line, a JSON object
  ``{"status": "error", "check": NAME, "message": TEXT}`` whose message is one line and
  names the offending argument; without: stdout empty, stderr exactly one
  ``jaxlimb: error: ...`` line naming it (``jaxlimb: warning:`` lines aside).
"""

from __future__ import annotations

import contextlib
import io
import json
from dataclasses import dataclass

from jaxlimb.cli import main

#: Every case run by the fuzz suite, counted for the session summary (conftest).
CASES = {"n": 0}


@dataclass(frozen=True)
class Result:
    code: int
    out: str
    err: str


def run_cli(argv: list[str]) -> Result:
    """``jaxlimb ARGV`` in this process: exit code, stdout, stderr (SystemExit caught)."""
    CASES["n"] += 1
    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        try:
            code = main([str(a) for a in argv])
        except SystemExit as e:  # main never lets one out: that is a failure of the contract too
            code = -1000 - (e.code if isinstance(e.code, int) else 0)
    return Result(code, out.getvalue(), err.getvalue())


def assert_refused(res: Result, code: int, names: tuple[str, ...] | str = (), check: str | None = None,
                   json_mode: bool = True) -> dict | None:
    """Assert the contract for a refused input; returns the JSON error object (``json_mode``)."""
    names = (names,) if isinstance(names, str) else names
    ctx = f"exit {res.code}\nstdout: {res.out!r}\nstderr: {res.err!r}"
    assert "Traceback" not in res.out + res.err, ctx
    assert res.code == code, ctx
    for line in res.err.splitlines():  # stderr: one-line messages only
        assert line.startswith(("jaxlimb: error:", "jaxlimb: warning:")) or "\r" in line or not line.strip(), ctx
    if json_mode:
        lines = res.out.splitlines()
        assert len(lines) == 1, ctx
        obj = json.loads(lines[0])
        assert obj["status"] == "error" and isinstance(obj["check"], str) and "\n" not in obj["message"], ctx
        if check is not None:
            assert obj["check"] == check, ctx
        message = obj["message"]
    else:
        errors = [ln for ln in res.err.splitlines() if ln.startswith("jaxlimb: error:")]
        assert len(errors) == 1 and res.out == "", ctx
        message = errors[0]
        obj = None
    assert any(n.lower() in message.lower() for n in names) or not names, f"message names none of {names}: {ctx}"
    return obj
