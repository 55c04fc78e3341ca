r"""Scenes for the truth renderer: an ellipsoidal body, its pose, the Sun, albedo and atmosphere.

Frames (docs/design.md): camera frame ``+z`` boresight, ``+x`` toward ``+col``, ``+y``
toward ``+row``.  ``R_body_to_camera`` rotates body-fixed vectors into the camera
frame; ``center_cam`` is the body centre in the camera frame (km); the Sun
direction is a unit vector **from the body toward the Sun**, camera frame.

Image-plane angles (``sun_angle_deg``, ``north_angle_deg``) are position angles
measured from ``+col`` turning toward ``-row`` (counter-clockwise on the image as
displayed, row down): angle ``psi`` is the image direction
``(d_row, d_col) = (-sin psi, cos psi)``, i.e. ``0`` = right, ``90`` = up,
``180`` = left, ``270`` = down.  This matches the ellipse ``angle_rad`` convention
of :mod:`jaxlimb.geometry.ellipsoid`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from ..errors import ConfigError, GeometryError, LimbInputError
from ..geometry.camera import Camera
from ..geometry.ellipsoid import check_radii, check_rotation, check_vec3

__all__ = [
    "EARTH_RADII_KM",
    "MOON_RADIUS_KM",
    "AlbedoPatches",
    "Atmosphere",
    "Scene",
    "earth_scene",
    "image_direction_camera",
    "moon_scene",
    "sun_direction_for_phase",
]

MOON_RADIUS_KM = 1737.4
EARTH_RADII_KM = (6378.137, 6378.137, 6356.752)  # WGS-84 equatorial, equatorial, polar


def _finite_pos(val: object, name: str, allow_zero: bool = False) -> float:
    try:
        v = float(val)  # type: ignore[arg-type]
    except (TypeError, ValueError):
        raise ConfigError(f"`{name}` must be a number, got {val!r}") from None
    ok = math.isfinite(v) and (v >= 0 if allow_zero else v > 0)
    if not ok:
        rng = ">= 0" if allow_zero else "> 0"
        raise ConfigError(f"`{name}` must be finite and {rng}, got {v!r}")
    return v


@dataclass(frozen=True)
class AlbedoPatches:
    r"""A seeded random albedo field on the surface (multiplies the scene albedo).

    The field is a sum of ``n_modes`` random plane waves of the body-fixed unit
    direction :math:`\hat x`:
    :math:`F(\hat x) = \sum_k A_k\cos(\kappa_k\,\hat e_k\cdot\hat x + \phi_k)`,
    wavenumbers :math:`\kappa_k` log-uniform in ``wavenumber_range`` (rad per body
    radius; 10 means features ~ R/10 across), amplitudes :math:`\propto\kappa^{-1}`,
    normalised to unit standard deviation; the albedo factor is
    :math:`\max(0.05, 1 + \text{amplitude}\,F)`.  Deterministic given ``seed``,
    independent of the image noise seed (the surface does not change between frames).
    """

    seed: int = 0
    amplitude: float = 0.15
    n_modes: int = 48
    wavenumber_range: tuple[float, float] = (2.0, 40.0)

    def __post_init__(self) -> None:
        _finite_pos(self.amplitude, "AlbedoPatches.amplitude", allow_zero=True)
        if not (isinstance(self.n_modes, (int, np.integer)) and self.n_modes >= 1):
            raise ConfigError(f"`AlbedoPatches.n_modes` must be an integer >= 1, got {self.n_modes!r}")
        lo, hi = self.wavenumber_range
        if not (0 < lo <= hi and math.isfinite(hi)):
            raise ConfigError(f"`AlbedoPatches.wavenumber_range` must satisfy 0 < lo <= hi, got {self.wavenumber_range}")

    def _modes(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        rng = np.random.default_rng(self.seed)
        e = rng.normal(size=(self.n_modes, 3))
        e /= np.linalg.norm(e, axis=1, keepdims=True)
        lo, hi = self.wavenumber_range
        kap = np.exp(rng.uniform(math.log(lo), math.log(hi), self.n_modes))
        ph = rng.uniform(0, 2 * np.pi, self.n_modes)
        amp = 1.0 / kap
        amp = amp / math.sqrt(float(np.sum(amp**2)) / 2.0)
        return e * kap[:, None], ph, amp

    def factor_exact(self, x_body_unit: np.ndarray) -> np.ndarray:
        """Albedo factor at body-fixed unit directions ``(..., 3)`` (direct sum of the modes)."""
        k, ph, amp = self._modes()
        arg = np.asarray(x_body_unit) @ k.T + ph
        F = np.cos(arg) @ amp
        return np.maximum(0.05, 1.0 + self.amplitude * F)

    def factor(self, x_body_unit: np.ndarray) -> np.ndarray:
        """Albedo factor at body-fixed unit directions ``(..., 3)``.

        Bilinear look-up in a cached longitude/latitude texture of the field
        (:meth:`factor_exact` sampled on a 1024 x 512 grid; the shortest wavelength
        ``2 pi / 40`` rad spans ~13 texels, so the interpolation error is < 1e-3 of the
        field's standard deviation).
        """
        from scipy.ndimage import map_coordinates

        tex = _albedo_texture(self)
        x = np.asarray(x_body_unit, dtype=float)
        lon = np.arctan2(x[..., 1], x[..., 0])  # (-pi, pi]
        lat = np.arcsin(np.clip(x[..., 2], -1.0, 1.0))
        nlat, nlon = tex.shape
        u = (lon + np.pi) / (2 * np.pi) * (nlon - 1)
        v = (lat + np.pi / 2) / np.pi * (nlat - 1)
        out = map_coordinates(tex, [v.ravel(), u.ravel()], order=1, mode="nearest")
        return out.reshape(lon.shape)


_TEXTURE_CACHE: dict[AlbedoPatches, np.ndarray] = {}


def _albedo_texture(p: AlbedoPatches, nlat: int = 512, nlon: int = 1024) -> np.ndarray:
    if p not in _TEXTURE_CACHE:
        lon = np.linspace(-np.pi, np.pi, nlon)
        lat = np.linspace(-np.pi / 2, np.pi / 2, nlat)
        LA, LO = np.meshgrid(lat, lon, indexing="ij")
        xyz = np.stack([np.cos(LA) * np.cos(LO), np.cos(LA) * np.sin(LO), np.sin(LA)], axis=-1)
        if len(_TEXTURE_CACHE) > 8:
            _TEXTURE_CACHE.clear()
        _TEXTURE_CACHE[p] = p.factor_exact(xyz)
    return _TEXTURE_CACHE[p]


@dataclass(frozen=True)
class Atmosphere:
    r"""An optically thin glowing shell (e.g. the Earth's limb glow / haze).

    Emission per unit length :math:`\propto e^{-h/H}` for altitudes
    :math:`0 \le h \le` ``height_km`` (H = ``scale_height_km``).  For a ray with
    tangent altitude :math:`h_t` that misses the body, the column is the Chapman
    grazing integral :math:`\sqrt{2\pi R H}\,e^{-h_t/H}`; a ray that hits the
    surface with emission cosine :math:`\mu` collects the near half only,
    :math:`\min(H/\mu, \sqrt{\pi R H/2})\,e^{0}`.  The rendered glow is
    ``brightness`` times the column divided by :math:`\sqrt{2\pi R H}` -- i.e.
    ``brightness`` is the radiance (units of the surface's normal-incidence
    radiance) of a ray grazing the surface just outside the limb.  Altitudes are
    ellipsoidal: :math:`h = (\sqrt{x^TJx} - 1)\,R_{loc}` with :math:`R_{loc}` the
    radius in the direction of :math:`x`.  Rays with :math:`h_t >` ``height_km``
    get no glow.
    """

    height_km: float = 100.0
    scale_height_km: float = 8.0
    brightness: float = 0.3

    def __post_init__(self) -> None:
        _finite_pos(self.height_km, "Atmosphere.height_km")
        _finite_pos(self.scale_height_km, "Atmosphere.scale_height_km")
        _finite_pos(self.brightness, "Atmosphere.brightness", allow_zero=True)


@dataclass(frozen=True, eq=False)
class Scene:
    """What the camera sees: one ellipsoidal body.

    Attributes
    ----------
    radii
        Semi-axes ``(a, b, c)`` km along the body-fixed x, y, z axes.
    center_cam
        Body centre in the camera frame (km), ``z > 0``.
    R_body_to_camera
        3x3 rotation, body-fixed -> camera.
    sun_dir_cam
        Unit vector from the body toward the Sun (camera frame); ``None`` for an
        unlit scene (only meaningful with the ``"uniform"`` reflectance, which
        ignores the Sun).
    albedo
        Surface albedo (multiplies the reflectance; > 0).
    albedo_patches
        Optional random albedo field.
    atmosphere
        Optional glowing shell.
    name
        Free text (``"moon"``, ``"earth"``, ...).
    """

    radii: tuple[float, float, float]
    center_cam: tuple[float, float, float]
    R_body_to_camera: np.ndarray = field(default_factory=lambda: np.eye(3))
    sun_dir_cam: tuple[float, float, float] | None = (0.0, 0.0, -1.0)
    albedo: float = 1.0
    albedo_patches: AlbedoPatches | None = None
    atmosphere: Atmosphere | None = None
    name: str = "body"

    def __post_init__(self) -> None:
        r = check_radii(self.radii, "Scene.radii")
        object.__setattr__(self, "radii", tuple(float(v) for v in r))
        q = check_vec3(self.center_cam, "Scene.center_cam")
        if not q[2] > 0:
            raise GeometryError(f"`Scene.center_cam` must be in front of the camera (z > 0), got {q.tolist()} km")
        if float(np.sum((q / r) ** 2)) <= 1.0:
            raise GeometryError(f"the camera is inside the body: `Scene.center_cam` = {q.tolist()} km, radii {r.tolist()}")
        object.__setattr__(self, "center_cam", tuple(float(v) for v in q))
        R = check_rotation(self.R_body_to_camera, "Scene.R_body_to_camera").copy()
        R.setflags(write=False)
        object.__setattr__(self, "R_body_to_camera", R)
        if self.sun_dir_cam is not None:
            s = check_vec3(self.sun_dir_cam, "Scene.sun_dir_cam")
            n = float(np.linalg.norm(s))
            if not n > 0:
                raise LimbInputError("`Scene.sun_dir_cam` must be a non-zero vector (body -> Sun), got [0, 0, 0]")
            object.__setattr__(self, "sun_dir_cam", tuple(float(v) for v in s / n))
        _finite_pos(self.albedo, "Scene.albedo")
        if self.albedo_patches is not None and not isinstance(self.albedo_patches, AlbedoPatches):
            raise ConfigError(f"`Scene.albedo_patches` must be an AlbedoPatches or None, got {self.albedo_patches!r}")
        if self.atmosphere is not None and not isinstance(self.atmosphere, Atmosphere):
            raise ConfigError(f"`Scene.atmosphere` must be an Atmosphere or None, got {self.atmosphere!r}")

    # ------------------------------------------------------------------ derived
    @property
    def q(self) -> np.ndarray:
        return np.asarray(self.center_cam, dtype=float)

    @property
    def range_km(self) -> float:
        """Distance camera -> body centre (km)."""
        return float(np.linalg.norm(self.q))

    @property
    def observer_body(self) -> np.ndarray:
        """Camera position in the body frame (km), ``p = -R^T q``."""
        return -self.R_body_to_camera.T @ self.q

    @property
    def phase_angle_rad(self) -> float | None:
        """Sun-body-observer angle at the body centre (rad): between ``sun_dir_cam`` and ``-q``."""
        if self.sun_dir_cam is None:
            return None
        s = np.asarray(self.sun_dir_cam)
        u = -self.q / self.range_km
        return float(math.atan2(np.linalg.norm(np.cross(s, u)), float(s @ u)))

    @property
    def mean_radius_km(self) -> float:
        return float(np.cbrt(np.prod(self.radii)))


# =============================================================================== helpers
def image_direction_camera(camera: Camera, center_rc: object, angle_deg: float) -> tuple[np.ndarray, np.ndarray]:
    """Unit line of sight ``u`` to pixel ``center_rc`` and the unit vector ``e`` perpendicular to it
    whose image at that pixel points along the position angle ``angle_deg``
    (``(d_row, d_col) = (-sin, cos)``; module docstring)."""
    rc = np.asarray(center_rc, dtype=float)
    u = camera.los(rc)
    psi = math.radians(float(angle_deg))
    # pixel displacement (dr, dc) corresponds to camera (x, y) = (dc, dr)/f at z = 1
    v = np.array([math.cos(psi), -math.sin(psi), 0.0])
    # project v onto the plane perpendicular to u, along the image: points X = u/u_z + eps v
    e = v - (v @ u) * u
    return u, e / np.linalg.norm(e)


def sun_direction_for_phase(u: np.ndarray, e: np.ndarray, phase_rad: float) -> np.ndarray:
    r"""Sun direction (body -> Sun) giving phase angle ``phase_rad`` with the lit side toward ``e``.

    The direction from the body to the observer is :math:`-u`; the Sun direction
    :math:`s = \cos\alpha\,(-u) + \sin\alpha\,e` makes the angle :math:`\alpha`
    with it.  ``alpha = 0`` is a full, ``pi`` a new Moon.
    """
    return math.cos(phase_rad) * (-u) + math.sin(phase_rad) * e


def _range_center(camera: Camera, center_rc: object | None, range_km: float) -> tuple[np.ndarray, np.ndarray]:
    if center_rc is None:
        center_rc = camera.principal_point_rc
    rc = np.asarray(center_rc, dtype=float)
    if rc.shape != (2,) or not np.all(np.isfinite(rc)):
        raise ConfigError(f"`center_rc` must be two finite numbers (row, col), got {center_rc!r}")
    return rc, camera.los(rc)


def moon_scene(
    range_km: float,
    phase_deg: float,
    center_rc: object | None = None,
    camera: Camera | None = None,
    sun_angle_deg: float = 0.0,
    R_body_to_camera: object | None = None,
    albedo: float = 1.0,
    albedo_patches: AlbedoPatches | None = None,
    radius_km: float = MOON_RADIUS_KM,
) -> Scene:
    """The Moon (sphere, 1737.4 km) at ``range_km`` whose centre projects onto ``center_rc``.

    Parameters
    ----------
    range_km
        Camera-to-centre distance (> radius).
    phase_deg
        Sun-Moon-observer angle at the centre, ``[0, 180]`` (0 = full).
    center_rc
        Pixel ``(row, col)`` where the Moon's centre projects (default: principal point);
        may lie outside the frame.
    camera
        Default :meth:`Camera.default`.
    sun_angle_deg
        Position angle of the lit side in the image (module docstring: 0 = toward
        ``+col``, 90 = toward ``-row``).
    R_body_to_camera
        Body orientation (matters only for albedo patches); identity by default.
    """
    cam = camera or Camera.default()
    D = _finite_pos(range_km, "range_km")
    R = _finite_pos(radius_km, "radius_km")
    if D <= R:
        raise GeometryError(f"`range_km` must exceed the radius {R} km, got {D}")
    ph = float(phase_deg)
    if not (math.isfinite(ph) and 0.0 <= ph <= 180.0):
        raise ConfigError(f"`phase_deg` must be in [0, 180], got {phase_deg!r}")
    _, u = _range_center(cam, center_rc, D)
    _, e = image_direction_camera(cam, cam.project(u), sun_angle_deg)
    s = sun_direction_for_phase(u, e, math.radians(ph))
    return Scene(
        radii=(R, R, R),
        center_cam=tuple(D * u),
        R_body_to_camera=np.eye(3) if R_body_to_camera is None else np.asarray(R_body_to_camera, dtype=float),
        sun_dir_cam=tuple(s),
        albedo=albedo,
        albedo_patches=albedo_patches,
        name="moon",
    )


def earth_scene(
    range_km: float,
    latitude_deg: float,
    phase_deg: float,
    center_rc: object | None = None,
    camera: Camera | None = None,
    sun_angle_deg: float = 0.0,
    north_angle_deg: float = 90.0,
    atmosphere: Atmosphere | None = None,
    albedo: float = 1.0,
    albedo_patches: AlbedoPatches | None = None,
    radii: object = EARTH_RADII_KM,
) -> Scene:
    r"""The Earth (WGS-84 ellipsoid) seen from geocentric latitude ``latitude_deg``.

    The observer sits at :math:`p = D(\cos\varphi, 0, \sin\varphi)` in the Earth-fixed
    frame (longitude 0, geocentric latitude :math:`\varphi`, :math:`D` = ``range_km``
    from the centre).  The Earth's centre projects onto ``center_rc``; the body's
    north pole (+z) appears at position angle ``north_angle_deg`` in the image
    (default 90 = up, toward ``-row``).  Construction: with ``u`` the line of sight to
    ``center_rc`` and ``n_c`` the camera vector perpendicular to ``u`` pointing to
    ``north_angle_deg`` (:func:`image_direction_camera`), and in the body frame
    :math:`-\hat p` and :math:`n_b` = the pole's component perpendicular to :math:`\hat p`,
    :math:`R = [u, n_c, u\times n_c]\,[-\hat p, n_b, -\hat p\times n_b]^T`.

    The Sun is placed as in :func:`moon_scene` (``phase_deg``, ``sun_angle_deg``).
    """
    cam = camera or Camera.default()
    r = check_radii(radii)
    D = _finite_pos(range_km, "range_km")
    lat = float(latitude_deg)
    if not (math.isfinite(lat) and -90.0 < lat < 90.0):
        raise ConfigError(f"`latitude_deg` must be in (-90, 90), got {latitude_deg!r}")
    ph = float(phase_deg)
    if not (math.isfinite(ph) and 0.0 <= ph <= 180.0):
        raise ConfigError(f"`phase_deg` must be in [0, 180], got {phase_deg!r}")
    la = math.radians(lat)
    p = D * np.array([math.cos(la), 0.0, math.sin(la)])
    if float(np.sum((p / r) ** 2)) <= 1.0:
        raise GeometryError(f"observer at range {D} km, latitude {lat} deg is inside the body")
    _, u = _range_center(cam, center_rc, D)
    rc_c = cam.project(u)
    _, n_c = image_direction_camera(cam, rc_c, north_angle_deg)
    R = _earth_to_camera(u, n_c, p / D)
    _, e = image_direction_camera(cam, rc_c, sun_angle_deg)
    s = sun_direction_for_phase(u, e, math.radians(ph))
    return Scene(
        radii=tuple(float(v) for v in r),
        center_cam=tuple(D * u),
        R_body_to_camera=R,
        sun_dir_cam=tuple(s),
        albedo=albedo,
        albedo_patches=albedo_patches,
        atmosphere=atmosphere,
        name="earth",
    )


def _earth_to_camera(u: np.ndarray, n_c: np.ndarray, ph_hat: np.ndarray) -> np.ndarray:
    r"""The rotation :math:`R = [u, n_c, u\times n_c]\,[-\hat p, n_b, -\hat p\times n_b]^T` of :func:`earth_scene`."""
    z = np.array([0.0, 0.0, 1.0])
    n_b = z - (z @ ph_hat) * ph_hat
    n_b /= np.linalg.norm(n_b)
    Bc = np.column_stack([u, n_c, np.cross(u, n_c)])
    Bb = np.column_stack([-ph_hat, n_b, np.cross(-ph_hat, n_b)])
    return Bc @ Bb.T
