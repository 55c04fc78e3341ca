r"""The profile-refit and body-centre stages of the two round bodies of :func:`jaxlimb.pipeline.locate`.

* **Sphere** (the Moon, Europa, any body with equal radii): after the circular sigmoid, the physical
  limb profile of a sunlit lunar-Lambert sphere (:data:`jaxlimb.models.LIMB_PROFILE`, when the Sun
  direction is known) or, with a camera, the elliptical sigmoid with the axis ratio and orientation of
  the image of a sphere at the estimated place (:func:`~jaxlimb.pipeline.sphere.fits.fit_sphere_annulus`);
  ``model="ellipse"``: the free elliptical sigmoid.  Then the exact sphere map of
  :mod:`jaxlimb.pipeline.sphere.center`.
* **Disc** (the Sun): the blurred limb-darkened disc (:data:`jaxlimb.models.LIMB_DARKENED`) on a full
  annulus, or, where the disc is brightest at its limb (the EUV), the optically thin corona over an opaque disc
  (:data:`jaxlimb.models.corona.CORONA`); its covariance widened by the model-error terms of
  :mod:`jaxlimb.model_error` (the cluster-robust sandwich over sectors of the limb and the split witness); the
  disc's centre is the body's (orthographic: ``(R/f)^2 ~ 1e-5``).
"""

from __future__ import annotations

import math
import warnings
from typing import Any

import numpy as np

from ...errors import ConvergenceError, SaturationWarning
from ...fitting import solver_from_name
from ...models import LIMB_DARKENED, CircleParams, EllipseParams, LimbProfileParams
from ...models.corona import CORONA, CoronaParams
from ..checks import MIN_LIT_ARC_DEG, check_lit_arc
from ..frame import arc_angles, frame_mask
from ..profile.albedo_field import with_albedo_field
from ..profile.fit import fit_lunar_profile
from ..profile.model_error import with_model_error
from ..profile.passes import l_rejection, saturation_level
from ..stages import BodyCenter, EdgeFit, Frame, RefineResult
from .center import circle_center, free_ellipse_center, sphere_center
from .fits import fit_ellipse_annulus, fit_sphere_annulus
from .sun import fit_limb_darkened


def _saturation(frame: Frame, edge: EdgeFit, extras: dict[str, Any]) -> float | None:
    """The image's clip level; warn when >= 20 pixels of the limb annulus sit on it."""
    img, circ = frame.img, edge.circ
    sat = saturation_level(img)
    z_ann = circ.data.z if circ.data.weights is None else img[circ.coords[:, 0].astype(np.int64),
                                                                circ.coords[:, 1].astype(np.int64)]
    n_sat = int(np.count_nonzero(np.asarray(z_ann) >= sat)) if sat is not None else 0
    if n_sat >= 20:
        extras["saturation"] = {"level": sat, "n_clipped_in_annulus": n_sat, "n_annulus": int(len(z_ann))}
        warnings.warn(SaturationWarning(
            f"{n_sat} of the {len(z_ann)} pixels of the limb annulus are clipped at {sat:g}: the radius (range) may be "
            "biased outward by up to ~1 px; expose shorter"), stacklevel=4)
    return sat


def lunar_profile_refit(frame: Frame, edge: EdgeFit, sat: float | None, extras: dict[str, Any]
                        ) -> tuple[RefineResult | None, RefineResult | None]:
    """The physical profile on the edge fit's pixels: ``(accepted, rejected)``.  ``accepted`` is ``None`` when
    (``profile="auto"``) the fit failed or it is not lunar-Lambert-like
    (:func:`~jaxlimb.pipeline.profile.passes.in_band`; ``extras["profile_rejected"]`` says why); ``rejected`` is the
    fit in the second case, else ``None``.

    Parameters
    ----------
    frame : Frame
    edge : EdgeFit
        The circular sigmoid fit whose pixels and parameters start the profile fit.
    sat : float or None
        The image's clip level (clipped pixels are left out).
    extras : dict
        Updated with the rejection or the clipped-pixel count.

    Returns
    -------
    tuple
        ``(accepted, rejected)``, each a :class:`~jaxlimb.pipeline.stages.RefineResult` or ``None``.
    """
    opt = frame.opt
    try:
        res, n_clipped = fit_lunar_profile(frame, edge.circ.fit.params, edge.circ.data, sat)
    except ConvergenceError as e:
        if opt.profile != "auto":
            raise
        extras["profile_rejected"] = {"model": "lunar-lambert", "reason": str(e)}
        return None, None
    if n_clipped and "saturation" in extras:
        extras["saturation"]["n_left_out_of_profile_fit"] = n_clipped
    out = res if opt.profile == "albedo-field" else with_albedo_field(frame, res)
    rejected = l_rejection(res.fit, out.fit) if opt.profile == "auto" else None
    if rejected is not None:  # the limb is not lunar-Lambert-like (a flat disc): keep the sigmoid, say why
        extras["profile_rejected"] = rejected
        return None, res
    return out, None


