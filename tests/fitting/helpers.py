"""Synthetic limb problems with known truth for the fitting tests."""

import jax.numpy as jnp
import numpy as np

from jaxlimb.models import CIRCLE, ELLIPSE, CircleParams, EllipseParams


def circle_problem(radius=150.0, sigma=10.0, seed=0, shape=(400, 400), band=6.0, k=3.0):
    """Pixels within ``band`` of the true limb of a CSF disk, noisy intensities, truth."""
    r0, c0 = (shape[0] - 1) / 2 + 0.3, (shape[1] - 1) / 2 - 0.4
    truth = CircleParams(r0, c0, radius, k, 200.0, 20.0)
    rr, cc = np.mgrid[0 : shape[0], 0 : shape[1]]
    sel = np.abs(np.hypot(rr - r0, cc - c0) - radius) <= band
    coords = np.stack([rr[sel], cc[sel]], -1).astype(float)
    z = np.asarray(CIRCLE.intensity(truth, jnp.asarray(coords)))
    z = z + sigma * np.random.default_rng(seed).standard_normal(z.shape)
    return coords, z, truth


def ellipse_problem(a=120.0, rho=0.8, theta=0.4, sigma=5.0, seed=0, shape=(300, 300), band=6.0):
    r0, c0 = 150.2, 149.7
    truth = EllipseParams(r0, c0, a, theta, rho, 2.5, 180.0, 15.0)
    rr, cc = np.mgrid[0 : shape[0], 0 : shape[1]]
    grid = np.stack([rr.ravel(), cc.ravel()], -1).astype(float)
    from jaxlimb.models import ellipse_coords

    x, y = (np.asarray(v) for v in ellipse_coords(truth, jnp.asarray(grid)))
    beta = np.hypot(rho * x, y)
    coords = grid[np.abs(beta - rho * a) <= band]
    z = np.asarray(ELLIPSE.intensity(truth, jnp.asarray(coords)))
    z = z + sigma * np.random.default_rng(seed).standard_normal(z.shape)
    return coords, z, truth
