"""Progress bars: on stderr whenever stderr is a terminal (also with ``--json``), never with ``--quiet``;
``JAXLIMB_PROGRESS`` forces them on or off; stdout stays the result alone."""

from __future__ import annotations

import argparse
import contextlib
import io
import json
import os
import pty
import sys

import pytest

from jaxlimb.cli import build_parser, main, show_progress


@contextlib.contextmanager
def _stderr_on_a_terminal():
    """``sys.stderr`` on the slave side of a pseudo-terminal."""
    master, slave = pty.openpty()
    stream = open(slave, "w", closefd=True)  # noqa: SIM115 - closed below
    old, sys.stderr = sys.stderr, stream
    try:
        yield
    finally:
        sys.stderr = old
        stream.close()
        os.close(master)


@pytest.mark.parametrize(("env", "quiet", "tty", "shown"), [
    (None, False, True, True),    # a terminal: progress
    (None, False, False, False),  # a log file or a pipe: none
    (None, True, True, False),    # --quiet wins
    ("1", False, False, True),    # forced on without a terminal
    ("1", True, False, False),    # ... but --quiet still wins
    ("0", False, True, False),    # forced off
])
def test_who_decides_progress(monkeypatch, env, quiet, tty, shown):
    if env is None:
        monkeypatch.delenv("JAXLIMB_PROGRESS", raising=False)
    else:
        monkeypatch.setenv("JAXLIMB_PROGRESS", env)
    args = argparse.Namespace(quiet=quiet)
    if tty:
        with _stderr_on_a_terminal():
            assert show_progress(args) is shown
    else:
        with contextlib.redirect_stderr(io.StringIO()):
            assert show_progress(args) is shown


@pytest.mark.parametrize("argv", [["--quiet", "montecarlo"], ["montecarlo", "--quiet"], ["-q", "compare"],
                                  ["los", "locate", "x.png", "--db", "d.npz", "--camera", "c.json", "-q"],
                                  ["posterior", "x.png", "--quiet"], ["locate", "a.png", "b.png", "--quiet"]])
def test_quiet_before_or_after_the_command(argv):
    assert build_parser().parse_args(argv).quiet is True


def test_not_quiet_by_default():
    assert build_parser().parse_args(["montecarlo"]).quiet is False
    assert build_parser().parse_args(["los", "build-db", "m.obj", "--out", "d.npz"]).quiet is False


def test_help_says_where_progress_goes(capsys):
    with pytest.raises(SystemExit):
        build_parser().parse_args(["--help"])
    text = " ".join(capsys.readouterr().out.split())
    for words in ("--quiet", "progress bars on stderr when stderr is a terminal, also with --json",
                  "JAXLIMB_PROGRESS=1"):
        assert words in text


@pytest.mark.parametrize("quiet", [False, True])
def test_json_keeps_stdout_clean_while_progress_goes_to_stderr(monkeypatch, capsys, quiet):
    monkeypatch.setenv("JAXLIMB_PROGRESS", "1")  # as on a terminal: capsys's stderr is not one
    argv = ["montecarlo", "--n", "8", "--radius", "30", "--batch", "4", "--json", *(["--quiet"] if quiet else [])]
    assert main(argv) == 0
    out, err = capsys.readouterr()
    lines = out.splitlines()
    assert len(lines) == 1 and json.loads(lines[0])["status"] == "ok"  # the result alone
    assert ("trial" in err and "8/8" in err) is not quiet, err
    assert "Traceback" not in err


def test_quiet_is_not_a_run_setting_of_resume():
    """``--out F --resume`` accepts a file written with or without ``--quiet`` (it changes no answer)."""
    from jaxlimb.cli._batch import run_settings

    args = build_parser().parse_args(["locate", "a.png", "b.png", "--out", "f.jsonl"])
    quiet = build_parser().parse_args(["locate", "a.png", "b.png", "--out", "f.jsonl", "--quiet"])
    assert args.quiet is False and quiet.quiet is True
    assert run_settings(args) == run_settings(quiet)
