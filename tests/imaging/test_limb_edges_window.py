"""``limb_edges`` filters only the window around the limb band: the same edges as the whole frame."""

import numpy as np
import pytest

from jaxlimb.imaging import predicted
from jaxlimb.imaging.predicted import LimbShape, limb_edges


def _disc(shape=(300, 400), center=(140.3, 210.7), radius=90.0, seed=0):
    rr, cc = np.mgrid[0 : shape[0], 0 : shape[1]]
    d = np.hypot(rr - center[0], cc - center[1])
    img = 20.0 + 180.0 / (1.0 + np.exp(np.clip(2.0 * (d - radius), -50, 50)))
    return img + 2.0 * np.random.default_rng(seed).standard_normal(shape)


@pytest.mark.parametrize("with_mask", [False, True])
@pytest.mark.parametrize("center", [(140.3, 210.7), (40.0, 380.0)])  # whole disc; cut by two frame edges
def test_window_gives_the_whole_frame_answer(monkeypatch, with_mask, center):
    img = _disc(center=center)
    mask = None
    if with_mask:
        mask = np.ones(img.shape, bool)
        mask[100:104, :] = False  # a band of missing lines across the limb
        mask[:, 300:302] = False
    shape = LimbShape(center, 90.0, 1.0, 0.0)
    got = limb_edges(img, shape, mask=mask, search_px=12.0)
    monkeypatch.setattr(predicted, "_window", lambda pts, s, m: ((0, s[0]), (0, s[1])))
    ref = limb_edges(img, shape, mask=mask, search_px=12.0)
    np.testing.assert_array_equal(got[2], ref[2])
    np.testing.assert_allclose(got[0][got[2]], ref[0][ref[2]], rtol=0, atol=1e-9)
    np.testing.assert_allclose(got[1], ref[1], rtol=0, atol=1e-9)
    assert got[2].sum() > 50
