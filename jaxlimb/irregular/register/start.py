"""The starting pose of render-and-register: the lit figure, its extents and the cross-correlation peak.

The body centre is put on the line of sight of the figure centroid (Eq. 4 of Wu et al.) at the range of
the hints (or, without one, the range at which the predicted lit figure has the observed size), then moved
by the offset between the observed and predicted lit figures (:func:`extent_update`, three passes), then by
the peak of the normalised cross-correlation of the rendered model (``cv2.matchTemplate``,
``TM_CCOEFF_NORMED``: integer peak, parabolic sub-pixel).
"""

from __future__ import annotations

import math

import cv2
import numpy as np

from ...errors import MatchError
from ...imaging.prior import sun_direction_image
from ..mesh import Mesh
from ..model_render import clustered_mesh
from ..silhouette import cached_topology, figure_center, figure_extents, render_silhouette, segment_components
from .gauss_newton import Problem
from .pyramid import blur_schedule, figure_size, level_center, level_of, pose, render_model, window

_SEARCH_PX = 12  # half-width (px) of the cross-correlation search


def phase_angle_deg(sun_dir_camera: np.ndarray, camera: object, center_rc: np.ndarray) -> float:
    """Sun-body-camera angle (deg) at the body seen at ``center_rc``.

    Parameters
    ----------
    sun_dir_camera : np.ndarray (3,)
        Unit vector from the body toward the Sun, camera frame.
    camera : Camera
        Pinhole camera.
    center_rc : np.ndarray (2,)
        Image of the body, px ``(row, col)``.

    Returns
    -------
    float
        Phase angle, degrees (0: full, 180: new).
    """
    u = np.asarray(camera.los(center_rc), dtype=float)  # type: ignore[attr-defined]
    return math.degrees(math.acos(max(-1.0, min(1.0, float(-u @ np.asarray(sun_dir_camera, dtype=float))))))


def sun_phase_deg(camera: object, P: np.ndarray, sun: np.ndarray | None) -> float:
    """:func:`phase_angle_deg` at ``P`` for any Sun vector (normalised; ``sun=None``: zero phase).

    Parameters
    ----------
    camera : Camera
        Pinhole camera.
    P : np.ndarray (2,)
        Image of the body, px ``(row, col)``.
    sun : np.ndarray (3,) or None
        Direction toward the Sun, camera frame (any length).

    Returns
    -------
    float
        Phase angle, degrees; 0 without a Sun direction.
    """
    if sun is None:
        return 0.0
    return phase_angle_deg(np.asarray(sun, dtype=float) / float(np.linalg.norm(sun)), camera, P)


def lit_figure(image: np.ndarray, min_frac: float = 0.02) -> tuple[np.ndarray, float]:
    """The whole lit figure: :func:`~jaxlimb.irregular.silhouette.segment_body`'s threshold, every component of
    at least ``min_frac`` of the largest one (holes filled).

    At phase > 0 the lit part of a non-convex body (a contact binary's two lobes, a ridge beyond a dark
    valley) can fall apart into several pieces; the largest alone is not the figure the model predicts.

    Parameters
    ----------
    image : np.ndarray (rows, cols)
        Grey frame.
    min_frac : float
        Smallest component kept, as a fraction of the largest one's area (and at least 20 px).

    Returns
    -------
    mask : np.ndarray (rows, cols)
        The lit figure (non-zero inside).
    threshold : float
        The segmentation's grey level.
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


def extent_update(
    obs: np.ndarray, pred: np.ndarray, P: np.ndarray, s_img: np.ndarray | None, pred_contours: list | None = None
) -> tuple[np.ndarray, float]:
    """Shift and scale (about ``P``) taking the predicted lit figure onto the observed one.

    With a Sun direction ``s_img`` in the image, the lit figure's extents across the Sun direction (the
    limb/terminator cusps) and toward the Sun (the sub-solar limb) are those of the silhouette (exact for a
    convex body), whatever the dim terminator does: the scale is the ratio of the cross-Sun widths, the shift
    matches the cross-Sun mid-point and the sunward extreme.  Without one (zero phase): area ratio and
    centroids.

    Parameters
    ----------
    obs, pred : np.ndarray (rows, cols)
        Observed and predicted lit figures (masks).
    P : np.ndarray (2,)
        Predicted body-centre image, px ``(row, col)``: the centre of the scaling.
    s_img : np.ndarray (2,) or None
        Unit direction toward the Sun in the image ``(row, col)``; ``None``: zero phase.
    pred_contours : list, optional
        The outer contours of ``pred``, if known (:func:`~jaxlimb.irregular.silhouette.figure_extents`).

    Returns
    -------
    shift : np.ndarray (2,)
        Shift (px, ``(row, col)``) to add to ``P``.
    k : float
        Scale of the observed over the predicted figure (the range is divided by it).
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
    """``(P, D)`` from the observed lit figure ``mask`` (module docstring).

    The centre starts at the figure centroid and the range at the hints' value (or the one at which the
    bounding sphere spans the figure), then three :func:`extent_update` passes match the predicted figure.

    Parameters
    ----------
    mesh : Mesh
        Shape model (km, body frame).
    camera : Camera
        Pinhole camera.
    R : np.ndarray (3, 3)
        Body-to-camera rotation.
    sun : np.ndarray (3,) or None
        Unit vector toward the Sun, camera frame; ``None``: zero phase.
    mask : np.ndarray (rows, cols)
        Observed lit figure.
    range_km : float or None
        Range prior, km.

    Returns
    -------
    P : np.ndarray (2,)
        Body-centre image, px ``(row, col)``.
    D : float
        Range, km.

    Raises
    ------
    MatchError
        The predicted lit figure is empty (wrong attitude or range).
    """
    topo = cached_topology(mesh)
    fc = figure_center(mask)
    rr, cc = np.nonzero(mask.any(axis=1))[0], np.nonzero(mask.any(axis=0))[0]
    extent = float(max(rr[-1] - rr[0], cc[-1] - cc[0]) + 1)
    D = float(range_km) if range_km else 2.0 * mesh.max_radius * camera.focal_px / extent  # type: ignore[attr-defined]
    P = fc.copy()
    for _ in range(3):
        t = pose(camera, P, D)
        pred, contours = render_silhouette(topo, R, t, camera.focal_px, camera.principal_point_rc, camera.shape, sun_dir_camera=sun)  # type: ignore[attr-defined]
        if float(pred.sum()) < 4:
            raise MatchError("the predicted lit figure is empty at the initial pose (wrong attitude or range?)")
        s = None if sun is None else sun_direction_image(sun, camera, P, min_norm=0.08)
        shift, k = extent_update(mask, pred, P, None if s is None else np.asarray(s), contours)
        P, D = P + shift, D / k
    return P, D


