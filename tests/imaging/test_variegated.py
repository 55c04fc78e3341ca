"""A variegated body at low phase: bright clouds on a dark disc whose Lambert
limb darkens to zero.  Eq. (10)'s threshold finds the clouds, the strongest gradients are their edges; the
detection, both front ends and the pipeline's front-end fallback must still find the limb."""

from __future__ import annotations

import math

import cv2
import numpy as np
import pytest

from jaxlimb.errors import TooManyOutliersError
from jaxlimb.imaging import detect_body, gradient_front_end
from jaxlimb.imaging.front_end_common import check_region_inside

CENTER, RADIUS = (201.3, 198.6), 150.0


def cloudy_disc(seed: int = 2, shape=(400, 400)) -> np.ndarray:
    """Lambert disc at zero phase (radiance ~ mu, 0 at the limb) with albedo 0.2 and bright (0.9) cloud banks
    (14 of them, up to 1.02 R from the centre), PSF 1 px, 1 DN noise, 8 bits."""
    rng = np.random.default_rng(seed)
    ss = 4
    r, c = np.mgrid[0 : shape[0] * ss, 0 : shape[1] * ss]
    y, x = (r + 0.5) / ss - 0.5 - CENTER[0], (c + 0.5) / ss - 0.5 - CENTER[1]
    rho2 = (x * x + y * y) / RADIUS**2
    mu = np.sqrt(np.clip(1.0 - rho2, 0.0, None))
    albedo = np.full(r.shape, 0.2)
    for _ in range(14):
        a = rng.uniform(0, 2 * math.pi)
        d = rng.uniform(0.0, 0.8) * RADIUS
        w = rng.uniform(0.1, 0.22) * RADIUS
        albedo[(x - d * math.cos(a)) ** 2 + (y - d * math.sin(a)) ** 2 < w * w] = 0.9
    rad = 250.0 * albedo * mu
    img = cv2.resize(rad, shape[::-1], interpolation=cv2.INTER_AREA)
    img = cv2.GaussianBlur(img, (0, 0), 1.0) + 2.0 + rng.normal(0.0, 1.0, shape)
    return np.clip(np.round(img), 0, 255)


@pytest.mark.parametrize("seed", [0, 2])
def test_detection_takes_the_whole_disc_not_the_clouds(seed):
    img = cloudy_disc(seed)
    region = detect_body(img)
    assert region.dark_surface
    assert region.area_px > 0.9 * math.pi * RADIUS**2  # Eq. (10)'s threshold alone: the largest cloud bank
    assert math.hypot(region.centroid_rc[0] - CENTER[0], region.centroid_rc[1] - CENTER[1]) < 3.0


@pytest.mark.parametrize("seed", [0, 2])
def test_gradient_front_end_looks_for_the_limb_near_the_outline(seed):
    """Candidates only near the detected outline (``outline_band``): the cloud edges inside the disc are the
    strongest gradients, and a circle through them was the answer before."""
    lc = gradient_front_end(cloudy_disc(seed))
    assert math.hypot(lc.center_rc[0] - CENTER[0], lc.center_rc[1] - CENTER[1]) < 3.5  # a start for the fit
    assert abs(lc.radius - RADIUS) < 4.0


def test_one_bright_patch_is_not_a_variegated_body():
    """A thin crescent: the low threshold adds its faint horns (the region grows 1.6 times or more) but it is one
    bright patch, not clouds on a darker disc: Eq. (10)'s region is kept."""
    from ._synth import render_disk

    img = render_disk((400, 400), CENTER, 80.0, phase_deg=165.0, sun_dir_rc=(0.0, 1.0), blur_sigma=1.0, noise_sigma=1.0, ss=2)
    from jaxlimb.imaging import DetectOptions

    assert not detect_body(img, DetectOptions(run_checks=False)).dark_surface


def test_a_circle_that_leaves_the_lit_region_outside_is_refused():

    region = detect_body(cloudy_disc())
    check_region_inside(CENTER, RADIUS, region, 0.05)
    with pytest.raises(TooManyOutliersError, match="lit region outside"):
        check_region_inside((CENTER[0] + 30.0, CENTER[1]), 0.7 * RADIUS, region, 0.05)


def test_a_uniform_disc_keeps_eq10s_region():
    """No dark surface: the low threshold's region is no larger, Eq. (10)'s threshold is kept."""
    from ._synth import render_disk

    img = render_disk((400, 400), CENTER, RADIUS, phase_deg=60.0, blur_sigma=1.0, noise_sigma=1.0, seed=3)
    region = detect_body(img)
    assert region.threshold > 0.2 * (img.max() - img.min())
