"""Inputs that cannot have an answer never exit 0; results are never lost; files stay sound.

* frames without a body (all black, all white, noise) -> exit 3 with a typed check, for
  ``locate``, ``los locate`` and ``posterior``; a posterior on pure noise is refused by its
  quality checks instead of reporting k = 2e5 and means of 1e62;
* ``gradcheck`` beyond its tolerance -> exit 3 with the JSON error object (``status`` field);
* a picture that cannot be written after the computation: the result is printed, then the
  error (exit 2) -- never ``internal_error`` with the result lost;
* ``los build-db``: a second writer of the same ``--out`` is refused (lock), the temporaries a
  killed build left are removed by the next build.
"""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from jaxlimb.errors import NoBodyError, PosteriorImproperError

from ._cli import assert_refused, run_cli


@pytest.mark.parametrize("frame", ["black.png", "white.png", "noise.png"])
@pytest.mark.parametrize("command", ["locate", "los-locate", "posterior"])
def test_frame_without_a_body_never_exits_0(command, frame, inputs):
    f = inputs
    argv = {"locate": ["locate", f[frame], "--camera", f["camera.json"], "--json"],
            "los-locate": ["los", "locate", f[frame], "--db", f["db.npz"], "--camera", f["camera.json"], "--json"],
            "posterior": ["posterior", f[frame], "--json"]}[command]
    res = run_cli(argv)
    if command == "los-locate" and frame == "noise.png":  # not constant: the (empty) database is read first
        assert_refused(res, 2, "db.npz", check="bad_database")
        return
    obj = assert_refused(res, 3)
    assert obj["check"] in ("no_body", "too_big", "too_small", "too_thin")
    if frame == "black.png":
        assert obj["check"] == "no_body"  # the same check for `locate` and `los locate`


def test_posterior_on_pure_noise_is_refused(inputs):
    res = run_cli(["posterior", inputs["noise.npy"], "--center-rc", "60", "80", "--radius", "30", "--max-time", "5",
                   "--json"])
    obj = assert_refused(res, 3)
    assert obj["check"] in ("no_body", "no_convergence", "posterior_improper")


class _Fit:
    """The attributes of a :class:`~jaxlimb.fitting.LimbFit` the quality checks read (no compilation)."""

    free = ("r0", "c0", "radius", "k", "ymax", "ymin")

    def __init__(self, k: float, contrast: float, sd_contrast: float) -> None:
        self.params = type("P", (), {"as_dict": lambda _: {"r0": 60.0, "c0": 80.0, "radius": 30.0, "k": k,
                                                           "ymax": 20.0 + contrast, "ymin": 20.0}})()
        self.covariance = np.diag([0.01, 0.01, 0.01, 0.01, sd_contrast**2 / 2, sd_contrast**2 / 2])
        self.sigma2, self.n_pixels = 100.0, 1000
        self.std = {n: math.sqrt(self.covariance[i, i]) for i, n in enumerate(self.free)}


class _Posterior:
    names = ("r0", "c0", "radius")

    def __init__(self, mean, std) -> None:
        self.mean, self.std = np.asarray(mean, float), np.asarray(std, float)

    def mean_dict(self):
        return dict(zip(self.names, self.mean))

    def std_dict(self):
        return dict(zip(self.names, self.std))


@pytest.mark.parametrize(("k", "contrast", "sd", "ok"), [
    (2.0, 180.0, 1.0, True),  # a real limb: 180 DN at 1 DN
    (2.2e5, 180.0, 1.0, False),  # the k = 2.2e5: a step put through noise
    (2.0, 3.0, 1.0, False),  # 3 sd of contrast: noise
    (math.nan, 180.0, 1.0, False),
])
def test_posterior_refuses_a_fit_that_measured_no_limb(k, contrast, sd, ok):
    from jaxlimb.analysis.posterior import check_limb_fit

    if ok:
        check_limb_fit(_Fit(k, contrast, sd))
    else:
        with pytest.raises(NoBodyError, match="no limb"):
            check_limb_fit(_Fit(k, contrast, sd))


@pytest.mark.parametrize(("mean", "std", "ok"), [
    ([60.0, 80.0, 30.0], [0.1, 0.1, 0.1], True),
    ([1e62, 80.0, 30.0], [1e61, 0.1, 0.1], False),  # the means of 1e62
    ([60.0, 80.0, 30.0], [0.1, 50.0, 0.1], False),  # 500x the Laplace sd: walkers ran away
    ([math.nan, 80.0, 30.0], [0.1, 0.1, 0.1], False),
])
def test_posterior_refuses_runaway_walkers(mean, std, ok):
    from jaxlimb.analysis.posterior import check_posterior

    post, fit_ = _Posterior(mean, std), _Fit(2.0, 180.0, 1.0)
    if ok:
        check_posterior(post, fit_)
    else:
        with pytest.raises(PosteriorImproperError):
            check_posterior(post, fit_)


