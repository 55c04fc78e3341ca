r"""The measurement of one frame and its model: body-centre pixel and apparent size from the state and the camera.

``locate`` reports, per frame, the image of the body centre ``(center_r, center_c)`` and either the
on-axis-equivalent radius ``X = f tan(alpha)`` (px; a sphere, the Moon) or the range ``X = D`` (km; the
ellipsoid strategy, the Earth), with their 3x3 covariance (:func:`jaxlimb.pipeline.locate`).  The model of
that triple is the whole chain from the state to the pixels, in JAX so that every derivative is autodiff:

* camera frame: ``q = C_ci (s_b - r)`` (``r`` the spacecraft, ``s_b`` the body, geocentric ICRF; ``C_ci``
  inertial -> camera, DESIGN.md);
* pixel of the body centre: normalised ``(x, y) = (q_x, q_y) / q_z``, Brown's first radial term
  ``(x, y) (1 + k1 (x^2 + y^2))`` and ``(row, col) = (r_c + f y_d, c_c + f x_d)`` (:mod:`jaxlimb.geometry.camera`);
* apparent size: ``alpha = asin(R / |q|)``, the radius ``f tan(alpha)`` (Eq. 36 of the Aerospace 2015 Moon
  paper) scaled by ``1 + 2 k1 rho^2`` (the mean of the radial, ``1 + 3 k1 rho^2``, and tangential,
  ``1 + k1 rho^2``, stretch of the lens at the centre, to first order in ``k1``); a range reported by
  ``locate`` with the nominal focal length ``f_0`` is that radius turned back into a range with ``f_0``:
  ``R / sin(atan(f tan(alpha) / f_0))`` (``= |q|`` when ``f = f_0``).

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
    f_nominal : (n,) focal length (px) ``locate`` used (turns a range back into an apparent size).
    theta : (n, 4) the nominal camera of each frame (``CAMERA_PARAMS``).
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
    f_nominal: np.ndarray
    theta: np.ndarray
    attitude_sigma: np.ndarray
    labels: tuple[str, ...]
    sun_pos: np.ndarray | None = None
    R_noise: np.ndarray | None = None

    def __len__(self) -> int:
        return int(self.t.shape[0])

    def arrays(self) -> tuple[jax.Array, ...]:
        """The per-frame arrays in the order :func:`predict` takes them (after the state and ``theta``)."""
        return tuple(jnp.asarray(a) for a in (self.C, self.body_pos, self.radius_km, self.is_range, self.f_nominal))

    def subset(self, idx) -> Frames:
        """The frames ``idx`` (an index array or a boolean mask)."""
        idx = np.asarray(idx)
        opt = {k: None if getattr(self, k) is None else getattr(self, k)[idx] for k in ("sun_pos", "R_noise")}
        return Frames(*(getattr(self, k)[idx] for k in ("t", "z", "R", "C", "body_pos", "radius_km", "is_range",
                                                         "f_nominal", "theta", "attitude_sigma")),
                      labels=tuple(np.asarray(self.labels, dtype=object)[idx]), **opt)


def predict(r: jax.Array, theta: jax.Array, C: jax.Array, body_pos: jax.Array, radius_km: jax.Array,
            is_range: jax.Array, f_nominal: jax.Array, sun_pos: jax.Array | None = None,
            bias: jax.Array | None = None) -> jax.Array:
    """Predicted ``(center_r, center_c, X)`` of one frame (module docstring); with ``bias = (b_sun, b_scale)``
    and ``sun_pos``, the body's biased image (:func:`jaxlimb.track.bias.sun_direction_px`)."""
    f, rc, cc, k1 = theta[0], theta[1], theta[2], theta[3]
    q = C @ (body_pos - r)
    x, y = q[0] / q[2], q[1] / q[2]
    rho2 = x * x + y * y
    d = 1.0 + k1 * rho2
    D = jnp.linalg.norm(q)
    size = f * jnp.tan(jnp.arcsin(radius_km / D)) * (1.0 + 2.0 * k1 * rho2)
    centre = jnp.stack([rc + f * y * d, cc + f * x * d])
    if bias is not None:  # a centre offset along the Sun's image direction (a fraction of the radius), a size scale
        centre = centre + bias[0] * size * sun_direction_px(q, C @ (sun_pos - r))
        size = size * (1.0 + bias[1])
    rng = radius_km / jnp.sin(jnp.arctan(size / f_nominal))
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


def frames_from_records(records: list[dict], arc, camera, *, attitude_sigma_rad: float = 0.0) -> Frames:
    """Frames from per-frame records ``{"image", "t_s", "C_ci", "body", "measurement"}`` (``measurement``: the
    ``locate --json`` object).  Records whose measurement is not ``ok`` are left out by the caller."""
    rows = []
    theta0 = camera_theta(camera)
    for rec in records:
        m, body = rec["measurement"], rec["body"]
        if body not in BODY_RADIUS_KM:
            raise ConfigError(f"track measures the Moon and the Earth, got body {body!r}")
        third = "range_km" if body == "earth" else "radius"
        names = ("center_r", "center_c", third)
        cov = _block(m["covariance"], names)
        if cov is None:
            raise ConfigError(f"frame {rec['image']!r}: the measurement has no covariance of {list(names)}")
        X = m["range_km"] if body == "earth" else m["radius_px"]
        rows.append((rec["t_s"], [m["center_rc"][0], m["center_rc"][1], X], cov, rec["C_ci"], body, rec["image"],
                     noise_covariance(m, names)))
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
                  f_nominal=np.full(n, theta0[0]), theta=np.tile(theta0, (n, 1)),
                  attitude_sigma=np.full(n, float(attitude_sigma_rad)), labels=tuple(row[5] for row in rows),
                  sun_pos=sun, R_noise=noise)


def single_frame_position(frames: Frames, k: int) -> np.ndarray:
    """The spacecraft position (km) from frame ``k`` alone: the body-centre line of sight of the pixel and the
    range of the apparent size, inverted through the pinhole part of the model (initial orbit determination)."""
    f, rc, cc, _ = frames.theta[k]
    row, col, X = frames.z[k]
    u = np.array([(col - cc) / f, (row - rc) / f, 1.0])
    u /= np.linalg.norm(u)
    D = X if frames.is_range[k] else frames.radius_km[k] / math.sin(math.atan(X / f))
    return frames.body_pos[k] - frames.C[k].T @ (D * u)


__all__ = ["BODY_RADIUS_KM", "CAMERA_PARAMS", "EARTH_RADIUS_KM", "MOON_RADIUS_KM", "Frames", "attitude_jacobian",
           "camera_theta", "frames_from_records", "noise_covariance", "predict", "single_frame_position", "sun_direction_px",
           "total_covariance"]
