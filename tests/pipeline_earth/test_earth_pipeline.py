"""Earth pipeline (§IV, Fig. 2): cone lifting, ellipse -> position, locate (ellipsoid strategy) on renders."""

from __future__ import annotations

import math

import numpy as np
import pytest

from jaxlimb.errors import ConfigError, GeometryError
from jaxlimb.geometry.camera import Camera
from jaxlimb.geometry.earth import EARTH_EQUATORIAL_KM, EARTH_POLAR_KM, earth_radii, gamma_off
from jaxlimb.geometry.earth_cone import earth_position_from_ellipse, image_ellipse_cone, max_gamma_off
from jaxlimb.geometry.ellipsoid import image_conic, limb_cone, limb_cone_matrix_camera
from jaxlimb.pipeline import locate
from jaxlimb.pipeline import EllipsoidOptions
from jaxlimb.pipeline.ellipsoid.center import unsigned_offset_cov
from jaxlimb.pipeline.options import LocateOptions
from jaxlimb.pipeline.stages import FitData, RefineResult
from jaxlimb.render import RenderOptions, earth_scene, render_body
from jaxlimb.pipeline import covariance_block

RADII = (EARTH_EQUATORIAL_KM, EARTH_EQUATORIAL_KM, EARTH_POLAR_KM)


def _geometry(D, lat, f=8.0, n=1400, center_rc=(650.0, 760.0)):
    cam = Camera(focal_length_mm=f, rows=n, cols=n)
    sc = earth_scene(D, lat, 40.0, center_rc=center_rc, camera=cam, north_angle_deg=70.0)
    return cam, sc


@pytest.mark.parametrize("D, lat", [(40000.0, 0.0), (40000.0, 50.0), (380000.0, 30.0)])
def test_image_ellipse_cone_is_the_limb_cone(D, lat):
    cam, sc = _geometry(D, lat)
    ic = image_conic(cam, sc.radii, sc.q, sc.R_body_to_camera)
    cone = image_ellipse_cone(cam, ic.center_rc, ic.semi_axes_px, ic.angle_rad)
    truth = limb_cone(sc.radii, sc.observer_body)
    axis_cam = sc.R_body_to_camera @ truth.axis
    assert np.allclose(cone.axis, axis_cam, atol=1e-10)
    assert cone.semi_axes == pytest.approx(truth.semi_axes, rel=1e-9)
    # the free-ellipse range (Re / a') is good to 1e-4 at 40 000 km for any latitude
    assert EARTH_EQUATORIAL_KM / cone.semi_axes[0] == pytest.approx(D, rel=1e-4)


@pytest.mark.parametrize("lat", [0.0, 35.0, -60.0])
def test_position_from_exact_ellipse_recovers_observer(lat):
    D = 40000.0
    cam, sc = _geometry(D, lat)
    ic = image_conic(cam, sc.radii, sc.q, sc.R_body_to_camera)
    p_true = -sc.q
    p0 = 1.02 * D * (-(sc.q + np.array([300.0, -200.0, 0.0])) / np.linalg.norm(sc.q + np.array([300.0, -200.0, 0.0])))
    p, info = earth_position_from_ellipse(
        cam, ic.center_rc, ic.semi_axes_px, ic.angle_rad, p0, pole_camera=sc.R_body_to_camera[:, 2]
    )
    assert np.linalg.norm(p - p_true) < 1e-6 * D
    assert info["iterations"] <= 6
    # the centre offset matters: the cone axis alone is wrong by gamma_off (15 arcsec here)
    axis_err = math.acos(min(1.0, float(info["cone"].axis @ (sc.q / D))))
    if lat != 0.0:
        assert axis_err > 1e-5
        assert abs(abs(info["gamma_off_rad"]) - axis_err) < 1e-9
    # projected centre: exact
    assert np.allclose(cam.project(-p), ic.body_center_rc, atol=1e-6)


def test_position_needs_outside_prior():
    cam, sc = _geometry(40000.0, 10.0)
    ic = image_conic(cam, sc.radii, sc.q, sc.R_body_to_camera)
    with pytest.raises(GeometryError, match="outside"):
        earth_position_from_ellipse(
            cam, ic.center_rc, ic.semi_axes_px, ic.angle_rad, np.array([0.0, 0.0, -1000.0]),
            pole_camera=sc.R_body_to_camera[:, 2],
        )


