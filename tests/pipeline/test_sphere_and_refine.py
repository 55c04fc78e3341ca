"""Unit tests of the pieces of the pipeline: the sphere-image inverse, the annulus rules, the checks."""

from __future__ import annotations

import math

import numpy as np
import pytest

from jaxlimb.errors import JumpError, RadiusInconsistentError, TooBigError, TooManyOutliersError, TooSmallError
from jaxlimb.geometry.camera import Camera, sphere_image_ellipse
from jaxlimb.geometry.sphere_image import sphere_from_ellipse_center
from jaxlimb.pipeline.checks import (CenterOutOfFieldError, check_center_in_field, check_jump, check_radius_prior,
                                     check_size)
from jaxlimb.pipeline.options import LocateOptions
from jaxlimb.pipeline.sphere.annulus import annulus_halfwidth, lit_halfangle, select_annulus
from jaxlimb.pipeline.sphere.fits import fit_circle_annulus


@pytest.mark.parametrize("direction", [(0.0, 0.0, 1.0), (0.1, -0.08, 1.0), (0.16, 0.12, 1.0), (-0.2, 0.05, 1.0)])
@pytest.mark.parametrize("range_km", [8000.0, 60000.0, 380000.0])
def test_sphere_inverse_is_exact(direction, range_km):
    cam = Camera()
    u = np.asarray(direction) / np.linalg.norm(direction)
    e = sphere_image_ellipse(cam, range_km * u, 1737.4)
    s = sphere_from_ellipse_center(cam.focal_px, cam.principal_point_rc, e["center_rc"], e["semi_axes_px"][0])
    assert np.allclose(s.body_center_rc, e["body_center_rc"], atol=1e-8)
    assert s.b == pytest.approx(e["semi_axes_px"][1], abs=1e-9)
    assert s.alpha_rad == pytest.approx(e["alpha_rad"], rel=1e-12)
    assert np.allclose(s.los, u, atol=1e-13)
    if e["theta_rad"] > 0:
        assert (s.angle_rad - e["angle_rad"] + 1e-12) % math.pi < 1e-9
    # f tan(alpha) = b^2 / a: the on-axis equivalent radius
    assert s.radius_equivalent_px == pytest.approx(cam.focal_px * math.tan(e["alpha_rad"]), rel=1e-12)


def test_annulus_halfwidth_rule():
    assert annulus_halfwidth(80.0, 0.1) == 6.0  # floor
    assert annulus_halfwidth(500.0, 0.1) == pytest.approx(10.0)  # 2 % of r
    assert annulus_halfwidth(80.0, 2.0) == pytest.approx(8.0)  # 4 rms
    assert annulus_halfwidth(8.0, 2.0) == 6.0  # capped at max(min, r/2)


def test_lit_halfangle_rule():
    assert lit_halfangle(None, 100, 6) == pytest.approx(math.radians(80))
    assert lit_halfangle(0.0, 100, 6) == math.pi  # full: no dark sliver
    assert lit_halfangle(math.radians(60), 100, 6, 10) == pytest.approx(math.radians(80))
    # crescent: the terminator must stay dr + 2 px inside the limb
    h = lit_halfangle(math.radians(150), 100, 6, 10)
    c2 = math.cos(math.radians(150)) ** 2
    t = 100 / math.sqrt(math.cos(h) ** 2 / c2 + math.sin(h) ** 2)
    assert 100 - t == pytest.approx(8.0, abs=0.2)
    assert h < math.radians(60)


def _disk(shape=(200, 240), c=(100.3, 118.7), r=60.0, sigma=1.0, lo=10.0, hi=200.0):
    from scipy.special import ndtr

    rr, cc = np.mgrid[0 : shape[0], 0 : shape[1]]
    d = np.hypot(rr - c[0], cc - c[1])
    return lo + (hi - lo) * ndtr((r - d) / math.hypot(sigma, math.sqrt(1 / 12)))


def test_select_annulus_lit_side_and_fit():
    img = _disk()
    opt = LocateOptions()
    sel = select_annulus(img, (100.0, 119.0), 60.5, 6.0, (0.0, 1.0), math.radians(60))
    ang = sel.angles()
    assert np.all(np.abs(ang) <= math.radians(60) + 1e-9)  # toward +col only
    d = np.hypot(sel.coords[:, 0] - 100.0, sel.coords[:, 1] - 119.0)
    assert np.all(np.abs(d - 60.5) <= 6.0)
    assert sel.inner_level == pytest.approx(200.0, abs=1.0) and sel.outer_level == pytest.approx(10.0, abs=1.0)
    res = fit_circle_annulus(sel, opt)
    p = res.fit.params
    assert float(p.r0) == pytest.approx(100.3, abs=0.01)
    assert float(p.c0) == pytest.approx(118.7, abs=0.01)
    assert float(p.radius) == pytest.approx(60.0, abs=0.01)


def test_select_annulus_drops_dark_bins():
    img = _disk()
    img[:, :100] = 10.0  # the left half of the disk is dark: no edge there
    sel = select_annulus(img, (100.3, 118.7), 60.0, 6.0, None, math.pi)
    assert np.all(sel.coords[:, 1] >= 92)  # a 5-deg bin (5 px of arc) may straddle the boundary
    assert sel.n_bins_kept < sel.n_bins


def test_select_annulus_outside_frame():
    img = _disk()
    with pytest.raises(TooManyOutliersError):
        select_annulus(img, (1000.0, 1000.0), 50.0, 6.0, None, math.pi)


def test_check_functions():
    ang = np.linspace(-1, 1, 50)
    assert check_jump((0, 0), 50.0, (0.5, 0.0), 50.2, ang, 2.0) == pytest.approx(0.2 + 0.5 * math.sin(1.0), abs=1e-9)
    with pytest.raises(JumpError):
        check_jump((0, 0), 50.0, (3.0, 0.0), 50.0, ang, 2.0)
    with pytest.raises(RadiusInconsistentError):
        check_radius_prior(80.0, (40.0, 60.0))
    check_radius_prior(50.0, (40.0, 60.0))
    with pytest.raises(TooSmallError):
        check_size(4.0, (100, 100))
    with pytest.raises(TooBigError):
        check_size(80.0, (100, 100))
    check_center_in_field((-40.0, 50.0), 45.0, (100, 100))  # cropped, centre outside but limb in
    with pytest.raises(CenterOutOfFieldError):
        check_center_in_field((-60.0, 50.0), 45.0, (100, 100))


def test_options_validation():
    from jaxlimb.errors import ConfigError

    for kw in ({"front_end": "x"}, {"model": "hyperbola"}, {"solver": "nope"}, {"max_steps": 0},
               {"min_lit_arc_deg": 400.0}, {"max_center_sigma_px": -1.0}, {"ellipsoid": object()}, {"gradient": 3}):
        with pytest.raises(ConfigError):
            LocateOptions(**kw)