def ncc_shift(image: np.ndarray, model: np.ndarray, lo: np.ndarray, search: int) -> tuple[np.ndarray, float]:
    """Shift (row, col) of ``model`` (rendered in the window starting at ``lo``) that maximises the NCC.

    Normalised cross-correlation (``cv2.TM_CCOEFF_NORMED``) over shifts up to ``search`` px; integer peak
    refined by a parabola along each axis.

    Parameters
    ----------
    image : np.ndarray (rows, cols)
        Frame.
    model : np.ndarray (h, w)
        Rendered model.
    lo : np.ndarray (2,) of int
        Frame pixel of the model's first pixel.
    search : int
        Largest shift searched (px, per axis).

    Returns
    -------
    shift : np.ndarray (2,)
        Sub-pixel shift ``(row, col)`` to add to the model's position; zeros when the window leaves the frame
        or the model is flat.
    ncc : float
        Peak correlation (``nan`` in those cases).
    """
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


def start_pose(problem: Problem, R: np.ndarray, range_km: float | None, initial=None):  # type: ignore[no-untyped-def]
    """The initial pose (or ``initial``, ``(P, D)``) moved by the NCC peak at full resolution.

    Parameters
    ----------
    problem : Problem
        The registration problem (frame pyramid, mesh, Sun, options).
    R : np.ndarray (3, 3)
        Body-to-camera rotation.
    range_km : float or None
        Range prior, km (:func:`initial_center`).
    initial : (np.ndarray (2,), float), optional
        ``(P, D)`` to start from instead of :func:`initial_center`.

    Returns
    -------
    P : np.ndarray (2,)
        Body-centre image, px ``(row, col)``.
    D : float
        Range, km.
    ncc : float
        Peak normalised cross-correlation (:func:`ncc_shift`).
    """
    image, camera, mask = problem.pyramid[1]
    P, D = initial_center(problem.mesh, camera, R, problem.sun, mask, range_km) if initial is None else initial
    lo, hi = window(camera, P, D, problem.mesh, mask)
    M, _ = render_model(problem.mesh, camera, R, pose(camera, P, D), problem.sun, lo, hi, problem.options)
    shift, ncc = ncc_shift(image, M, lo, _SEARCH_PX)
    return P + shift, D, ncc


def coarse_ncc(problem: Problem, R: np.ndarray, initial: tuple[np.ndarray, float]) -> tuple[np.ndarray, float, float]:
    """The NCC peak on the pyramid level of the first blurred iteration of the attitude fit (a template's pose
    is off by pixels, not by less).

    Parameters
    ----------
    problem : Problem
        The registration problem (frame pyramid, mesh, Sun, options).
    R : np.ndarray (3, 3)
        Body-to-camera rotation of the template hypothesis.
    initial : (np.ndarray (2,), float)
        The hypothesis' ``(P, D)``: centre image (px) and range (km).

    Returns
    -------
    P : np.ndarray (2,)
        Body-centre image moved by the peak, px ``(row, col)`` at full resolution.
    D : float
        Range, km (unchanged).
    ncc : float
        Peak normalised cross-correlation.
    """
    P, D = np.asarray(initial[0], dtype=float), float(initial[1])
    camera, mask = problem.pyramid[1].camera, problem.pyramid[1].mask
    blur = blur_schedule(mask, True)
    k = level_of(blur[0], figure_size(mask)) if blur else 1
    img, cam, mask = problem.pyramid[k]
    lo, hi = window(cam, level_center(P, k), D, problem.mesh, mask)
    facets = problem.mesh if k == 1 else clustered_mesh(problem.mesh, 2.0 * k * D / camera.focal_px)  # type: ignore[attr-defined]
    M, _ = render_model(facets, cam, R, pose(camera, P, D), problem.sun, lo, hi, problem.options)  # type: ignore[arg-type]
    shift, ncc = ncc_shift(img, M, lo, max(2, math.ceil(_SEARCH_PX / k)))
    return P + k * shift, D, ncc


__all__ = ["coarse_ncc", "extent_update", "initial_center", "lit_figure", "ncc_shift", "phase_angle_deg", "start_pose", "sun_phase_deg"]