def test_distorted_camera_rejected():
    cam = Camera(focal_length_mm=8.0, rows=200, cols=200, k1=0.01)
    with pytest.raises(ConfigError, match="pinhole"):
        image_ellipse_cone(cam, (100.0, 100.0), (50.0, 49.0), 0.3)


@pytest.fixture(scope="module")
def earth_far():
    """Earth at 380 000 km, 16 mm camera (300 x 300 crop), latitude 30 deg, gibbous (40 deg)."""
    cam = Camera(focal_length_mm=16.0, rows=300, cols=300)
    sc = earth_scene(380000.0, 30.0, 40.0, center_rc=(148.3, 153.6), camera=cam, sun_angle_deg=30.0, north_angle_deg=80.0)
    img, truth = render_body(sc, cam, RenderOptions(), seed=11)
    return cam, sc, img, truth


def _hints(sc, truth, known_R=True, **kw):
    h = {"body": "earth", "range_prior_km": 1.01 * truth.range_km, "sun_dir_camera": list(truth.sun_dir_cam)}
    if known_R:
        h["R_body_to_camera"] = np.asarray(sc.R_body_to_camera).tolist()
    h.update(kw)
    return h


def test_locate_earth_known_attitude_meets_targets(earth_far):
    cam, sc, img, truth = earth_far
    m = locate(img, cam, _hints(sc, truth))
    err = np.hypot(*np.subtract(m.center_rc, truth.center_rc))
    assert err <= 0.1, f"centre error {err:.3f} px"
    assert abs(m.range_km / truth.range_km - 1) <= 1e-3
    # the default refits the limb with the physical profile (Sun direction known): Lommel-Seeliger
    # render -> L ~ 1, and the sigmoid's 0.06 px / 0.05 % limb-brightening bias is gone
    assert m.extras["model"] == "lunar_limb" and 0.9 <= m.extras["profile"]["L"] <= 1.1
    assert err <= 0.03 and abs(m.range_km / truth.range_km - 1) <= 2e-4
    assert np.allclose(m.los_camera, truth.los_cam, atol=0.1 / cam.focal_px)
    assert m.extras["fits"][0]["range_iterations"] <= 6
    assert len(m.extras["fits"]) <= 3
    # the ellipse is the limb (not the projected centre): its centre is offset from the body centre
    assert m.ellipse is not None and m.ellipse.semi_axes_px[0] >= m.ellipse.semi_axes_px[1]
    cov = m.covariance
    assert cov["center_r"]["center_r"] > 0 and cov["range_km"]["range_km"] > 0
    out = m.to_json()
    assert out["status"] == "ok" and len(out["los_camera"]) == 3


def test_flat_sigmoid_is_biased_on_gibbous_earth(earth_far):
    """The paper's flat-topped ESF (interior_ramp=False) is pulled toward the Sun; the ramp model is not."""
    cam, sc, img, truth = earth_far
    m0 = locate(img, cam, _hints(sc, truth), LocateOptions(ellipsoid=EllipsoidOptions(interior_ramp=False, band_px=6.0)))
    m1 = locate(img, cam, _hints(sc, truth))
    e0 = np.hypot(*np.subtract(m0.center_rc, truth.center_rc))
    e1 = np.hypot(*np.subtract(m1.center_rc, truth.center_rc))
    assert e0 > 2 * e1


def test_locate_earth_free_ellipse(earth_far):
    cam, sc, img, truth = earth_far
    m = locate(img, cam, _hints(sc, truth, known_R=False))
    assert m.extras["free_ellipse"]
    err = np.subtract(m.center_rc, truth.center_rc)
    P = m.center_covariance
    assert np.hypot(*err) < 0.5
    assert abs(m.range_km / truth.range_km - 1) < 4e-3
    assert np.all(np.linalg.eigvalsh(P) > 0)


def test_locate_earth_bad_inputs(earth_far):
    cam, sc, img, truth = earth_far
    with pytest.raises(ConfigError, match="camera"):
        locate(img, None, _hints(sc, truth))
    with pytest.raises(GeometryError, match="spheroid"):
        locate(img, cam, _hints(sc, truth, body_radii_km=[6378.0, 6370.0, 6357.0]))
    with pytest.raises(ConfigError, match="R_body_to_camera"):
        locate(img, cam, _hints(sc, truth, R_body_to_camera=[[1, 0, 0], [0, 1, 0], [0, 0, 2]]))
    with pytest.raises(ConfigError, match="band_px"):
        LocateOptions(ellipsoid=EllipsoidOptions(band_px=-1.0))


