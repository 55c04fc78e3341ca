"""The Earth's centre with the pole unknown, marginalised over the poles a Sun-declination bound allows
(jaxlimb.pipeline.ellipsoid.pole_prior): exact geometry, no rendering."""

from __future__ import annotations

import math
from types import SimpleNamespace

import numpy as np
import pytest

from jaxlimb.errors import ConfigError
from jaxlimb.geometry.camera import Camera
from jaxlimb.geometry.earth import EARTH_EQUATORIAL_KM as RE, EARTH_POLAR_KM as RP
from jaxlimb.geometry.earth_cone import earth_position_from_ellipse
from jaxlimb.geometry.ellipsoid import image_conic
from jaxlimb.pipeline import EllipsoidOptions
from jaxlimb.pipeline.ellipsoid.pole_prior import cone_flattening, ellipse_flattening, marginal_center, spheroid_cones
from jaxlimb.pipeline import covariance_block

SIN_OBLIQUITY = math.sin(math.radians(23.44))


def _scene(lat_deg: float, phase_deg: float, discriminating: bool):
    """A near Earth (40 000 km, 8 mm lens, off-axis) seen from latitude ``lat_deg``; the Sun at ``phase_deg`` with
    ``s . pole = 0`` (its mirror pole then has ``|s . p'| = 2 sin(lat) cos(phase)``: excluded by the bound) or, when
    not ``discriminating``, in the plane of the line of sight and the cone's major axis (both poles equally allowed)."""
    cam = Camera(focal_length_mm=8.0)
    q = 40000.0 * cam.los(np.array([700.0, 1700.0]))
    w = -q / np.linalg.norm(q)  # toward the observer
    n = np.cross(w, [1.0, 0.0, 0.0])
    n /= np.linalg.norm(n)
    m = np.cross(w, n)
    a, b = math.sin(math.radians(lat_deg)), math.cos(math.radians(lat_deg))
    pole = a * w + b * n
    c = math.cos(math.radians(phase_deg))
    d = -a * c / b if discriminating else 0.0
    s = c * w + d * n + math.sqrt(1.0 - c * c - d * d) * m
    x = np.cross(n, pole)
    R = np.column_stack([x / np.linalg.norm(x), np.cross(pole, x / np.linalg.norm(x)), pole])
    ic = image_conic(cam, (RE, RE, RP), q, R)
    ell = (tuple(ic.center_rc), tuple(ic.semi_axes_px), float(ic.angle_rad))
    p_free, _ = earth_position_from_ellipse(cam, *ell, np.zeros(3))
    return cam, ell, np.asarray(ic.body_center_rc), -p_free, s, pole


def test_flattening_of_the_image_ellipse_is_the_spheroids_cone():
    """The flattening vector of the limb ellipse's cone (``ellipse_flattening``) equals that of the spheroid's
    cone built from its pole (``spheroid_cones``), and the centre construction ``2 v_obs - v_k`` with the true pole
    recovers the body centre's image from the free position (to 1.3e-5 px)."""
    cam, ell, body_rc, q_free, _, pole = _scene(40.0, 50.0, True)
    g_ell = ellipse_flattening(cam, ell)
    g_true, axes = cone_flattening(spheroid_cones(q_free, pole[None], RE, RP))
    # q_free (the free ellipse's position, along the cone axis) is not the body's own: 3e-7 of 1.9e-3 apart
    assert np.allclose(g_ell, g_true[0], atol=1e-6), (g_ell, g_true)
    assert 0.5 * (1 - RP / RE) < np.hypot(*g_ell) < (1 - RP / RE)  # |g| ~ f cos^2(lat)
    v_obs = q_free / np.linalg.norm(q_free)
    assert np.hypot(*(cam.project(2.0 * v_obs - axes[0]) - body_rc)) < 1e-4  # first order in 1e-4 rad: 1.3e-5 px
    assert np.hypot(*(cam.project(v_obs) - body_rc)) > 0.2  # the cone axis is gamma_off away (0.31 px here)


def _params(ell):
    return SimpleNamespace(r0=ell[0][0], c0=ell[0][1], a=ell[1][0], rho=ell[1][1] / ell[1][0], theta=ell[2])