@pytest.mark.parametrize("worst", [1e-3, math.nan])
def test_gradcheck_failure_is_exit_3_with_a_json_error_object(worst, monkeypatch):
    """A Jacobian off by more than --tol (or NaN: never a pass) -> exit 3, one JSON error object."""
    import jaxlimb.models.gradcheck as gc

    rows = [gc.GradCheck("circle", "r0", 1e-16, 1e-10, 1), gc.GradCheck("ellipse", "rho", worst, 1e-10, 1)]
    monkeypatch.setattr(gc, "run_gradcheck", lambda **kw: rows)
    obj = assert_refused(run_cli(["gradcheck", "--json"]), 3, "ellipse.rho", check="gradient_mismatch")
    assert len(obj["checks"]) == 2 and obj["tol"] is None and obj["worst"] == "ellipse.rho"
    res = run_cli(["gradcheck"])
    assert res.code == 3 and res.err.startswith("jaxlimb: error: ellipse.rho") and res.err.count("\n") == 1
    monkeypatch.setattr(gc, "run_gradcheck", lambda **kw: rows[:1])
    res = run_cli(["gradcheck", "--json"])
    assert res.code == 0 and json.loads(res.out)["status"] == "ok"


def test_figure_failure_after_the_result_keeps_the_result(inputs, monkeypatch, tmp_path):
    """The result is computed, the figure writer fails (disk full...): result printed, then exit 2."""
    import jaxlimb.pipeline as pipeline
    from jaxlimb.pipeline.result import LimbMeasurement

    meas = LimbMeasurement(center_rc=(60.3, 80.7), radius_px=30.0, ellipse=None, k=2.0, ymax=200.0, ymin=20.0,
                           covariance={}, iterations=3, solver="lm", front_end="gradient", n_pixels=500)
    monkeypatch.setattr(pipeline, "locate", lambda *a, **k: meas)

    def disk_full(*a, **k):
        raise OSError(28, "No space left on device")

    monkeypatch.setattr(pipeline, "save_locate_figure", disk_full)
    for json_mode in (True, False):
        res = run_cli(["locate", inputs["moon.png"], "--figure", tmp_path / "fit.png"] + (["--json"] * json_mode))
        assert res.code == 2 and "Traceback" not in res.out + res.err
        assert res.err.count("jaxlimb: error:") == 1 and "--figure" in res.err and "No space left" in res.err
        if json_mode:
            out = json.loads(res.out)
            assert out["status"] == "ok" and out["center_rc"] == [60.3, 80.7] and "--figure" in out["figure_error"]
        else:
            assert "60.3" in res.out


def test_second_writer_of_the_same_database_is_refused(inputs, tmp_path):
    from jaxlimb._io import exclusive_output

    target = tmp_path / "db.npz"
    with exclusive_output(target):  # another build holds the lock
        res = run_cli(["los", "build-db", inputs["mesh.obj"], "--out", target, "--json", "--no-progress"])
    assert_refused(res, 2, str(target), check="output_busy")
    assert not target.exists()
    assert not list(tmp_path.glob(".*.lock"))  # the lock file goes with its holder


def _pid_exists(pid: int) -> bool:
    import os

    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    return True


def test_next_build_removes_the_temporaries_of_a_killed_build(inputs, tmp_path):
    target = tmp_path / "db.npz"
    dead = next(pid for pid in range(4_000_000, 1, -1) if not _pid_exists(pid))
    stale = [tmp_path / ".db.npz.k1ll3d.tmp", tmp_path / f".db.npz.{dead}-x.tmp"]  # older name; a killed writer's
    for p in stale:
        p.write_bytes(b"half a database")
    other = tmp_path / ".other.npz.abc.tmp"  # another output's temporary is not ours to remove
    other.write_bytes(b"")
    res = run_cli(["los", "build-db", inputs["mesh.obj"], "--out", target, "--step-deg", "30", "--template-size", "64",
                   "--json", "--no-progress"])
    assert res.code == 0, res
    out = json.loads(res.out)
    assert out["status"] == "ok" and out["n_templates"] == 50 and target.is_file()
    assert not any(p.exists() for p in stale) and other.exists()
    assert sorted(p.name for p in tmp_path.iterdir()) == [".other.npz.abc.tmp", "db.npz"]
