"""One ``locate`` pipeline of small stages over body strategies: its structure, its options, and "a fit
is physical or it is a failure"."""

from __future__ import annotations

import ast
import json
import math
import pathlib
from types import SimpleNamespace

import cv2
import numpy as np
import pytest

from jaxlimb._validate import check_center_sigma
from jaxlimb.cli import main
from jaxlimb.errors import ArcTooShortError, CenterTooUncertainError, CheckFailed, ConfigError, ConvergenceError
from jaxlimb.geometry.camera import Camera
from jaxlimb.geometry.earth_cone import earth_position_from_ellipse
import jaxlimb.pipeline as pipeline_pkg
from jaxlimb.pipeline import covariance_block, locate
from jaxlimb.pipeline.checks import NonPhysicalFitError, check_edge_width, check_levels
from jaxlimb.pipeline.options import BodyShape, FrontEnd, LocateOptions, Profile

from ._scenes import SMALL_CAMERA, scene, sun_hints


def _functions(root: pathlib.Path):
    for path in sorted(root.rglob("*.py")):
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
                yield path.name, node.name, node.end_lineno - node.lineno + 1


def test_no_pipeline_function_over_60_lines():
    root = pathlib.Path(pipeline_pkg.__file__).parent
    long = [(f, n, k) for f, n, k in _functions(root) if k > 60]
    assert long == [], long
    # the entry point is a short composition of stages (its docstring is most of it)
    assert max(k for f, n, k in _functions(root) if n == "locate" and f == "locate.py") <= 60


def test_strategies_are_final_and_chosen_by_the_hints():
    import inspect

    import jaxlimb.pipeline.locate as locate_module
    from jaxlimb.pipeline.bodies import body_strategy
    from jaxlimb.pipeline.ellipsoid import Ellipsoid
    from jaxlimb.pipeline.frame import prepare
    from jaxlimb.pipeline.small.body import SmallBody
    from jaxlimb.pipeline.sphere import Disc, PredictedLimbSphere, Sphere
    from jaxlimb.pipeline.stages import Body

    # one abstract body; every strategy a final class that implements every stage
    assert inspect.isabstract(Body)
    for cls in (Sphere, Disc, PredictedLimbSphere, Ellipsoid, SmallBody):
        assert cls.__bases__ == (Body,) and not inspect.isabstract(cls) and getattr(cls, "__final__", False)
    assert ".name" not in inspect.getsource(locate_module)  # locate never tests a body's name
    img = np.zeros((64, 80), np.uint8)
    cam = Camera(focal_length_mm=8.0, rows=64, cols=80)
    pick = lambda h, o=None: body_strategy(prepare(img, cam, h, o))  # noqa: E731
    assert isinstance(pick({"body": "earth"}), Ellipsoid)
    assert isinstance(pick({"body": "sun"}), Disc)
    assert type(pick({"body": "moon"})) is Sphere and type(pick(None)) is Sphere
    assert isinstance(pick({"body": "moon"}, LocateOptions(shape="ellipsoid")), Ellipsoid)
    # a limb the hints predict (SPICE-like): the whole limb; a disc larger than the frame: its arc
    predicted = {"body": "moon", "range_prior_km": 400000.0, "expected_center_rc": [32.0, 40.0]}
    assert pick(predicted) == PredictedLimbSphere(arc=False)
    assert pick({"body": "moon", "range_prior_km": 3000.0}) == PredictedLimbSphere(arc=True)
    # the ellipsoid honours `model` (free ellipse) and refuses what it cannot do
    assert pick({"body": "earth", "R_body_to_camera": np.eye(3).tolist()}).free is False
    assert pick({"body": "earth", "R_body_to_camera": np.eye(3).tolist()}, LocateOptions(model="ellipse")).free
    with pytest.raises(ConfigError, match="estimate_k"):
        pick({"body": "earth"}, LocateOptions(estimate_k=False))
    with pytest.raises(ConfigError, match="camera"):
        body_strategy(prepare(img, None, {"body": "earth"}, None))


def test_options_are_enums_checked_at_construction():
    o = LocateOptions(front_end="scanline", profile="sigmoid", shape="disc")
    assert o.front_end is FrontEnd.SCANLINE and o.front_end == "scanline" and str(o.front_end) == "scanline"
    assert o.profile is Profile.SIGMOID and o.shape is BodyShape.DISC
    assert json.dumps({"f": o.front_end}) == '{"f": "scanline"}'
    for bad in (dict(front_end="sobel"), dict(model="square"), dict(profile="lambert"), dict(shape="cube"),
                dict(max_center_sigma_px=-1.0)):
        with pytest.raises(ConfigError):
            LocateOptions(**bad)


