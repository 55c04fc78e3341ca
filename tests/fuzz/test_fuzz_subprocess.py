"""The few contracts that need a real process (started together, they cost one start-up).

* stdout closed by its reader (``jaxlimb ... --json | head -c 1``): no ``BrokenPipeError``
  traceback nor "Exception ignored" noise, exit 141 (128 + SIGPIPE);
* stderr is one line per message: OpenCV's own ``[ WARN ]`` logging (a truncated PNG named
  ``.tif``) and Python warnings never reach it.
"""

from __future__ import annotations

import os
import subprocess
import sys

_CMD = [sys.executable, "-m", "jaxlimb.cli"]


def _env() -> dict[str, str]:
    env = dict(os.environ)
    env.pop("JAXLIMB_DEBUG", None)
    env.pop("OPENCV_LOG_LEVEL", None)  # the CLI must silence OpenCV itself
    return env


def test_real_processes_closed_stdout_and_one_line_stderr(inputs, tmp_path):
    tif = tmp_path / "truncated.tif"
    tif.write_bytes(inputs["moon.png"].read_bytes()[:300])
    closed = subprocess.Popen([*_CMD, "gradcheck", "--tol", "nan", "--json"], stdout=subprocess.PIPE,
                              stderr=subprocess.PIPE, env=_env())
    closed.stdout.close()  # the reader is gone before the command writes
    head = subprocess.Popen(f"{' '.join(_CMD)} locate {inputs['missing']} --json | head -c 1", shell=True,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, env=_env())
    warn = subprocess.Popen([*_CMD, "locate", str(tif)], stdout=subprocess.PIPE, stderr=subprocess.PIPE, env=_env())

    err = closed.stderr.read().decode()
    closed.stderr.close()
    assert closed.wait(timeout=120) == 141, err
    assert err == "", err  # not even "Exception ignored ... BrokenPipeError"

    out, err = head.communicate(timeout=120)
    assert out == b"{" and err == b"", err

    out, err = warn.communicate(timeout=120)
    lines = err.decode().splitlines()
    assert warn.returncode == 2 and out == b""
    assert len(lines) == 1 and lines[0].startswith("jaxlimb: error:") and "truncated.tif" in lines[0], lines
