r"""``render_body``: a synthetic image of an ellipsoidal body with its exact truth.

The image is the sensor model of :mod:`jaxlimb.render.sensor` applied to the
supersampled ray-traced radiance of :mod:`jaxlimb.render.raytrace`.  The truth
(:class:`RenderTruth`) is computed from the geometry, not from the image: the
pinhole projection of the body centre, the limb ellipse of Eq. (2) of
Mortari et al. 2016 (:func:`jaxlimb.geometry.ellipsoid.image_conic`), the range,
the phase angle, the apparent radius, the Sun direction, the terminator and the
stars/hot pixels that were drawn.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from ..errors import ConfigError
from ..geometry.camera import Camera
from ..geometry.ellipsoid import ImageConic, image_conic, limb_cone
from ..geometry.terminator import TerminatorImage, terminator_image
from .raytrace import pixel_rays, render_radiance, trace_rays
from .reflectance import LUNAR_LAMBERT_MCEWEN, REFLECTANCE_MODELS
from .scene import Scene
from .sensor import add_point_sources, digitise, gaussian_psf, psf_pad

__all__ = ["RenderOptions", "RenderTruth", "render_body"]


def _num(val: object, name: str, lo: float = 0.0, strict: bool = False) -> float:
    try:
        v = float(val)  # type: ignore[arg-type]
    except (TypeError, ValueError):
        raise ConfigError(f"`RenderOptions.{name}` must be a number, got {val!r}") from None
    if not math.isfinite(v) or v < lo or (strict and v == lo):
        op = ">" if strict else ">="
        raise ConfigError(f"`RenderOptions.{name}` must be finite and {op} {lo}, got {val!r}")
    return v


@dataclass(frozen=True)
class RenderOptions:
    """Rendering and sensor settings.

    Attributes
    ----------
    reflectance
        ``"lommel-seeliger"`` (default), ``"lunar-lambert"``, ``"lambert"`` or ``"uniform"``
        (:mod:`jaxlimb.render.reflectance`).
    lunar_lambert_coeffs
        ``(A, B, C)`` of McEwen's ``L(alpha)`` (alpha in degrees).
    n_subsamples
        Sub-samples per edge pixel (Fibonacci lattice); 1 = centre sampling only.
    psf_sigma_px
        Gaussian PSF standard deviation (px); 0 = none.
    exposure_e
        Electrons per unit radiance; ``None`` = auto: the brightest blurred body pixel
        reaches ``auto_exposure_level * full_well_e``.
    auto_exposure_level
        See ``exposure_e`` (in (0, 1]).
    full_well_e
        Full-well capacity (e-).
    bit_depth
        8, 12, 16 (-> ``uint8``/``uint16`` with saturation) or ``None`` (float DN, no clipping).
    gain_e_per_dn
        e- per DN; ``None`` = ``full_well_e / (2**bit_depth - 1)`` (or 1 when ``bit_depth`` is None).
    background_e
        Mean dark + sky signal per pixel (e-).
    read_noise_e
        Gaussian read noise (e- rms).
    extra_noise_dn
        Additional Gaussian noise in DN (e.g. 10 grey levels, Aerospace 2015 Sec. 7).
    photon_noise
        Poisson noise on the signal.
    noise
        Master switch: ``False`` disables photon, read and extra noise.
    n_stars, star_flux_e
        Number of background stars and their total flux range (e-, log-uniform).
    n_hot_pixels, hot_pixel_e
        Number of hot pixels and their excess signal range (e-, uniform).
    """

    reflectance: str = "lommel-seeliger"
    lunar_lambert_coeffs: tuple[float, float, float] = LUNAR_LAMBERT_MCEWEN
    n_subsamples: int = 89
    psf_sigma_px: float = 1.0
    exposure_e: float | None = None
    auto_exposure_level: float = 0.8
    full_well_e: float = 20000.0
    bit_depth: int | None = 12
    gain_e_per_dn: float | None = None
    background_e: float = 20.0
    read_noise_e: float = 10.0
    extra_noise_dn: float = 0.0
    photon_noise: bool = True
    noise: bool = True
    n_stars: int = 0
    star_flux_e: tuple[float, float] = (500.0, 20000.0)
    n_hot_pixels: int = 0
    hot_pixel_e: tuple[float, float] = (2000.0, 20000.0)

    def __post_init__(self) -> None:
        if self.reflectance not in REFLECTANCE_MODELS:
            raise ConfigError(f"`RenderOptions.reflectance` must be one of {list(REFLECTANCE_MODELS)}, got {self.reflectance!r}")
        n = self.n_subsamples
        if not (isinstance(n, (int, np.integer)) and not isinstance(n, bool) and 1 <= n <= 4096):
            raise ConfigError(f"`RenderOptions.n_subsamples` must be an integer in [1, 4096], got {n!r}")
        _num(self.psf_sigma_px, "psf_sigma_px")
        if self.psf_sigma_px > 50:
            raise ConfigError(f"`RenderOptions.psf_sigma_px` must be <= 50 px, got {self.psf_sigma_px!r}")
        if self.exposure_e is not None:
            _num(self.exposure_e, "exposure_e")
        lvl = _num(self.auto_exposure_level, "auto_exposure_level", strict=True)
        if lvl > 1:
            raise ConfigError(f"`RenderOptions.auto_exposure_level` must be in (0, 1], got {lvl!r}")
        _num(self.full_well_e, "full_well_e", strict=True)
        if self.bit_depth not in (8, 12, 16, None):
            raise ConfigError(f"`RenderOptions.bit_depth` must be 8, 12, 16 or None, got {self.bit_depth!r}")
        if self.gain_e_per_dn is not None:
            _num(self.gain_e_per_dn, "gain_e_per_dn", strict=True)
        for name in ("background_e", "read_noise_e", "extra_noise_dn"):
            _num(getattr(self, name), name)
        for name in ("n_stars", "n_hot_pixels"):
            v = getattr(self, name)
            if not (isinstance(v, (int, np.integer)) and not isinstance(v, bool) and v >= 0):
                raise ConfigError(f"`RenderOptions.{name}` must be an integer >= 0, got {v!r}")
        for name in ("star_flux_e", "hot_pixel_e"):
            lo, hi = getattr(self, name)
            if not (0 < lo <= hi and math.isfinite(hi)):
                raise ConfigError(f"`RenderOptions.{name}` must be (lo, hi) with 0 < lo <= hi, got {getattr(self, name)!r}")

    @property
    def gain(self) -> float:
        if self.gain_e_per_dn is not None:
            return float(self.gain_e_per_dn)
        return 1.0 if self.bit_depth is None else self.full_well_e / (2**self.bit_depth - 1)

    @classmethod
    def noiseless(cls, **kw: Any) -> RenderOptions:
        """Float output in electrons, no noise, no background (for geometry tests)."""
        base: dict[str, Any] = dict(noise=False, bit_depth=None, background_e=0.0, read_noise_e=0.0)
        base.update(kw)
        return cls(**base)


@dataclass(frozen=True, eq=False)
class RenderTruth:
    """The exact truth of a rendered frame (geometry from the scene, not from the image).

    Attributes
    ----------
    center_rc
        Pinhole projection ``(row, col)`` of the body centre (may be outside the frame).
    limb
        Limb conic/ellipse (Eq. 2): ``limb.center_rc`` is the ellipse centre, which differs
        from ``center_rc`` off-axis; ``limb.semi_axes_px``, ``limb.angle_rad`` (convention of
        :mod:`jaxlimb.geometry.ellipsoid`).
    range_km
        Camera -> body-centre distance.
    los_cam
        Unit line of sight to the body centre (camera frame).
    phase_angle_rad
        Sun-body-camera angle at the centre (``None`` without a Sun).
    apparent_radius_px
        ``f_px R / sqrt(D^2 - R^2)`` with ``R`` the volumetric mean radius (Eq. 1 of Aerospace 2015).
    sun_dir_cam
        Unit vector body -> Sun, camera frame.
    cone_rho, gamma_off_rad
        The limb cone's semi-axis ratio (Eq. 9) and centre-offset angle (Sec. IV).
    terminator
        :class:`~jaxlimb.geometry.terminator.TerminatorImage` (``None`` without a Sun).
    atmosphere_limb
        Image conic of the top of the atmosphere shell (``None`` without an atmosphere).
    crop
        ``"none"`` (limb ellipse entirely inside the frame), ``"partial"`` or ``"outside"``.
    stars_rc, stars_flux_e, stars_visible
        Stars drawn (``visible`` = not behind the body).
    hot_pixels_rc, hot_pixels_e
        Hot pixel indices ``(row, col)`` and excess electrons.
    exposure_e, gain_e_per_dn
        The exposure (e- per unit radiance) and gain used.
    n_supersampled
        Number of pixels that were averaged over sub-samples.
    scene, camera, options, seed
        The inputs (``seed`` is the integer entropy actually used).
    """

    center_rc: tuple[float, float]
    limb: ImageConic
    range_km: float
    los_cam: np.ndarray
    phase_angle_rad: float | None
    apparent_radius_px: float
    sun_dir_cam: np.ndarray | None
    cone_rho: float
    gamma_off_rad: float
    terminator: TerminatorImage | None
    atmosphere_limb: ImageConic | None
    crop: str
    stars_rc: np.ndarray
    stars_flux_e: np.ndarray
    stars_visible: np.ndarray
    hot_pixels_rc: np.ndarray
    hot_pixels_e: np.ndarray
    exposure_e: float
    gain_e_per_dn: float
    n_supersampled: int
    scene: Scene = field(repr=False)
    camera: Camera = field(repr=False)
    options: RenderOptions = field(repr=False)
    seed: int | None = None

    @property
    def phase_angle_deg(self) -> float | None:
        return None if self.phase_angle_rad is None else math.degrees(self.phase_angle_rad)

    def as_dict(self) -> dict[str, Any]:
        """JSON-friendly summary."""
        return {
            "center_rc": list(self.center_rc),
            "ellipse": self.limb.as_dict(),
            "range_km": self.range_km,
            "los_camera": self.los_cam.tolist(),
            "phase_angle_rad": self.phase_angle_rad,
            "apparent_radius_px": self.apparent_radius_px,
            "sun_dir_camera": None if self.sun_dir_cam is None else self.sun_dir_cam.tolist(),
            "cone_rho": self.cone_rho,
            "gamma_off_rad": self.gamma_off_rad,
            "crop": self.crop,
            "radii_km": list(self.scene.radii),
            "R_body_to_camera": np.asarray(self.scene.R_body_to_camera).tolist(),
            "n_stars_visible": int(np.sum(self.stars_visible)),
            "exposure_e": self.exposure_e,
            "gain_e_per_dn": self.gain_e_per_dn,
            "seed": self.seed,
        }


def _crop_state(limb: ImageConic, camera: Camera) -> str:
    r0, r1, c0, c1 = limb.bbox_rc()
    lo_r, hi_r, lo_c, hi_c = -0.5, camera.rows - 0.5, -0.5, camera.cols - 0.5
    if r0 >= lo_r and r1 <= hi_r and c0 >= lo_c and c1 <= hi_c:
        return "none"
    if r1 < lo_r or r0 > hi_r or c1 < lo_c or c0 > hi_c:
        return "outside"
    # the bbox overlaps the frame; check that the ellipse itself reaches it
    pts = limb.points(2048)
    inside = (pts[:, 0] >= lo_r) & (pts[:, 0] <= hi_r) & (pts[:, 1] >= lo_c) & (pts[:, 1] <= hi_c)
    rc_pp = np.array([[lo_r, lo_c], [lo_r, hi_c], [hi_r, lo_c], [hi_r, hi_c]])
    corner_in = np.any(limb.evaluate(rc_pp) < 0)
    return "partial" if (np.any(inside) or corner_in) else "outside"


def render_body(
    scene: Scene,
    camera: Camera | None = None,
    options: RenderOptions | None = None,
    seed: int | None = None,
) -> tuple[np.ndarray, RenderTruth]:
    """Render ``scene`` and return ``(image, truth)``.

    Parameters
    ----------
    scene
        The body, its pose and illumination (:class:`~jaxlimb.render.scene.Scene`,
        :func:`~jaxlimb.render.scene.moon_scene`, :func:`~jaxlimb.render.scene.earth_scene`).
    camera
        Pinhole camera (default :meth:`Camera.default`).
    options
        :class:`RenderOptions` (default: Lommel-Seeliger, 89 sub-samples, PSF 1 px, 12 bit).
    seed
        Seed of ``np.random.default_rng`` for stars, hot pixels and noise (independent
        streams spawned from it).  ``None`` draws fresh entropy (recorded in ``truth.seed``).

    Returns
    -------
    image
        ``(rows, cols)`` array indexed ``[row, col]``: ``uint8``/``uint16`` or float64 (``bit_depth=None``).
    truth
        :class:`RenderTruth`.
    """
    cam, opt = _checked_inputs(scene, camera, options, seed)
    ss = np.random.SeedSequence(seed)
    rng_stars, rng_hot, rng_noise = (np.random.default_rng(s) for s in ss.spawn(3))

    sigma = float(opt.psf_sigma_px)
    win = render_radiance(scene, cam, opt.reflectance, opt.n_subsamples, psf_pad(sigma), opt.lunar_lambert_coeffs)
    frame, exposure = _exposed_frame(win, cam, opt, sigma)
    stars = _add_stars(frame, scene, cam, opt, rng_stars, sigma)
    hot_rc, hot_e = _hot_pixels(cam, opt, rng_hot)
    image = digitise(
        frame,
        rng_noise,
        bit_depth=opt.bit_depth,
        full_well_e=opt.full_well_e,
        gain_e_per_dn=opt.gain,
        read_noise_e=opt.read_noise_e if opt.noise else 0.0,
        extra_noise_dn=opt.extra_noise_dn if opt.noise else 0.0,
        photon_noise=opt.photon_noise and opt.noise,
        hot_pixels=(hot_rc, hot_e) if hot_e.size else None,
    )
    truth = _truth(scene, cam, opt, win, stars, (hot_rc, hot_e), exposure,
                   int(ss.entropy) if seed is None else int(seed))  # type: ignore[arg-type]
    return image, truth


def _checked_inputs(scene: Scene, camera: Camera | None, options: RenderOptions | None,
                    seed: int | None) -> tuple[Camera, RenderOptions]:
    """The camera and options of :func:`render_body` (defaults filled in); :class:`ConfigError` on a wrong type."""
    if not isinstance(scene, Scene):
        raise ConfigError(f"`scene` must be a Scene, got {type(scene).__name__}")
    cam = camera or Camera.default()
    if not isinstance(cam, Camera):
        raise ConfigError(f"`camera` must be a Camera, got {type(cam).__name__}")
    opt = options or RenderOptions()
    if not isinstance(opt, RenderOptions):
        raise ConfigError(f"`options` must be a RenderOptions, got {type(opt).__name__}")
    if seed is not None and not (isinstance(seed, (int, np.integer)) and not isinstance(seed, bool) and seed >= 0):
        raise ConfigError(f"`seed` must be a non-negative integer or None, got {seed!r}")
    return cam, opt


def _exposed_frame(win, cam: Camera, opt: RenderOptions, sigma: float) -> tuple[np.ndarray, float]:
    """The radiance window blurred by the Gaussian PSF, exposed (electrons) and placed on the sky background."""
    blurred = gaussian_psf(win.image, sigma)
    peak = float(blurred.max()) if blurred.size else 0.0
    if opt.exposure_e is not None:
        exposure = float(opt.exposure_e)
    else:
        exposure = opt.auto_exposure_level * opt.full_well_e / (peak if peak > 0 else 1.0)
    frame = np.full(cam.shape, float(opt.background_e))
    if blurred.size:
        r0, c0 = win.row0, win.col0
        h, w = blurred.shape
        fr0, fr1 = max(r0, 0), min(r0 + h, cam.rows)
        fc0, fc1 = max(c0, 0), min(c0 + w, cam.cols)
        if fr0 < fr1 and fc0 < fc1:
            frame[fr0:fr1, fc0:fc1] += exposure * blurred[fr0 - r0 : fr1 - r0, fc0 - c0 : fc1 - c0]
    return frame, exposure


def _add_stars(frame: np.ndarray, scene: Scene, cam: Camera, opt: RenderOptions, rng: np.random.Generator,
               sigma: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Stars at uniform positions with log-uniform fluxes, added where the body does not hide them;
    returns their positions, fluxes and visibility."""
    n_st = int(opt.n_stars)
    if not n_st:
        return np.zeros((0, 2)), np.zeros(0), np.zeros(0, bool)
    st_rc = np.column_stack([rng.uniform(-0.5, cam.rows - 0.5, n_st), rng.uniform(-0.5, cam.cols - 0.5, n_st)])
    lo, hi = opt.star_flux_e
    st_f = np.exp(rng.uniform(math.log(lo), math.log(hi), n_st))
    vis = ~trace_rays(scene, pixel_rays(cam, st_rc)).hit
    add_point_sources(frame, st_rc[vis], st_f[vis], sigma)
    return st_rc, st_f, vis