def test_earth_radii_helper_unchanged():
    assert earth_radii(10.0).tolist() == [6388.137, 6388.137, 6366.752]


def test_blurred_sqrt_matches_quadrature():
    from scipy.integrate import quad
    from scipy.stats import norm

    from jaxlimb.models.ellipse_ramp import _blurred_sqrt

    xs = np.array([-4.0, -1.0, 0.0, 0.37, 2.5, 9.0, 15.99, 16.01, 40.0])
    got = np.asarray(_blurred_sqrt(xs))
    want = np.array([quad(lambda t, x=x: math.sqrt(t) * norm.pdf(x - t), max(0.0, x - 12), x + 12, limit=200)[0] for x in xs])
    assert np.allclose(got, want, rtol=2e-6, atol=1e-9)


def test_edge_model_is_exact_blur_of_profile():
    """f(u) equals the numerical Gaussian blur of H(u) (T + g u + g2 sqrt(u)) across the limb."""
    from scipy.integrate import quad
    from scipy.stats import norm

    from jaxlimb.models import EllipseRampParams, ellipse_ramp_intensity

    k, T, ymin, g, g2 = 0.9, 1000.0, 50.0, -30.0, 80.0
    p = EllipseRampParams(r0=0.0, c0=0.0, a=100.0, theta=0.0, rho=1.0, k=k, ymax=T, ymin=ymin, g=g, g2=g2,
                          h1=0.0, h2=0.0, h3=0.0, h4=0.0)
    cols = np.array([95.0, 99.0, 100.0, 100.6, 103.0])
    got = np.asarray(ellipse_ramp_intensity(p, np.column_stack([np.zeros_like(cols), cols])))
    s = 1.0 / k
    for c, f in zip(cols, got):
        u = 100.0 - c
        prof = lambda t: (T - ymin + g * t + g2 * math.sqrt(t)) * norm.pdf(u - t, scale=s)  # noqa: E731
        want = ymin + quad(prof, 0, np.inf, limit=200)[0]
        assert f == pytest.approx(want, rel=1e-6)


def test_free_ellipse_offset_bound_covers_every_latitude():
    """Without the attitude the body centre is the limb ellipse's centre +- gamma_off along the unseen polar
    axis: the model-error term uses the largest offset over the latitude (isotropic), ~0.3 px at 40 000 km
    with 8 mm / 2.2 um, so a frame at 44 deg (0.305 px off) is within its covariance."""

    cam = Camera(focal_length_mm=8.0, pixel_pitch_mm=0.0022, rows=1944, cols=2592)
    g = max_gamma_off(40000.0, EARTH_EQUATORIAL_KM, EARTH_POLAR_KM, 0.0)
    for lat in (0.0, 20.0, 44.0, 60.0, 90.0):
        t = math.radians(lat)
        pe = 40000.0 * np.array([math.cos(t), 0.0, math.sin(t)])
        assert abs(gamma_off(pe, 0.0, equatorial_km=EARTH_EQUATORIAL_KM, polar_km=EARTH_POLAR_KM)) <= g * (1 + 1e-9)
    assert 0.28 < g * cam.focal_px < 0.32
    P, _ = unsigned_offset_cov(cam, ((900.0, 1200.0), (600.0, 599.0), 0.3), 40000.0, EARTH_EQUATORIAL_KM,
                               EARTH_POLAR_KM, 0.0, 3)
    assert np.allclose(P[:2, :2], (g * cam.focal_px) ** 2 / 3 * np.eye(2)) and P[2, 2] == 0.0


