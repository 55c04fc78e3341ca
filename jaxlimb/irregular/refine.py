r"""Soft-silhouette least-squares refinement of the matched pose (beyond Wu et al.).

The template match (Eq. 15-25 of Wu et al.) leaves the error of the nearest template; after the local
densification of the view sphere (:mod:`.densify`), the sigmoid limb model of the ellipsoid papers is
carried over to an irregular body.  Near its outline the image is modelled as

.. math::  I(p) = y_{min} + (y_{max} - y_{min})\,\sigma\big(k\, d(p; \theta)\big)\,(1 + g\,\max(d, 0))

where :math:`d` is the signed distance (px, positive inside) from pixel :math:`p` to the projected outline
of the mesh at pose :math:`\theta` (:mod:`.outline`: limb pieces only) and :math:`g` a brightness slope
inside the edge (a Lommel-Seeliger limb at phase > 0 is brightest at the very edge), fitted to the pixels
near the outline.

Parameters (10): a small rotation ``omega`` (3, camera frame), the image of the body centre ``P`` (2), the
scale (1: range ``D = D0 exp(-s)``), ``k``, ``ymax``, ``ymin``, ``g``.  The body centre is placed at
``t = D u(P)`` (Eq. 4), so ``P`` *is* the estimate.  Rotation and scale are expressed in pixels of outline
motion and the levels in units of the initial contrast, so every parameter is O(1).

Solver.  The geometry is linearised per outer iteration, ``d(p; theta) ~ d0(p) + G(p) delta`` with ``G``
from one ``jax.jacfwd`` of the signed-distance function; the photometric model on the linearised distances
is solved with ``optimistix.LevenbergMarquardt``; the pose is updated (step limited to half the band: a
trust region), the outline re-extracted and the loop repeated with a band shrinking from ``_BAND_START_PX``
to ``_BAND_PX`` (a wide band and a soft edge widen the basin of a template ~2 deg off).  Pixels whose
residual exceeds ``_OUTLIER_SIGMA`` robust sigmas are dropped once per outer iteration.  The signed
distance is a soft-min (scale ``_SOFT_PX``) blend of the signed distances to the four nearest pieces' lines:
continuous across piece junctions and concave corners, where a hard nearest-piece choice flips sign.

Limitation: the template database holds full (zero-phase) silhouettes, so at large phase angles the *match*
that initialises the refinement can be far off; the refinement itself handles a lit fraction below one
given a starting pose within about a degree and a few pixels (``initial_pose_override``).
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass

import jax
import jax.numpy as jnp
import numpy as np
import optimistix as optx

from ..errors import ConvergenceError
from .database import TemplateDatabase
from .densify import densify_match, initial_pose
from .matching import LocateResult
from .outline import outline_data
from .silhouette import cached_topology

_BAND_PX = 4.0  # half-width (px) of the band of pixels around the outline in the last solves
_BAND_START_PX = 10.0  # ... in the first solve, each later one _BAND_SHRINK times the previous
_BAND_SHRINK = 0.7
_OUTER_ITERATIONS = 12  # outline re-extractions (each followed by a solve)
_MAX_STEPS = 30  # Levenberg-Marquardt steps per solve
_K_INIT = 1.0  # initial edge sharpness (1/px)
_TOL_PX = 0.005  # the outer loop stops when the centre moves less (px)
_OUTLIER_SIGMA = 4.0  # residuals beyond this many robust standard deviations (MAD) are dropped


@dataclass(frozen=True)
class RefineOptions:
    """Options of :func:`refine_center`.

    Parameters
    ----------
    densify_levels
        Levels of :func:`~.densify.densify_match` run before the least-squares fit (0: start from the
        database template).
    """

    densify_levels: int = 3


@dataclass(frozen=True)
class RefineResult:
    """Result of :func:`refine_center`.

    Attributes
    ----------
    center_rc
        Refined image of the body centre (row, col).
    los_camera
        Unit line of sight (Eq. 4).
    R_body_to_camera, t_camera
        Refined pose (``t`` in km along the line of sight; its length is only as
        good as the template scale).
    k, ymax, ymin
        Fitted edge sharpness and levels.
    iterations
        Total Levenberg-Marquardt steps.
    rms_residual
        RMS of the final residuals (grey levels).
    n_pixels
        Pixels in the final fit.
    """

    center_rc: np.ndarray
    los_camera: np.ndarray
    R_body_to_camera: np.ndarray
    t_camera: np.ndarray
    k: float
    ymax: float
    ymin: float
    iterations: int
    rms_residual: float
    n_pixels: int


def _rotvec(w: jnp.ndarray) -> jnp.ndarray:
    """Rodrigues rotation matrix of a rotation vector (smooth at 0)."""
    th2 = jnp.dot(w, w)
    th = jnp.sqrt(th2 + 1e-30)
    K = jnp.array([[0.0, -w[2], w[1]], [w[2], 0.0, -w[0]], [-w[1], w[0], 0.0]])
    a = jnp.where(th2 < 1e-12, 1.0 - th2 / 6.0, jnp.sin(th) / th)
    b = jnp.where(th2 < 1e-12, 0.5 - th2 / 24.0, (1.0 - jnp.cos(th)) / (th2 + 1e-30))
    return jnp.eye(3) + a * K + b * (K @ K)


def _sd_factory(focal: float, pp_rc: tuple[float, float]):  # type: ignore[no-untyped-def]
    """Signed distance (px, positive inside) of each band pixel to the frozen outline at a pose."""
    f = focal
    r0, c0 = pp_rc

    def sdist(g: jnp.ndarray, args: tuple) -> jnp.ndarray:  # type: ignore[type-arg]
        (A, B, C, pix, nbr, R0, P0, D0, size) = args
        w = g[0:3] / size
        P = P0 + g[3:5]
        D = D0 * jnp.exp(-g[5] / size)
        R = _rotvec(w) @ R0
        u = jnp.array([(P[1] - c0) / f, (P[0] - r0) / f, 1.0])
        t = D * u / jnp.linalg.norm(u)

        def proj(X: jnp.ndarray) -> jnp.ndarray:
            Xc = X @ R.T + t
            return jnp.stack([r0 + f * Xc[:, 1] / Xc[:, 2], c0 + f * Xc[:, 0] / Xc[:, 2]], axis=-1)

        a, b, c = proj(A), proj(B), proj(C)
        e = b - a
        # outward normal: perpendicular to e, away from the third vertex c
        nrm = jnp.stack([-e[:, 1], e[:, 0]], axis=-1)
        side = jnp.sign(jnp.sum(nrm * (c - a), axis=-1))
        nrm = -side[:, None] * nrm / (jnp.linalg.norm(nrm, axis=-1, keepdims=True) + 1e-30)
        an, en, nn = a[nbr], e[nbr], nrm[nbr]  # (Npix, K, 2)
        d = pix[:, None, :] - an
        tt = jnp.clip(jnp.sum(d * en, -1) / (jnp.sum(en * en, -1) + 1e-30), 0.0, 1.0)
        q = d - tt[..., None] * en
        dist = jnp.sqrt(jnp.sum(q * q, -1) + 1e-12)  # distance to the piece (segment)
        perp = -jnp.sum(d * nn, -1)  # signed distance to the piece's line, positive inside
        # smooth blend: soft-min weights on the segment distances (continuous across piece
        # junctions and concave corners, where a hard nearest-piece choice flips sign)
        wgt = jax.nn.softmax(-dist / _SOFT_PX, axis=1)
        return jnp.sum(wgt * perp, axis=1)

    return sdist


def _photometric_residual(y: jnp.ndarray, args: tuple) -> jnp.ndarray:  # type: ignore[type-arg]
    """Inner residual: sigmoid edge on the linearised signed distance ``sd0 + G @ delta``."""
    sd0, G, val, weight, lev0, lev1 = args
    s = sd0 + G @ y[0:6]
    # inside the edge the level may vary linearly with depth (slope y[9] per px): at phase > 0 a
    # Lommel-Seeliger limb is brightest at the very edge and darkens inward
    model = y[8] + (y[7] - y[8]) * jax.nn.sigmoid(y[6] * s) * (1.0 + y[9] * jnp.maximum(s, 0.0))
    return weight * (model - (val - lev0) / (lev1 - lev0))


def _make_solver(max_steps: int):  # type: ignore[no-untyped-def]
    def _solve(y0, args):  # type: ignore[no-untyped-def]
        sol = optx.least_squares(
            _photometric_residual,
            optx.LevenbergMarquardt(rtol=1e-8, atol=1e-8),
            y0,
            args=args,
            max_steps=max_steps,
            throw=False,
        )
        return sol.value, sol.stats["num_steps"]

    return jax.jit(_solve)


_SOLVERS: dict = {}

#: Scale (px) of the soft-min blending of the signed distances to nearby outline pieces.
_SOFT_PX = 0.25


def refine_center(
    image: np.ndarray,
    db: TemplateDatabase,
    camera: object,
    match: LocateResult,
    sun_dir_camera: np.ndarray | None = None,
    options: RefineOptions = RefineOptions(),
    initial_pose_override: tuple[np.ndarray, np.ndarray] | None = None,
) -> RefineResult:
    """Refine the template-matched body-centre image by a soft-silhouette fit.

    Parameters
    ----------
    image
        The grey image the match was made on.
    db
        Template database (holds the mesh).
    camera
        The image's :class:`~jaxlimb.geometry.camera.Camera`.
    match
        Result of :func:`~jaxlimb.irregular.matching.locate_center`.
    sun_dir_camera
        Unit vector from the body toward the Sun in the camera frame (``None``:
        zero phase, the whole visible figure is lit).
    options
        Refinement options.
    initial_pose_override
        ``(R_body_to_camera, t_camera)`` to start from instead of the match (e.g.
        a navigation filter's prediction); ``match`` then only supplies the mask.

    Returns
    -------
    RefineResult
        Refined centre image (px, row-col), line of sight (Eq. 4), pose and the fitted edge sharpness and levels.

    Raises
    ------
    ConvergenceError
        Too few limb pixels, or a non-finite / diverged solution.
    """
    with jax.enable_x64(True):
        return _refine(np.asarray(image, dtype=float), db, camera, match, sun_dir_camera, options, initial_pose_override)


def _start_pose(image, db, camera, match, options, override):  # type: ignore[no-untyped-def]
    """The starting attitude, position and (densified) match: the override, the densified match or the match."""
    if override is not None:
        R, t = (np.asarray(v, dtype=float) for v in override)
        return R, t, dataclasses.replace(match, center_rc=np.asarray(camera.project(t), dtype=float))
    if options.densify_levels > 0:
        dens = densify_match(match.mask, db, camera, match, levels=options.densify_levels)
        match = dataclasses.replace(
            match, center_rc=dens.center_rc, theta=dens.theta, scale=dens.scale, contour_mean_px=dens.contour_mean_px
        )
        R, t = initial_pose(db, match, camera, R_template=dens.R_template)
        return R, t, match
    R, t = initial_pose(db, match, camera)
    return R, t, match


def _figure_levels(image: np.ndarray, mask: np.ndarray) -> tuple[float, float, float]:
    """The figure's size (px) and the background and body levels around it (``ConvergenceError`` if not brighter)."""
    rr, cc = np.nonzero(mask.any(axis=1))[0], np.nonzero(mask.any(axis=0))[0]
    size = float(max(rr[-1] - rr[0], cc[-1] - cc[0]) + 1)
    inside_med = float(np.median(image[mask > 0]))
    win = (slice(max(rr[0] - 6, 0), rr[-1] + 7), slice(max(cc[0] - 6, 0), cc[-1] + 7))
    om = mask[win] == 0
    lev0 = float(np.median(image[win][om])) if om.any() else float(image.min())
    lev1 = inside_med if inside_med > lev0 else float(image.max())
    if not lev1 > lev0:
        raise ConvergenceError("refinement: the body is not brighter than the background")
    return size, lev0, lev1


def _compiled(f: float, pp: tuple):  # type: ignore[no-untyped-def]
    """The jitted signed distances, their Jacobian and the solver, kept per camera."""
    key = (f, pp)
    if key not in _SOLVERS:
        if len(_SOLVERS) > 8:
            _SOLVERS.clear()
        sd_fn = _sd_factory(f, pp)
        _SOLVERS[key] = (jax.jit(sd_fn), jax.jit(jax.jacfwd(sd_fn)))
    sd_jit, jac_jit = _SOLVERS[key]
    if _MAX_STEPS not in _SOLVERS:
        _SOLVERS[_MAX_STEPS] = _make_solver(_MAX_STEPS)
    return sd_jit, jac_jit, _SOLVERS[_MAX_STEPS]


def _solve_robust(solve, y0, sd0, G, val, weight, lev0, lev1):  # type: ignore[no-untyped-def]
    """Solve, drop the photometric outliers (> ``_OUTLIER_SIGMA`` MADs, if fewer than 20 %) and solve again."""
    args = (sd0, G, jnp.asarray(val), jnp.asarray(weight), lev0, lev1)
    y_sol, n_steps = solve(y0, args)
    iterations = int(n_steps)
    r1 = np.asarray(_photometric_residual(y_sol, args))
    live = weight > 0
    mad = 1.4826 * float(np.median(np.abs(r1[live])))
    bad = live & (np.abs(r1) > max(_OUTLIER_SIGMA * mad, 0.15))
    if 0 < bad.sum() < 0.2 * live.sum():
        weight = np.where(bad, 0.0, weight)
        args = (sd0, G, jnp.asarray(val), jnp.asarray(weight), lev0, lev1)
        y_sol, n_steps = solve(y_sol, args)
        iterations += int(n_steps)
    return y_sol, args, weight, iterations


def _small_rotation(w: np.ndarray) -> np.ndarray:
    """Rodrigues' rotation matrix of the rotation vector ``w``."""
    th = float(np.linalg.norm(w))
    Kx = np.array([[0.0, -w[2], w[1]], [w[2], 0.0, -w[0]], [-w[1], w[0], 0.0]])
    return np.eye(3) + (math.sin(th) / th if th > 1e-12 else 1.0) * Kx + ((1 - math.cos(th)) / th**2 if th > 1e-12 else 0.5) * Kx @ Kx


@dataclass(frozen=True)
class _Setup:
    """What the outer loop does not change: mesh topology, camera, frame, Sun, figure size and levels, the
    compiled functions and the matched centre."""

    topo: object
    camera: object
    image: np.ndarray
    sun: np.ndarray | None
    size: float
    lev0: float
    lev1: float
    compiled: tuple
    P_match: np.ndarray


@dataclass
class _Fit:
    """The pose and photometric parameters of the outer loop (``y``: ``k, ymax, ymin, g`` of the module docstring)."""

    R: np.ndarray
    t: np.ndarray
    P: np.ndarray
    D: float
    y: tuple[float, float, float, float] = (_K_INIT, 1.0, 0.0, 0.0)
    iterations: int = 0
    rms: float = math.nan
    npix: int = 0
    sizes: tuple[int, int] = (0, 0)  # padded shapes kept: one compilation per image


def _outer_step(su: _Setup, fit: _Fit, band: float) -> float:
    """Extract the outline at the current pose, linearise, solve, update ``fit`` in place; the centre step (px)."""
    sd_jit, jac_jit, solve = su.compiled
    data = outline_data(su.topo, su.camera, su.image, fit.R, fit.t, su.sun, band, fit.sizes)
    if data is None:
        raise ConvergenceError("refinement: fewer than 20 limb pixels around the outline")
    A, B, C, pix, val, nbr, weight = data
    fit.sizes = (pix.shape[0], A.shape[0])
    zero6 = jnp.zeros(6)
    geo = tuple(jnp.asarray(x) for x in (A, B, C, pix, nbr, fit.R, fit.P)) + (fit.D, su.size)
    sd0, G = sd_jit(zero6, geo), jac_jit(zero6, geo)
    y0 = jnp.array([0.0, 0.0, 0.0, 0.0, 0.0, 0.0, *fit.y])
    y_sol, args, weight, n_it = _solve_robust(solve, y0, sd0, G, val, weight, su.lev0, su.lev1)
    fit.iterations += n_it
    fit.npix = int(weight.sum())
    y = np.asarray(y_sol)
    if not np.all(np.isfinite(y)) or not y[6] > 0:
        raise ConvergenceError(f"refinement diverged (parameters {y.tolist()})")
    # a linearised step must stay small: limit it to the band (trust region)
    g = y[0:6] * min(1.0, 0.5 * band / max(float(np.max(np.abs(np.asarray(G) @ y[0:6]))), 1e-12))
    res = np.asarray(_photometric_residual(jnp.asarray(y), args))
    fit.rms = float(np.sqrt(np.sum(res**2) / max(fit.npix, 1))) * (su.lev1 - su.lev0)
    fit.R = _small_rotation(g[0:3] / su.size) @ fit.R
    P_new = fit.P + g[3:5]
    fit.D = fit.D * math.exp(-g[5] / su.size)
    fit.y = (float(y[6]), float(y[7]), float(y[8]), float(y[9]))
    step = float(np.linalg.norm(P_new - fit.P))
    fit.P = P_new
    if np.any(np.abs(fit.P - su.P_match) > 0.25 * su.size):
        raise ConvergenceError(f"refinement moved the centre by more than a quarter of the body size ({(fit.P - su.P_match).tolist()})")
    fit.t = fit.D * np.asarray(su.camera.los(fit.P))  # type: ignore[attr-defined]
    return step


def _refine(image, db, camera, match, sun_dir_camera, options, override=None):  # type: ignore[no-untyped-def]
    """Outer loop: extract the outline at the current pose, linearise, solve, update (coarse-to-fine band)."""
    R, t, match = _start_pose(image, db, camera, match, options, override)
    P = np.asarray(match.center_rc, dtype=float).copy()
    size, lev0, lev1 = _figure_levels(image, match.mask)
    sun = None if sun_dir_camera is None else np.asarray(sun_dir_camera, dtype=float)
    pp = tuple(float(v) for v in camera.principal_point_rc)
    su = _Setup(cached_topology(db.mesh), camera, image, sun, size, lev0, lev1, _compiled(float(camera.focal_px), pp), P.copy())
    fit = _Fit(R, t, P, float(np.linalg.norm(t)))
    band = max(_BAND_START_PX, _BAND_PX)
    for _outer in range(_OUTER_ITERATIONS):
        step = _outer_step(su, fit, band)
        at_final = band <= _BAND_PX + 1e-9
        band = max(_BAND_PX, band * _BAND_SHRINK)
        if at_final and step < _TOL_PX:
            break
    k, a_max, a_min, _ = fit.y
    return RefineResult(
        center_rc=fit.P,
        los_camera=np.asarray(camera.los(fit.P)),
        R_body_to_camera=fit.R,
        t_camera=fit.t,
        k=k,
        ymax=lev0 + (lev1 - lev0) * a_max,
        ymin=lev0 + (lev1 - lev0) * a_min,
        iterations=fit.iterations,
        rms_residual=fit.rms,
        n_pixels=fit.npix,
    )


__all__ = ["RefineOptions", "RefineResult", "refine_center"]
