r"""Render-and-register: the body-centre image when the body's attitude is known (beyond Wu et al.).

Operational optical navigation of irregular bodies renders the *predicted* lit
image of the shape model for the known attitude ``R_body_to_camera`` and Sun
direction, and registers it to the frame.  Here:

1. **Initial pose** from the segmented lit figure: the body centre is put on the
   line of sight of the figure centroid at the range given by the hints (or, without
   one, the range at which the predicted lit figure has the observed area), then
   moved by the offset between the observed and predicted lit-figure centroids (two
   passes, lit silhouettes of :func:`~jaxlimb.irregular.silhouette.render_silhouette`).
2. **Normalised cross-correlation** of the rendered lit image (``cv2.matchTemplate``,
   ``TM_CCOEFF_NORMED``) over +-``search_px``: integer peak, parabolic sub-pixel.
3. **Photometric Gauss-Newton** (Lucas-Kanade with re-rendering): the model

   .. math::  I(x) \approx a\,M(x; P, s) + b, \qquad
              M(x; P + \delta, s + \delta_s) \approx M - \delta\cdot\nabla M
              - \delta_s\,(x - P)\cdot\nabla M

   is linear in ``(a, b, a delta, a delta_s)``; each iteration renders ``M`` (radiance,
   unit albedo) at the current centre ``P`` and range ``D`` (scale ``s = -ln D``), solves
   the 5-parameter linear least squares on the window around the body, and moves the
   pose.  The body centre is placed at ``t = D u(P)`` (Eq. 4 of Wu et al.), so ``P``
   is the estimate itself.  The rendering is exact perspective, so no template
   approximation remains.  Coarse to fine: the blurred iterations run on a pyramid
   (frame box-averaged, :mod:`.model_render`); with the attitude fitted (three more
   columns from the same render), the unblurred ones first on the 2x2-averaged frame,
   the last ones at full resolution.
   **What a real surface adds** (each measured on ray-traced frames of
   :mod:`jaxlimb.render.independent.mesh_rays`, whose bias it removed): the model radiance is a
   fitted mix of Lommel-Seeliger, Lambert, Minnaert ``k = 1/2`` (and ``k = 3/4`` below 75 deg phase, for
   the limb darkening ``mu^(2k-1)`` of a Minnaert surface at zero phase) and smooth (Phong-interpolated)
   shading (linear columns, :func:`.model_render.render_window`; a Lambert body: 1.5 -> 0.01 px);
   facets in the body's own cast shadow are darkened (:func:`jaxlimb.render.mesh.shadow_fractions`);
   before the sharp iterations the camera's PSF is estimated (:func:`estimate_psf`, a Gaussian
   blur of the model only; 0.24 -> 0.01 px for a 0.8 px PSF); a sharp step that reverses the
   last one is halved (the rendering's sub-pixel quantisation otherwise makes a limit cycle).
   The smooth-shading column is that of the fitted mix (:class:`.model_render.MixedLaw`), and where
   it varies across the body the opposition surge is fitted (:func:`surge_fields`).
4. **Covariance** ``sigma^2 (A^T A)^{-1}`` of the linear solve at convergence, with
   ``sigma^2`` the residual variance, mapped to ``(row, col)`` by ``1/a``, plus the
   cluster-robust model-error term of :mod:`jaxlimb.fitting.model_error` over position-angle
   sectors (an albedo the model does not know biases the centre by ~0.1 px: the term makes the
   reported sigma say so), plus a model floor (``model_floor_px``).  Monte Carlo (30 noise
   draws, Thebe, phase 30): mean NEES 2.4 at 10 DN noise without the floor (chi^2_2: 2).
5. **Checks** (:class:`~jaxlimb.errors.MatchError`, exit 3): the excess of the residual
   over the background noise relative to the body's contrast, the overlap (IoU) of
   the observed and predicted lit figures, and convergence.
6. **The lit limb** (attitude known, from ``limb_min_phase_deg``): the centre is combined with a
   second estimate from the edge positions of the lit limb alone (:mod:`.limb_edges`, each edge with
   its own contrast: an albedo the model does not know moves the intensity fit, not the edges).

Rendering is :func:`jaxlimb.render.mesh.rasterise` (painter's algorithm, facets) in a window
camera around the body (:func:`.model_render.render_window`).
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass

import cv2
import numpy as np

from ..errors import ConvergenceError, MatchError
from .._identity_cache import IdentityCache
from .._validate import check_center_sigma
from .mesh import Mesh
from .model_render import attitude_columns, clustered_mesh, downsample, level_camera, mix_laws, render_window
from .silhouette import cached_topology, figure_center, figure_extents, render_silhouette, segment_components


@dataclass(frozen=True)
class RegisterOptions:
    """Options of :func:`register_known_attitude`.

    Parameters
    ----------
    supersample
        Sub-pixels per pixel side of the model rendering.
    reflectance
        Reflectance law of the model (see :class:`~jaxlimb.render.mesh.MeshRenderOptions`).
    max_iterations, tol_px
        Gauss-Newton iterations and the centre step (px) at which they stop.
    max_final_step_px
        Largest last step (px) accepted as converged when ``max_iterations`` are used up
        (the rendering is quantised on the sub-pixel grid: steps jitter at ~0.005 px).
    attitude_blur_frac, attitude_blur_min_px
        When the attitude is fitted too: blur schedule in fractions of the figure size
        (coarse to fine: a template a few degrees off moves the outline by a few percent
        of the size), blurs below ``attitude_blur_min_px`` dropped.  The attitude
        columns come from the same render (:func:`.model_render.attitude_columns`).
    pyramid_blur_px, pyramid_min_size_px
        An iteration with blur ``sigma`` runs on the frame box-averaged by
        ``k = floor(sigma / pyramid_blur_px)`` (:mod:`.model_render`), as long as the
        figure stays at least ``pyramid_min_size_px`` across.
    sharp_level2_iterations
        At most this many unblurred iterations on the frame box-averaged 2x2 (its optimum is
        that of the full frame up to the rendering's quantisation) before those at full
        resolution; 0 when the attitude is known.
    coarse_min_level
        The coarse stage of a template hypothesis (:func:`start_search_registration`)
        stops before the first iteration below this pyramid factor.
    blur_px
        Gaussian blur (px) of image and model in the first iterations (a wider basin).
    search_px
        Half-width of the cross-correlation search (px).
    margin_px
        Pixels added around the union of the predicted and observed figures.
    max_excess_frac
        Largest accepted model misfit: RMS residual in excess of the noise, over the
        fitted contrast ``a`` (fraction).
    min_iou
        Smallest accepted overlap of the observed and predicted lit figures.
    max_center_sigma_px
        Largest accepted 1-sigma of the centre (px, the larger axis), as ``LocateOptions.max_center_sigma_px`` for
        round bodies: a registration that does not measure the centre better is a typed failure
        (``center_too_uncertain``), not ``ok`` with a wide covariance (an Eros at 90 deg phase and 10x its long
        axis finished 1.84 px off with sigma 2.2 px); ``None``: no limit.
    albedo_order
        Degree of a polynomial albedo field across the body fitted with the model (linear columns
        ``M x^i y^j``, ``1 <= i + j <= albedo_order``); 0: uniform albedo.
    albedo_harmonics
        Harmonics of the albedo along the position angle about the centre (columns
        ``M cos k theta``, ``M sin k theta``): the outline's contrast varies with the surface's
        albedo, and an intensity fit that does not know it moves the outline.
    surge_widths, surge_min_range
        Opposition-surge widths ``h`` (rad) of the columns ``M (B_h(g) - B_h(g_center))`` fitted with the model
        (:func:`surge_fields`; Hapke 1986, Eq. 11), each only where it varies by at least ``surge_min_range``
        across the window (empty: none).  A ray-traced Eros with a surge (Lommel-Seeliger, ``B_0 = 1.4``,
        ``h = 0.067``) at zero phase and 3x the long axis: 0.33 -> 0.11 px.
    cast_shadows
        Scale each facet's radiance by its lit fraction seen from the Sun
        (:func:`jaxlimb.render.mesh.shadow_fractions`): a lumpy body's own cast shadows, unmodelled,
        biased a registration by 0.16 px at 45 deg phase.
    coarse_cast_shadows
        Cast shadows on pyramid levels of factor ``coarse_min_level`` and more too (blurs of 8 px and
        more, where a template hypothesis is ranked and brought near).  Off, a cold locate skips the
        Sun's view of each hypothesis's attitude (two thirds of its shadow maps; ``jaxlimb los locate``
        on the Phobos 3x frame of ``benchmarks/irregular_speed.py``: 0.84x the CPU time); the answers
        move within the noise (``benchmarks/irregular_independent.py --views 1``, attitude unknown:
        median / p90 / max 0.141 / 0.424 / 0.524 px against 0.141 / 0.421 / 0.533 with it, 2026-11-25).
    psf_grid_px
        Gaussian PSF sigmas (px) among which :func:`estimate_psf` picks the camera's before the
        sharp iterations (the model is blurred by it; empty: an ideal camera).
    model_error_sectors
        The centre covariance carries the cluster-robust model-error term of
        :mod:`jaxlimb.fitting.model_error` with the window's pixels grouped in this many
        position-angle sectors about the centre (0: off): a surface whose albedo, shading or
        shadows differ from the model's leaves residuals that follow the centre's columns
        from one side of the body to the other, and the white-noise covariance alone then
        reports 0.006 px for a 0.2 px error (``benchmarks/irregular_independent.py``).
    model_error_scale
        The model-error term is multiplied by this squared.  Sixteen sectors of a smooth misfit
        are not independent, and the sandwich alone under-reports: on the ray-traced frames of
        ``benchmarks/irregular_independent.py`` (47 located, 2026-11-25) the error over the
        reported sigma had median 2.0 and 90th percentile 4.2 with the term unscaled.
    fit_photometry
        Fit the photometric mix ``m`` of the model radiance ``LS + m_1 (Lambert - LS) +
        m_2 (Minnaert_1/2 - LS) [+ m_3 (Minnaert_3/4 - LS)]`` (:func:`.model_render.render_window`, ``mix_laws``;
        McEwen's lunar-Lambert law is ``m_1 = 1 - L``), more linear columns: the reflectance of
        a real surface is not known in advance, and a Lambert or Minnaert body registered
        with a Lommel-Seeliger model is biased by 0.6-1 px
        (``benchmarks/irregular_independent.py``).  ``m`` is kept in ``mix_bounds``.
    mix_laws
        Laws of :data:`.model_render.MIX_LAWS` in the mix (its first ``mix_laws``): 3 adds Minnaert with
        ``k = 3/4``, ``m_3 (Minnaert_3/4 - LS)``.  Near zero phase ``mu0 = mu``, Lommel-Seeliger and Minnaert 1/2
        are both flat and the mix of two laws spans only ``1`` and ``mu``, while a Minnaert surface
        (Minnaert 1941, ``mu0^k mu^(k-1)``) shows ``mu^(2k-1)``: with ``k = 0.81`` a ray-traced cratered body was
        registered 0.40 px off, 0.04 px with ``mu^(1/2)`` in the mix (``benchmarks/irregular_independent.py``,
        attitude known, 32 frames: median / p90 / max 0.098 / 0.178 / 0.403 -> 0.080 / 0.163 / 0.249 px).
    mix_laws_max_phase_deg
        From this phase angle on, at most two laws (``mix_laws`` is meant for the zero-phase degeneracy).  At
        90 deg the third law left the frames of ``benchmarks/irregular_independent.py`` about as they were
        (24 ray-traced frames, median 0.106 -> 0.102 px) but let our own Lommel-Seeliger render of a cratered
        body drift from 0.030 to 0.085 px.
    pedestal_min_dark_frac
        A constant column (a level under the whole frame: bias, dark current, stray light) besides
        the sky column ``1 - C`` (a background the body hides), when at least this fraction of the
        model's covered pixels is unlit (:func:`has_dark_side`; without a dark side the constant is
        nearly ``M`` and ``1 - C`` combined).  With the sky column alone, the unlit side of a body on a
        pedestal looks like a dark edge: a ray-traced Eros at 90 deg phase (Lommel-Seeliger, flat
        shading, no PSF) on 10 DN for 200 DN of contrast was registered 0.18 px off, 0.12 px with the
        column, as on 0 DN; an own render of a lumpy body on 30 DN at 60 deg, 0.22 -> 0.01 px.  0: never.
    exact_coverage
        Full-resolution renders show in every sub-pixel the facet containing its centre
        (:func:`jaxlimb.render.mesh.rasterise`).  Without, ``cv2.fillConvexPoly``'s painter's buffer lets every
        nearer facet overlap its farther neighbour and the sky by half a sub-pixel, which moves the shading
        pattern of a body at high phase toward the Sun: ``benchmarks/irregular_resample.py --view 6`` (90 deg,
        32 ray-traced frames) median 0.111 -> 0.088 px, mean NEES 6.5 -> 2.0 with it.
    limb_min_phase_deg
        From this phase angle on (attitude known), the centre is the information-weighted mean of the registration
        and of the lit limb's edge positions (:mod:`.limb_edges`: each edge's shift with its own gain, so the
        surface's albedo does not move it); ``None``: never.  At 90 deg, median / p90 / max px:
        ``benchmarks/irregular_independent.py --views 1`` (8 frames, RENDER_VERSION 3) 0.136 / 0.171 / 0.203 ->
        0.088 / 0.182 / 0.195; the same with RENDER_VERSION 4 (other scenes) 0.100 / 0.263 / 0.559 -> 0.095 /
        0.169 / 0.260; ``benchmarks/irregular_resample.py`` (24 renders, truths corrected for the renderer's
        jitter pattern) 0.085 / 0.244 / 0.264 -> 0.069 / 0.203 / 0.243.  At 60 deg, without the scatter limit, it
        moved the coarse-model cratered body from 0.19 to 0.39 px: not used below 75 deg.
    limb_lit_frac, limb_half_px, limb_floor_px, limb_max_scatter_px
        The lit limb's points: model radiance inside at least ``limb_lit_frac`` of the body's; profiles of
        ``+-limb_half_px``; ``limb_floor_px`` (per axis) added to the edge estimate's covariance; not used when the
        robust scatter of the edge shifts exceeds ``limb_max_scatter_px`` (the model's outline does not follow the
        body's: a shape model coarser than the body).
    model_floor_px
        Standard deviation (px, per axis) added to the covariance for the rendering's
        own quantisation (sub-pixel coverage steps of 1/16 at ``supersample=4``):
        measured by Monte Carlo on a Thebe frame at 2 DN noise, the scatter is
        0.0035 px and the bias 0.003 px against a noise-only sigma of 0.001 px.
    """

    supersample: int = 4
    reflectance: str = "lommel-seeliger"
    max_iterations: int = 16
    blur_px: tuple[float, ...] = (3.0, 1.5)
    attitude_blur_frac: tuple[float, ...] = (0.04, 0.025, 0.015, 0.008, 0.004)
    attitude_blur_min_px: float = 1.0
    pyramid_blur_px: float = 2.0
    coarse_min_level: int = 4
    sharp_level2_iterations: int = 0
    pyramid_min_size_px: float = 48.0
    tol_px: float = 0.01
    max_final_step_px: float = 0.05
    search_px: int = 12
    margin_px: int = 4
    max_excess_frac: float = 0.12
    min_iou: float = 0.9
    max_center_sigma_px: float | None = 1.0
    model_floor_px: float = 0.004
    model_error_sectors: int = 16
    model_error_scale: float = 2.5
    psf_grid_px: tuple[float, ...] = (0.0, 0.5, 0.9, 1.4, 2.2)
    cast_shadows: bool = True
    coarse_cast_shadows: bool = True
    albedo_order: int = 0
    albedo_harmonics: int = 0
    surge_widths: tuple[float, ...] = (0.03, 0.1)
    surge_min_range: float = 0.04
    fit_photometry: bool = True
    mix_bounds: tuple[float, float] = (-1.0, 1.0)
    mix_laws: int = 3
    mix_laws_max_phase_deg: float = 75.0
    pedestal_min_dark_frac: float = 0.02
    exact_coverage: bool = True
    limb_min_phase_deg: float | None = 75.0
    limb_lit_frac: float = 0.3
    limb_half_px: float = 5.0
    limb_floor_px: float = 0.03
    limb_max_scatter_px: float = 0.35


@dataclass(frozen=True)
class RegisterResult:
    """Result of :func:`register_known_attitude`.

    Attributes
    ----------
    center_rc, los_camera
        Body-centre image (row, col) and its unit line of sight.
    range_km, t_camera
        Fitted range and body centre in the camera frame (km).
    covariance_rc
        2x2 covariance of ``center_rc`` (px^2).
    gain, offset
        Fitted ``a`` (DN per unit albedo) and ``b`` (background DN).
    rms_residual, noise_sigma
        RMS residual of the fit and the background noise (DN).
    excess_frac, iou, ncc
        Quality measures (see the module docstring).
    iterations
        Gauss-Newton iterations.
    R_body_to_camera
        The attitude used (fitted when ``fit_attitude``).
    """

    center_rc: np.ndarray
    los_camera: np.ndarray
    range_km: float
    t_camera: np.ndarray
    covariance_rc: np.ndarray
    gain: float
    offset: float
    rms_residual: float
    noise_sigma: float
    excess_frac: float
    iou: float
    ncc: float
    iterations: int
    R_body_to_camera: np.ndarray


def render_model(
    mesh: Mesh, camera: object, R: np.ndarray, t: np.ndarray, sun: np.ndarray | None, lo, hi, options: RegisterOptions
) -> tuple[np.ndarray, np.ndarray]:
    """Radiance (unit albedo, zero background) and coverage of the mesh at pose ``(R, t)`` in the window ``lo..hi``."""
    m = render_window(mesh, camera, R, t, sun, lo, hi, options.supersample, options.reflectance, exact=options.exact_coverage)
    return m.M, m.C


def _lit_figure(topo, camera, R, t, sun):  # type: ignore[no-untyped-def]
    """Predicted lit figure (full frame, uint8) of the mesh at pose ``(R, t)`` and its outer contours."""
    return render_silhouette(topo, R, t, camera.focal_px, camera.principal_point_rc, camera.shape, sun_dir_camera=sun)


def _pose(camera: object, P: np.ndarray, D: float) -> np.ndarray:
    return D * np.asarray(camera.los(P), dtype=float)  # type: ignore[attr-defined]


def extent_update(
    obs: np.ndarray, pred: np.ndarray, P: np.ndarray, s_img: np.ndarray | None, pred_contours: list | None = None
) -> tuple[np.ndarray, float]:
    """Shift and scale (about ``P``) taking the predicted lit figure onto the observed one.

    With a Sun direction ``s_img`` in the image, the lit figure's extents across the
    Sun direction (the limb/terminator cusps) and toward the Sun (the sub-solar limb)
    are those of the silhouette (exact for a convex body), whatever the dim terminator
    does: the scale is the ratio of the cross-Sun widths, the shift matches the
    cross-Sun mid-point and the sunward extreme.  Without one (zero phase): area ratio
    and centroids.  ``pred_contours``: the outer contours of ``pred``, if known
    (:func:`~.silhouette.figure_extents`).
    """
    if s_img is None:
        k = math.sqrt(float(obs.sum()) / float(pred.sum()))
        fp = figure_center(pred)
        return figure_center(obs) - (P + k * (fp - P)), k
    e = np.array([-s_img[1], s_img[0]])
    axes = np.stack([e, -e, s_img])
    xo, xp = figure_extents(obs, axes), figure_extents(pred, axes, pred_contours)
    pe, ps = float(P @ e), float(P @ s_img)
    k = (xo[0] + xo[1]) / (xp[0] + xp[1])
    mid_o, mid_p = 0.5 * (xo[0] - xo[1]), 0.5 * (xp[0] - xp[1])
    d_e = mid_o - (pe + k * (mid_p - pe))
    d_s = xo[2] - (ps + k * (xp[2] - ps))
    return d_e * e + d_s * s_img, float(k)


def initial_center(mesh: Mesh, camera: object, R: np.ndarray, sun, mask: np.ndarray, range_km: float | None):  # type: ignore[no-untyped-def]
    """Step 1 of the module docstring: ``(P, D)`` from the observed lit figure ``mask``."""
    from ..imaging.prior import sun_direction_image

    topo = cached_topology(mesh)
    fc = figure_center(mask)
    rr, cc = np.nonzero(mask.any(axis=1))[0], np.nonzero(mask.any(axis=0))[0]
    extent = float(max(rr[-1] - rr[0], cc[-1] - cc[0]) + 1)
    D = float(range_km) if range_km else 2.0 * mesh.max_radius * camera.focal_px / extent  # type: ignore[attr-defined]
    P = fc.copy()
    for _ in range(3):
        pred, contours = _lit_figure(topo, camera, R, _pose(camera, P, D), sun)
        if float(pred.sum()) < 4:
            raise MatchError("the predicted lit figure is empty at the initial pose (wrong attitude or range?)")
        s = None if sun is None else sun_direction_image(sun, camera, P, min_norm=0.08)
        shift, k = extent_update(mask, pred, P, None if s is None else np.asarray(s), contours)
        P, D = P + shift, D / k
    return P, D


def lit_figure(image: np.ndarray, min_frac: float = 0.02) -> tuple[np.ndarray, float]:
    """The whole lit figure: :func:`segment_body`'s threshold, every component of at least
    ``min_frac`` of the largest one (holes filled).

    At phase > 0 the lit part of a non-convex body (a contact binary's two lobes, a
    ridge beyond a dark valley) can fall apart into several pieces; the largest alone
    is not the figure the model predicts.
    """
    mask, thr, labels, stats = segment_components(image)  # the components labelled once
    n = stats.shape[0]
    if n <= 2:
        return mask, thr
    area = stats[1:, cv2.CC_STAT_AREA]
    keep = 1 + np.nonzero(area >= max(min_frac * float(area.max()), 20.0))[0]
    comp = np.isin(labels, keep).astype(np.uint8)
    contours, _ = cv2.findContours(comp, cv2.RETR_EXTERNAL, cv2.CHAIN_APPROX_NONE)
    full = np.zeros_like(comp)
    cv2.drawContours(full, contours, -1, color=1, thickness=cv2.FILLED)
    return full, thr


def _window(camera: object, P: np.ndarray, D: float, mesh: Mesh, mask: np.ndarray, pad: int):  # type: ignore[no-untyped-def]
    """Pixel window holding the predicted body (bounding sphere) and the observed figure, plus ``pad``."""
    rad = camera.focal_px * mesh.max_radius / max(D - mesh.max_radius, 1e-9 * D)  # type: ignore[attr-defined]
    box = _bbox(mask)
    lo = np.minimum(np.floor(P - rad), box[:2]) - pad
    hi = np.maximum(np.ceil(P + rad), box[2:]) + pad
    shape = np.array(camera.shape)  # type: ignore[attr-defined]
    return np.maximum(lo, 0).astype(int), np.minimum(hi, shape - 1).astype(int)


def ncc_shift(image: np.ndarray, model: np.ndarray, lo: np.ndarray, search: int) -> tuple[np.ndarray, float]:
    """Shift (row, col) of ``model`` (rendered in the window starting at ``lo``) that maximises the NCC."""
    h, w = model.shape
    big = np.pad(image, search, mode="edge")
    region = big[int(lo[0]) : int(lo[0]) + h + 2 * search, int(lo[1]) : int(lo[1]) + w + 2 * search]
    if region.shape != (h + 2 * search, w + 2 * search) or float(model.std()) == 0.0:
        return np.zeros(2), float("nan")
    score = cv2.matchTemplate(region.astype(np.float32), model.astype(np.float32), cv2.TM_CCOEFF_NORMED)
    i, j = np.unravel_index(int(np.argmax(score)), score.shape)
    d = np.array([i, j], dtype=float) - search
    for ax, k in ((0, i), (1, j)):
        line = score[:, j] if ax == 0 else score[i, :]
        if 0 < k < line.shape[0] - 1:
            den = line[k - 1] - 2 * line[k] + line[k + 1]
            if den < 0:
                d[ax] += 0.5 * (line[k - 1] - line[k + 1]) / den
    return d, float(score[i, j])


def _gn_system(M: np.ndarray, C: np.ndarray, ratio: float, P_win: np.ndarray, n_rows: int = 5) -> np.ndarray:
    """Transposed design matrix ``(n_rows, n)`` of the linearised model ``a M + b (1 - C)`` (the body hides the sky).

    Rows: ``M``, ``1 - C``, ``-dG/dr``, ``-dG/dc``, ``-(x - P).grad G`` with
    ``G = M - ratio C`` (``ratio = b/a`` of the previous solve); rows 5.. are left for
    the attitude (:func:`.model_render.attitude_columns`).  Rows, not columns: each is
    written in one contiguous pass and the normal matrix is ``At At^T``.
    """
    h, w = M.shape
    At = np.empty((n_rows, h * w))
    gr, gc = np.gradient(M - ratio * C)
    At[0] = M.ravel()
    np.subtract(1.0, C.ravel(), out=At[1])
    np.negative(gr.ravel(), out=At[2])
    np.negative(gc.ravel(), out=At[3])
    radial = At[4].reshape(h, w)
    np.multiply(P_win[0] - np.arange(h, dtype=float)[:, None], gr, out=radial)
    radial -= (np.arange(w, dtype=float) - P_win[1])[None, :] * gc
    return At


def _background_sigma(image: np.ndarray, mask: np.ndarray, lo, hi) -> float:  # type: ignore[no-untyped-def]
    """Robust (MAD) noise of the background pixels of the window, away from the figure."""
    win = (slice(lo[0], hi[0] + 1), slice(lo[1], hi[1] + 1))
    far = cv2.dilate(np.ascontiguousarray(mask, dtype=np.uint8), np.ones((7, 7), np.uint8))[win] == 0
    vals = image[win][far]
    if vals.size < 50:
        return float("nan")
    return float(1.4826 * np.median(np.abs(vals - np.median(vals))))


def _blur(a: np.ndarray, sigma: float) -> np.ndarray:
    return a if sigma <= 0 else cv2.GaussianBlur(a, (0, 0), sigma, borderType=cv2.BORDER_REPLICATE)


_CHUNK = 4096  # columns per product: 8 x 8 x 4096 stays below OpenBLAS's threading threshold


def _normal_equations(At: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``(At At^T, At y)`` in column chunks single-threaded BLAS handles (``einsum`` for the vector).

    One product over all the window's pixels wakes OpenBLAS's thread pool, whose threads
    then spin for every later call: on 2 busy cores that doubled the CPU time of a locate.
    """
    N = np.zeros((At.shape[0], At.shape[0]))
    for j in range(0, At.shape[1], _CHUNK):
        blk = At[:, j : j + _CHUNK]
        N += blk @ blk.T
    return N, np.einsum("ij,j->i", At, y)


def _solve(At: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, float, np.ndarray]:
    """Linear least squares ``At^T beta ~ y`` by the (column-scaled) normal equations: a few columns, many rows.

    Returns ``beta``, the residual sum of squares ``|y|^2 - 2 beta.At y + beta.N beta``
    (no residual vector: ~1e-12 relative, the residual is >= 1e-6 of ``|y|^2`` here) and the normal
    matrix ``N = At At^T`` (for the covariance of the last solve, :func:`finish_registration`).
    """
    N, r = _normal_equations(At, y)
    sc = np.maximum(np.sqrt(np.diag(N)), 1e-300)
    try:
        beta = np.linalg.solve(N / np.outer(sc, sc), r / sc) / sc
    except np.linalg.LinAlgError:
        raise ConvergenceError("registration: singular normal matrix (the model has no texture or edge)") from None
    return beta, max(float(np.einsum("i,i->", y, y)) - 2.0 * float(beta @ r) + float(beta @ N @ beta), 0.0), N


def _rotvec_matrix(w: np.ndarray) -> np.ndarray:
    """Rodrigues rotation of a rotation vector ``w`` (rad)."""
    th = float(np.linalg.norm(w))
    if th < 1e-15:
        return np.eye(3)
    K = np.array([[0.0, -w[2], w[1]], [w[2], 0.0, -w[0]], [-w[1], w[0], 0.0]]) / th
    return np.eye(3) + math.sin(th) * K + (1.0 - math.cos(th)) * K @ K


class _Pyramid:
    """The frame, camera and lit figure box-averaged by integer factors (:mod:`.model_render`), made on demand."""

    def __init__(self, image: np.ndarray, camera: object, mask: np.ndarray) -> None:
        self.levels = {1: (image, camera, mask)}

    def __getitem__(self, k: int):  # type: ignore[no-untyped-def]
        if k not in self.levels:
            image, camera, mask = self.levels[1]
            self.levels[k] = (downsample(image, k), level_camera(camera, k), downsample(mask.astype(np.float32), k) > 0)
        return self.levels[k]


def _level(sigma: float, size: float, options: RegisterOptions) -> int:
    """Pyramid factor of an iteration with blur ``sigma`` (px) on a figure ``size`` px across."""
    k = int(sigma // options.pyramid_blur_px)
    return max(1, min(k, int(size // options.pyramid_min_size_px)))


_BBOX = IdentityCache(maxsize=17)


def _bbox(mask: np.ndarray) -> np.ndarray:
    """``(r0, c0, r1, c1)`` of a figure, remembered for the last few masks (the pyramid's, asked every iteration)."""

    def box() -> np.ndarray:
        rr, cc = np.nonzero(mask.any(axis=1))[0], np.nonzero(mask.any(axis=0))[0]
        return np.array([rr[0], cc[0], rr[-1], cc[-1]])

    return _BBOX.get((mask,), box)


def _figure_size(mask: np.ndarray) -> float:
    box = _bbox(mask)
    return float(max(box[2] - box[0], box[3] - box[1]) + 1)


def _render_level(pyr, mesh, camera, R, sun, P, D, k, options, fit_attitude, mix):  # type: ignore[no-untyped-def]
    """The model at pyramid factor ``k``: ``(model, lo, hi, Pk)`` (window in level-``k`` pixels)."""
    _, cam, mask = pyr[k]
    Pk = (P - (k - 1) / 2.0) / k
    lo, hi = _window(cam, Pk, D, mesh, mask, options.margin_px)
    facets = mesh if k == 1 else clustered_mesh(mesh, 2.0 * k * D / camera.focal_px)
    model = render_window(facets, cam, R, _pose(camera, P, D), sun, lo, hi, options.supersample, options.reflectance, fit_attitude, mix,
                          options.cast_shadows and sun is not None and (options.coarse_cast_shadows or k < options.coarse_min_level), k == 1 and options.exact_coverage)
    return model, lo, hi, Pk


def _albedo_rows(M: np.ndarray, P_win: np.ndarray, order: int, harmonics: int) -> list[np.ndarray]:
    """``M`` times the monomials of degree 1..``order`` of the offsets from ``P_win`` (units of the
    window size) and times ``cos k theta``, ``sin k theta`` (``k = 1..harmonics``, ``theta`` the position
    angle about ``P_win``): an albedo that varies across the body and along its outline
    (:attr:`RegisterOptions.albedo_order`, :attr:`RegisterOptions.albedo_harmonics`)."""
    h, w = M.shape
    y = (np.arange(h)[:, None] - P_win[0]) / max(h, w) * np.ones((1, w))
    x = (np.arange(w)[None, :] - P_win[1]) / max(h, w) * np.ones((h, 1))
    rows = [M * y**i * x ** (d - i) for d in range(1, order + 1) for i in range(d + 1)]
    th = np.arctan2(y, x)
    rows += [M * f(k * th) for k in range(1, harmonics + 1) for f in (np.cos, np.sin)]
    return [r.ravel() for r in rows]


def surge_fields(cam, lo, hi, Pk, sun, widths, min_range: float = 0.0) -> list[np.ndarray]:  # type: ignore[no-untyped-def]
    """``1 / (1 + tan(g/2) / h)`` over the window ``lo..hi`` of ``cam`` for each width ``h`` of ``widths``, with
    ``g`` the phase angle (Sun -- surface -- camera) of each pixel's ray (``sun=None``: the Sun behind the
    camera, along the ray through ``Pk``).

    The shadow-hiding opposition surge (Hapke 1986, Eq. 11: ``B(g) = B_0 / (1 + tan(g/2) / h)``) brightens
    the part of the body nearest zero phase; at 3x the long axis the phase angle varies by ~10 deg across
    the body, and an unmodelled surge (Lommel-Seeliger with surge, Hapke) moved a registration at zero
    phase by 0.2 px (ray-traced Eros, ``benchmarks/irregular_independent.py``).  ``M`` times these fields
    are linear columns (:attr:`RegisterOptions.surge_widths`); each field is zero at ``Pk`` (the body
    centre), so that the coefficient of ``M`` stays the contrast there.  A field that varies by less than
    ``min_range`` over the window is left out: it is then a gentle gradient the surge hardly shows, and a
    free column took up other misfits instead (our own render of a cratered body at 90 deg phase, 10x
    the long axis, range 0.03: 0.06 -> 0.36 px).
    """
    f = cam.focal_px  # type: ignore[attr-defined]
    pr, pc = cam.principal_point_rc  # type: ignore[attr-defined]
    yn = ((lo[0] + np.arange(hi[0] - lo[0] + 1)) - pr)[:, None] / f
    xn = ((lo[1] + np.arange(hi[1] - lo[1] + 1)) - pc)[None, :] / f
    ray = np.array([(Pk[1] - pc) / f, (Pk[0] - pr) / f, 1.0])
    s = -ray if sun is None else np.asarray(sun, dtype=float)
    s = s / np.linalg.norm(s)
    cos_g = -(s[0] * xn + s[1] * yn + s[2]) / np.sqrt(xn * xn + yn * yn + 1.0)
    t = np.tan(0.5 * np.arccos(np.clip(cos_g, -1.0, 1.0)))
    t0 = math.tan(0.5 * math.acos(max(-1.0, min(1.0, -float(s @ ray) / float(np.linalg.norm(ray))))))
    fields = [1.0 / (1.0 + t / h) - 1.0 / (1.0 + t0 / h) for h in widths]
    return [f for f in fields if float(f.max() - f.min()) >= min_range]


def has_dark_side(model, min_frac: float) -> bool:  # type: ignore[no-untyped-def]
    """Whether at least ``min_frac`` (and 16 pixels) of the model's covered pixels are unlit (the pedestal
    column of :func:`_system` is then identifiable; 0: never)."""
    body = model.C > 0.99
    n = int(np.count_nonzero(body))
    dark = int(np.count_nonzero(body & (model.M <= 1e-6)))
    return min_frac > 0 and n > 0 and dark >= max(min_frac * n, 16)


def _system(model, img, lo, hi, Pk, s, psf, ratio, fit_attitude, mix, albedo=(0, 0), fields=(), pedestal=0.0):  # type: ignore[no-untyped-def]
    """Transposed design matrix and data of one solve: frame blurred by ``s``, model by ``hypot(s, psf)``
    (the camera's PSF, :func:`estimate_psf`).  Rows: :func:`_gn_system`, the attitude (if fitted), the
    albedo field (:func:`_albedo_rows`), ``M`` times each of ``fields`` (:func:`surge_fields`), a constant
    (the pedestal, where :func:`has_dark_side` with ``pedestal``), and with ``mix`` last ``dM/dmix``."""
    sm = math.hypot(s, psf)
    Mb = _blur(model.M, sm)
    extra = _albedo_rows(Mb, Pk - lo, *albedo) if (albedo[0] or albedo[1]) else []
    extra += [_blur(model.M * fld, sm).ravel() for fld in fields]
    extra += [np.ones(Mb.size)] if has_dark_side(model, pedestal) else []
    extra += [] if mix is None else [_blur(d, sm).ravel() for d in model.dM_dmix]  # type: ignore[union-attr]
    n5 = 8 if fit_attitude else 5
    At = _gn_system(Mb, _blur(model.C, sm), ratio, Pk - lo, n5 + len(extra))
    if fit_attitude:
        attitude_columns(model, ratio, lambda a: _blur(a, sm), out=At[5:8])
    for i, row in enumerate(extra):
        At[n5 + i] = row
    y = _blur(img[lo[0] : hi[0] + 1, lo[1] : hi[1] + 1], s).ravel()
    return At, y


def _gn_step(pyr, mesh, camera, R, sun, P, D, sigma, k, ratio, options, fit_attitude, mix=None, psf=0.0, rendered=None):  # type: ignore[no-untyped-def]
    """One linearised solve at pyramid factor ``k``: ``(beta, rss, N, At, y, lo, hi)`` (window in level-``k`` pixels).

    ``rendered``: :func:`_render_level`'s answer for this very pose, if already made (:func:`estimate_psf`'s)."""
    model, lo, hi, Pk = _render_level(pyr, mesh, camera, R, sun, P, D, k, options, fit_attitude, mix) if rendered is None else rendered
    fields = surge_fields(pyr[k][1], lo, hi, Pk, sun, options.surge_widths, options.surge_min_range) if options.surge_widths else ()
    At, y = _system(model, pyr[k][0], lo, hi, Pk, sigma / k, psf / k, ratio, fit_attitude, mix, (options.albedo_order, options.albedo_harmonics), fields,
                    options.pedestal_min_dark_frac)
    return (*_solve(At, y), At, y, lo, hi)


def estimate_psf(st: GNState, pyr, mesh, camera, sun, options, fit_attitude, rendered=None) -> float:  # type: ignore[no-untyped-def]
    """Gaussian sigma (px) of the camera's PSF: the one of ``options.psf_grid_px`` whose blurred model
    leaves the smallest residual at the current pose (one render), refined by a parabola through the
    three values around the minimum.  An unmodelled PSF of 0.8 px biased a registration by 0.24 px
    (ray-traced frames, ``benchmarks/irregular_independent.py``).  ``rendered``: the full-resolution
    :func:`_render_level` of the current pose, if made (the next iteration's: one render for both)."""
    model, lo, hi, Pk = _render_level(pyr, mesh, camera, st.R, sun, st.P, st.D, 1, options, False, st.mix) if rendered is None else rendered
    grid = np.asarray(options.psf_grid_px, dtype=float)
    cost = []
    for g in grid:
        # the pose and photometry columns only: the residual's minimum over the blur is the same, at a third of the cost
        At, y = _system(model, pyr[1][0], lo, hi, Pk, 0.0, float(g), st.ratio, False, None, pedestal=options.pedestal_min_dark_frac)
        cost.append(_solve(At, y)[1])
    i = int(np.argmin(cost))
    if 0 < i < grid.size - 1:
        c0, c1, c2 = cost[i - 1], cost[i], cost[i + 1]
        den = c0 - 2.0 * c1 + c2
        if den > 0:
            h = 0.5 * (c0 - c2) / den
            return float(grid[i] + h * (grid[i + 1] - grid[i - 1]) / 2.0)
    return float(grid[i])


@dataclass
class GNState:
    """State of the Gauss-Newton registration between stages (:func:`start_registration`).

    ``rms_frac`` is the RMS residual of the last solve over the fitted contrast ``a``
    (comparable between hypotheses registered on the same frame at the same blur).
    """

    P: np.ndarray
    D: float
    R: np.ndarray
    ratio: float = 0.0
    mix: np.ndarray | None = None  # photometric mix (RegisterOptions.fit_photometry), None: not fitted
    psf: float = 0.0  # Gaussian PSF sigma of the model (px, estimate_psf)
    prev_step: np.ndarray | None = None  # the last sharp centre step (damping of limit cycles)
    it: int = 0
    step_px: float = math.inf
    rms_frac: float = math.nan
    last: tuple | None = None  # (At, y, beta, lo, hi, N) of the last solve (At: transposed design matrix, N = At At^T)
    n_pose: int = 5  # rows of the last solve up to the radiance terms: contrast, background, centre, scale (attitude)
    history: list = dataclasses.field(default_factory=list)  # rms_frac of every iteration


def _blur_schedule(mask: np.ndarray, options: RegisterOptions, wide: bool) -> tuple[float, ...]:
    if not wide:
        return tuple(options.blur_px)
    size = _figure_size(mask)
    return tuple(f * size for f in options.attitude_blur_frac if f * size >= options.attitude_blur_min_px)


def _iterate(st: GNState, pyr, mesh, camera, sun, sigma, options, fit_attitude, k=None, rendered=None) -> bool:  # type: ignore[no-untyped-def]
    """One Gauss-Newton iteration at blur ``sigma`` (in place; pyramid factor ``k``, default from the blur);
    ``True`` when converged (sharp, small steps).  ``rendered``: :func:`_gn_step`'s."""
    if k is None:
        k = _level(sigma, _figure_size(pyr[1][2]), options)
    beta, rss, N, At, y, lo, hi = _gn_step(pyr, mesh, camera, st.R, sun, st.P, st.D, sigma, k, st.ratio, options, fit_attitude, st.mix, st.psf,
                                        rendered)  # fmt: skip
    a = float(beta[0])
    if not a > 0:
        raise ConvergenceError("registration: the fitted contrast of the model is not positive")
    if st.mix is not None:
        st.mix = np.clip(st.mix + beta[-len(st.mix):] / a, *options.mix_bounds)
    st.it, st.ratio, st.last = st.it + 1, float(beta[1]) / a, (At, y, beta, lo, hi, N)
    st.n_pose = 8 if fit_attitude else 5
    st.rms_frac = math.sqrt(rss / y.size) / a
    st.history.append(st.rms_frac)
    step, ds = beta[2:4] / a * k, float(beta[4] / a)
    n = float(np.linalg.norm(step))
    if n > 2.0 + 2.0 * sigma:
        f = (2.0 + 2.0 * sigma) / n
        step, ds, beta = step * f, ds * f, np.concatenate([beta[:5], beta[5:] * f])
    if sigma == 0 and st.prev_step is not None and float(step @ st.prev_step) < -0.5 * n * float(np.linalg.norm(st.prev_step)):
        # a sharp step reversing the last one: the rendering's sub-pixel quantisation makes a limit
        # cycle of growing amplitude; half steps damp it to the mid-point
        step, n = 0.5 * step, 0.5 * n
    st.prev_step = step if sigma == 0 else None
    st.P = st.P + step
    st.D = st.D * math.exp(-max(min(ds, 0.05), -0.05))
    dw = 0.0
    if fit_attitude:
        w = beta[5:8] / a
        dw = float(np.linalg.norm(w))
        if dw > math.radians(3.0):
            w = w * (math.radians(3.0) / dw)
        st.R = _rotvec_matrix(w) @ st.R
    prev, st.step_px = st.step_px, n
    # the attitude of an elongated body far away jitters at ~1e-3 rad, moving the centre by ~0.01 px
    return sigma == 0 and abs(ds) < 1e-4 and ((n < options.tol_px and dw < 1e-4) or max(n, prev) < 2.0 * options.tol_px)


def coarse_stage(st: GNState, pyr, mesh, camera, sun, options, fit_attitude, wide) -> GNState:  # type: ignore[no-untyped-def]
    """The first blurred iteration of :func:`_blur_schedule` and those after it at pyramid factors of at least
    ``coarse_min_level`` (cheap: a 600 px figure is 75-120 px across there)."""
    size = _figure_size(pyr[1][2])
    for sigma in _blur_schedule(pyr[1][2], options, wide):
        if st.it and _level(sigma, size, options) < options.coarse_min_level:
            break
        _iterate(st, pyr, mesh, camera, sun, sigma, options, fit_attitude)
    return st


def fine_stage(st: GNState, pyr, mesh, camera, sun, options, fit_attitude, wide, guard=None) -> GNState:  # type: ignore[no-untyped-def]
    """The rest of the blur schedule, then sharp iterations to convergence (``max_iterations`` in all).

    ``guard(state, sigma)``, if given, is called after every iteration and may raise a
    :class:`~jaxlimb.errors.CheckFailed` to abandon the registration.
    """
    blur = _blur_schedule(pyr[1][2], options, wide)
    size = _figure_size(pyr[1][2])
    k2 = 2 if size >= 2 * options.pyramid_min_size_px and options.sharp_level2_iterations > 0 else 1
    n2, psf_done = 0, False
    while st.it < options.max_iterations:
        sigma = blur[st.it] if st.it < len(blur) else 0.0
        k = _level(sigma, size, options)
        if n2 < options.sharp_level2_iterations:  # no full-resolution iteration before the half-resolution optimum
            k = max(k, k2)
            n2 += sigma == 0
        rendered = None
        if sigma == 0 and k == 1 and options.psf_grid_px and not psf_done:
            # one render for the PSF estimate and this iteration (the same pose)
            rendered = _render_level(pyr, mesh, camera, st.R, sun, st.P, st.D, 1, options, fit_attitude, st.mix)
            st.psf, psf_done = estimate_psf(st, pyr, mesh, camera, sun, options, fit_attitude, rendered), True
        done = _iterate(st, pyr, mesh, camera, sun, sigma, options, fit_attitude, k, rendered)
        if guard is not None:
            guard(st, sigma)
        if k > 1 and sigma == 0 and st.step_px < 4.0 * options.tol_px:
            n2 = options.sharp_level2_iterations  # converged on the half-resolution frame (its own jitter): full resolution
        elif done:
            break
    if st.step_px > options.max_final_step_px:
        raise ConvergenceError(f"registration did not converge in {options.max_iterations} iterations (last step {st.step_px:.3g} px)")
    return st


def phase_angle_deg(sun_dir_camera: np.ndarray, camera: object, center_rc: np.ndarray) -> float:
    """Sun-body-camera angle (deg) at the body seen at ``center_rc`` (``sun_dir_camera``: a unit vector)."""
    u = np.asarray(camera.los(center_rc), dtype=float)  # type: ignore[attr-defined]
    return math.degrees(math.acos(max(-1.0, min(1.0, float(-u @ np.asarray(sun_dir_camera, dtype=float))))))


def _phase_deg(camera: object, P: np.ndarray, sun: np.ndarray | None) -> float:
    """:func:`phase_angle_deg` at ``P`` for any Sun vector (normalised; ``sun=None``: zero phase)."""
    if sun is None:
        return 0.0
    return phase_angle_deg(np.asarray(sun, dtype=float) / float(np.linalg.norm(sun)), camera, P)


def _mix0(options: RegisterOptions, phase_deg: float = 0.0) -> np.ndarray | None:
    """The initial photometric mix: ``options.mix_laws`` laws, two from ``options.mix_laws_max_phase_deg`` on."""
    if not options.fit_photometry:
        return None
    n = options.mix_laws if phase_deg < options.mix_laws_max_phase_deg else min(options.mix_laws, 2)
    return np.zeros(len(mix_laws(n)) + 1)


def _gauss_newton(image, mesh, camera, R, sun, P, D, mask, options, fit_attitude=False, wide=False):  # type: ignore[no-untyped-def]
    """Step 3 of the module docstring (coarse to fine: blurred iterations first, on the pyramid)."""
    pyr = _Pyramid(image, camera, mask)
    st = GNState(np.asarray(P, dtype=float), float(D), np.asarray(R, dtype=float), mix=_mix0(options, _phase_deg(camera, P, sun)))
    coarse_stage(st, pyr, mesh, camera, sun, options, fit_attitude, fit_attitude or wide)
    return fine_stage(st, pyr, mesh, camera, sun, options, fit_attitude, fit_attitude or wide)


def register_known_attitude(
    image: np.ndarray,
    mesh: Mesh,
    camera: object,
    R_body_to_camera: np.ndarray,
    sun_dir_camera: np.ndarray | None = None,
    range_km: float | None = None,
    options: RegisterOptions = RegisterOptions(),
    segmentation: tuple[np.ndarray, float] | None = None,
    fit_attitude: bool = False,
    initial: tuple[np.ndarray, float] | None = None,
) -> RegisterResult:
    """Body-centre image of a body of known attitude by render-and-register (module docstring).

    Parameters
    ----------
    image
        Grey frame ``[row, col]``.
    mesh
        Shape model (km, body frame; the mesh origin is the body centre).
    camera
        :class:`~jaxlimb.geometry.camera.Camera` of the frame.
    R_body_to_camera
        Known attitude (``x_cam = R x_body``).
    sun_dir_camera
        Unit vector from the body toward the Sun (camera frame); ``None``: zero phase.
    range_km
        Range prior (initial value only); ``None``: from the figure's area.
    options
        Registration options.
    segmentation
        ``(mask, threshold)`` of :func:`lit_figure`, if already segmented.
    fit_attitude
        Also fit a small rotation of ``R_body_to_camera`` (three columns from the same
        render, :func:`.model_render.attitude_columns`; used when the attitude comes from a
        template match, not from the hints).
    initial
        ``(P, D)`` to start from instead of step 1 (e.g. a template match).

    Raises
    ------
    MatchError
        The registered model does not explain the frame (residual, overlap).
    ConvergenceError
        No convergence.
    """
    img = np.asarray(image, dtype=float)
    R = np.asarray(R_body_to_camera, dtype=float)
    mask, thr = lit_figure(img) if segmentation is None else segmentation
    P, D, ncc = _start(img, mesh, camera, R, sun_dir_camera, range_km, options, mask, initial)
    try:
        st = _gauss_newton(img, mesh, camera, R, sun_dir_camera, P, D, mask, options, fit_attitude)
    except ConvergenceError:
        if fit_attitude:
            raise
        # a poor start (a non-convex body's extents): again with the coarse-to-fine blur of the attitude fit
        st = _gauss_newton(img, mesh, camera, R, sun_dir_camera, P, D, mask, options, False, True)
    res = finish_registration(img, camera, (mask, thr), st, ncc, options)
    lim = options.limb_min_phase_deg
    if fit_attitude or lim is None or sun_dir_camera is None or _phase_deg(camera, res.center_rc, sun_dir_camera) < lim:
        return res
    return with_lit_limb(res, st, camera, options)


def with_lit_limb(res: RegisterResult, st: GNState, camera: object, options: RegisterOptions) -> RegisterResult:
    """``res`` with its centre and covariance combined with the lit limb's estimate (:mod:`.limb_edges`,
    :attr:`RegisterOptions.limb_min_phase_deg`), from the last solve of ``st`` (sharp, full resolution).

    The fitted model of that solve is linearised at the centre before its last step: the edge estimate is a
    shift of that point.  ``res`` itself when the edge estimate has too few points or too wide a scatter.
    The reported covariance stays the registration's.
    """
    from .limb_edges import combine, lit_limb_center

    At, y, beta, lo, hi, _ = st.last  # type: ignore[misc]
    shape = (hi[0] - lo[0] + 1, hi[1] - lo[1] + 1)
    n = st.n_pose
    F = (np.einsum("i,ij->j", beta[:2], At[:2]) + np.einsum("i,ij->j", beta[n:], At[n:])).reshape(shape)
    P_lin = st.P - (st.prev_step if st.prev_step is not None else 0.0)
    edge = lit_limb_center(F, y.reshape(shape), 1.0 - At[1].reshape(shape), P_lin - lo, options.limb_lit_frac, options.limb_half_px)
    if edge is None or not edge[2] <= options.limb_max_scatter_px:
        return res
    P, _ = combine(res.center_rc, res.covariance_rc, edge[0] + lo, edge[1] + options.limb_floor_px**2 * np.eye(2))
    # the covariance stays the registration's: the edge estimate's sandwich alone under-reports (the combined
    # one gave a mean NEES of 8.3 on 24 renders at 90 deg; the registration's, 0.74)
    return dataclasses.replace(res, center_rc=P, los_camera=np.asarray(camera.los(P), dtype=float), t_camera=_pose(camera, P, res.range_km))


def _start(img, mesh, camera, R, sun, range_km, options, mask, initial):  # type: ignore[no-untyped-def]
    """Steps 1-2: initial pose (or ``initial``) moved by the NCC peak; ``(P, D, ncc)``."""
    P, D = initial_center(mesh, camera, R, sun, mask, range_km) if initial is None else initial
    lo, hi = _window(camera, P, D, mesh, mask, options.margin_px)
    M, _ = render_model(mesh, camera, R, _pose(camera, P, D), sun, lo, hi, options)
    shift, ncc = ncc_shift(img, M, lo, options.search_px)
    return P + shift, D, ncc


def _coarse_ncc(pyr, mesh, camera, R, sun, initial, options):  # type: ignore[no-untyped-def]
    """Step 2 on the pyramid level of the first blurred iteration (a template's pose is off by pixels, not by less)."""
    P, D = np.asarray(initial[0], dtype=float), float(initial[1])
    img, cam, mask = pyr[1]
    blur = _blur_schedule(mask, options, True)
    k = _level(blur[0], _figure_size(mask), options) if blur else 1
    img, cam, mask = pyr[k]
    Pk = (P - (k - 1) / 2.0) / k
    lo, hi = _window(cam, Pk, D, mesh, mask, options.margin_px)
    facets = mesh if k == 1 else clustered_mesh(mesh, 2.0 * k * D / camera.focal_px)
    M, _ = render_model(facets, cam, R, _pose(camera, P, D), sun, lo, hi, options)  # type: ignore[arg-type]
    shift, ncc = ncc_shift(img, M, lo, max(2, math.ceil(options.search_px / k)))
    return P + k * shift, D, ncc


@dataclass
class Registration:
    """A registration with the attitude fitted, stopped after :func:`coarse_stage` (:func:`start_search_registration`)."""

    image: np.ndarray
    mesh: Mesh
    camera: object
    sun: np.ndarray | None
    segmentation: tuple[np.ndarray, float]
    pyramid: _Pyramid
    state: GNState
    ncc: float
    options: RegisterOptions


def start_search_registration(
    image: np.ndarray, mesh: Mesh, camera: object, R: np.ndarray, sun: np.ndarray | None, initial: tuple[np.ndarray, float],
    segmentation: tuple[np.ndarray, float], options: RegisterOptions = RegisterOptions(),
) -> Registration:  # fmt: skip
    """NCC and the coarse (pyramid) iterations of a template hypothesis, attitude fitted; cheap.

    ``state.rms_frac`` then ranks the hypotheses before the expensive full-resolution
    iterations (:func:`complete_search_registration`).
    """
    img = np.asarray(image, dtype=float)
    R = np.asarray(R, dtype=float)
    pyr = _Pyramid(img, camera, segmentation[0])
    P, D, ncc = _coarse_ncc(pyr, mesh, camera, R, sun, initial, options)
    st = coarse_stage(GNState(np.asarray(P, dtype=float), float(D), R, mix=_mix0(options)), pyr, mesh, camera, sun, options, True, True)
    return Registration(img, mesh, camera, sun, segmentation, pyr, st, ncc, options)


def complete_search_registration(reg: Registration, guard=None) -> RegisterResult:  # type: ignore[no-untyped-def]
    """The full-resolution iterations and the checks of a :func:`start_search_registration` (``guard``: :func:`fine_stage`)."""
    st = fine_stage(reg.state, reg.pyramid, reg.mesh, reg.camera, reg.sun, reg.options, True, True, guard)
    return finish_registration(reg.image, reg.camera, reg.segmentation, st, reg.ncc, reg.options)


_IOU_MISFIT = 1.0  # the misfit band of _overlap in units of the residual excess (times the contrast)


def _overlap(obs: np.ndarray, model_flat: np.ndarray, thr: float, sigma: float, misfit: float = 0.0) -> float:
    """IoU of the observed figure and the fitted model thresholded like the frame.

    Pixels whose model value lies within 3 noise sigmas plus ``misfit`` (DN) of the threshold (a dim
    terminator, an edge) can fall either way by noise or by the model's accepted misfit alone and are
    left out.  ``misfit`` is the fit's residual excess times its contrast (:func:`finish_registration`):
    the background of an 8-bit frame can be noiseless (MAD 0) while the body's own photon and
    quantisation noise and the misfit of a real surface are not, and a correct ray-traced Phobos fit
    (0.02 px, excess 0.057) had IoU 0.891 with the noise band alone, above 0.9 with it.  Twice that band
    let another body's model through (IoU 0.83 -> 0.90, ``tests/irregular/test_locate_los.py``); once, 0.87.
    """
    model = model_flat.reshape(obs.shape)
    sure = np.abs(model - thr) > 3.0 * (sigma if math.isfinite(sigma) else 0.0) + misfit
    pred = (model > thr) & sure
    o = obs & sure
    return float(np.logical_and(pred, o).sum()) / max(float(np.logical_or(pred, o).sum()), 1.0)


def _with_sector_model_error(At, N, res, lo, hi, P, cov, a, n_sectors, scale=1.0):  # type: ignore[no-untyped-def]
    """The centre covariance with the cluster-robust model-error term of :mod:`jaxlimb.fitting.model_error`
    (pixels grouped in ``n_sectors`` position-angle sectors about ``P``; :attr:`RegisterOptions.model_error_sectors`;
    ``N = At At^T``, the normal matrix of the last solve)."""
    from ..analysis.model_error import cluster_robust_from_normal, positive_part, sector_groups

    rr, cc = np.mgrid[lo[0] : hi[0] + 1, lo[1] : hi[1] + 1]
    groups = sector_groups(np.stack([rr.ravel(), cc.ravel()], axis=1).astype(float), P, n_sectors)
    C_s = cluster_robust_from_normal(At, N, res, groups, n_sectors)
    return cov + scale**2 * positive_part(C_s[2:4, 2:4] / a**2 - cov)


def finish_registration(img, camera, segmentation, st: GNState, ncc: float, options: RegisterOptions) -> RegisterResult:  # type: ignore[no-untyped-def]
    """Covariance and the checks of step 4-5, from the last (sharp, full-resolution) solve of ``st``."""
    P, D, R, iters = st.P, st.D, st.R, st.it
    At, y, beta, lo, hi, N = st.last  # type: ignore[misc]
    a, b = float(beta[0]), float(beta[1])
    res = y - np.einsum("i,ij->j", beta, At)
    dof = max(res.size - At.shape[0], 1)
    s2 = float(np.einsum("i,i->", res, res)) / dof
    try:
        cov_beta = s2 * np.linalg.inv(N)
    except np.linalg.LinAlgError:
        raise ConvergenceError("registration: singular normal matrix") from None
    cov = cov_beta[2:4, 2:4] / a**2
    if options.model_error_sectors:
        cov = _with_sector_model_error(At, N, res, lo, hi, P, cov, a, options.model_error_sectors, options.model_error_scale)
    cov = cov + options.model_floor_px**2 * np.eye(2)
    sigma = _background_sigma(img, segmentation[0], lo, hi)
    rms = math.sqrt(s2)
    excess = math.sqrt(max(s2 - (sigma**2 if math.isfinite(sigma) else 0.0), 0.0)) / a
    mask, thr = segmentation
    # the fitted image: contrast and background, and the radiance terms after the pose rows (albedo, surge, mix)
    n = st.n_pose
    fitted = np.einsum("i,ij->j", beta[:2], At[:2]) + np.einsum("i,ij->j", beta[n:], At[n:])
    iou = _overlap(mask[lo[0] : hi[0] + 1, lo[1] : hi[1] + 1] > 0, fitted, thr, sigma, _IOU_MISFIT * excess * a)
    if not np.all(np.isfinite(P)) or not np.all(np.isfinite(cov)):
        raise ConvergenceError("registration produced a non-finite centre or covariance")
    if excess > options.max_excess_frac:
        raise MatchError(
            f"the registered model leaves a residual of {excess:.3f} of the body's contrast above the noise"
            f" (limit {options.max_excess_frac}): the shape model, attitude or Sun direction does not fit the frame"
        )
    if iou < options.min_iou:
        raise MatchError(f"the predicted and observed lit figures overlap by IoU {iou:.3f} (limit {options.min_iou})")
    check_center_sigma(cov, options.max_center_sigma_px)
    t = _pose(camera, P, D)
    return RegisterResult(
        center_rc=np.asarray(P, dtype=float),
        los_camera=np.asarray(camera.los(P), dtype=float),
        range_km=float(D),
        t_camera=t,
        covariance_rc=cov,
        gain=a,
        offset=b,
        rms_residual=rms,
        noise_sigma=sigma,
        excess_frac=excess,
        iou=iou,
        ncc=ncc,
        iterations=iters,
        R_body_to_camera=np.asarray(R, dtype=float),
    )


__all__ = ["RegisterOptions", "RegisterResult", "initial_center", "lit_figure", "complete_search_registration", "ncc_shift", "phase_angle_deg", "register_known_attitude", "start_search_registration", "render_model"]
