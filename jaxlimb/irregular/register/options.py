"""Options and result of render-and-register (:mod:`jaxlimb.irregular.register`)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..model_render import mix_laws


@dataclass(frozen=True)
class RegisterOptions:
    """Options of :func:`~jaxlimb.irregular.register.register_known_attitude`.

    Parameters
    ----------
    reflectance
        Reflectance law of the model (see :class:`~jaxlimb.render.mesh.MeshRenderOptions`).
    max_iterations
        Gauss-Newton iterations in all.
    sharp_level2_iterations
        At most this many unblurred iterations on the frame box-averaged 2x2 (its optimum is that of the full
        frame up to the rendering's quantisation) before those at full resolution; 0: none.
    max_excess_frac
        Largest accepted model misfit: RMS residual in excess of the noise, over the fitted contrast ``a``
        (check ``poor_match``).
    max_center_sigma_px
        Largest accepted 1-sigma of the centre (px, the larger axis), as ``LocateOptions.max_center_sigma_px`` for
        round bodies: a registration that does not measure the centre better is a typed failure
        (``center_too_uncertain``), not ``ok`` with a wide covariance; ``None``: no limit.
    fit_psf
        Estimate the camera's Gaussian PSF before the sharp iterations and blur the model by it
        (:func:`~jaxlimb.irregular.register.gauss_newton.estimate_psf`); off: an ideal camera.
    model_error
        The centre covariance carries the cluster-robust model-error term of :mod:`jaxlimb.model_error`
        over position-angle sectors about the centre: a surface whose albedo, shading or shadows differ from the
        model's leaves residuals that follow the centre's columns, which white noise alone does not report.
    cast_shadows, coarse_cast_shadows
        Scale each facet's radiance by its lit fraction seen from the Sun
        (:func:`jaxlimb.render.mesh.shadow_fractions`: a lumpy body's own cast shadows); on the coarse pyramid
        levels too (where a template hypothesis is ranked and brought near).
    albedo_order, albedo_harmonics
        An albedo field fitted with the model: polynomial across the body (columns ``M x^i y^j``,
        ``1 <= i + j <= albedo_order``) and harmonics along the position angle (``M cos k theta``,
        ``M sin k theta``, ``k <= albedo_harmonics``); 0: uniform.
    surge_widths
        Opposition-surge widths ``h`` (rad) of the columns ``M (B_h(g) - B_h(g_center))`` (Hapke 1986, Eq. 11;
        :func:`~jaxlimb.irregular.register.design.surge_fields`); empty: none.
    fit_photometry, mix_laws
        Fit the photometric mix ``m`` of the model radiance ``LS + m_1 (Lambert - LS) + m_2 (Minnaert_1/2 - LS)
        [+ m_3 (Minnaert_3/4 - LS)]`` and the smooth-shading column (:func:`~jaxlimb.irregular.model_render.render_window`;
        McEwen's lunar-Lambert law is ``m_1 = 1 - L``) over the first ``mix_laws`` laws of
        :data:`~jaxlimb.irregular.model_render.MIX_LAWS`.  The third (Minnaert ``k = 3/4``) resolves the
        zero-phase degeneracy of Lommel-Seeliger and Minnaert 1/2 (both flat when ``mu0 = mu``).
    fit_pedestal
        A constant column (a level under the whole frame: bias, dark current, stray light) besides the sky
        column ``1 - C`` when the model shows a dark side
        (:func:`~jaxlimb.irregular.register.design.has_dark_side`): the unlit side of a body on a pedestal
        otherwise looks like a dark edge.
    exact_coverage
        Full-resolution renders show in every sub-pixel the facet containing its centre
        (:func:`jaxlimb.render.mesh.rasterise`) instead of ``cv2.fillConvexPoly``'s painter's fill (which lets
        nearer facets overlap their neighbours by half a sub-pixel).
    limb_min_phase_deg
        From this phase angle on (attitude known), the centre is the information-weighted mean of the
        registration and of the lit limb's edge positions (:mod:`jaxlimb.irregular.limb_edges`: each edge with
        its own gain, so the surface's albedo does not move it); ``None``: never.
    """

    reflectance: str = "lommel-seeliger"
    max_iterations: int = 16
    sharp_level2_iterations: int = 0
    max_excess_frac: float = 0.12
    max_center_sigma_px: float | None = 1.0
    fit_psf: bool = True
    model_error: bool = True
    cast_shadows: bool = True
    coarse_cast_shadows: bool = True
    albedo_order: int = 0
    albedo_harmonics: int = 0
    surge_widths: tuple[float, ...] = (0.03, 0.1)
    fit_photometry: bool = True
    mix_laws: int = 3
    fit_pedestal: bool = True
    exact_coverage: bool = True
    limb_min_phase_deg: float | None = 75.0

    def __post_init__(self) -> None:
        mix_laws(self.mix_laws)  # a ConfigError now rather than in the middle of a registration


@dataclass(frozen=True)
class RegisterResult:
    """Result of :func:`~jaxlimb.irregular.register.register_known_attitude`.

    Attributes
    ----------
    center_rc, los_camera
        Body-centre image (row, col) and its unit line of sight (Eq. 4 of Wu et al.).
    range_km, t_camera
        Fitted range and body centre in the camera frame (km).
    covariance_rc
        2x2 covariance of ``center_rc`` (px^2).
    gain, offset
        Fitted ``a`` (DN per unit albedo) and ``b`` (background DN).
    rms_residual, noise_sigma
        RMS residual of the fit and the background noise (DN).
    excess_frac, iou, ncc
        Quality measures (:mod:`jaxlimb.irregular.register.checks`).
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


__all__ = ["RegisterOptions", "RegisterResult"]
