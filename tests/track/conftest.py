"""The tiny drawn transfer the track tests share (one per module: diffrax + jacfwd compile once)."""

from __future__ import annotations

import numpy as np
import pytest

from jaxlimb.geometry.ephemeris import epoch_to_jd_tdb
from jaxlimb.track import Propagator, make_arc, make_transfer

THETA = np.array([1000.0, 127.5, 127.5, 0.0])
N = 24


@pytest.fixture(scope="module")
def setup():
    jd = epoch_to_jd_tdb("2026-03-07T12:00:00Z")
    arc = make_arc(jd, jd + 3.6)
    prop = Propagator(arc.table)
    tr = make_transfer(arc, prop, N, THETA, 256, 256, rng=np.random.default_rng(5))
    return arc, prop, tr