@pytest.mark.parametrize("lat_deg, off_axis", [(35.0, (0.0, 0.0)), (50.0, (0.08, -0.05)), (15.0, (-0.1, 0.12))])
def test_pole_unknown_limb_cannot_sign_the_center_offset(lat_deg, off_axis):
    """Why the attitude-unknown Earth target (0.15 px median) has a floor on near frames: the mirror image
    of the spheroid through a principal plane of its limb cone (one that contains the cone's axis) is another
    Earth (same radii, a proper attitude) with the *same* limb cone, hence the same image ellipse, perspective and
    off-axis view included, yet its centre images ``2 |gamma_off|`` away.  Nothing measured on the limb tells the
    two apart; the cone axis (the pipeline's answer) is off by ``|gamma_off|`` for both (``floor_px`` of
    ``benchmarks/families.py``'s ``earth_noR`` rows: median 0.27 px on the 40 000 km frames)."""
    cam = Camera(focal_length_mm=8.0, pixel_pitch_mm=0.0022, rows=1944, cols=2592)
    radii = earth_radii(0.0)
    u = np.array([off_axis[0], off_axis[1], 1.0])
    q = 40000.0 * u / np.linalg.norm(u)  # body centre, camera frame
    t = math.radians(lat_deg)  # the pole at lat_deg from the plane normal to the line of sight, tilted in the image
    side = np.cross(q, [0.3, 1.0, 0.0])
    side /= np.linalg.norm(side)
    pole = math.cos(t) * side + math.sin(t) * (-q / np.linalg.norm(q))
    x = np.cross(pole, [1.0, 0.0, 0.0])
    x /= np.linalg.norm(x)
    R = np.column_stack([x, np.cross(pole, x), pole])
    Mc = limb_cone_matrix_camera(radii, q, R)
    ic = image_conic(cam, radii, q, R)
    w, V = np.linalg.eigh(Mc)
    seen = []
    for e in V.T:
        S = np.eye(3) - 2.0 * np.outer(e, e)
        q2, R2 = S @ q, S @ R @ np.diag([1.0, 1.0, -1.0])  # the mirror Earth: a proper rotation, same radii
        if q2[2] <= 0:  # the plane normal to the cone's axis: the mirror body is behind the camera
            continue
        assert np.linalg.det(R2) == pytest.approx(1.0)
        Mc2 = limb_cone_matrix_camera(radii, q2, R2)
        assert np.allclose(Mc2, Mc, rtol=0, atol=1e-9 * np.abs(Mc).max())  # the same limb cone
        ic2 = image_conic(cam, radii, q2, R2)
        assert np.allclose(ic2.conic, ic.conic, atol=1e-9)  # the same image ellipse
        seen.append((float(np.hypot(*(np.asarray(ic2.body_center_rc) - ic.body_center_rc))), ic2.body_center_rc))
    assert len(seen) == 2
    seen.sort(key=lambda x: x[0])
    (still, _), (moved, other_center) = seen
    # one mirror leaves the centre where it is (the plane holds it), the other moves it 2 |gamma_off| (0.32-0.61 px)
    assert still < 1e-6 and 0.3 < moved < 0.7
    p_axis, _ = earth_position_from_ellipse(cam, ic.center_rc, ic.semi_axes_px, ic.angle_rad, np.zeros(3))
    off = [float(np.hypot(*(np.asarray(cam.project(-p_axis)) - np.asarray(c)))) for c in (ic.body_center_rc, other_center)]
    assert off == pytest.approx([0.5 * moved, 0.5 * moved], rel=0.05)


def _ellipse_edge_fit():
    """An elliptical sigmoid fitted (``rho, theta`` held) to a noisy 140-deg arc of its own model: the fit and its
    :class:`RefineResult`."""
    import jax

    from jaxlimb.fitting import fit
    from jaxlimb.models import ELLIPSE, EllipseParams

    jax.config.update("jax_enable_x64", True)
    truth = EllipseParams(r0=200.3, c0=250.7, a=80.0, theta=0.3, rho=0.97, k=1.5, ymax=200.0, ymin=10.0)
    rr, cc = np.meshgrid(np.arange(100, 300), np.arange(150, 350), indexing="ij")
    d = np.hypot(rr - 200.3, cc - 250.7)
    sel = (np.abs(d - 79.0) < 5) & (np.abs(np.arctan2(rr - 200.3, cc - 250.7) - 0.2) < 1.2)
    pts = np.column_stack([rr[sel], cc[sel]]).astype(float)
    z = np.asarray(ELLIPSE.intensity(truth, pts)) + 2.0 * np.random.default_rng(0).standard_normal(pts.shape[0])
    res = fit(ELLIPSE, pts, z, truth, fixed=("rho", "theta"), throw=True)
    return res, RefineResult(res, FitData(pts, z, None, 0.0, 1.0), 0, ("rho", "theta"))


