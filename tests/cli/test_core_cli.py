"""CLI contract of the core commands: gradcheck, montecarlo, demo; errors are one line, never a traceback."""

import json

from jaxlimb.cli import main


def test_gradcheck_json(capsys):
    """The command's JSON on two models (every model at 1e-9: tests/models/test_physical_models.py and
    test_gradcheck.py); the command knows every model of the registry."""
    from jaxlimb.cli._gradcheck import MODEL_NAMES
    from jaxlimb.models import ALL_MODELS

    assert set(MODEL_NAMES) == set(ALL_MODELS)
    assert main(["gradcheck", "--n-points", "4", "--model", "circle", "--model", "lunar_limb", "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert len(out["checks"]) == sum(len(ALL_MODELS[m].param_names) for m in ("circle", "lunar_limb"))  # one per column
    assert {c["model"] for c in out["checks"]} == {"circle", "lunar_limb"}
    for c in out["checks"]:
        assert c["n_points"] == 4 and c["passed"] and c["max_rel_err"] <= c["tol"]


def test_montecarlo_json(capsys):
    assert main(["montecarlo", "--n", "40", "--radius", "50", "--batch", "20", "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["n"] == 40 and out["converged"] == 40
    assert set(out) >= {"n", "converged", "wall_s", "fit_s", "rms", "bias", "crlb"}
    assert set(out["rms"]) == {"r0", "c0", "radius", "k", "ymax", "ymin"}


def test_montecarlo_ellipse_json(capsys):
    assert main(["montecarlo", "--model", "ellipse", "--n", "10", "--radius", "50", "--batch", "10", "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert "theta" in out["rms"] and "rho" not in out["rms"]


def test_bad_arguments_exit_2_with_json_error(capsys):
    assert main(["montecarlo", "--solver", "nope", "--json"]) == 2
    out = json.loads(capsys.readouterr().out)
    assert out["status"] == "error" and "nope" in out["message"]
    assert main(["montecarlo", "--radius", "-3", "--json"]) == 2
    out = json.loads(capsys.readouterr().out)
    assert out["check"] == "bad_arguments" and "radius" in out["message"]


def test_error_without_json_is_one_line_on_stderr(capsys):
    assert main(["montecarlo", "--n", "1"]) == 2
    cap = capsys.readouterr()
    assert cap.out == ""
    assert cap.err.count("\n") == 1 and cap.err.startswith("jaxlimb: error:") and "Traceback" not in cap.err


def test_figures_outside_a_checkout_is_a_clear_error(capsys, monkeypatch, tmp_path):
    from jaxlimb.cli import _figures

    monkeypatch.setattr(_figures, "_SCRIPT", tmp_path / "missing" / "make_all.py")
    assert main(["figures", "--quick"]) == 2
    err = capsys.readouterr().err
    assert "source checkout" in err and err.count("\n") == 1
