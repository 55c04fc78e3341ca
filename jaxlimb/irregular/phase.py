r"""Phase-aware template search: match what is lit when the Sun direction is known (beyond Wu et al.).

At phase angle ``phi > 0`` the figure in the frame is the *lit* part of the body:
the lit limb plus the terminator.  The Hu moments of Eq. (10)-(13) describe the
whole silhouette, so Eq. (15)-(17) compares unlike figures.  With the Sun
direction known in the camera frame, its image-plane direction ``s`` fixes which
part of any template silhouette is lit limb: a silhouette point whose outward
normal ``n`` (image plane) has ``n . s > 0`` is lit (the surface normal there is
``(n, 0)`` in the camera frame, and ``(n, 0) . s_3d = sin(phi) n . s``); the rest
of the silhouette is dark, and the terminator is *not* limb.

Search over every template ``j`` and in-plane roll ``theta`` (a 5 deg grid):

1. rotate the template contour (Eq. 22-23's rotation) and take its extents across
   ``s`` (the limb/terminator cusps) and toward ``s`` (the sub-solar limb): for a
   convex body these are the lit figure's extents, so the ratio of the cross-Sun
   widths gives the scale ``k`` (Eq. 20) and the extents give the translation;
2. score: mean distance (truncated) from the template's lit-limb points
   (``n . s > 0.25``) to the observed outline -- the terminator never enters.

The best distinct hypotheses are returned as poses ``(R_body_to_camera, P, D)``
in the frame's camera, for the render-and-register stage (:mod:`.register`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import cv2
import numpy as np

from .._identity_cache import IdentityCache
from .database import TemplateDatabase
from .rectify import Chamfer, rot_z_to
from .silhouette import figure_extents


_ROLL_STEP_DEG = 5.0  # in-plane roll grid step (deg)
_N_POINTS = 32  # contour points per template used in the search
_LIMB_COS = 0.25  # a template point is lit limb when n . s exceeds this
_TRUNCATE_FRAC = 0.1  # chamfer distances are truncated at this fraction of the figure size
_CHUNK = 256  # templates scored per vectorised block (memory)


@dataclass(frozen=True)
class PoseHypothesis:
    """A candidate pose: template, roll, scale and the implied pose in the frame's camera."""

    template_index: int
    theta: float
    scale: float
    score_px: float
    center_rc: np.ndarray
    R_body_to_camera: np.ndarray
    range_km: float


def contour_normals(xy: np.ndarray, at: np.ndarray | None = None) -> np.ndarray:
    """Outward unit normals of closed contours, from the central difference of each point's neighbours.

    Parameters
    ----------
    xy : np.ndarray (..., n, 2)
        Closed contours ``(x, y)``, either winding.
    at : np.ndarray of int, optional
        Only at these point indices (the same values as at those points of the whole contour).

    Returns
    -------
    np.ndarray (..., n, 2) or (..., len(at), 2)
        Outward unit normals ``(x, y)``.
    """
    n = xy.shape[-2]
    if at is None:
        d = np.roll(xy, -1, axis=-2) - np.roll(xy, 1, axis=-2)
    else:
        at = np.asarray(at)
        d = xy[..., (at + 1) % n, :] - xy[..., (at - 1) % n, :]
    nrm = np.stack([d[..., 1], -d[..., 0]], axis=-1)
    area2 = np.sum(xy[..., 0] * np.roll(xy[..., 1], -1, axis=-1) - np.roll(xy[..., 0], -1, axis=-1) * xy[..., 1], axis=-1)
    nrm = nrm * np.sign(area2)[..., None, None]
    return nrm / np.maximum(np.linalg.norm(nrm, axis=-1, keepdims=True), 1e-12)


