r"""Soft-silhouette least-squares refinement of the matched pose (beyond Wu et al.).

The template match (Eq. 15-25) leaves the error of the nearest template: the
true viewpoint is up to ~half a sampling step away.  Two steps remove it.

1. :func:`densify_match` -- local densification of the view sphere around the
   matched template (3x3 grids of tilts, step/3, step/9, step/27), each
   rendered and aligned exactly like a database template.

2. :func:`refine_center` -- the sigmoid limb model of the ellipsoid papers
   carried over to an irregular body.  Near its outline the image is modelled as

   .. math::  I(p) = y_{min} + (y_{max} - y_{min})\,\sigma\big(k\, d(p; \theta)\big)\,(1 + g\,\max(d, 0))

   where :math:`d` is the signed distance (px, positive inside) from pixel
   :math:`p` to the projected outline of the mesh at pose :math:`\theta` and
   :math:`g` a brightness slope inside the edge (a Lommel-Seeliger limb at phase
   > 0 is brightest at the very edge).  Fitted to the pixels within ``band_px``
   of the outline.

Parameters (10): a small rotation ``omega`` (3, rotation vector applied in the
camera frame), the image of the body centre ``P`` (2: the image-plane shift),
the scale (1: range ``D = D0 exp(-s)``), ``k``, ``ymax``, ``ymin``, ``g``.  The
body centre is placed at ``t = D u(P)`` with ``u(P)`` the unit line of sight of
``P`` (Eq. 4), so ``P`` *is* the estimate and the mesh origin projects exactly
onto it.  Rotation and scale are expressed in pixels of outline motion and the
levels in units of the initial contrast, so every parameter is O(1).

Solver (a decision, for speed).  The geometry is linearised per outer iteration:
``d(p; theta) ~ d0(p) + G(p) delta`` with ``G`` from one ``jax.jacfwd`` of the
signed-distance function; the inner problem (photometric model on the
linearised distances, 10 parameters) is solved with
``optimistix.LevenbergMarquardt``; the pose is updated (step limited to half the
band: a trust region for the linearisation), the outline re-extracted and the
loop repeated (coarse-to-fine band, ``outer_iterations``).  Running
optimistix's LM on the full geometric model was ~50x slower (a Jacobian of the
geometry at every LM step).  Pixels whose residual exceeds
``outlier_sigma`` robust sigmas are dropped once per outer iteration.

Outline.  For a pose, the outline edges are the edges between a *visible* face
and a non-visible one, visible meaning front-facing (``n.v > 0``) and, when a
Sun direction is given, also lit (``n.s > 0``): the lit silhouette.  Edges are
split into pieces of ``piece_px``; only pieces on the *outer* boundary of the
(lit) figure are kept (tested on the figure rasterised at ``test_supersample``
x).  Of those, only **limb** pieces -- whose other face is back-facing -- are
fitted; pixels nearest to a terminator piece (other face front-facing but
unlit) are left out, because the terminator of a Lommel-Seeliger surface is a
soft, albedo- and slope-dependent ramp, not a sigmoid edge.  Pixels near a
dangling piece end (a T-junction where one limb passes behind another) are
dropped too.  Cast shadows are not modelled.

Signed distance to the frozen outline: each band pixel keeps its
``n_neighbours`` nearest pieces; the distance is a soft-min (scale
``_SOFT_PX``) blend of the signed distances to the pieces' lines, signed by the
outward normal (away from the third vertex of the visible face) -- continuous
across piece junctions and concave corners, where a hard nearest-piece choice
flips sign.

Limitation: the template database holds full (zero-phase) silhouettes, so at
large phase angles the *match* that initialises the refinement can be far off
(the lit figure is not the silhouette); the refinement itself handles a lit
fraction below one (see ``tests/irregular/test_refine_render.py``), given a
starting pose within about a degree and a few pixels (e.g. a navigation
filter's prediction, ``initial_pose_override``).
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass

import jax
import jax.numpy as jnp
import numpy as np
import optimistix as optx
from scipy.spatial import cKDTree

from ..errors import ConvergenceError, GeometryError
from .database import TemplateDatabase
from .matching import LocateResult, _rot_z_to
from .silhouette import cached_topology, outline_edges, render_silhouette, visible_faces


@dataclass(frozen=True)
class RefineOptions:
    """Options of :func:`refine_center`.

    Parameters
    ----------
    band_px
        Half-width of the band of pixels around the outline that enters the fit
        (final value).
    band_start_px, band_shrink
        Coarse-to-fine schedule: the first solve uses a band of ``band_start_px``
        (and ``k_init``), each later one ``band_shrink`` times the previous, down
        to ``band_px``.  The nearest template can be ~2 deg off, which moves parts
        of the outline by several pixels; a wide band and a soft edge widen the
        basin of convergence, re-extracting the outline after a few steps keeps
        the frozen outline and neighbour lists valid.
    outer_iterations
        Maximum number of outline re-extractions (each followed by a solve).
    max_steps
        Maximum Levenberg-Marquardt steps per solve.
    n_neighbours
        Candidate outline segments kept per pixel.
    k_init
        Initial edge sharpness (1/px).
    tol_px
        Stop the outer loop when the centre moves less than this (px).
    piece_px
        Outline edges are split into pieces of at most this length (px); only
        pieces on the outer boundary are used (hidden parts of an edge at a
        T-junction are dropped piece by piece).
    test_supersample, test_offset_px
        A piece is on the outer boundary when the point ``test_offset_px`` outside
        its midpoint lies outside the figure rasterised at ``test_supersample`` x
        resolution (folds of the surface closer than that to the outline count as
        outline, harmlessly).
    densify_levels
        Levels of :func:`densify_match` run before the least-squares fit (0: start
        from the database template).
    outlier_sigma
        After each solve, pixels whose residual exceeds this many robust
        standard deviations (MAD) are dropped and the solve is repeated once.
    """

    band_px: float = 4.0
    band_start_px: float = 10.0
    band_shrink: float = 0.7
    outer_iterations: int = 12
    max_steps: int = 30
    n_neighbours: int = 4
    k_init: float = 1.0
    tol_px: float = 0.005
    piece_px: float = 2.0
    test_supersample: int = 8
    test_offset_px: float = 0.3
    outlier_sigma: float = 4.0
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


@dataclass(frozen=True)
class DensifyResult:
    """Result of :func:`densify_match`: a locally refined template pose.

    Attributes
    ----------
    center_rc
        Body-centre image by Eq. (25) with the best densified template.
    R_template
        Body->template-camera rotation of the best densified template.
    theta, scale, contour_mean_px
        In-plane rotation (Eq. 23), scale (Eq. 20) and contour agreement.
    """

    center_rc: np.ndarray
    R_template: np.ndarray
    theta: float
    scale: float
    contour_mean_px: float


def _rx(a: float) -> np.ndarray:
    c, s = math.cos(a), math.sin(a)
    return np.array([[1.0, 0.0, 0.0], [0.0, c, -s], [0.0, s, c]])


def _ry(a: float) -> np.ndarray:
    c, s = math.cos(a), math.sin(a)
    return np.array([[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]])


def densify_match(
    mask: np.ndarray, db: TemplateDatabase, camera: object, match: LocateResult, levels: int = 3, n_far: int = 3
) -> DensifyResult:
    """Local densification of the view sphere around the matched template (beyond Wu et al.).

    The template grid leaves up to about half a step between the true viewpoint
    and the nearest template.  Around the matched template, views tilted by
    ``(a, b)`` about the template camera's x and y axes are rendered on a 3x3 grid
    of spacing ``step/3``, then ``step/9``, ... (``levels`` levels); each is
    aligned with the observed figure exactly like a database template (guarded
    rotation, contour agreement), and the best one is kept.  Cost: ``8 levels``
    silhouettes at template resolution.
    """
    from .features import features_from_contours
    from .matching import observe

    topo = cached_topology(db.mesh)
    ob = observe(mask, camera, db.options.n_contour)
    S = db.options.template_size_px
    t = np.array([0.0, 0.0, db.distance_km])
    best_R = np.asarray(db.R_body_to_camera[match.template_index])
    best = None
    step = math.radians(db.options.step_deg) / 3.0
    for _level in range(levels):
        cands, feats = [], []
        for a in (-step, 0.0, step):
            for b in (-step, 0.0, step):
                R = _rx(a) @ _ry(b) @ best_R
                _, contours = render_silhouette(topo, R, t, db.focal_px, db.principal_rc, (S, S))
                if not contours:
                    continue
                cands.append(R)
                feats.append(features_from_contours(contours, db.options.n_contour))
        conts = np.stack([f.contour_xy for f in feats])
        areas = np.array([f.area for f in feats])
        orients = np.array([f.orientation for f in feats])
        th, sc = ob.align(conts, areas, orients, n_far)
        i = int(np.argmin(sc))
        best_R = cands[i]
        best = (feats[i], float(th[i]), float(sc[i]))
        step /= 3.0
    f, theta, score = best  # type: ignore[misc]
    P = ob.center(f.area, f.center_rc, db.center_image_rc, theta)
    return DensifyResult(
        center_rc=np.asarray(P, dtype=float),
        R_template=best_R,
        theta=theta,
        scale=math.sqrt(ob.obs.area / f.area),
        contour_mean_px=score,
    )


def initial_pose(
    db: TemplateDatabase, result: LocateResult, camera: object, R_template: np.ndarray | None = None
) -> tuple[np.ndarray, np.ndarray]:
    """Pose ``(R_body_to_camera, t_camera)`` implied by a template match.

    ``R = R_P Rz(theta) R_T``: the template's body->camera rotation ``R_T``,
    rolled by the in-plane rotation ``theta`` of Eq. (23), then turned so the
    boresight points along the line of sight of the matched centre ``P``
    (``R_P``: smallest rotation taking +z to ``u(P)``).  Range from the scale
    of Eq. (20): ``D = f D_T / (f_T k_c)``.
    """
    j = result.template_index
    c, s = math.cos(result.theta), math.sin(result.theta)
    Rz = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
    u = np.asarray(camera.los(result.center_rc))  # type: ignore[attr-defined]
    RT = db.R_body_to_camera[j] if R_template is None else R_template
    R = _rot_z_to(u) @ Rz @ RT
    D = camera.focal_px * db.distance_km / (db.focal_px * result.scale)  # type: ignore[attr-defined]
    return R, D * u


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


def _bucket(n: int) -> int:
    return int(2 ** math.ceil(math.log2(max(n, 16))))


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


def _compiled(f: float, pp: tuple, max_steps: int):  # type: ignore[no-untyped-def]
    """The jitted signed distances, their Jacobian and the solver, kept per camera and step budget."""
    key = (f, pp)
    if key not in _SOLVERS:
        if len(_SOLVERS) > 8:
            _SOLVERS.clear()
        sd_fn = _sd_factory(f, pp)
        _SOLVERS[key] = (jax.jit(sd_fn), jax.jit(jax.jacfwd(sd_fn)))
    sd_jit, jac_jit = _SOLVERS[key]
    if max_steps not in _SOLVERS:
        _SOLVERS[max_steps] = _make_solver(max_steps)
    return sd_jit, jac_jit, _SOLVERS[max_steps]


def _solve_robust(solve, y0, sd0, G, val, weight, lev0, lev1, options):  # type: ignore[no-untyped-def]
    """Solve, drop the photometric outliers (> ``outlier_sigma`` MADs, if fewer than 20 %) and solve again."""
    args = (sd0, G, jnp.asarray(val), jnp.asarray(weight), lev0, lev1)
    y_sol, n_steps = solve(y0, args)
    iterations = int(n_steps)
    r1 = np.asarray(_photometric_residual(y_sol, args))
    live = weight > 0
    mad = 1.4826 * float(np.median(np.abs(r1[live])))
    bad = live & (np.abs(r1) > max(options.outlier_sigma * mad, 0.15))
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


def _refine(image, db, camera, match, sun_dir_camera, options, override=None):  # type: ignore[no-untyped-def]
    """Outer loop: extract the outline at the current pose, linearise, solve, update."""
    topo = cached_topology(db.mesh)
    f = float(camera.focal_px)
    pp = tuple(float(v) for v in camera.principal_point_rc)
    R, t, match = _start_pose(image, db, camera, match, options, override)
    P = np.asarray(match.center_rc, dtype=float).copy()
    P_match = P.copy()
    D = float(np.linalg.norm(t))
    size, lev0, lev1 = _figure_levels(image, match.mask)
    sun = None if sun_dir_camera is None else np.asarray(sun_dir_camera, dtype=float)
    k, a_max, a_min, slope = options.k_init, 1.0, 0.0, 0.0
    sd_jit, jac_jit, solve = _compiled(f, pp, options.max_steps)
    iterations, rms, npix = 0, math.nan, 0
    band = max(options.band_start_px, options.band_px)
    zero6 = jnp.zeros(6)
    sizes = (0, 0)
    for _outer in range(options.outer_iterations):
        data = _outline_data(topo, R, t, f, pp, image.shape, image, sun, options, band, sizes)
        if data is None:
            raise ConvergenceError("refinement: fewer than 20 limb pixels around the outline")
        A, B, C, pix, val, nbr, weight = data
        sizes = (pix.shape[0], A.shape[0])  # keep the padded shapes: one compilation per image
        geo = tuple(jnp.asarray(x) for x in (A, B, C, pix, nbr, R, P)) + (D, size)
        sd0 = sd_jit(zero6, geo)
        G = jac_jit(zero6, geo)
        y0 = jnp.array([0.0, 0.0, 0.0, 0.0, 0.0, 0.0, k, a_max, a_min, slope])
        y_sol, args, weight, n_it = _solve_robust(solve, y0, sd0, G, val, weight, lev0, lev1, options)
        iterations += n_it
        npix = int(weight.sum())
        y = np.asarray(y_sol)
        if not np.all(np.isfinite(y)) or not y[6] > 0:
            raise ConvergenceError(f"refinement diverged (parameters {y.tolist()})")
        # a linearised step must stay small: limit it to the band (trust region)
        scale_step = min(1.0, 0.5 * band / max(float(np.max(np.abs(np.asarray(G) @ y[0:6]))), 1e-12))
        g = y[0:6] * scale_step
        res = np.asarray(_photometric_residual(jnp.asarray(y), args))
        rms = float(np.sqrt(np.sum(res**2) / max(npix, 1))) * (lev1 - lev0)
        R = _small_rotation(g[0:3] / size) @ R
        P_new = P + g[3:5]
        D = D * math.exp(-g[5] / size)
        k, a_max, a_min, slope = float(y[6]), float(y[7]), float(y[8]), float(y[9])
        step = float(np.linalg.norm(P_new - P))
        P = P_new
        if np.any(np.abs(P - P_match) > 0.25 * size):
            raise ConvergenceError(
                f"refinement moved the centre by more than a quarter of the body size ({(P - P_match).tolist()})"
            )
        t = D * np.asarray(camera.los(P))
        at_final = band <= options.band_px + 1e-9
        band = max(options.band_px, band * options.band_shrink)
        if at_final and step < options.tol_px:
            break
    return RefineResult(
        center_rc=P,
        los_camera=np.asarray(camera.los(P)),
        R_body_to_camera=R,
        t_camera=t,
        k=k,
        ymax=lev0 + (lev1 - lev0) * a_max,
        ymin=lev0 + (lev1 - lev0) * a_min,
        iterations=iterations,
        rms_residual=rms,
        n_pixels=npix,
    )


def _outline_pieces(rc, V, edges, third, limb, fig, lo, ss, options):  # type: ignore[no-untyped-def]
    """Every outline edge split into pieces of <= ``piece_px`` (3-D interpolation projects onto the same
    straight line); only the pieces on the outer boundary of the figure ``fig`` are kept.  Returns the
    3-D end points and third vertex ``PA, PB, PC``, the image end points ``pa, pb`` and the limb flag."""
    a2, b2 = rc[edges[:, 0]], rc[edges[:, 1]]
    L = np.linalg.norm(b2 - a2, axis=1)
    npieces = np.maximum(np.ceil(L / options.piece_px).astype(int), 1)
    parent = np.repeat(np.arange(edges.shape[0]), npieces)
    start = np.concatenate([np.arange(n) / n for n in npieces])
    stop = np.concatenate([np.arange(1, n + 1) / n for n in npieces])
    VA, VB = V[edges[parent, 0]], V[edges[parent, 1]]
    PA = VA + start[:, None] * (VB - VA)
    PB = VA + stop[:, None] * (VB - VA)
    PC = V[third[parent]]
    limb = limb[parent]
    pa = a2[parent] + start[:, None] * (b2 - a2)[parent]
    pb = a2[parent] + stop[:, None] * (b2 - a2)[parent]
    pc = rc[third[parent]]
    e = pb - pa
    nrm = np.stack([-e[:, 1], e[:, 0]], axis=1)
    side = np.sign(np.sum(nrm * (pc - pa), axis=1))
    nrm = -side[:, None] * nrm / np.maximum(np.linalg.norm(nrm, axis=1, keepdims=True), 1e-30)
    mid = (0.5 * (pa + pb) + options.test_offset_px * nrm - lo + 0.5) * ss - 0.5
    ir = np.clip(np.round(mid[:, 0]).astype(int), 0, fig.shape[0] - 1)
    ic = np.clip(np.round(mid[:, 1]).astype(int), 0, fig.shape[1] - 1)
    outer = fig[ir, ic] == 0
    return PA[outer], PB[outer], PC[outer], pa[outer], pb[outer], limb[outer]


def _band_pixels(PA, PB, pa, pb, limb, lo, hi, band):  # type: ignore[no-untyped-def]
    """Pixels within ``band`` of a limb piece, away from dangling piece ends (T-junctions, hidden cuts: no
    sign is reliable there); with the KD tree of points sampled along the pieces (<= 0.5 px apart) and
    each point's piece index."""
    L = np.linalg.norm(pb - pa, axis=1)
    ns = np.maximum(np.ceil(L / 0.5).astype(int), 1)
    seg_id = np.repeat(np.arange(pa.shape[0]), ns + 1)
    frac = np.concatenate([np.linspace(0.0, 1.0, n + 1) for n in ns])
    pts = pa[seg_id] + frac[:, None] * (pb - pa)[seg_id]
    tree = cKDTree(pts)
    r_idx, c_idx = np.mgrid[lo[0] : hi[0] + 1, lo[1] : hi[1] + 1]
    pix_all = np.stack([r_idx.ravel(), c_idx.ravel()], axis=1).astype(float)
    d1, i1 = tree.query(pix_all, k=1, distance_upper_bound=band)
    keep = np.isfinite(d1)
    keep[keep] &= limb[seg_id[i1[keep]]]
    ends = np.concatenate([PA, PB], axis=0)
    _, inv, cnt = np.unique(np.round(ends, 9), axis=0, return_inverse=True, return_counts=True)
    dangling = cnt[inv.ravel()] == 1
    if np.any(dangling):
        end2d = np.concatenate([pa, pb], axis=0)[dangling]
        dd, _ = cKDTree(end2d).query(pix_all[keep], k=1)
        kidx = np.nonzero(keep)[0]
        keep[kidx[dd <= band]] = False
    return pix_all[keep], tree, seg_id