def test_physical_checks_are_typed_exit_3():
    with pytest.raises(NonPhysicalFitError, match="wrong sign") as e:
        check_levels(-1830.0, 12.0, "ellipsoid")
    assert e.value.exit_code == 3 and e.value.check == "non_physical_fit"
    check_levels(200.0, 10.0, "sphere")
    with pytest.raises(NonPhysicalFitError, match="PSF"):
        check_edge_width(7.5, "sphere")
    with pytest.raises(NonPhysicalFitError):
        check_edge_width(float("nan"), "sphere")
    check_edge_width(1.2, "sphere")
    with pytest.raises(CenterTooUncertainError, match="1-sigma is 2") as e:
        check_center_sigma(np.diag([4.0, 0.01]), 1.0)
    assert e.value.exit_code == 3
    assert check_center_sigma(np.diag([4.0, 0.01]), None) == pytest.approx(2.0)


def test_covariance_is_one_square_matrix_and_a_stated_tolerance_fails_the_frame():
    img, tr = scene(30000.0, 30.0, (190.0, 260.0), 20.0)
    m = locate(img, SMALL_CAMERA, sun_hints(tr))
    names = list(m.covariance)
    assert names[:3] == ["center_r", "center_c", "radius"]
    assert all(list(row) == names for row in m.covariance.values())
    P = covariance_block(m.covariance, names)
    assert np.allclose(P, P.T) and np.all(np.linalg.eigvalsh(P) > -1e-12 * np.abs(P).max())
    s = math.sqrt(max(np.linalg.eigvalsh(P[:2, :2])))
    assert m.extras["timings_s"]["total"] > 0 and {"front_end", "refine", "profile", "body_center"} <= set(
        m.extras["timings_s"])
    with pytest.raises(CenterTooUncertainError):
        locate(img, SMALL_CAMERA, sun_hints(tr), LocateOptions(max_center_sigma_px=0.5 * s))


def test_earth_short_arc_is_arc_too_short():
    """Without the Sun the lit window is the arc the front end found (its ends are where it found no lit edge, not
    horns: no margin); with the Sun, the lit half-circle less the margin at each horn."""
    from jaxlimb.pipeline.bodies import body_strategy
    from jaxlimb.pipeline.frame import prepare

    cam = Camera(focal_length_mm=8.0, rows=400, cols=400)
    frame = prepare(np.zeros((400, 400), np.uint8), cam, {"body": "earth"}, None)
    body = body_strategy(frame)
    cand = SimpleNamespace(center_rc=(200.0, 200.0), radius=120.0, lit_direction=(0.0, 1.0),
                           lit_halfangle=math.radians(4.0), info={})
    with pytest.raises(ArcTooShortError, match="the lit limb arc the front end found spans 8 deg") as e:
        body.limb_pixels(frame, cand)
    assert e.value.check == "arc_too_short"


def test_range_iteration_without_convergence_is_a_failed_check():
    from jaxlimb.geometry.ellipsoid import image_conic
    from jaxlimb.render import earth_scene

    cam = Camera(focal_length_mm=8.0, rows=1400, cols=1400)
    sc = earth_scene(40000.0, 35.0, 40.0, center_rc=(650.0, 760.0), camera=cam, north_angle_deg=70.0)
    ic = image_conic(cam, sc.radii, sc.q, sc.R_body_to_camera)
    p0 = -1.2 * sc.q
    with pytest.raises(ConvergenceError) as e:
        earth_position_from_ellipse(cam, ic.center_rc, ic.semi_axes_px, ic.angle_rad, p0,
                                    pole_camera=sc.R_body_to_camera[:, 2], max_iter=1)
    assert e.value.exit_code == 3