def sphere_refit(frame: Frame, cand: Any, edge: EdgeFit, physical: bool, extras: dict[str, Any]) -> RefineResult:
    """Stage "profile refit" of a sphere (module docstring).

    Parameters
    ----------
    frame : Frame
    cand : LimbCandidates
        The front end's answer (the free ellipse's start orientation).
    edge : EdgeFit
        The circular-sigmoid fit.
    physical : bool
        Try the lunar-Lambert profile first.
    extras : dict
        Updated with saturation, profile rejection and outlier counts.

    Returns
    -------
    RefineResult
        The profile, the sphere-shaped ESF (camera), the free ESF (``model="ellipse"``) or ``edge.circ``.

    Notes
    -----
    When the profile was fitted but rejected for its ``L``, the sigmoid that answers instead carries the move between
    the two in its covariance (:meth:`~jaxlimb.pipeline.stages.RefineResult.with_move_witness`, the whole move as its
    sigma): the sigmoid's centre lies off the limb's by the shading it does not model, a bias that grows with the
    phase, and the profile that would correct it is the one the band refused.
    """
    opt, circ = frame.opt, edge.circ
    sat = _saturation(frame, edge, extras)
    final, rejected = lunar_profile_refit(frame, edge, sat, extras) if physical else (None, None)
    if physical and final is None and opt.min_lit_arc_deg is None:
        # back on the sigmoid: its own (longer) shortest arc applies
        check_lit_arc(arc_angles(circ.coords, edge.center_rc), MIN_LIT_ARC_DEG, edge.pixels.half)
    if final is None and frame.use_camera:
        cam = frame.cam
        assert cam is not None
        fitp = circ.fit.params
        data = circ.data.with_coords(cam.undistort(circ.coords)) if cam.has_distortion else circ.data
        c_id = frame.to_ideal(np.array([float(fitp.r0), float(fitp.c0)]))
        final = fit_sphere_annulus(data, fitp.replace(r0=float(c_id[0]), c0=float(c_id[1])), cam.focal_px,
                                   cam.principal_point_rc, opt)
    final = final if final is not None else circ
    if opt.model == "ellipse":
        final = fit_ellipse_annulus(final.data, _ellipse_start(final, edge, cand), opt)
    extras["n_outliers"] += int(final.n_outliers) if final is not circ else 0
    return final if rejected is None else final.with_move_witness(rejected, 1.0)


def _ellipse_start(final: RefineResult, edge: EdgeFit, cand: Any) -> EllipseParams:
    """Start of the free ESF: the sphere-constrained ESF's ellipse (camera), else the CSF circle with the
    orientation of an algebraic ellipse fit of the front end's points."""
    q = final.fit.params
    if isinstance(q, EllipseParams):
        return EllipseParams(r0=q.r0, c0=q.c0, a=q.a, theta=q.theta, rho=min(float(q.rho), 0.999), k=q.k,
                             ymax=q.ymax, ymin=q.ymin)
    p = edge.circ.fit.params
    return EllipseParams(r0=p.r0, c0=p.c0, a=p.radius, theta=_orientation(cand.points_rc), rho=0.995, k=p.k, ymax=p.ymax,
                         ymin=p.ymin)


def _orientation(points_rc: Any) -> float:
    """``theta`` from :func:`cv2.fitEllipse` of the front end's limb points when near-circular (ratio > 0.8),
    else 0 (``rho`` starts at 0.995: at exactly 1 the orientation column of the Jacobian vanishes)."""
    pts = np.asarray(points_rc, dtype=np.float32)
    if pts.shape[0] < 5:
        return 0.0
    import cv2

    try:
        (_, _), (w, h), ang = cv2.fitEllipse(pts[:, ::-1].copy())
    except cv2.error:  # pragma: no cover
        return 0.0
    if min(w, h) <= 0.8 * max(w, h):
        return 0.0
    # OpenCV: angle (deg) of the `w` axis from +x (col) toward +y (row); ours from +col toward -row
    major_deg = ang if w >= h else ang + 90.0
    return math.radians(-major_deg) % math.pi


