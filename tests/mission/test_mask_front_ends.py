"""The validity mask in every front end: masked pixels are neither limb nor background."""

import sys
from pathlib import Path

import numpy as np
import pytest

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "pipeline"))
from _scenes import errors, scene, sun_hints  # noqa: E402

from jaxlimb.errors import CheckFailed  # noqa: E402
from jaxlimb.imaging import box_filter, scanline_front_end  # noqa: E402
from jaxlimb.pipeline import locate, select_annulus  # noqa: E402
from jaxlimb.pipeline.options import LocateOptions  # noqa: E402

BAND = slice(150, 170)  # 20 rows across the upper limb of the 122 px Moon centred at (200, 250)


def _banded(value: float):
    img, truth = scene(20000.0, 20.0, (200.0, 250.0))
    b = np.array(img, dtype=float)
    b[BAND] = value
    mask = np.ones(b.shape, bool)
    mask[BAND] = False
    return img, b, mask, truth


def test_box_filter_rejects_a_candidate_whose_far_pixel_is_masked():
    img = np.zeros((40, 40))
    img[:, 20:] = 100.0
    g = np.zeros_like(img)
    g[:, 19:21] = 50.0
    pts = np.array([[10, 20], [30, 20]])
    keep, _ = box_filter(g, img, pts, 7)
    assert keep.all()
    valid = np.ones(img.shape, bool)
    valid[30, 15:18] = False  # the sky sample of the second point (3 px off the edge) is missing
    keep, _ = box_filter(g, img, pts, 7, valid=valid)
    assert keep.tolist() == [True, False]


def test_scanline_front_end_ignores_a_masked_band():
    img, b, mask, _ = _banded(0.0)
    ref = scanline_front_end(img)
    cand = scanline_front_end(b, mask=mask)
    # no transition within reach of the band, and the circle of the clean frame
    assert not np.any((cand.points_rc[:, 0] > BAND.start - 9) & (cand.points_rc[:, 0] < BAND.stop + 9))
    assert np.hypot(*np.subtract(cand.center_rc, ref.center_rc)) < 0.5
    assert cand.radius == pytest.approx(ref.radius, abs=0.5)


def test_annulus_leaves_out_masked_pixels():
    _, b, mask, truth = _banded(0.0)
    sel = select_annulus(b, truth.center_rc, truth.apparent_radius_px, 4.0, None, np.pi, mask)
    assert not np.any((sel.coords[:, 0] >= BAND.start) & (sel.coords[:, 0] < BAND.stop))
    full = select_annulus(b, truth.center_rc, truth.apparent_radius_px, 4.0, None, np.pi)
    assert full.n > sel.n


@pytest.mark.parametrize("front_end", ["gradient", "scanline"])
@pytest.mark.parametrize("fill", [0.0, 255.0])
def test_locate_with_a_masked_band_across_the_limb(front_end, fill):
    """Zero or saturated fill across the lit limb: with the mask the clean frame's answer; without it, the
    band's edges are taken for the limb and the measurement fails."""
    img, b, mask, truth = _banded(fill)
    opt = LocateOptions(front_end=front_end)
    ref = locate(img, None, sun_hints(truth), opt)
    m = locate(b, None, sun_hints(truth), opt, mask=mask)
    assert abs(errors(m, truth)[0] - errors(ref, truth)[0]) < 0.05
    assert abs(m.radius_px - ref.radius_px) < 0.05
    with pytest.raises(CheckFailed):
        locate(b, None, sun_hints(truth), opt)