def test_earth_on_a_moon_frame_is_not_ok(tmp_path, capsys):
    """A 100 008 km Moon measured as the Earth: the Earth's radius at the hints' range does not fit the
    disc in the frame -- a failed check (exit 3), never ``status: ok`` with a 366 000 km range."""
    cam = SMALL_CAMERA
    img, tr = scene(100008.0, 30.0, (190.0, 260.0), 20.0)
    cv2.imwrite(str(tmp_path / "moon.png"), img)
    (tmp_path / "camera.json").write_text(json.dumps(cam.to_dict()))
    (tmp_path / "hints.json").write_text(json.dumps({"sun_dir_camera": list(map(float, tr.sun_dir_cam)),
                                                     "range_prior_km": 100008.0}))
    with pytest.raises(CheckFailed):
        locate(img, cam, {"body": "earth", "sun_dir_camera": list(map(float, tr.sun_dir_cam)),
                          "range_prior_km": 100008.0})
    code = main(["locate", str(tmp_path / "moon.png"), "--camera", str(tmp_path / "camera.json"), "--hints",
                 str(tmp_path / "hints.json"), "--body", "earth", "--json"])
    out = json.loads(capsys.readouterr().out)
    assert code == 3 and out["status"] == "error", out


def test_front_end_fallback():
    """When the chosen front end finds no limb on a variegated body (here Check 2 of a gradient front end asked
    for 5000 box-filter survivors, on bright clouds over a dark Lambert disc), the pipeline tries the other and
    says so in ``front_end``; with ``front_end_fallback=False``, or on a body of one albedo, the first failure is
    the answer (the EUV Sun of ``aia_171_level1.fits`` was answered 1.9 px off by the second front end)."""
    from jaxlimb.errors import TooManyOutliersError
    from jaxlimb.imaging import GradientOptions
    from jaxlimb.pipeline import LocateOptions, locate
    from tests.imaging._synth import render_disk
    from tests.imaging.test_variegated import cloudy_disc

    from jaxlimb.pipeline.frame import candidates, prepare
    from tests.imaging.test_variegated import CENTER

    strict = GradientOptions(min_points_box=5000)
    cand = candidates(prepare(cloudy_disc(0), None, None, LocateOptions(gradient=strict)))
    assert cand.front_end == "scanline"
    assert math.hypot(cand.center_rc[0] - CENTER[0], cand.center_rc[1] - CENTER[1]) < 3.0
    with pytest.raises(TooManyOutliersError, match="min_points_box = 5000"):
        candidates(prepare(cloudy_disc(0), None, None, LocateOptions(gradient=strict, front_end_fallback=False)))
    img = render_disk((400, 400), (201.3, 198.6), 120.0, phase_deg=40.0, blur_sigma=1.0, noise_sigma=1.0, ss=2)
    with pytest.raises(TooManyOutliersError, match="min_points_box = 5000"):
        locate(img, options=LocateOptions(gradient=strict))


def test_move_witness_carries_the_move_of_a_circle_fit_too():
    """``RefineResult.with_move_witness``: the move of ``(r0, c0, size)`` from another model of the same limb is added
    to the variances, the size being a circle's ``radius`` (the sigmoid without a camera) or a profile's ``a``."""
    import jax.numpy as jnp

    from jaxlimb.fitting import fit
    from jaxlimb.models import CIRCLE, CircleParams
    from jaxlimb.pipeline.stages import FitData, RefineResult

    truth = CircleParams(r0=60.0, c0=70.0, radius=30.0, k=2.0, ymax=200.0, ymin=10.0)
    rr, cc = np.mgrid[20:100, 30:110]
    coords = np.stack([rr.ravel(), cc.ravel()], axis=1).astype(float)
    z = np.asarray(CIRCLE.intensity(truth, jnp.asarray(coords))) + np.random.default_rng(0).normal(0, 1.0, len(coords))
    f = fit(CIRCLE, coords, z, truth.replace(r0=60.3, c0=69.8, radius=30.2))
    circ = RefineResult(f, FitData(coords, z, None, 0.0, 1.0), 0, ())
    other = SimpleNamespace(fit=SimpleNamespace(params=SimpleNamespace(r0=float(f.params.r0) + 0.3,
                                                                       c0=float(f.params.c0) - 0.4,
                                                                       a=float(f.params.radius) + 0.2)))
    out = circ.with_move_witness(other, 1.0)
    free = list(f.free)
    added = np.diag(np.asarray(out.fit.covariance) - np.asarray(f.covariance))
    assert added[free.index("r0")] == pytest.approx(0.25) and added[free.index("c0")] == pytest.approx(0.25)
    assert added[free.index("radius")] == pytest.approx(0.04)
    assert np.allclose(np.delete(added, [free.index(n) for n in ("r0", "c0", "radius")]), 0.0)