COV = np.diag([1e-4, 1e-4, 1e-4, 1e-10, 1e-6])


def test_the_sun_declination_bound_signs_the_centre_offset():
    """The Sun 50 deg from the observer, on the true pole's equator: the mirror pole puts it 59 deg from its equator,
    beyond the Earth's 23.44 deg, so the marginal centre is the body's (measured 0.046 px off) while the cone axis is
    0.31 px off; the Sun in the cone's symmetry plane allows both poles, and the answer stays at the cone axis with the offset
    left in the covariance."""
    cam, ell, body_rc, q_free, s, _ = _scene(40.0, 50.0, True)
    axis_rc = cam.project(q_free / np.linalg.norm(q_free))
    mean, cov, info = marginal_center(cam, _params(ell), COV, q_free, s, SIN_OBLIQUITY, RE, RP)
    assert np.hypot(*(mean - body_rc)) < 0.06 < 0.2 < np.hypot(*(axis_rc - body_rc)), (mean, body_rc, axis_rc)
    assert np.sqrt(np.max(np.linalg.eigvalsh(cov))) < 0.1 and info["effective_poles"] > 1

    cam, ell, body_rc, q_free, s, _ = _scene(40.0, 50.0, False)
    axis_rc = cam.project(q_free / np.linalg.norm(q_free))
    mean, cov, _ = marginal_center(cam, _params(ell), COV, q_free, s, SIN_OBLIQUITY, RE, RP)
    gap = np.hypot(*(axis_rc - body_rc))
    assert np.hypot(*(mean - axis_rc)) < 0.3 * gap  # no side chosen
    assert np.sqrt(np.max(np.linalg.eigvalsh(cov))) > 0.7 * gap  # the offset stays in the covariance


def test_a_bound_few_poles_meet_gives_a_finite_answer_or_none():
    """A zero bound with the Sun along the line of sight leaves only the grid's poles normal to it: the marginal is a
    finite answer or ``None`` (the default's answer then stands), never NaN; an out-of-range option is a
    ConfigError."""
    cam, ell, _, q_free, _, _ = _scene(40.0, 50.0, True)
    out = marginal_center(cam, _params(ell), COV, q_free, -q_free, 0.0, RE, RP)
    assert out is None or np.all(np.isfinite(out[0]))
    with pytest.raises(ConfigError):
        EllipsoidOptions(sun_declination_max_deg=120.0)


def test_locate_with_the_bound_on_an_independent_earth():
    """``locate`` without the attitude on an independent render (``benchmarks/earth_pole_prior.py``'s ``defocus`` 2,
    40 000 km, the Sun within 23.44 deg of the equator): the default answers at the cone axis, 0.26 px from the body
    centre (the mirror offset); with ``sun_declination_max_deg = 23.44`` measured 0.023 px, at NEES below 2."""
    import jax

    jax.config.update("jax_enable_x64", True)
    from jaxlimb.pipeline import LocateOptions, locate
    from jaxlimb.render.independent import EARTH_FAMILIES, earth_case

    rng = np.random.default_rng([2026, 1, EARTH_FAMILIES.index("defocus"), 2])
    case = earth_case("defocus", rng, far=False, sun_declination_max_deg=23.44)
    hints = {k: v for k, v in case.hints.items() if k != "R_body_to_camera"}
    truth = np.asarray(case.truth.body_center_rc)
    plain = locate(case.image, case.camera, hints)
    opts = LocateOptions(ellipsoid=EllipsoidOptions(sun_declination_max_deg=23.44))
    bound = locate(case.image, case.camera, hints, opts)
    e0, e1 = np.subtract(plain.center_rc, truth), np.subtract(bound.center_rc, truth)
    c = bound.covariance
    P = covariance_block(c)
    assert "pole_prior" not in plain.extras and bound.extras["pole_prior"]["sun_declination_max_deg"] == 23.44
    assert np.hypot(*e0) > 0.2 and np.hypot(*e1) < 0.06, (e0, e1)
    assert float(e1 @ np.linalg.solve(P, e1)) < 2.0