def _nearest_pieces(pix, tree, seg_id, kn: int) -> np.ndarray:  # type: ignore[no-untyped-def]
    """The ``kn`` distinct pieces nearest each pixel, in order of proximity (the nearest repeated when fewer)."""
    _, ik = tree.query(pix, k=min(6 * kn, tree.n))
    segs = seg_id[np.atleast_2d(ik)]
    first = np.ones_like(segs, dtype=bool)  # first occurrence of each piece id per row
    for j in range(1, segs.shape[1]):
        first[:, j] = np.all(segs[:, :j] != segs[:, j : j + 1], axis=1)
    order = np.argsort(~first, axis=1, kind="stable")
    ranked = np.take_along_axis(segs, order, axis=1)
    nfirst = first.sum(axis=1)
    nbr = ranked[:, :kn].copy()
    short = nfirst < kn
    if np.any(short):
        for j in range(kn):
            m = short & (nfirst <= j)
            nbr[m, j] = ranked[m, 0]
    return nbr


def _padded(pieces, pix, val, nbr, min_sizes):  # type: ignore[no-untyped-def]
    """Pieces and pixels padded to size buckets (fewer recompilations); padded pixels get weight 0."""
    npx, ne = pix.shape[0], pieces[0].shape[0]
    bp, be = max(_bucket(npx), min_sizes[0]), max(_bucket(ne), min_sizes[1])
    pix_p = np.repeat(pix[:1], bp, axis=0)
    pix_p[:npx] = pix
    val_p = np.zeros(bp)
    val_p[:npx] = val
    nbr_p = np.zeros((bp, nbr.shape[1]), dtype=np.int64)
    nbr_p[:npx] = nbr
    weight = np.zeros(bp)
    weight[:npx] = 1.0

    def padv(X: np.ndarray) -> np.ndarray:
        out = np.repeat(X[:1], be, axis=0)
        out[:ne] = X
        return out

    return (*(padv(X) for X in pieces), pix_p, val_p, nbr_p, weight)