def _hot_pixels(cam: Camera, opt: RenderOptions, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    """Distinct random hot pixels and their charge (electrons)."""
    n_hot = min(int(opt.n_hot_pixels), cam.rows * cam.cols)
    if not n_hot:
        return np.zeros((0, 2), int), np.zeros(0)
    flat = rng.choice(cam.rows * cam.cols, size=n_hot, replace=False)
    hot_rc = np.column_stack(np.unravel_index(flat, cam.shape))
    return hot_rc, rng.uniform(opt.hot_pixel_e[0], opt.hot_pixel_e[1], n_hot)


def _truth(scene: Scene, cam: Camera, opt: RenderOptions, win, stars, hot, exposure: float, seed: int) -> RenderTruth:
    """The :class:`RenderTruth` of a render: limb, cone, terminator, atmosphere limb, stars and hot pixels."""
    q = scene.q
    D = scene.range_km
    Rm = scene.mean_radius_km
    limb = win.limb
    cone = limb_cone(scene.radii, scene.observer_body)
    term = None
    if scene.sun_dir_cam is not None:
        term = terminator_image(cam, scene.radii, q, scene.R_body_to_camera, scene.sun_dir_cam)
    atm_limb = None
    if scene.atmosphere is not None:
        atm_limb = image_conic(cam, np.asarray(scene.radii) + scene.atmosphere.height_km, q, scene.R_body_to_camera)
    st_rc, st_f, vis = stars
    return RenderTruth(
        center_rc=limb.body_center_rc,
        limb=limb,
        range_km=D,
        los_cam=q / D,
        phase_angle_rad=scene.phase_angle_rad,
        apparent_radius_px=cam.focal_px * Rm / math.sqrt(D * D - Rm * Rm) if D > Rm else float("nan"),
        sun_dir_cam=None if scene.sun_dir_cam is None else np.asarray(scene.sun_dir_cam),
        cone_rho=cone.rho,
        gamma_off_rad=cone.gamma_off,
        terminator=term,
        atmosphere_limb=atm_limb,
        crop=_crop_state(limb, cam),
        stars_rc=st_rc,
        stars_flux_e=st_f,
        stars_visible=vis,
        hot_pixels_rc=hot[0],
        hot_pixels_e=hot[1],
        exposure_e=exposure,
        gain_e_per_dn=opt.gain,
        n_supersampled=win.n_supersampled,
        scene=scene,
        camera=cam,
        options=opt,
        seed=seed,
    )
