"""Template matching and the similarity transform (Eq. 15-25 of Wu et al.), line of sight (Eq. 1-4).

Pipeline of :func:`locate_center`:

1. segment the body (:func:`~jaxlimb.irregular.silhouette.segment_body`);
2. *rectify* the figure to a virtual camera whose boresight passes through the figure centre (:mod:`.rectify`),
   as the on-axis templates (Sec. 3.3) and the similarity principle of Eq. (18)-(19) assume;
3. features of the rectified figure (Eq. 10-14);
4. shape distance to every template, Eq. (15), with weights Eq. (16), keep the ``top_k`` best;
5. for each kept template, estimate the rotation ``theta`` (Eq. 18-23, guarded, see below), score the alignment
   of the template contour with the observed contour, keep the best template;
6. centre point by the similarity transform, Eq. (24)-(25), mapped back through the rectification; line of
   sight, Eq. (4) (:meth:`Camera.los`).

Decisions and guards (each is tested in ``tests/irregular/test_matching.py``)
---------------------------------------------------------------------------
* **Weights (Eq. 16).**  As printed, ``lambda_l = max |h_l^m - h_l^n|`` (the range of ``h_l`` over the database)
  *multiplies* ``|h_l^i - h_l^j|``, so the moment with the largest spread (``h1``) dominates and ``h3..h7`` are
  ignored -- the opposite of a normalisation.  We read it as a normalisation and use ``lambda_l = 1 / range_l``
  (``weights="inverse_range"``, default); ``weights="paper"`` applies Eq. (16) literally.
* **Near-zero moments.**  The distance is computed on the guarded log-scaled moments of
  :func:`~jaxlimb.irregular.features.log_hu` (``sign(h) log10(1 + |h|/floor)``), so that moments near zero
  neither match anything (raw ``|h|`` differences all ~0) nor explode (``log|h|``).
* **Mirror images.**  The sign of ``h7`` is kept, and the final choice among the ``top_k`` candidates is made by
  contour agreement under a *proper* rotation (no reflection), which rejects the mirror-image (antipodal)
  template.
* **Unstable attitude vector.**  The paper's farthest point jumps between distant contour points when two are
  almost equally far (near-symmetric figures).  The rotation candidates are: every pairing of the three farthest
  distinct points of the two figures (Eq. 23 for each pair), and the second-moment orientation difference and
  that plus pi; each is scored by the mean distance of the transformed template contour to the observed contour
  (chamfer distance), the best is refined on a fine angular grid.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import cv2
import numpy as np

from ..errors import ConfigError, NoBodyError
from .database import TemplateDatabase
from .features import FigureFeatures, far_point_candidates, log_hu
from .rectify import Chamfer, apply_homography, rectified_features, rot_z_to
from .silhouette import SegmentOptions, brightness_center, figure_center, segment_body

N_FAR = 3  # farthest-point candidates per figure for the rotation (Eq. 23, guarded)


@dataclass(frozen=True)
class MatchOptions:
    """Options of :func:`locate_center`.

    Parameters
    ----------
    top_k
        Templates kept after the Hu-moment distance (Eq. 17) for the contour check.
    weights
        ``"inverse_range"`` (default) or ``"paper"`` (Eq. 16 literally).
    log_scale
        Compare guarded log-scaled Hu moments (default) instead of raw ones.
    rectify
        Rectify off-axis figures to a virtual on-axis camera (default True).
    rotation
        ``"guarded"`` (default): rotation candidates scored by contour agreement
        over the ``top_k`` templates (see the module docstring); ``"paper"``:
        the best template of Eq. (17) and the farthest-point rotation of
        Eq. (23) only -- the method exactly as published (for comparison).
    segment
        Segmentation options.
    """

    top_k: int = 8
    weights: str = "inverse_range"
    log_scale: bool = True
    rectify: bool = True
    rotation: str = "guarded"
    segment: SegmentOptions = field(default_factory=SegmentOptions)

    def __post_init__(self) -> None:
        if not (isinstance(self.top_k, int) and self.top_k >= 1):
            raise ConfigError(f"`top_k` must be an integer >= 1, got {self.top_k!r}")
        if self.weights not in ("inverse_range", "paper"):
            raise ConfigError(f"`weights` must be 'inverse_range' or 'paper', got {self.weights!r}")
        if self.rotation not in ("guarded", "paper"):
            raise ConfigError(f"`rotation` must be 'guarded' or 'paper', got {self.rotation!r}")


@dataclass(frozen=True)
class LocateResult:
    """Result of :func:`locate_center`.

    Attributes
    ----------
    center_rc
        Estimated image of the body centre ``P_G`` (row, col), Eq. (25).
    los_camera
        Unit line of sight to the body centre (camera frame), Eq. (4).
    template_index
        Index of the chosen template ``F_B``.
    theta
        Rotation ``theta`` (rad) from the template to the observed figure, Eq. (23),
        in the (x=col, y=row) plane of the rectified image.
    scale
        ``k_c = sqrt(S_G / S_B)``, Eq. (20).
    match_distance
        Shape distance ``SE(F_B, F_G)``, Eq. (15).
    contour_mean_px
        Mean distance (px) of the aligned template contour to the observed contour.
    figure_center_rc, brightness_center_rc
        The FC and BC baselines (row, col).
    R_virtual
        Rotation of the rectification (camera -> virtual camera is ``R_virtual.T``).
    """

    center_rc: np.ndarray
    los_camera: np.ndarray
    template_index: int
    theta: float
    scale: float
    match_distance: float
    contour_mean_px: float
    figure_center_rc: np.ndarray
    brightness_center_rc: np.ndarray
    R_virtual: np.ndarray
    mask: np.ndarray = field(repr=False)
    candidates: tuple[int, ...] = ()


# --------------------------------------------------------------------------- Eq. 15-17
def match_weights(features: np.ndarray, mode: str = "inverse_range") -> np.ndarray:
    """Weights ``lambda_l`` of Eq. (16) from the database features.

    ``range_l = max_{m,n} |h_l^m - h_l^n| = max_m h_l^m - min_m h_l^m``.  ``mode="paper"``
    returns ``range_l`` (Eq. 16 as printed); ``"inverse_range"`` returns
    ``1 / range_l`` (a feature with zero range gets weight 0).

    Parameters
    ----------
    features : np.ndarray (N, 7)
        Feature vectors of the ``N`` templates (:func:`database_features`).
    mode : str
        ``"inverse_range"`` or ``"paper"``.

    Returns
    -------
    np.ndarray (7,)
    """
    f = np.asarray(features, dtype=float)
    rng = f.max(axis=0) - f.min(axis=0)
    if mode == "paper":
        return rng
    if mode == "inverse_range":
        return np.where(rng > 0, 1.0 / np.where(rng > 0, rng, 1.0), 0.0)
    raise ConfigError(f"weights mode must be 'inverse_range' or 'paper', got {mode!r}")


def shape_distance(obs: np.ndarray, templates: np.ndarray, weights: np.ndarray) -> np.ndarray:
    """Shape similarity error ``SE = sum_l lambda_l |h_l^i - h_l^j|``, Eq. (15), against every template.

    Parameters
    ----------
    obs : np.ndarray (7,)
        Features of the observed figure.
    templates : np.ndarray (N, 7)
        Features of the templates.
    weights : np.ndarray (7,)
        ``lambda_l`` (:func:`match_weights`).

    Returns
    -------
    np.ndarray (N,)
    """
    return np.abs(np.asarray(templates) - np.asarray(obs)) @ np.asarray(weights)


# --------------------------------------------------------------------------- Eq. 18-25
def rotation_from_attitude(cf_template_xy: np.ndarray, cf_observed_xy: np.ndarray) -> float:
    """Rotation angle ``theta`` of Eq. (22)-(23) from the two attitude vectors (x, y).

    ``theta = atan2(x_B y_G - y_B x_G, x_B x_G + y_B y_G)``; the common positive
    factor ``sqrt(S_B/S_G) / |CF_B|^2`` of Eq. (22) does not change ``atan2``.

    Parameters
    ----------
    cf_template_xy, cf_observed_xy : np.ndarray (2,)
        Attitude vectors ``C_B F_B`` and ``C_G F_G``, ``(x=col, y=row)``.

    Returns
    -------
    float
        Rotation from the template to the observed figure, rad, in ``(-pi, pi]``.
    """
    xb, yb = cf_template_xy
    xg, yg = cf_observed_xy
    return math.atan2(xb * yg - yb * xg, xb * xg + yb * yg)


def similarity_center(
    center_obs_rc: np.ndarray, area_obs: float, center_tpl_rc: np.ndarray, area_tpl: float, point_tpl_rc: np.ndarray, theta: float
) -> np.ndarray:  # fmt: skip
    """Image of the body centre in the observed figure, Eq. (24)-(25).

    ``P_G = C_G + sqrt(S_G/S_B) Rot(theta) (P_B - C_B)`` with the rotation acting in
    the (x=col, y=row) plane.

    Parameters
    ----------
    center_obs_rc, area_obs : np.ndarray (2,), float
        Observed figure centre ``C_G`` (row, col) and area ``S_G`` (px^2).
    center_tpl_rc, area_tpl : np.ndarray (2,), float
        Template figure centre ``C_B`` and area ``S_B``.
    point_tpl_rc, theta : np.ndarray (2,), float
        Body-centre image ``P_B`` in the template, and the rotation (rad, Eq. 23).

    Returns
    -------
    np.ndarray (2,)
        ``P_G``, px (row, col).
    """
    k = math.sqrt(area_obs / area_tpl)
    d = np.asarray(point_tpl_rc, dtype=float) - np.asarray(center_tpl_rc, dtype=float)
    dx, dy = d[1], d[0]
    c, s = math.cos(theta), math.sin(theta)
    return np.asarray(center_obs_rc, dtype=float) + k * np.array([s * dx + c * dy, c * dx - s * dy])


def line_of_sight(camera: object, center_rc: np.ndarray) -> np.ndarray:
    """Unit line of sight to an image point, Eq. (4) of Wu et al. (``k_x = k_y = f/pitch``).

    Parameters
    ----------
    camera : Camera
        Pinhole camera.
    center_rc : np.ndarray (2,)
        Image point, px (row, col).

    Returns
    -------
    np.ndarray (3,)
        Unit vector, camera frame.
    """
    return np.asarray(camera.los(np.asarray(center_rc, dtype=float)))  # type: ignore[attr-defined]


def _rotation_candidates(tpl_contour: np.ndarray, tpl_orient: float, obs: FigureFeatures, obs_far: np.ndarray, n_far: int) -> np.ndarray:
    tfar = far_point_candidates(tpl_contour, np.zeros(2), n=n_far)
    th = [rotation_from_attitude(a, b) for a in tfar for b in obs_far]
    d2 = obs.orientation - tpl_orient
    th += [d2, d2 + math.pi]
    return np.array(th)


def database_features(db: TemplateDatabase, options: MatchOptions) -> np.ndarray:
    """The per-template feature vectors compared by Eq. (15): guarded log-Hu or raw Hu.

    Parameters
    ----------
    db : TemplateDatabase
        Templates.
    options : MatchOptions
        ``log_scale``.

    Returns
    -------
    np.ndarray (N, 7)
    """
    return log_hu(db.hu) if options.log_scale else np.asarray(db.hu)


@dataclass
class Observed:
    """The observed figure prepared for alignment (:func:`observe`: crop, rectification, features, chamfer map)."""

    off: np.ndarray
    fc: np.ndarray
    Rv: np.ndarray
    Hinv: np.ndarray
    obs: FigureFeatures
    obs_cxy: np.ndarray
    chamfer: Chamfer
    cG: np.ndarray

    def score(self, conts: np.ndarray, ks: np.ndarray, theta: np.ndarray) -> np.ndarray:
        """Mean chamfer distance of scaled, rotated template contours to the observed figure.

        Parameters
        ----------
        conts : np.ndarray (K, n, 2)
            Template contours ``(x, y)`` relative to their centres.
        ks : np.ndarray (K,)
            Scale of each template (Eq. 20).
        theta : np.ndarray (K, T)
            Rotations tried per template, rad.

        Returns
        -------
        np.ndarray (K, T)
            Mean distance (px) of each transformed contour to the observed outline.
        """
        c, s = np.cos(theta)[..., None], np.sin(theta)[..., None]
        x, y = conts[:, None, :, 0], conts[:, None, :, 1]
        kk = ks[:, None, None]
        cG = self.cG
        pts_v = np.stack([cG[1] + kk * (s * x + c * y), cG[0] + kk * (c * x - s * y)], axis=-1)  # (row, col)
        pts, _ = apply_homography(self.Hinv, pts_v)
        return self.chamfer(pts).mean(axis=-1)

    def align(self, conts: np.ndarray, areas: np.ndarray, orients: np.ndarray, n_far: int = N_FAR) -> tuple[np.ndarray, np.ndarray]:
        """Guarded rotation of each template: candidates from the ``n_far`` farthest points and the second-moment
        orientations (module docstring), then two fine grids.

        Parameters
        ----------
        conts, areas, orients : np.ndarray (K, n, 2), (K,), (K,)
            Template contours, areas (px^2) and orientations (rad).
        n_far : int
            Farthest-point candidates per figure.

        Returns
        -------
        theta, score : np.ndarray (K,)
            Best rotation of each template (rad) and its mean contour distance (px).
        """
        ks = np.sqrt(self.obs.area / np.asarray(areas, dtype=float))
        obs_far = far_point_candidates(self.obs_cxy, self.cG, n=n_far)
        cand = np.stack([_rotation_candidates(conts[i], float(orients[i]), self.obs, obs_far, n_far) for i in range(len(conts))])
        coarse = conts[:, ::2]  # every other contour point for the coarse stages
        sc = self.score(coarse, ks, cand)
        idx = np.arange(len(conts))
        th = cand[idx, np.argmin(sc, axis=1)]
        s_all = sc[idx, np.argmin(sc, axis=1)]
        for half, step, pts in ((math.radians(4.0), math.radians(0.5), coarse), (math.radians(0.5), math.radians(0.05), conts)):
            grid = th[:, None] + np.arange(-half, half + 0.5 * step, step)[None, :]
            sg = self.score(pts, ks, grid)
            i_best = np.argmin(sg, axis=1)
            th = grid[idx, i_best]
            s_all = sg[idx, i_best]
        return th, s_all

    def center(self, area_B: float, center_B_rc: np.ndarray, P_B_rc: np.ndarray, theta: float) -> np.ndarray:
        """Eq. (24)-(25) in the rectified frame, mapped back to image pixels.

        Parameters
        ----------
        area_B, center_B_rc, P_B_rc, theta : float, np.ndarray (2,), np.ndarray (2,), float
            Template area, figure centre, body-centre image (row, col) and the rotation (rad).

        Returns
        -------
        np.ndarray (2,)
            Body-centre image in the frame, px (row, col).
        """
        P_v = similarity_center(self.obs.center_rc, self.obs.area, center_B_rc, area_B, P_B_rc, theta)
        P, _ = apply_homography(self.Hinv, P_v)
        return P + self.off


def observe(mask: np.ndarray, camera: object, n_contour: int, rectify: bool = True) -> Observed:
    """Crop, rectify (module docstring, step 2) and describe an observed binary figure.

    Parameters
    ----------
    mask : np.ndarray (rows, cols)
        Binary figure in the frame.
    camera : Camera
        Camera of the frame (``K`` and ``los``).
    n_contour : int
        Points of the resampled contour.
    rectify : bool
        Rectify to the virtual camera through the figure centre.

    Returns
    -------
    Observed

    Raises
    ------
    NoBodyError
        Empty figure.
    """
    m_full = np.ascontiguousarray(mask, dtype=np.uint8)
    bx, by, bw, bh = cv2.boundingRect(m_full)  # (x=col, y=row, width, height), C speed
    if bw == 0 or bh == 0:
        raise NoBodyError("empty figure")
    size = max(bw, bh)
    pad = 8 + int(0.25 * size)
    r0, c0 = max(by - pad, 0), max(bx - pad, 0)
    r1 = min(by + bh - 1 + pad, m_full.shape[0] - 1)
    c1 = min(bx + bw - 1 + pad, m_full.shape[1] - 1)
    crop = np.ascontiguousarray(m_full[r0 : r1 + 1, c0 : c1 + 1], dtype=np.uint8)  # work in the crop
    off = np.array([r0, c0], dtype=float)
    fc = figure_center(crop) + off
    Rv = rot_z_to(camera.los(fc)) if rectify else np.eye(3)  # type: ignore[attr-defined]
    K = np.array(camera.K, dtype=float)  # type: ignore[attr-defined]
    K[0, 2] -= c0
    K[1, 2] -= r0
    H = K @ Rv.T @ np.linalg.inv(K)  # crop pixel -> virtual (crop) pixel
    obs, obs_cxy = rectified_features(crop, H, n_contour)
    return Observed(off=off, fc=fc, Rv=Rv, Hinv=np.linalg.inv(H), obs=obs, obs_cxy=obs_cxy, chamfer=Chamfer(crop),
                    cG=np.array([obs.center_rc[1], obs.center_rc[0]]))  # fmt: skip


def locate_in_mask(
    mask: np.ndarray, db: TemplateDatabase, camera: object, options: MatchOptions = MatchOptions()
) -> tuple[np.ndarray, dict]:
    """Body-centre image from a binary figure (steps 2-6 of the module docstring).

    Parameters
    ----------
    mask, db, camera, options
        Binary figure (frame pixels); as :func:`locate_center`.

    Returns
    -------
    P : np.ndarray (2,)
        Body-centre image, px (row, col).
    info : dict
        ``template_index``, ``theta``, ``scale``, ``match_distance``, ``contour_mean_px``, ``R_virtual``,
        ``candidates``, ``figure_center_rc`` and the ``observed`` features.
    """
    ob = observe(mask, camera, db.options.n_contour, options.rectify)
    obs, Rv, fc = ob.obs, ob.Rv, ob.fc
    feats = database_features(db, options)
    w = match_weights(feats, options.weights)
    fo = log_hu(obs.hu) if options.log_scale else obs.hu
    se = shape_distance(fo, feats, w)
    k_top = min(options.top_k, se.shape[0])
    top = np.argpartition(se, k_top - 1)[:k_top]
    top = top[np.argsort(se[top])]
    js = [int(j) for j in top]
    conts = np.asarray(db.contour_xy[top], dtype=float)  # (K, n, 2)
    if options.rotation == "paper":
        # Eq. (18)-(23) as printed: best template by Eq. (17), rotation from the farthest points
        j = js[0]
        theta = rotation_from_attitude(db.attitude_xy[j], obs.attitude_xy)
        s_best = float(ob.score(conts[:1], np.sqrt(obs.area / db.area[[j]]), np.array([[theta]]))[0, 0])
    else:
        th, s_all = ob.align(conts, db.area[top], db.orientation[top])
        i = int(np.argmin(s_all))
        s_best, j, theta = float(s_all[i]), js[i], float(th[i])
    P = ob.center(db.area[j], db.center_rc[j], db.center_image_rc, theta)
    k_c = math.sqrt(obs.area / db.area[j])
    info = {"template_index": j, "theta": theta, "scale": k_c, "match_distance": float(se[j]), "contour_mean_px": s_best,
            "R_virtual": Rv, "candidates": tuple(int(t) for t in top), "figure_center_rc": fc, "observed": obs}  # fmt: skip
    return np.asarray(P, dtype=float), info


def locate_center(
    image: np.ndarray, db: TemplateDatabase, camera: object, options: MatchOptions = MatchOptions()
) -> LocateResult:
    """Locate the image of the body centre by template matching (Sec. 4 of Wu et al.).

    Parameters
    ----------
    image
        Grey image ``[row, col]`` (float or integer).
    db
        Template database of the body.
    camera
        :class:`jaxlimb.geometry.camera.Camera` of the image.
    options
        Matching options.

    Returns
    -------
    LocateResult
        Centre ``P_G`` (Eq. 25), line of sight (Eq. 4), the chosen template and its transform, the baselines.

    Raises
    ------
    ConfigError
        Image shape other than the camera's.
    NoBodyError, TooSmallError, TooBigError
        From the segmentation.
    """
    img = np.asarray(image, dtype=float)
    if img.shape != tuple(camera.shape):  # type: ignore[attr-defined]
        raise ConfigError(f"image shape {img.shape} does not match the camera {tuple(camera.shape)}")  # type: ignore[attr-defined]
    mask, _ = segment_body(img, options.segment)
    P, info = locate_in_mask(mask, db, camera, options)
    if not np.all(np.isfinite(P)):
        raise NoBodyError("template matching produced a non-finite centre")
    return LocateResult(
        center_rc=P, los_camera=line_of_sight(camera, P), template_index=info["template_index"], theta=info["theta"],
        scale=info["scale"], match_distance=info["match_distance"], contour_mean_px=info["contour_mean_px"],
        figure_center_rc=info["figure_center_rc"], brightness_center_rc=brightness_center(img, mask),
        R_virtual=info["R_virtual"], mask=mask, candidates=info["candidates"],
    )  # fmt: skip


__all__ = [
    "LocateResult", "MatchOptions", "database_features", "line_of_sight", "locate_center", "locate_in_mask",
    "match_weights", "rotation_from_attitude", "shape_distance", "similarity_center",
]  # fmt: skip
