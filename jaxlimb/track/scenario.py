r"""A cislunar transfer to test the estimators on: the true trajectory, the pointing of each frame, and
measurements drawn from a stated noise model.

The transfer starts ``start_radius_km`` from the Earth on an outbound coast whose end, ``duration_days`` later,
is ``flyby_km`` from the Moon (perpendicular to the Earth--Moon line, in the Moon's orbital plane): the
initial velocity is found by shooting with optimistix's Levenberg--Marquardt through the full dynamics of
:mod:`jaxlimb.track.dynamics`, from the two-body ellipse whose apogee is the target.  Frames alternate between
the Earth and the Moon; each is pointed so that the body's centre falls at a random pixel within
``max_offset_frac`` of the half-frame (minus the body's radius and a margin), with a random roll about the
line of sight: off-axis bodies are what make the focal length and the principal point observable
(:mod:`jaxlimb.track.batch`).  The attitude the estimator receives is the true one rotated by a random vector of
``attitude_sigma_rad`` per axis.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import jax.numpy as jnp
import numpy as np
import optimistix as optx

from ..errors import ConvergenceError
from .dynamics import GM_EARTH, Arc, Propagator
from .measurement import BODY_RADIUS_KM, Frames, predict


@dataclass(frozen=True)
class Transfer:
    """A true trajectory and the frames' geometry.

    Attributes
    ----------
    arc, prop : the time frame and the dynamics.
    t : (n,) frame times (s after ``arc.jd0``); states : (n, 6) the true states there.
    x0 : the true state at ``t = 0``.
    bodies : the body of each frame; C_true : (n, 3, 3) true attitudes ``C_ci``; theta : the true camera.
    rows, cols : the frame size.
    """

    arc: Arc
    prop: Propagator
    t: np.ndarray
    states: np.ndarray
    x0: np.ndarray
    bodies: tuple[str, ...]
    C_true: np.ndarray
    theta: np.ndarray
    rows: int
    cols: int

    def body_positions(self) -> np.ndarray:
        return np.stack([self.arc.body_position(b, np.array([t]))[0] for b, t in zip(self.bodies, self.t)])


def _shoot(prop: Propagator, r0: np.ndarray, v_guess: np.ndarray, t1: float, target: np.ndarray) -> np.ndarray:
    def res(v, _):  # noqa: ANN001, ANN202
        return (prop.step(jnp.concatenate([jnp.asarray(r0), v]), jnp.asarray(0.0), jnp.asarray(t1))[:3] - target) / 1e3

    sol = optx.least_squares(res, optx.LevenbergMarquardt(rtol=1e-12, atol=1e-9), jnp.asarray(v_guess), max_steps=200,
                             throw=False)
    if sol.result != optx.RESULTS.successful:
        raise ConvergenceError("the transfer's shooting did not converge")
    return np.asarray(sol.value)


def transfer_initial_state(arc: Arc, prop: Propagator, *, duration_days: float = 3.5, start_radius_km: float = 100_000.0,
                           flyby_km: float = 40_000.0) -> np.ndarray:
    """The initial state (t = 0) of the transfer (module docstring)."""
    T = duration_days * 86400.0
    m1 = arc.body_position("moon", np.array([T]))[0]
    m0 = arc.body_position("moon", np.array([T - 3600.0]))[0]
    h = np.cross(m0, m1)
    side = np.cross(h, m1)
    target = m1 + flyby_km * side / np.linalg.norm(side)
    ra, rp = float(np.linalg.norm(target)), 7000.0
    a, e = 0.5 * (ra + rp), (ra - rp) / (ra + rp)
    p = a * (1 - e * e)
    nu = math.acos(max(-1.0, min(1.0, (p / start_radius_km - 1) / e)))  # outbound true anomaly at the start
    ex = -target / ra  # perigee direction
    ey = np.cross(h / np.linalg.norm(h), ex)
    r0 = start_radius_km * (math.cos(nu) * ex + math.sin(nu) * ey)
    vr, vt = math.sqrt(GM_EARTH / p) * e * math.sin(nu), math.sqrt(GM_EARTH / p) * (1 + e * math.cos(nu))
    v_guess = vr * r0 / start_radius_km + vt * (-math.sin(nu) * ex + math.cos(nu) * ey)
    return np.concatenate([r0, _shoot(prop, r0, v_guess, T, target)])


def _rotation_about(u: np.ndarray, angle: float) -> np.ndarray:
    K = np.array([[0, -u[2], u[1]], [u[2], 0, -u[0]], [-u[1], u[0], 0]])
    return np.eye(3) + math.sin(angle) * K + (1 - math.cos(angle)) * K @ K


def point_at(q_inertial: np.ndarray, offset_rc: tuple[float, float], theta: np.ndarray, roll: float) -> np.ndarray:
    """``C_ci`` that images the inertial direction ``q_inertial`` at ``principal point + offset_rc`` (pinhole),
    rolled by ``roll`` (rad) about it."""
    f, rc, cc, _ = theta
    d = np.array([offset_rc[1] / f, offset_rc[0] / f, 1.0])
    d /= np.linalg.norm(d)
    u = q_inertial / np.linalg.norm(q_inertial)
    ref = np.array([0.0, 0.0, 1.0]) if abs(u[2]) < 0.9 else np.array([1.0, 0.0, 0.0])
    a = np.cross(ref, u)
    a /= np.linalg.norm(a)
    B_in = np.column_stack([u, a, np.cross(u, a)])  # inertial basis with u first
    e = np.array([1.0, 0.0, 0.0]) - d[0] * d
    e /= np.linalg.norm(e)
    B_cam = np.column_stack([d, e, np.cross(d, e)])
    return _rotation_about(d, roll) @ B_cam @ B_in.T


def make_transfer(arc: Arc, prop: Propagator, n_frames: int, theta: np.ndarray, rows: int, cols: int, *,
                  rng: np.random.Generator, duration_days: float = 3.5, max_offset_frac: float = 0.8,
                  margin_px: float = 14.0, **kw) -> Transfer:
    """The transfer with ``n_frames`` frames evenly spaced over ``duration_days`` (module docstring)."""
    x0 = transfer_initial_state(arc, prop, duration_days=duration_days, **kw)
    t = np.linspace(0.0, duration_days * 86400.0, n_frames)
    X = np.asarray(prop.trajectory(jnp.asarray(x0), jnp.asarray(0.0), jnp.asarray(t)))
    bodies = tuple("earth" if k % 2 == 0 else "moon" for k in range(n_frames))
    Cs = []
    for k, b in enumerate(bodies):
        q = arc.body_position(b, t[k : k + 1])[0] - X[k, :3]
        R_px = theta[0] * math.tan(math.asin(BODY_RADIUS_KM[b] / np.linalg.norm(q)))
        half = max(0.0, (min(rows, cols) / 2 - R_px - margin_px) * max_offset_frac)
        rad, ang = half * math.sqrt(rng.uniform()), rng.uniform(0, 2 * math.pi)
        Cs.append(point_at(q, (rad * math.sin(ang), rad * math.cos(ang)), theta, rng.uniform(0, 2 * math.pi)))
    return Transfer(arc, prop, t, X, x0, bodies, np.array(Cs), np.asarray(theta, float), rows, cols)


def perturb_attitudes(C: np.ndarray, sigma_rad: float, rng: np.random.Generator) -> np.ndarray:
    """``(I - [dphi x]) C`` made orthonormal (the exact rotation), ``dphi ~ N(0, sigma^2 I)`` per frame."""
    out = []
    for Ck in C:
        phi = sigma_rad * rng.standard_normal(3)
        ang = float(np.linalg.norm(phi))
        out.append((_rotation_about(phi / ang, -ang) if ang > 0 else np.eye(3)) @ Ck)
    return np.array(out)


def true_measurements(tr: Transfer, theta_locate: np.ndarray | None = None) -> np.ndarray:
    """``h`` of every frame at the truth (true camera and attitude), as ``locate`` given the camera ``theta_locate``
    (default the true one) reports it."""
    bp = tr.body_positions()
    th0 = jnp.asarray(tr.theta if theta_locate is None else theta_locate)
    return np.array([np.asarray(predict(jnp.asarray(tr.states[k, :3]), jnp.asarray(tr.theta), jnp.asarray(tr.C_true[k]),
                                        jnp.asarray(bp[k]), BODY_RADIUS_KM[b], 1.0 if b == "earth" else 0.0, th0))
                     for k, b in enumerate(tr.bodies)])


def drawn_frames(tr: Transfer, R: np.ndarray, rng: np.random.Generator, *, attitude_sigma_rad: float = 1e-5,
                 theta_nominal: np.ndarray | None = None) -> Frames:
    """Frames whose measurements are the truth plus noise drawn from ``R`` (n, 3, 3), with attitudes
    perturbed by ``attitude_sigma_rad``; ``theta_nominal`` is the camera the estimator is told (default: the
    true one)."""
    th = tr.theta if theta_nominal is None else np.asarray(theta_nominal, float)
    z = true_measurements(tr, th)
    z = z + np.einsum("kij,kj->ki", np.linalg.cholesky(R), rng.standard_normal(z.shape))
    n = len(tr.t)
    return Frames(t=tr.t.copy(), z=z, R=np.asarray(R, float), C=perturb_attitudes(tr.C_true, attitude_sigma_rad, rng),
                  body_pos=tr.body_positions(), radius_km=np.array([BODY_RADIUS_KM[b] for b in tr.bodies]),
                  is_range=np.array([1.0 if b == "earth" else 0.0 for b in tr.bodies]), theta_locate=np.tile(th, (n, 1)),
                  theta=np.tile(th, (n, 1)), attitude_sigma=np.full(n, attitude_sigma_rad),
                  labels=tuple(f"frame{k:04d}" for k in range(n)))


def nominal_noise(tr: Transfer, sigma_center_px: float = 0.03, sigma_size_px: float = 0.03) -> np.ndarray:
    """A simple measurement covariance per frame: ``sigma_center_px`` on the centre, ``sigma_size_px`` on the
    apparent radius (for the Earth mapped to the range: ``D sigma_size / size``)."""
    z = true_measurements(tr)
    out = []
    for k, b in enumerate(tr.bodies):
        if b == "earth":
            size = tr.theta[0] * math.tan(math.asin(BODY_RADIUS_KM[b] / z[k, 2]))
            s3 = z[k, 2] * sigma_size_px / size
        else:
            s3 = sigma_size_px
        out.append(np.diag([sigma_center_px**2, sigma_center_px**2, s3**2]))
    return np.array(out)


__all__ = ["Transfer", "drawn_frames", "make_transfer", "nominal_noise", "perturb_attitudes", "point_at",
           "transfer_initial_state", "true_measurements"]
