"""Scan-line front end (illuminated-ellipsoid paper §IV-A, §VI): lit limb vs terminator."""

from __future__ import annotations

import math
from functools import lru_cache

import numpy as np
import pytest

from jaxlimb._data import shared_data_dir
from jaxlimb.errors import ConfigError
from jaxlimb.imaging import Hints, ScanlineOptions, inertia_axes, scan_transitions, scanline_front_end
from jaxlimb.imaging.scanline import threshold_eq10

from ._synth import render_disk, sun_vector

C0 = (203.3, 196.7)


@lru_cache(maxsize=None)
def img(phase, sun, seed=5, stars=0, albedo=0.0):
    return render_disk((400, 400), C0, 150.0, phase_deg=phase, sun_dir_rc=sun, blur_sigma=1.0, noise_sigma=2.0,
                       seed=seed, n_stars=stars, n_hot=stars, albedo_variation=albedo, ss=3)


SUNS = [(0.6, 0.8), (-0.6, -0.8), (1.0, 0.0), (0.0, -1.0)]


@pytest.mark.parametrize("phase", [30.0, 60.0, 90.0, 120.0])
@pytest.mark.parametrize("sun", SUNS)
def test_picks_lit_limb_not_terminator(phase, sun):
    im = img(phase, sun, stars=8, albedo=0.2)
    lc = scanline_front_end(im)
    assert lc.front_end == "scanline"
    assert math.hypot(lc.center_rc[0] - C0[0], lc.center_rc[1] - C0[1]) < 1.5
    assert abs(lc.radius - 150.0) < 1.5
    assert lc.lit_direction is not None and np.dot(lc.lit_direction, sun) > 0.95
    # the limb points are on the Sun side of the centre
    d = (lc.points_rc - np.array(lc.center_rc)) @ np.asarray(sun)
    assert np.all(d > -1.0)
    other = lc.info["other_set"]
    assert other["residual_rms"] is None or other["residual_rms"] > lc.residual_rms
    assert lc.n_points >= 15


@pytest.mark.parametrize("phase", [45.0, 110.0])
def test_with_sun_hint_uses_geometry(phase):
    sun = (-0.6, -0.8)
    h = Hints(sun_dir_camera=tuple(sun_vector(phase, sun)), expected_radius_px=150.0)
    lc = scanline_front_end(img(phase, sun), hints=h)
    assert lc.info["lit_set"] == "exit" and "Sun direction" in lc.info["choice"]
    assert lc.lit_direction == pytest.approx(sun, abs=1e-9)
    assert abs(lc.radius - 150.0) < 1.5


def test_full_disk_merges_sets():
    lc = scanline_front_end(img(0.0, (0.6, 0.8)))
    assert lc.info["merged"] and lc.lit_direction is None
    assert math.hypot(lc.center_rc[0] - C0[0], lc.center_rc[1] - C0[1]) < 0.5
    assert abs(lc.radius - 150.0) < 0.5


def test_inertia_axis_is_the_axis_of_symmetry():
    # crescent lit toward (row, col) = (0.6, 0.8): its axis of symmetry is that direction
    im = img(120.0, (0.6, 0.8))
    b = im > threshold_eq10(im)
    ax = inertia_axes(b)
    assert abs(np.dot(ax.axis_rc, (0.6, 0.8))) > 0.99
    assert 0.0 < ax.eigen_ratio < 0.5
    disk = inertia_axes(img(0.0, (0.6, 0.8)) > 50)
    assert disk.eigen_ratio > 0.95


def test_scan_transitions_binary_disk():
    r, c = np.mgrid[0:200, 0:200]
    grey = np.where(np.hypot(r - 100.0, c - 90.0) <= 60.0, 100.0, 0.0)
    b = grey > 50
    offs = np.arange(-5, 6) * 10.0
    tr = scan_transitions(b, grey, (100.0, 90.0), (0.0, 1.0), offs, subpixel=False)
    entry, exit_ = tr
    assert np.all(tr.entry_strength > 40) and np.all(tr.exit_strength > 40)
    assert entry.shape == (11, 2) and exit_.shape == (11, 2)
    for p in (entry, exit_):
        assert np.abs(np.hypot(p[:, 0] - 100, p[:, 1] - 90) - 60.0).max() < 1.0
    assert np.all(entry[:, 1] < 90) and np.all(exit_[:, 1] > 90)


def test_options_hold_the_nested_settings_only():
    assert ScanlineOptions().detect.dark_surface
    with pytest.raises(TypeError):  # the scan lines' numbers are constants, not settings
        ScanlineOptions(spacing_frac=0.1)


@pytest.mark.parametrize("phase", [0.0, 40.0, 100.0])
def test_cropped_body_with_visible_lit_limb(phase):
    im = render_disk((400, 400), (200.0, -60.0), 150.0, phase_deg=phase, sun_dir_rc=(0.0, 1.0), blur_sigma=1.0, noise_sigma=2.0, ss=2)
    lc = scanline_front_end(im)
    assert math.hypot(lc.center_rc[0] - 200.0, lc.center_rc[1] + 60.0) < 1.0
    assert abs(lc.radius - 150.0) < 1.0
    assert lc.points_rc[:, 1].min() > 1.0  # no point on the frame edge


def test_sdo_hmi_png_and_resampled_fits():

    from jaxlimb.imaging import load_image, sun_truth_from_header
    from jaxlimb.imaging.sdo import HMI_512_PNG, hmi_512_truth

    sun = shared_data_dir() / "sun"
    img, _ = load_image(sun / HMI_512_PNG)
    t = hmi_512_truth()
    lc = scanline_front_end(img)
    assert math.hypot(lc.center_rc[0] - t.center_rc[0], lc.center_rc[1] - t.center_rc[1]) < 1.0
    assert abs(lc.radius - t.radius_px) < 1.0
    img, info = load_image(sun / "resampled_hmi.fits")
    t = sun_truth_from_header(info.header)
    lc = scanline_front_end(img)
    assert math.hypot(lc.center_rc[0] - t.center_rc[0], lc.center_rc[1] - t.center_rc[1]) < 1.0
    assert abs(lc.radius - t.radius_px) < 1.0