def _score_block(conts, nrms, rolls, s_xy, xo, chamfer, limb_cos, size):  # type: ignore[no-untyped-def]
    """Scores, scales and translations ``(B, T)`` for a block of templates and every roll (float32).

    Every rotated quantity is linear in the template's (x, y): the projections of the
    rotated contour across the Sun and the normals' ``n . s`` are products
    ``(B, n, 2) x (2, T)`` (``einsum``, one pass each), the scaled and translated contour
    one batched product ``(B, n, 3) x (B, 3, T)`` per image axis (``x, y, 1``).
    """
    f4 = np.float32
    c, s = np.cos(rolls), np.sin(rolls)
    e = np.array([-s_xy[1], s_xy[0]])
    q = rolls.size // 4  # rolls a quarter turn apart: extents along -e and s are those along e of other rolls
    quarter = rolls.size % 4 == 0 and np.allclose(rolls, np.arange(rolls.size) * (2.0 * np.pi / rolls.size))
    # rolled contour X0 = c x - s y, X1 = s x + c y; a projection u . X = x (c u0 + s u1) + y (c u1 - s u0)
    dirs = (e,) if quarter else (e, -e, s_xy)
    proj = [np.stack([c * u[0] + s * u[1], c * u[1] - s * u[0]]) for u in dirs]
    B, n = conts.shape[:2]
    Y = np.einsum("bik,kt->bit", conts, np.concatenate(proj, axis=1).astype(f4)).reshape(B, n, len(dirs), rolls.size)
    h = Y.max(axis=1).astype(float)  # (B, 1 or 3, T) extents along e (-e, s)
    # the contour rolled by theta, along -e / s: rolled by theta + pi / theta + pi/2, along e
    xp = np.stack([h[:, 0], np.roll(h[:, 0], -2 * q, axis=1), np.roll(h[:, 0], -q, axis=1)] if quarter else [h[:, 0], h[:, 1], h[:, 2]], axis=-1)
    k = (xo[0] + xo[1]) / np.maximum(xp[..., 0] + xp[..., 1], 1e-9)
    d_e = 0.5 * (xo[0] - xo[1]) - k * 0.5 * (xp[..., 0] - xp[..., 1])
    d_s = xo[2] - k * xp[..., 2]
    T = d_e[..., None] * e + d_s[..., None] * s_xy  # (B, T, 2) translation (x, y)
    # chamfer-map coordinates k X + T - (c0, r0) of every point: [x, y, 1] @ W, W (2, B, 3, T)
    W = np.empty((2, B, 3, rolls.size), dtype=f4)
    W[0, :, 0], W[0, :, 1], W[0, :, 2] = k * c, -k * s, T[..., 0] - chamfer.c0
    W[1, :, 0], W[1, :, 1], W[1, :, 2] = k * s, k * c, T[..., 1] - chamfer.r0
    xyh = np.concatenate([conts, np.ones((B, n, 1), dtype=f4)], axis=-1)
    mx, my = np.matmul(xyh[None], W)  # (B, n, T) each
    n_s = np.stack([c * s_xy[0] + s * s_xy[1], c * s_xy[1] - s * s_xy[0]]).astype(f4)
    lit = np.einsum("bik,kt->bit", nrms, n_s) > limb_cos  # n . s of the rotated normals
    d = cv2.remap(chamfer.dt32, mx.reshape(B * n, -1), my.reshape(B * n, -1), interpolation=cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE)
    d = np.minimum(d.reshape(mx.shape), f4(_TRUNCATE_FRAC * size))
    n_lit = np.maximum(np.count_nonzero(lit, axis=1), 1)
    score = np.einsum("bit,bit->bt", d, lit.astype(f4)).astype(float) / n_lit + np.where(n_lit < 3, np.inf, 0.0)
    return score, k, T


_CONTOURS = IdentityCache(maxsize=1)


def _template_contours(db: TemplateDatabase, n_points: int) -> tuple[np.ndarray, np.ndarray]:
    """Subsampled template contours and their outward normals (float32), kept for the last database."""

    def make() -> tuple[np.ndarray, np.ndarray]:
        n_all = db.contour_xy.shape[1]
        sub = np.linspace(0, n_all, n_points, endpoint=False).astype(int)
        conts_all = np.asarray(db.contour_xy, dtype=float)
        nrms = contour_normals(conts_all, sub).astype(np.float32)
        return np.ascontiguousarray(conts_all[:, sub], dtype=np.float32), nrms

    return _CONTOURS.get((db,), make, n_points)