def _outline_data(topo, R, t, f, pp, shape, image, sun, options, band, min_sizes=(0, 0)):  # type: ignore[no-untyped-def]
    """Frozen outline (3-D end points), band pixels, their values and neighbour segments."""
    cam_body = -R.T @ t
    sun_body = None if sun is None else R.T @ sun
    front = visible_faces(topo, cam_body)
    flag = front if sun_body is None else front & visible_faces(topo, cam_body, sun_body)
    edges, third = outline_edges(topo, flag)
    # other face of each outline edge: limb if it is back-facing
    fa, fb = topo.adjacent[:, 0], topo.adjacent[:, 1]
    sel_a = flag[fa] & ~flag[fb]
    sel_b = flag[fb] & ~flag[fa]
    other = np.concatenate([fb[sel_a], fa[sel_b]])
    limb = ~front[other]
    V = topo.vertices
    Xc = V @ R.T + t
    if np.any(Xc[:, 2] <= 0):
        raise GeometryError("refinement: part of the mesh is behind the camera")
    rc = np.stack([pp[0] + f * Xc[:, 1] / Xc[:, 2], pp[1] + f * Xc[:, 0] / Xc[:, 2]], axis=1)
    lo = np.floor(rc.min(axis=0)).astype(int) - int(band) - 3
    hi = np.ceil(rc.max(axis=0)).astype(int) + int(band) + 3
    lo = np.maximum(lo, 0)
    hi = np.minimum(hi, np.array(shape) - 1)
    if np.any(hi - lo < 4):
        return None
    win = (int(hi[0] - lo[0] + 1), int(hi[1] - lo[1] + 1))
    ss = options.test_supersample
    fig, _ = render_silhouette(
        topo,
        R,
        t,
        f * ss,
        ((pp[0] - lo[0] + 0.5) * ss - 0.5, (pp[1] - lo[1] + 0.5) * ss - 0.5),
        (win[0] * ss, win[1] * ss),
        sun_dir_camera=None if sun is None else sun,
    )
    PA, PB, PC, pa, pb, limb = _outline_pieces(rc, V, edges, third, limb, fig, lo, ss, options)
    if not np.any(limb):
        return None
    pix, tree, seg_id = _band_pixels(PA, PB, pa, pb, limb, lo, hi, band)
    if pix.shape[0] < 20:
        return None
    nbr = _nearest_pieces(pix, tree, seg_id, options.n_neighbours)
    val = image[pix[:, 0].astype(int), pix[:, 1].astype(int)]
    return _padded((PA, PB, PC), pix, val, nbr, min_sizes)


__all__ = ["DensifyResult", "RefineOptions", "RefineResult", "densify_match", "initial_pose", "refine_center"]