def test_edge_fit_model_error_is_generic_and_keeps_the_noise_covariance():
    """``with_model_error`` on an elliptical sigmoid (the Earth's fallback when the profile is rejected): an
    exact model leaves the covariance near the noise-only one, which is kept for the CRLB."""
    from jaxlimb.models import ELLIPSE
    from jaxlimb.pipeline.profile.fit import with_model_error

    res, rr0 = _ellipse_edge_fit()
    out = with_model_error(rr0, model=ELLIPSE)
    C0, C = out.covariance_noise, np.asarray(out.fit.covariance)
    assert np.allclose(C0, np.asarray(res.covariance))
    assert np.all(np.diag(C) >= np.diag(C0) - 1e-15) and np.all(np.diag(C)[:2] < 4 * np.diag(C0)[:2])


def test_center_floor_lifts_only_the_directions_below_it():
    """``floor_center_var``: eigenvalues of the ``(r0, c0)`` block below the floor are lifted to it, the eigenvectors,
    the larger eigenvalue and the other parameters' variances kept."""
    from jaxlimb.pipeline.ellipsoid.profile import floor_center_var

    res, rr0 = _ellipse_edge_fit()
    C = np.asarray(res.covariance)
    w0, V0 = np.linalg.eigh(C[:2, :2])
    floor = float(np.sqrt(w0[0] * w0[1]))  # between the two eigenvalues: only the smaller one is lifted
    C2 = np.asarray(floor_center_var(rr0, floor).fit.covariance)
    w, V = np.linalg.eigh(C2[:2, :2])
    assert np.isclose(w[0], floor) and np.isclose(w[1], w0[1])
    assert np.allclose(np.abs(V.T @ V0), np.eye(2), atol=1e-9)
    assert np.allclose(C2[2:, 2:], C[2:, 2:])
    assert floor_center_var(rr0, 0.0) is rr0


def test_earth_center_sigma_has_the_specification_floor(earth_far):
    """``EllipsoidOptions.center_floor_px`` (default 0.0075 px): the reported centre sigma is never below it; with
    0 the noise and model-error terms alone (smaller on this clean own render)."""
    from jaxlimb.pipeline import LocateOptions
    from jaxlimb.pipeline import EllipsoidOptions

    cam, sc, img, truth = earth_far
    sig = {}
    for f in (0.0075, 0.0):
        m = locate(img, cam, _hints(sc, truth), LocateOptions(ellipsoid=EllipsoidOptions(center_floor_px=f)))
        c = m.covariance
        P = covariance_block(c)
        sig[f] = float(np.sqrt(np.linalg.eigvalsh(P)[0]))
    assert sig[0.0] < 0.0075 and 0.0075 * 0.9 <= sig[0.0075] < 0.02
    with pytest.raises(Exception, match="center_floor_px"):
        EllipsoidOptions(center_floor_px=-1.0)


def test_traced_start_leaves_a_front_end_circle_on_cloud_edges():
    """Full-disc cloudy Earth (independent renderer, ``benchmarks/earth_full_disc.py`` ``clouds`` 0, 1.5 million km,
    phase 11 deg): the front end's circle lies ~10 px inside the limb on cloud edges, and half the wide trace's
    crossings are within 1 px of it; the rays' own fit is on the limb, so the trace's start is that fit, not the
    circle (``ellipsoid._traced_start``; it used to keep the circle, and the band fit then failed Check 5)."""
    from jaxlimb.imaging import Hints
    from jaxlimb.pipeline.locate import body_strategy, prepare
    from jaxlimb.render.independent import EARTH_FULL_DISC_FAMILIES, earth_full_disc_case

    case = earth_full_disc_case("clouds", np.random.default_rng([2026, 2, EARTH_FULL_DISC_FAMILIES.index("clouds"), 0]))
    frame = prepare(case.image, case.camera, Hints.from_dict(case.hints), None, None)
    body = body_strategy(frame)
    frame = body.prepare(frame)
    cand = body.candidates(frame)
    start = body.limb_pixels(frame, cand).ellipse
    t = case.truth
    assert math.dist(cand.center_rc, t.ellipse_center_rc) > 5.0  # the premise: the front end is off
    assert math.dist(start[0], t.ellipse_center_rc) < 1.0 and abs(start[1][0] - t.semi_axes_px[0]) < 1.0