def phase_candidates(
    mask: np.ndarray, db: TemplateDatabase, camera: object, s_img_rc: np.ndarray, n_candidates: int = 10, whole_outline: bool = False
) -> list[PoseHypothesis]:
    """The ``n_candidates`` best distinct pose hypotheses for the lit figure ``mask`` (module docstring).

    Parameters
    ----------
    mask : np.ndarray (rows, cols)
        Observed lit figure.
    db : TemplateDatabase
        Templates searched (every template and 5-degree roll).
    camera : Camera
        Camera of the frame.
    s_img_rc : np.ndarray (2,)
        Unit image-plane direction (row, col) toward the Sun.
    n_candidates : int
        Hypotheses returned; any two are at least three view-sphere steps apart in attitude.
    whole_outline : bool
        Every template point counts as lit limb (zero phase, where ``s_img_rc`` only orients the extents).

    Returns
    -------
    list of PoseHypothesis
        Best score (truncated mean chamfer distance, px) first, each with its pose in the frame's camera.
    """
    s_xy = np.array([s_img_rc[1], s_img_rc[0]], dtype=float)
    s_xy /= np.linalg.norm(s_xy)
    e = np.array([-s_xy[1], s_xy[0]])
    xo = figure_extents(mask, np.stack([e, -e, s_xy])[:, ::-1])  # axes (x, y) -> (row, col)
    chamfer = Chamfer(mask)
    rr, cc = np.nonzero(mask.any(axis=1))[0], np.nonzero(mask.any(axis=0))[0]
    size = float(max(rr[-1] - rr[0], cc[-1] - cc[0]) + 1)
    conts_all, nrms_all = _template_contours(db, _N_POINTS)
    rolls = np.radians(np.arange(0.0, 360.0, _ROLL_STEP_DEG))
    limb_cos = -2.0 if whole_outline else _LIMB_COS  # n . s >= -1 > -2: every point
    scores = np.empty((len(db), rolls.size))
    ks = np.empty_like(scores)
    Ts = np.empty(scores.shape + (2,))
    for i0 in range(0, len(db), _CHUNK):
        sl = slice(i0, i0 + _CHUNK)
        scores[sl], ks[sl], Ts[sl] = _score_block(conts_all[sl], nrms_all[sl], rolls, s_xy, xo, chamfer, limb_cos, size)
    return _hypotheses(db, camera, scores, ks, Ts, rolls, n_candidates)


def _hypotheses(db, camera, scores, ks, Ts, rolls, n_candidates: int) -> list[PoseHypothesis]:  # type: ignore[no-untyped-def]
    """The ``n_candidates`` best (template, roll) cells, at least three view-sphere steps apart in attitude."""
    flat_scores = scores.ravel()
    top = np.argpartition(flat_scores, min(20000, flat_scores.size) - 1)[:20000]  # the 20000 best, then in order
    order = top[np.lexsort((top, flat_scores[top]))]
    out: list[PoseHypothesis] = []
    taken: list[np.ndarray] = []
    for flat in order:
        j, r = np.unravel_index(int(flat), scores.shape)
        if not np.isfinite(scores[j, r]):
            break
        h = _pose_of(db, camera, int(j), float(rolls[r]), float(ks[j, r]), Ts[j, r], float(scores[j, r]))
        if any(_angle(h.R_body_to_camera, R0) < math.radians(3 * db.options.step_deg) for R0 in taken):
            continue
        taken.append(h.R_body_to_camera)
        out.append(h)
        if len(out) >= n_candidates:
            break
    return out


def _angle(Ra: np.ndarray, Rb: np.ndarray) -> float:
    return math.acos(max(-1.0, min(1.0, (float(np.trace(Ra @ Rb.T)) - 1.0) / 2.0)))


def _pose_of(db, camera, j, theta, k, T_xy, score) -> PoseHypothesis:  # type: ignore[no-untyped-def]
    """Pose implied by template ``j`` rolled by ``theta``, scaled by ``k``, translated by ``T`` (Eq. 24-25)."""
    d = np.asarray(db.center_image_rc, dtype=float) - np.asarray(db.center_rc[j], dtype=float)
    dx, dy = d[1], d[0]
    c, s = math.cos(theta), math.sin(theta)
    P = np.array([T_xy[1] + k * (s * dx + c * dy), T_xy[0] + k * (c * dx - s * dy)])
    cR = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
    u = np.asarray(camera.los(P))  # type: ignore[attr-defined]
    R = rot_z_to(u) @ cR @ np.asarray(db.R_body_to_camera[j])
    D = camera.focal_px * db.distance_km / (db.focal_px * k)  # type: ignore[attr-defined]
    return PoseHypothesis(j, theta, k, score, P, R, float(D))


__all__ = ["PoseHypothesis", "contour_normals", "phase_candidates"]