def sphere_center_of(frame: Frame, final: RefineResult) -> BodyCenter:
    """Stage "body-centre mapping" of a sphere: by the kind of the final fit.

    Parameters
    ----------
    frame : Frame
    final : RefineResult
        A circle (:func:`~jaxlimb.pipeline.sphere.center.circle_center`), a free ellipse, a profile without camera
        (its circle) or a sphere-shaped limb (:func:`~jaxlimb.pipeline.sphere.center.sphere_center`).

    Returns
    -------
    BodyCenter
    """
    fp = final.fit.params
    free = tuple(final.fit.free)
    if isinstance(fp, CircleParams):
        return circle_center(frame, (fp.r0, fp.c0), float(fp.radius), ("r0", "c0", "radius"))
    if frame.opt.model == "ellipse":
        return free_ellipse_center(frame, fp, free)
    x0 = np.array([float(fp.r0), float(fp.c0), float(fp.a)])
    if isinstance(fp, LimbProfileParams) and not frame.use_camera:
        return circle_center(frame, x0[:2], x0[2])
    return sphere_center(frame, x0, ("r0", "c0", "a"))


def disc_refit(frame: Frame, edge: EdgeFit, extras: dict[str, Any]) -> RefineResult:
    """Stage "profile refit" of a self-luminous disc: the limb-darkened disc on a full annulus, or the EUV corona's
    limb that the edge stage fitted (:func:`~jaxlimb.pipeline.sphere.corona.corona_edge`) with its model-error
    terms.

    Parameters
    ----------
    frame : Frame
    edge : EdgeFit
        The circular sigmoid fit (start centre and radius), or the corona's.
    extras : dict
        Updated with the saturation numbers.

    Returns
    -------
    RefineResult
        The disc model's fit and its annulus pixels (unit weights, DN); its covariance widened by
        :func:`~jaxlimb.pipeline.profile.model_error.with_model_error`, the noise-only one kept as
        ``noise_covariance``.

    Notes
    -----
    The noise-only covariance of thousands of limb pixels is ~0.001 px on a 200 px
    white-light disc: far below what the pixels' errors allow when they are not the model's white noise --
    lossy compression (JPEG 2000 wavelet blocks), a resampling's interpolation kernel, granulation and spots, a
    limb-darkening law other than the quadratic one near the limb, the corona's loops and active regions.  All of
    these are correlated along a stretch of limb (the sector sandwich sees them) or are the same all along it and
    move the edge with depth (the split witness refits the sky side and the disc side and sees them).
    """
    opt = frame.opt
    _saturation(frame, edge, extras)
    if isinstance(edge.circ.fit.params, CoronaParams):  # the edge stage fitted the EUV corona's limb
        return with_model_error(edge.circ, model=CORONA)
    sun = fit_limb_darkened(disc_image(frame), edge.center_rc, edge.radius,
                            solver=None if opt.solver == "lm" else solver_from_name(opt.solver))
    return with_model_error(sun.refine_result(), model=LIMB_DARKENED)


def disc_image(frame: Frame) -> np.ndarray:
    """The image a disc's profile fits see: invalid pixels (the frame's mask) are NaN, neither limb nor sky.

    Parameters
    ----------
    frame : Frame

    Returns
    -------
    np.ndarray
    """
    mask = frame_mask(frame)
    return frame.img if mask is None else np.where(mask, np.asarray(frame.img, float), np.nan)


def disc_center_of(frame: Frame, final: RefineResult) -> BodyCenter:
    """Stage "body-centre mapping" of a disc: its centre, the line of sight, the range from the radius.

    Parameters
    ----------
    frame : Frame
    final : RefineResult
        The limb-darkened disc's fit (``r0, c0, a``).

    Returns
    -------
    BodyCenter
    """
    fp = final.fit.params
    return circle_center(frame, (fp.r0, fp.c0), float(fp.a), range_from_radius=True)


__all__ = ["disc_center_of", "disc_image", "disc_refit", "lunar_profile_refit", "sphere_center_of", "sphere_refit"]
