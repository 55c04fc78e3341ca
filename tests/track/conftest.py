"""The tiny drawn transfer the track tests share (one per module: diffrax + jacfwd compile once), and measurements
with a known split of ``locate``'s model error."""

from __future__ import annotations

import jax.numpy as jnp
import numpy as np
import pytest

from jaxlimb.geometry.ephemeris import epoch_to_jd_tdb
from jaxlimb.track import Frames, Propagator, make_arc, make_transfer, predict
from jaxlimb.track.scenario import perturb_attitudes, true_measurements

THETA = np.array([1000.0, 127.5, 127.5, 0.0])
N = 24


@pytest.fixture(scope="module")
def setup():
    jd = epoch_to_jd_tdb("2026-03-07T12:00:00Z")
    arc = make_arc(jd, jd + 3.6)
    prop = Propagator(arc.table)
    tr = make_transfer(arc, prop, N, THETA, 256, 256, rng=np.random.default_rng(5))
    return arc, prop, tr


NOISE_PX, MODEL_PX = 0.03, 0.1  # per-frame noise and model-error sigma of the centre and the radius (px)


def covariances(tr, sigma_px: float) -> np.ndarray:  # noqa: ANN001
    z = true_measurements(tr)
    out = []
    for k, b in enumerate(tr.bodies):
        size = THETA[0] * np.tan(np.arcsin(6378.137 / z[k, 2])) if b == "earth" else z[k, 2]
        s3 = z[k, 2] * sigma_px / size if b == "earth" else sigma_px
        out.append(np.diag([sigma_px**2, sigma_px**2, s3**2]))
    return np.array(out)


def locate_like_frames(arc, tr, rng: np.random.Generator, moon_offset: float, independent: float = 0.0) -> Frames:  # noqa: ANN001
    """``locate``-like measurements: noise ``NOISE_PX``, the fraction ``independent`` of the model error
    ``MODEL_PX`` drawn independently per frame, the Moon's centres moved along the Sun by ``moon_offset`` of
    their radius; the reported covariance is noise plus the whole model error."""
    sun = arc.body_position("sun", tr.t)
    bp = tr.body_positions()
    is_range = np.array([1.0 if b == "earth" else 0.0 for b in tr.bodies])
    radius = np.array([6378.137 if b == "earth" else 1737.4 for b in tr.bodies])
    z = np.array([np.asarray(predict(jnp.asarray(tr.states[k, :3]), jnp.asarray(THETA), jnp.asarray(tr.C_true[k]),
                                     jnp.asarray(bp[k]), radius[k], is_range[k], jnp.asarray(THETA), jnp.asarray(sun[k]),
                                     jnp.asarray([moon_offset * (b == "moon"), 0.0]))) for k, b in enumerate(tr.bodies)])
    noise, model = covariances(tr, NOISE_PX), covariances(tr, MODEL_PX)
    drawn = noise + independent * model
    z = z + np.einsum("kij,kj->ki", np.linalg.cholesky(drawn), rng.standard_normal(z.shape))
    return Frames(t=tr.t.copy(), z=z, R=noise + model, C=perturb_attitudes(tr.C_true, 1e-6, rng), body_pos=bp,
                  radius_km=radius, is_range=is_range, theta_locate=np.tile(THETA, (N, 1)), theta=np.tile(THETA, (N, 1)),
                  attitude_sigma=np.full(N, 1e-6), labels=tuple(f"f{k}" for k in range(N)), sun_pos=sun, R_noise=noise)
