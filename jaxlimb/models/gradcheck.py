"""Check the paper's analytic Jacobians against autodiff and central differences.

For each model (linear, circle, ellipse) we draw random parameter points --
steep and shallow ``k`` (log-uniform over [0.05, 20] 1/px), bright-on-dark and
dark-on-bright levels, any orientation -- and, for each, pixels inside, outside
and on the edge of the limb.  The analytic Jacobian (Eq. 14, Eq. 17, Sec. V-C
of Mortari et al. 2016) is compared with ``jax.jacfwd`` of the model.

The relative error of an entry is ``|J_paper - J_autodiff| / max(|J_autodiff|,
1e-8 * c)``, with ``c`` the largest magnitude in that column at that parameter
point: entries more than eight orders of magnitude below their column (pixels
deep inside or outside the body, where ``alpha/(1+alpha)^2`` underflows) are
compared against the column's scale rather than their own.

The central-difference check steps each parameter by ``h_j = 1e-5 (ymax - ymin)
/ c_j`` (so the intensity moves by at most 1e-5 of its range) and reports the
largest error relative to the column scale ``c_j``; it is limited by the O(h^2)
truncation and by rounding, ~1e-8.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass

import jax
import jax.numpy as jnp
import numpy as np

from ._base import LimbModel
from .sigmoid import CIRCLE, ELLIPSE, LINEAR, CircleParams, EllipseParams, LinearParams


@dataclass(frozen=True)
class GradCheck:
    """One row of the report: the worst error of one column over all points."""

    model: str
    param: str
    max_rel_err: float
    max_fd_err: float
    n_points: int


def _random_case(model: LimbModel, rng: np.random.Generator, n_pix: int):  # noqa: ANN202
    """A random parameter point and pixels inside / on / outside its limb."""
    k = float(np.exp(rng.uniform(np.log(0.05), np.log(20.0))))
    ymax, ymin = rng.uniform(50, 250), rng.uniform(0, 40)
    if rng.random() < 0.2:  # dark body on a bright sky
        ymax, ymin = ymin, ymax
    width = max(4.0 / k, 1.0)  # the transition is ~4/k px wide
    offs = np.concatenate(
        [rng.uniform(-3 * width, -0.5 * width, n_pix // 3),  # inside
         rng.uniform(-0.5 * width, 0.5 * width, n_pix // 3),  # on the edge
         rng.uniform(0.5 * width, 3 * width, n_pix - 2 * (n_pix // 3))]  # outside
    )
    if model.name == "linear":
        xt = rng.uniform(-50, 50)
        return LinearParams(xt, k, ymax, ymin), jnp.asarray(xt + offs)
    radius = rng.uniform(20, 400)
    offs = np.maximum(offs, -0.9 * radius)  # stay away from the centre
    phi = rng.uniform(0, 2 * np.pi, n_pix)
    r0, c0 = rng.uniform(-100, 1000, 2)
    if model.name == "circle":
        d = radius + offs
        rc = np.stack([r0 + d * np.sin(phi), c0 + d * np.cos(phi)], -1)
        return CircleParams(r0, c0, radius, k, ymax, ymin), jnp.asarray(rc)
    rho = rng.uniform(0.5, 1.0)
    theta = rng.uniform(-np.pi, np.pi)
    p = EllipseParams(r0, c0, radius, theta, rho, k, ymax, ymin)
    # points at "ellipse distance" beta = rho*a + offs along eccentric anomaly phi
    scale = (rho * radius + offs) / (rho * radius)
    x = radius * np.cos(phi) * scale
    y = rho * radius * np.sin(phi) * scale
    ct, st = np.cos(theta), np.sin(theta)
    rc = np.stack([r0 - x * st - y * ct, c0 + x * ct - y * st], -1)
    return p, jnp.asarray(rc)


def check_model(model: LimbModel, n_points: int = 100, n_pix: int = 60, seed: int = 0) -> list[GradCheck]:
    """Compare ``model.jacobian`` with ``jax.jacfwd`` and central differences at ``n_points`` random points."""
    rng = np.random.default_rng(seed)
    ptype = model.params_type
    names = model.param_names
    f = jax.jit(lambda v, x: model.intensity(ptype.from_vector(v), x))
    jac_ad = jax.jit(jax.jacfwd(lambda v, x: model.intensity(ptype.from_vector(v), x)))
    jac_an = jax.jit(lambda v, x: model.jacobian(ptype.from_vector(v), x))
    worst = np.zeros(len(names))
    worst_fd = np.zeros(len(names))
    for _ in range(n_points):
        p, x = _random_case(model, rng, n_pix)
        v = p.to_vector()
        a = np.asarray(jac_an(v, x))
        b = np.asarray(jac_ad(v, x))
        col = np.max(np.abs(b), axis=0)
        dy = abs(float(p.ymax) - float(p.ymin))
        denom = np.maximum(np.abs(b), 1e-8 * col[None, :])
        denom = np.where(denom > 0, denom, 1.0)
        worst = np.maximum(worst, np.max(np.abs(a - b) / denom, axis=0))
        for j in range(len(names)):
            h = 1e-5 * dy / max(col[j], 1e-300)  # moves f by at most 1e-5 of its range
            e = jnp.zeros_like(v).at[j].set(h)
            fd = (np.asarray(f(v + e, x)) - np.asarray(f(v - e, x))) / (2 * h)
            worst_fd[j] = max(worst_fd[j], float(np.max(np.abs(fd - a[:, j])) / max(col[j], 1e-300)))
    return [GradCheck(model.name, n, float(worst[i]), float(worst_fd[i]), n_points) for i, n in enumerate(names)]


def run_gradcheck(n_points: int = 100, seed: int = 0) -> list[GradCheck]:
    """All three models; see :func:`check_model`."""
    out: list[GradCheck] = []
    for i, model in enumerate((LINEAR, CIRCLE, ELLIPSE)):
        out.extend(check_model(model, n_points=n_points, seed=seed + i))
    return out


def report(checks: list[GradCheck]) -> dict[str, list[dict[str, object]]]:
    """The ``jaxlimb gradcheck --json`` object."""
    return {"checks": [asdict(c) for c in checks]}
