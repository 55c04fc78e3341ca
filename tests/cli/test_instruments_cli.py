"""The research instruments from the command line: ``compare``, ``montecarlo --solvers``, every solver on 1 and 2
XLA CPU devices (the optimistix solvers used to fail under ``shard_map``)."""

from __future__ import annotations

import json
import os
import subprocess
import sys

import pytest

from jaxlimb.cli import main

SMALL = ["--model", "linear", "--radius", "20", "--n", "6", "--chunk", "2", "--seed", "3"]


def test_solver_names_and_study_models_agree_with_the_package():
    from jaxlimb._solver_names import SOLVER_NAMES
    from jaxlimb.analysis.problems import STUDY_MODELS
    from jaxlimb.cli._study_args import MODELS
    from jaxlimb.fitting import SOLVERS

    assert tuple(SOLVERS) == SOLVER_NAMES and MODELS == STUDY_MODELS


@pytest.mark.slow
def test_every_solver_on_one_and_two_devices(tmp_path):
    """``compare --solvers all`` (every registered solver on the same realisations) with exit 0 on 1 and 2 devices,
    the same answers on both (the realisations do not depend on the split)."""
    env = {**os.environ, "JAXLIMB_CACHE_DIR": "off"}
    env.pop("XLA_FLAGS", None)
    out = {}
    for d in ("1", "2"):
        cmd = [sys.executable, "-m", "jaxlimb.cli", "compare", *SMALL, "--solvers", "all", "--devices", d, "--json"]
        r = subprocess.run(cmd, capture_output=True, text=True, env=env, timeout=900)
        assert r.returncode == 0, r.stdout[-2000:] + r.stderr[-2000:]
        out[d] = json.loads(r.stdout)
    assert (out["1"]["devices"], out["2"]["devices"]) == (1, 2)
    for a, b in zip(out["1"]["rows"], out["2"]["rows"]):
        assert a["solver"] == b["solver"] and a["success_rate"] == b["success_rate"] == 1.0
        assert a["params"]["xt"]["rms"] == pytest.approx(b["params"]["xt"]["rms"], rel=1e-9)
    assert [r["solver"] for r in out["2"]["rows"]] == ["lm", "optx-lm", "optx-normal-lm", "dogleg", "gauss-newton",
                                                       "bfgs", "paper", "scipy"]


def test_compare_table_json_plot_and_the_same_realisations(tmp_path, capsys):
    args = ["compare", *SMALL, "--solvers", "lm,paper,scipy", "--plot", str(tmp_path / "c.png"), "--out",
            str(tmp_path / "c.json")]
    assert main(args) == 0
    text = capsys.readouterr().out
    assert "RMS/CRLB xt" in text and "paper" in text
    res = json.loads((tmp_path / "c.json").read_text())
    assert (tmp_path / "c.png").stat().st_size > 1000
    rows = {r["solver"]: r for r in res["rows"]}
    assert res["options"]["n"] == 6 and rows["lm"]["ms_over_first"] == 1.0
    for r in rows.values():  # the same data: the same minimum to ~1e-8 px, timed in 3 interleaved chunks
        assert r["n_timings"] == 3 and r["ms_per_fit"] > 0 and r["cpu_ms_per_fit"] > 0
        assert r["max_abs_diff_vs_first_px"] < 1e-6
        assert r["params"]["xt"]["rms"] == pytest.approx(rows["lm"]["params"]["xt"]["rms"], rel=1e-5)


def test_montecarlo_solvers_is_the_comparison(capsys):
    assert main(["montecarlo", "--model", "linear", "--radius", "20", "--n", "4", "--batch", "2",
                 "--solvers", "lm,paper", "--json"]) == 0
    res = json.loads(capsys.readouterr().out)
    assert [r["solver"] for r in res["rows"]] == ["lm", "paper"] and res["problem"]["model"] == "linear"


@pytest.mark.parametrize("argv, words", [
    (["compare", "--solvers", "lm,nope"], "--solvers"),
    (["compare", "--solvers", "lm,lm"], "--solvers"),
    (["compare", "--model", "square"], "--model"),
    (["compare", "--frame", "x.png", "--render", "own"], "--render"),
    (["compare", "--plot", "x.txt"], "--plot"),
    (["montecarlo", "--families", "own"], "--pipeline"),
    (["montecarlo", "--solvers", "lm,paper", "--out", "/tmp/x"], "--out"),
])
def test_bad_arguments_are_one_line_exit_2(argv, words, capsys):
    assert main([*argv, "--json"]) == 2
    msg = json.loads(capsys.readouterr().out)["message"]
    assert words in msg
