r"""The measurement of one frame and its model: body-centre pixel and apparent size from the state and the camera.

``locate`` reports, per frame, the image of the body centre ``(center_r, center_c)`` and either the
on-axis-equivalent radius ``X = f tan(alpha)`` (px; a sphere, the Moon) or the range ``X = D`` (km; the
ellipsoid strategy, the Earth), with their 3x3 covariance (:func:`jaxlimb.pipeline.locate`).  The model of
that triple is the whole chain from the state to the pixels, in JAX so that every derivative is autodiff:

* camera frame: ``q = C_ci (s_b - r)`` (``r`` the spacecraft, ``s_b`` the body, geocentric ICRF; ``C_ci``
  inertial -> camera, DESIGN.md);
* the limb of the sphere of radius ``R`` seen along ``q`` through the camera ``theta``: with ``(x, y) = (q_x, q_y)
  / q_z``, ``t^2 = x^2 + y^2``, ``s = R / |q| = sin(alpha)`` and ``w = 1 - s^2 (1 + t^2)``, an ellipse of centre
  ``(x, y) / w`` and radial semi-axis ``s cos(alpha) (1 + t^2) / w`` (focal units; :mod:`jaxlimb.geometry.
  sphere_image`, written with ``tan(theta) = t``), with Brown's first radial term ``k1`` stretching its centre by
  ``1 + k1 rho^2`` and its size by ``1 + 2 k1 rho^2`` (the mean of the radial, ``1 + 3 k1 rho^2``, and tangential,
  ``1 + k1 rho^2``, stretch at the centre, to first order in ``k1``);
* what ``locate`` reports from that ellipse with *its* camera ``theta_l`` (the one it was given, which
  self-calibration says is wrong): the lens undone with ``theta_l``'s ``k1``, the sphere whose limb is the ellipse
  under ``theta_l`` (:func:`jaxlimb.geometry.sphere_image.sphere_from_ellipse_center`, here in closed form and
  JAX, :func:`_sphere_of_limb`), its body-centre pixel ``pp_l + f_l (x', y') (1 + k1_l rho'^2)`` and its
  on-axis-equivalent radius ``f_l tan(alpha')`` (Eq. 36 of the Aerospace 2015 Moon paper) or range
  ``R / sin(alpha')`` (the Earth).  With ``theta = theta_l`` this is the pixel ``pp + f (x, y) (1 + k1 rho^2)``,
  ``f tan(alpha)`` and ``|q|``; with a wrong ``theta_l`` it is what ``locate`` measured: the off-axis correction
  from the ellipse centre to the body centre (``f tan(theta) sin^2(alpha)``, up to 0.4 px on a Moon 45 px across
  and 180 px off the boresight) made with the wrong camera leaks ``sin^2(alpha)`` of a principal-point error into
  every centre, which a model that left it out would read as that much of the principal point.

Camera parameters ``theta = (f, r_c, c_c, k1)`` (px, px, px, 1) enter only here; they are estimated by
:func:`jaxlimb.track.batch.fit_arc` (self-calibration).

Attitude error.  ``C_est = (I - [dphi x]) C_ci`` with ``dphi ~ N(0, sigma_att^2 I)`` adds
``J_phi sigma_att^2 J_phi^T`` to the measurement covariance, ``J_phi = dh/d(dphi)`` by autodiff at the
predicted state (first order; Mortari et al. §II's attitude term of the observer position, written in
pixels).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import jax
import jax.numpy as jnp
import numpy as np

from ..errors import ConfigError

MOON_RADIUS_KM = 1737.4
EARTH_RADIUS_KM = 6378.137
BODY_RADIUS_KM = {"moon": MOON_RADIUS_KM, "earth": EARTH_RADIUS_KM}
#: Names of the camera parameters, in the order of ``theta``.
CAMERA_PARAMS = ("focal_px", "principal_r", "principal_c", "k1")


def camera_theta(camera) -> np.ndarray:
    """``theta = (f_px, r_c, c_c, k1)`` of a :class:`~jaxlimb.geometry.camera.Camera` (the other distortion terms
    must be zero: the model carries the first radial term only)."""
    if any(getattr(camera, k) != 0.0 for k in ("k2", "k3", "p1", "p2")):
        raise ConfigError("track models the first radial distortion term only; the camera has k2, k3, p1 or p2")
    r0, c0 = camera.principal_point_rc
    return np.array([camera.focal_px, r0, c0, camera.k1], float)


@dataclass(frozen=True)
class Frames:
    """The measurements of a sequence, as arrays (one row per frame, sorted by time).

    Attributes
    ----------
    t : (n,) seconds after the arc's reference epoch (TDB).
    z : (n, 3) ``(center_r, center_c, X)``.
    R : (n, 3, 3) covariance of ``z`` from ``locate`` (px^2; km^2 and px km for a range).
    C : (n, 3, 3) attitude ``C_ci`` (inertial -> camera).
    body_pos : (n, 3) geocentric position of the imaged body (km).
    radius_km : (n,) its radius (Moon 1737.4; the Earth's equatorial 6378.137 km).
    is_range : (n,) 1.0 where ``X`` is a range (km), 0.0 where it is a radius (px).
    theta_locate : (n, 4) the camera ``locate`` measured each frame with (``CAMERA_PARAMS``).
    theta : (n, 4) the camera the estimator is told (``CAMERA_PARAMS``; its start when it calibrates).
    attitude_sigma : (n,) per-axis attitude error (rad, 1 sigma).
    labels : frame names (image paths).
    sun_pos : (n, 3) geocentric position of the Sun (km), or ``None``: the direction of the bodies' phase offset
        (:mod:`jaxlimb.track.bias`).
    R_noise : (n, 3, 3) the noise-only part of ``R`` (``locate``'s Cramér--Rao bound with its correlations,
        :func:`noise_covariance`), or ``None``: ``R - R_noise``
        is the model-error part that sizes the bias states (:mod:`jaxlimb.track.bias`).
    """

    t: np.ndarray
    z: np.ndarray
    R: np.ndarray
    C: np.ndarray
    body_pos: np.ndarray
    radius_km: np.ndarray
    is_range: np.ndarray
    theta_locate: np.ndarray
    theta: np.ndarray
    attitude_sigma: np.ndarray
    labels: tuple[str, ...]
    sun_pos: np.ndarray | None = None
    R_noise: np.ndarray | None = None

    def __len__(self) -> int:
        return int(self.t.shape[0])

    def arrays(self) -> tuple[jax.Array, ...]:
        """The per-frame arrays in the order :func:`predict` takes them (after the state and ``theta``)."""
        return tuple(jnp.asarray(a) for a in (self.C, self.body_pos, self.radius_km, self.is_range, self.theta_locate))

    def subset(self, idx) -> Frames:
        """The frames ``idx`` (an index array or a boolean mask)."""
        idx = np.asarray(idx)
        opt = {k: None if getattr(self, k) is None else getattr(self, k)[idx] for k in ("sun_pos", "R_noise")}
        return Frames(*(getattr(self, k)[idx] for k in ("t", "z", "R", "C", "body_pos", "radius_km", "is_range",
                                                         "theta_locate", "theta", "attitude_sigma")),
                      labels=tuple(np.asarray(self.labels, dtype=object)[idx]), **opt)


def _limb_ellipse(xy: jax.Array, s: jax.Array, theta: jax.Array) -> tuple[jax.Array, jax.Array]:
    """Pixel centre ``(row, col)`` and radial semi-axis (px) of the limb of a sphere of ``sin(alpha) = s`` whose
    centre has normalised image ``xy = (x, y)``, through ``theta`` with its lens (module docstring)."""
    w1 = 1.0 + xy @ xy
    den = 1.0 - s * s * w1
    e = xy / den
    lens = theta[3] * (e @ e)
    a = s * jnp.sqrt(1.0 - s * s) * w1 / den * (1.0 + 2.0 * lens)
    return theta[1:3] + theta[0] * e[::-1] * (1.0 + lens), theta[0] * a


def _sphere_of_limb(centre: jax.Array, a_px: jax.Array, theta: jax.Array) -> tuple[jax.Array, jax.Array]:
    """Normalised body-centre image ``(x, y)`` and ``tan(alpha)`` of the sphere whose limb is the ellipse
    ``(centre, a_px)`` through ``theta`` (its lens undone first, to first order).

    The radial ends of the limb are the images of the rays at ``theta_b +- alpha`` (:func:`jaxlimb.geometry.camera.
    sphere_image_ellipse`): ``tan(theta_b +- alpha) = k +- A`` (``k`` the ellipse centre's distance from the
    principal point, ``A`` the radial semi-axis, focal units), so ``2 theta_b`` and ``2 alpha`` are the angles whose
    tangents are ``2k / (1 - k^2 + A^2)`` and ``2A / (1 + k^2 - A^2)``; the half-angle formula gives both tangents
    in closed form, ``tan(theta_b) / k`` without dividing by ``k`` (the map of
    :func:`jaxlimb.geometry.sphere_image.sphere_from_ellipse_center`, there by Newton)."""
    e = (centre - theta[1:3])[::-1] / theta[0]
    lens = theta[3] * (e @ e)
    e = e * (1.0 - lens)
    A = a_px / theta[0] * (1.0 - 2.0 * lens)
    k2, A2 = e @ e, A * A
    u, v = 1.0 - k2 + A2, 1.0 + k2 - A2
    t_over_k = 2.0 / (u + jnp.sqrt(u * u + 4.0 * k2))
    return e * t_over_k, 2.0 * A / (v + jnp.sqrt(v * v + 4.0 * A2))


def predict(r: jax.Array, theta: jax.Array, C: jax.Array, body_pos: jax.Array, radius_km: jax.Array,
            is_range: jax.Array, theta_locate: jax.Array, sun_pos: jax.Array | None = None,
            bias: jax.Array | None = None) -> jax.Array:
    """Predicted ``(center_r, center_c, X)`` of one frame as ``locate`` with ``theta_locate`` reports it (module
    docstring); with ``bias = (b_sun, b_scale)`` and ``sun_pos``, the body's biased image
    (:func:`jaxlimb.track.bias.sun_direction_px`)."""
    q = C @ (body_pos - r)
    D = jnp.linalg.norm(q)
    s = radius_km / D
    centre, a = _limb_ellipse(q[:2] / q[2], s, theta)
    f = theta_locate[0]
    xy, tan_alpha = _sphere_of_limb(centre, a, theta_locate)
    centre = theta_locate[1:3] + f * xy[::-1] * (1.0 + theta_locate[3] * (xy @ xy))
    size = f * tan_alpha
    if bias is not None:  # a centre offset along the Sun's image direction (a fraction of the radius), a size scale
        centre = centre + bias[0] * size * sun_direction_px(q, C @ (sun_pos - r))
        size = size * (1.0 + bias[1])
    rng = radius_km / jnp.sin(jnp.arctan(size / f))
    return jnp.concatenate([centre, jnp.where(is_range > 0, rng, size)[None]])


def sun_direction_px(q_body: jax.Array, q_sun: jax.Array) -> jax.Array:
    """Unit ``(row, col)`` direction of the Sun in the image about a body seen along ``q_body`` (camera frame):
    the Sun's direction ``q_sun`` with its component along the line of sight removed."""
    u = q_body / jnp.linalg.norm(q_body)
    s = q_sun / jnp.linalg.norm(q_sun)
    p = s - jnp.dot(s, u) * u
    d = jnp.stack([p[1], p[0]])
    return d / jnp.linalg.norm(d)


def attitude_jacobian(r: jax.Array, theta: jax.Array, C: jax.Array, *rest: jax.Array) -> jax.Array:
    """``dh / d(dphi)`` (3x3) for ``C_est = (I - [dphi x]) C`` (module docstring)."""

    def h(phi: jax.Array) -> jax.Array:
        S = jnp.array([[0.0, -phi[2], phi[1]], [phi[2], 0.0, -phi[0]], [-phi[1], phi[0], 0.0]])
        return predict(r, theta, (jnp.eye(3) - S) @ C, *rest)

    return jax.jacfwd(h)(jnp.zeros(3))


def total_covariance(r: jax.Array, theta: jax.Array, R: jax.Array, att_sigma: jax.Array, C: jax.Array,
                     *rest: jax.Array) -> jax.Array:
    """``R + sigma_att^2 J_phi J_phi^T`` (module docstring)."""
    J = attitude_jacobian(r, theta, C, *rest)
    return R + att_sigma**2 * J @ J.T


def _block(cov: dict, names: tuple[str, ...]) -> np.ndarray | None:
    """The rows and columns ``names`` of a ``{name: {name: value}}`` covariance, or ``None`` if one is missing."""
    if not all(a in cov and all(b in cov[a] for b in names) for a in names):
        return None
    return np.array([[cov[a][b] for b in names] for a in names], float)


def noise_covariance(measurement: dict, names: tuple[str, ...]) -> np.ndarray | None:
    """The noise-only part of a ``locate`` answer's covariance over ``names``: its ``covariance_noise`` (the
    Cramér--Rao bound with its correlations), or from an answer without it the bound's variances alone; ``None``
    without either.

    Parameters
    ----------
    measurement : dict
        The ``locate --json`` object.
    names : tuple of str
        Its rows, e.g. ``("center_r", "center_c", "range_km")``.

    Returns
    -------
    np.ndarray (len(names), len(names)) or None
    """
    full = _block(measurement.get("covariance_noise") or {}, names)
    if full is not None:
        return full
    crlb = measurement.get("crlb") or {}
    return np.diag([crlb[a] ** 2 for a in names]) if all(a in crlb for a in names) else None


def frame_covariances(measurement: dict, names: tuple[str, ...], X: float | None,
                      label: str) -> tuple[np.ndarray, np.ndarray | None]:
    """A frame's covariance of ``(center_r, center_c, X)`` and its noise-only part (:func:`noise_covariance`).

    A measurement of the centre alone (``locate``'s centre of brightness on a disc of a few pixels carries no size
    covariance) keeps its centre: ``X`` gets the variance ``(10 X)^2``, a size known to a factor of ten, which
    holds no information on the range (its weight in the state is 1e-4 of a 10 % size), in both parts, so its
    model-error part is zero.

    Raises
    ------
    ConfigError
        Neither the 3x3 nor the centre's 2x2 covariance, or no size at all.
    """
    cov = _block(measurement["covariance"], names)
    if cov is not None:
        return cov, noise_covariance(measurement, names)
    centre = _block(measurement["covariance"], names[:2])
    if centre is None or X is None or not X > 0:
        raise ConfigError(f"frame {label!r}: the measurement has no covariance of {list(names)}")
    vague = (10.0 * X) ** 2
    noise = noise_covariance(measurement, names[:2])
    return (np.block([[centre, np.zeros((2, 1))], [np.zeros((1, 2)), np.array([[vague]])]]),
            None if noise is None else np.block([[noise, np.zeros((2, 1))], [np.zeros((1, 2)), np.array([[vague]])]]))


def frames_from_records(records: list[dict], arc, camera, *, attitude_sigma_rad: float = 0.0) -> Frames:
    """Frames from per-frame records ``{"image", "t_s", "C_ci", "body", "measurement"}`` (``measurement``: the
    ``locate --json`` object).  Records whose measurement is not ``ok`` are left out by the caller."""
    rows = []
    theta0 = camera_theta(camera)
    for rec in records:
        m, body = rec["measurement"], rec["body"]
        if body not in BODY_RADIUS_KM:
            raise ConfigError(f"track measures the Moon and the Earth, got body {body!r}")
        X = m.get("range_km") if body == "earth" else m.get("radius_px")
        cov, noise = frame_covariances(m, ("center_r", "center_c", "range_km" if body == "earth" else "radius"), X,
                                       rec["image"])
        rows.append((rec["t_s"], [m["center_rc"][0], m["center_rc"][1], X], cov, rec["C_ci"], body, rec["image"], noise))
    rows.sort(key=lambda row: row[0])
    t = np.array([row[0] for row in rows], float)
    bodies = [row[4] for row in rows]
    body_pos = np.stack([arc.body_position(b, np.array([ti]))[0] for b, ti in zip(bodies, t)]) if rows else np.zeros((0, 3))
    n = len(rows)
    noise = None if any(row[6] is None for row in rows) or not rows else np.array([row[6] for row in rows], float)
    sun = arc.body_position("sun", t) if rows else None
    return Frames(t=t, z=np.array([row[1] for row in rows], float).reshape(n, 3),
                  R=np.array([row[2] for row in rows], float).reshape(n, 3, 3),
                  C=np.array([row[3] for row in rows], float).reshape(n, 3, 3), body_pos=body_pos,
                  radius_km=np.array([BODY_RADIUS_KM[b] for b in bodies], float),
                  is_range=np.array([1.0 if b == "earth" else 0.0 for b in bodies]),
                  theta_locate=np.tile(theta0, (n, 1)), theta=np.tile(theta0, (n, 1)),
                  attitude_sigma=np.full(n, float(attitude_sigma_rad)), labels=tuple(row[5] for row in rows),
                  sun_pos=sun, R_noise=noise)


def single_frame_position(frames: Frames, k: int) -> np.ndarray:
    """The spacecraft position (km) from frame ``k`` alone: the body-centre line of sight of the pixel and the
    range of the apparent size, inverted through the pinhole part of ``locate``'s camera (initial orbit determination)."""
    f, rc, cc, _ = frames.theta_locate[k]
    row, col, X = frames.z[k]
    u = np.array([(col - cc) / f, (row - rc) / f, 1.0])
    u /= np.linalg.norm(u)
    D = X if frames.is_range[k] else frames.radius_km[k] / math.sin(math.atan(X / f))
    return frames.body_pos[k] - frames.C[k].T @ (D * u)


__all__ = ["BODY_RADIUS_KM", "CAMERA_PARAMS", "EARTH_RADIUS_KM", "MOON_RADIUS_KM", "Frames", "attitude_jacobian",
           "camera_theta", "frame_covariances", "frames_from_records", "noise_covariance", "predict",
           "single_frame_position", "sun_direction_px", "total_covariance"]
