"""Local densification of the view sphere around a matched template, and the pose a match implies (beyond Wu et al.).

The template match (Eq. 15-25 of Wu et al.) leaves the error of the nearest template: the true viewpoint
is up to about half a sampling step (Eq. 5-7) away.  :func:`densify_match` renders tilted views around the
matched template and aligns each exactly like a database template; :func:`initial_pose` turns a match into
the pose ``(R_body_to_camera, t_camera)`` with the range from the scale of Eq. (20).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from .database import TemplateDatabase
from .features import features_from_contours
from .matching import LocateResult, observe
from .rectify import rot_z_to
from .silhouette import cached_topology, render_silhouette


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


def densify_match(mask: np.ndarray, db: TemplateDatabase, camera: object, match: LocateResult, levels: int = 3) -> DensifyResult:
    """Local densification of the view sphere around the matched template (beyond Wu et al.).

    The template grid leaves up to about half a step between the true viewpoint and the nearest template.
    Around the matched template, views tilted by ``(a, b)`` about the template camera's x and y axes are rendered
    on a 3x3 grid of spacing ``step/3``, then ``step/9``, ... (``levels`` levels); each is aligned with the
    observed figure exactly like a database template (guarded rotation, contour agreement), and the best one is
    kept.  Cost: ``9 levels`` silhouettes at template resolution.

    Parameters
    ----------
    mask, camera
        Observed figure (binary, frame pixels) and the frame's camera.
    db : TemplateDatabase
        Database the match came from (mesh, template camera, step).
    match : LocateResult
        The template match (:func:`~.matching.locate_center`).
    levels : int
        Refinement levels, each dividing the tilt step by 3.

    Returns
    -------
    DensifyResult
        Centre image (Eq. 25), rotation, scale and contour agreement of the best densified template.
    """
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
        th, sc = ob.align(conts, areas, orients)
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

    Parameters
    ----------
    db : TemplateDatabase
        Database the match came from.
    result : LocateResult
        The match: template index, ``theta``, scale and centre ``center_rc`` (px).
    camera : Camera
        Camera of the frame.
    R_template : np.ndarray (3, 3), optional
        Template rotation to use instead of the database's (e.g. :attr:`DensifyResult.R_template`).

    Returns
    -------
    R_body_to_camera : np.ndarray (3, 3)
        Attitude, body-fixed to camera frame.
    t_camera : np.ndarray (3,)
        Body centre in the camera frame, km.
    """
    j = result.template_index
    c, s = math.cos(result.theta), math.sin(result.theta)
    Rz = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
    u = np.asarray(camera.los(result.center_rc))  # type: ignore[attr-defined]
    RT = db.R_body_to_camera[j] if R_template is None else R_template
    R = rot_z_to(u) @ Rz @ RT
    D = camera.focal_px * db.distance_km / (db.focal_px * result.scale)  # type: ignore[attr-defined]
    return R, D * u


__all__ = ["DensifyResult", "densify_match", "initial_pose"]
