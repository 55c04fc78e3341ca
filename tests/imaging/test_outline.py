"""The outline front end of a self-luminous disc (:mod:`jaxlimb.imaging.outline`)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from jaxlimb.errors import NoBodyError, TooManyOutliersError
from jaxlimb.imaging.outline import outline_front_end

CENTER, RADIUS = (101.3, 97.8), 70.0


def _disc(shape=(200, 200), spot=True) -> np.ndarray:
    rr, cc = np.indices(shape)
    d = np.hypot(rr - CENTER[0], cc - CENTER[1])
    mu = np.sqrt(np.clip(1.0 - (d / RADIUS) ** 2, 0.0, None))
    img = np.where(d < RADIUS, 1000.0 * (1.0 - 0.6 * (1.0 - mu)), 20.0)
    if spot:  # a dark spot inside the disc and a bright one on its limb
        img[np.hypot(rr - 90, cc - 120) < 12] = 150.0
        img[np.hypot(rr - (CENTER[0] + RADIUS), cc - CENTER[1]) < 4] = 3000.0
    return img + np.random.default_rng(0).normal(0.0, 5.0, shape)


def test_outline_of_a_spotted_disc_is_its_limb():
    """Spots inside the disc do not move the outline's circle; a bright patch on the limb is an outlier."""
    c = outline_front_end(_disc())
    assert c.front_end == "outline" and c.lit_direction is None and c.lit_halfangle == math.pi
    assert math.hypot(c.center_rc[0] - CENTER[0], c.center_rc[1] - CENTER[1]) < 0.5
    assert abs(c.radius - RADIUS) < 2.0  # the threshold cuts the darkened limb a little inside


def test_outline_skips_the_frame_border_and_invalid_pixels():
    """A disc cut by the frame's border and by a data gap: the outline points there are not the limb."""
    img = _disc(spot=False)[:, :150]
    mask = np.ones(img.shape, bool)
    mask[:60, :] = False  # a data gap over the top of the disc
    img = np.where(mask, img, 0.0)
    c = outline_front_end(img, mask)
    assert math.hypot(c.center_rc[0] - CENTER[0], c.center_rc[1] - CENTER[1]) < 0.6
    assert c.points_rc[:, 0].min() > 60 and c.points_rc[:, 1].max() < 149


def test_outline_that_is_not_a_circle_is_refused():
    """A region that is no disc (a bar) is a typed refusal; a flat frame has no body."""
    img = np.full((120, 120), 10.0)
    img[40:80, 10:110] = 500.0
    with pytest.raises(TooManyOutliersError, match="not a circle"):
        outline_front_end(img + np.random.default_rng(1).normal(0, 1, img.shape))
    with pytest.raises(NoBodyError):
        outline_front_end(np.full((64, 64), 3.0))
