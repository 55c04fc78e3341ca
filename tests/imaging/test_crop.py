"""Cropped-target detection (Aerospace 2015 §3.4), noise estimate, body detection."""

from __future__ import annotations

import numpy as np
import pytest

from jaxlimb.errors import ConfigError
from jaxlimb.imaging import DetectOptions, detect_body, detect_cropping, estimate_noise

from ._synth import render_disk


@pytest.mark.parametrize(
    "shape, center, radius, n, sides",
    [
        ((200, 300), (100.0, 150.0), 60.0, 0, ()),
        ((200, 300), (100.0, -20.0), 60.0, 1, ("left",)),
        ((200, 300), (-10.0, -10.0), 60.0, 1, ("top", "left")),
        ((200, 300), (100.0, 150.0), 120.0, 2, ("top", "bottom")),
        ((200, 300), (100.0, 150.0), 165.0, 4, ("top", "right", "bottom", "left")),
    ],
)
def test_detect_cropping_counts_segments(shape, center, radius, n, sides):
    im = render_disk(shape, center, radius, ss=2)
    ci = detect_cropping(im)
    assert ci.n_crossings == n
    assert set(ci.sides) == set(sides)
    assert ci.cropped == (n > 0)


def test_estimate_noise(rng):
    im = render_disk((300, 300), (150.0, 150.0), 100.0, ss=2) + rng.normal(0, 3.0, (300, 300))
    assert estimate_noise(im) == pytest.approx(3.0, rel=0.08)
    assert estimate_noise(np.zeros((20, 20))) == 0.0


def test_detect_body_roi_and_region_on_block_averaged_frame():
    im = render_disk((1200, 1600), (500.0, 700.0), 200.0, blur_sigma=1.0, noise_sigma=2.0, ss=2)
    reg = detect_body(im)
    assert reg.factor == 4
    r0, r1, c0, c1 = reg.roi
    assert r0 <= 300 - 1 and r1 >= 700 + 1 and c0 <= 500 - 1 and c1 >= 900 + 1
    assert (r1 - r0) < 460 and (c1 - c0) < 460
    assert reg.centroid_rc == pytest.approx((500.0, 700.0), abs=1.5)
    assert reg.extent_major_px == pytest.approx(400.0, rel=0.03)
    assert reg.eigen_ratio > 0.95 and not reg.touches_border


def test_detect_options_are_the_two_switches():
    assert DetectOptions() == DetectOptions(run_checks=True, dark_surface=True)
    with pytest.raises(TypeError):  # the detection's numbers are constants, not settings
        DetectOptions(work_size=256)
