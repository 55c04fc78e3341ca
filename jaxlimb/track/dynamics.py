r"""Spacecraft dynamics about the Earth with the Sun and the Moon as third bodies, in JAX (diffrax).

Equations of motion (geocentric ICRF/J2000, km, s; Montenbruck & Gill, *Satellite Orbits*, Springer 2000,
Eq. 3.37)::

    r'' = -mu_E r / |r|^3 + sum_{b in (Moon, Sun)} mu_b [ (s_b - r) / |s_b - r|^3 - s_b / |s_b|^3 ]

with ``s_b(t)`` the geocentric position of body ``b`` from the shipped DE421 ephemeris
(:mod:`jaxlimb.geometry.ephemeris`).  The second term of the bracket is the indirect acceleration of the
geocentric frame.  ``s_b`` is tabulated once per arc with skyfield (positions and velocities at nodes
``step_s`` apart) and interpolated in JAX by cubic Hermite polynomials, so the dynamics are traceable and
differentiable.  The interpolation error is ``~ h^4 |s^{(4)}| / 384``: for the Moon (``|s^{(4)}| ~ n^4 a``,
``n = 2.66e-6 rad/s``) and the default 2-hour nodes it is ``1e-4 km``, far below anything an image measures.

Integration: diffrax's 8th-order Dormand--Prince solver with a PID step-size controller (``rtol = atol =
1e-12`` by default, relative to km and km/s).  State transition matrices are the forward-mode Jacobian of the
propagation, :func:`jax.jacfwd` through the solver (``diffrax.ForwardMode``): no hand-derived partials.

Constants: ``GM`` of the Earth, Moon and Sun from DE421 (Folkner, Williams & Boggs 2009, IPN Progress Report
42-178, Table 4), in km^3/s^2.
"""

from __future__ import annotations

import os
from dataclasses import dataclass

import diffrax
import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from ..errors import ConfigError

GM_EARTH = 398600.435436
GM_MOON = 4902.800066
GM_SUN = 132712440041.939400
_DAY_S = 86400.0


class BodyTable(eqx.Module):
    """Geocentric positions and velocities of the Moon and the Sun at nodes, for Hermite interpolation.

    Attributes
    ----------
    t : (n,) node times, seconds after the arc's reference epoch ``jd0`` (TDB).
    pos : (n, 2, 3) Moon, Sun positions (km, ICRF, geocentric).
    vel : (n, 2, 3) their velocities (km/s).
    """

    t: jax.Array
    pos: jax.Array
    vel: jax.Array

    def positions(self, t: jax.Array) -> jax.Array:
        """``(2, 3)`` Moon and Sun positions at ``t`` (s after ``jd0``), cubic Hermite between nodes."""
        i = jnp.clip(jnp.searchsorted(self.t, t, side="right") - 1, 0, self.t.shape[0] - 2)
        h = self.t[i + 1] - self.t[i]
        s = (t - self.t[i]) / h
        s2, s3 = s * s, s * s * s
        h00, h10 = 2 * s3 - 3 * s2 + 1, s3 - 2 * s2 + s
        h01, h11 = -2 * s3 + 3 * s2, s3 - s2
        return h00 * self.pos[i] + h10 * h * self.vel[i] + h01 * self.pos[i + 1] + h11 * h * self.vel[i + 1]


@dataclass(frozen=True)
class Arc:
    """The time frame of one arc: its reference epoch (TDB Julian date) and the third-body table."""

    jd0: float
    table: BodyTable

    def seconds(self, jd_tdb) -> np.ndarray:
        """Seconds after the reference epoch of TDB Julian dates."""
        return (np.asarray(jd_tdb, float) - self.jd0) * _DAY_S

    def body_position(self, name: str, t_s) -> np.ndarray:
        """Geocentric position (km) of ``"moon"``, ``"sun"`` or ``"earth"`` (zero) at ``t_s`` seconds."""
        t = jnp.asarray(t_s, float)
        if name == "earth":
            return np.zeros(t.shape + (3,))
        k = {"moon": 0, "sun": 1}[name]
        return np.asarray(jax.vmap(self.table.positions)(t.reshape(-1))[:, k].reshape(t.shape + (3,)))


def make_arc(jd_first: float, jd_last: float, *, step_s: float = 7200.0, margin_s: float = 86400.0,
             ephemeris_path: str | os.PathLike[str] | None = None) -> Arc:
    """Tabulate the Moon and the Sun (geocentric, DE421) from ``margin_s`` before ``jd_first`` to ``margin_s``
    after ``jd_last`` (TDB Julian dates), nodes ``step_s`` apart; the reference epoch is ``jd_first``.

    Raises
    ------
    ConfigError
        ``jd_last < jd_first`` or a non-positive step.
    EphemerisError
        The span is outside the kernel (the ephemeris checks it).
    """
    from ..geometry.ephemeris import load_ephemeris

    if not (np.isfinite(jd_first) and np.isfinite(jd_last) and jd_last >= jd_first):
        raise ConfigError(f"arc epochs must be finite and ordered, got {jd_first!r} .. {jd_last!r}")
    if not step_s > 0:
        raise ConfigError(f"`step_s` must be > 0, got {step_s!r}")
    eph = load_ephemeris(ephemeris_path)
    span = (jd_last - jd_first) * _DAY_S + 2 * margin_s
    n = int(np.ceil(span / step_s)) + 1
    t = -margin_s + step_s * np.arange(n)
    eph.time(float(jd_first + t[0] / _DAY_S))
    eph.time(float(jd_first + t[-1] / _DAY_S))  # both ends inside the kernel (EphemerisError otherwise)
    times = eph.timescale.tdb_jd(jd_first + t / _DAY_S)
    earth = eph.kernel["earth"]
    pos, vel = [], []
    for name in ("moon", "sun"):
        st = (eph.kernel[name] - earth).at(times)
        pos.append(np.asarray(st.position.km).T)
        vel.append(np.asarray(st.velocity.km_per_s).T)
    table = BodyTable(jnp.asarray(t), jnp.asarray(np.stack(pos, 1)), jnp.asarray(np.stack(vel, 1)))
    return Arc(float(jd_first), table)


def acceleration(t: jax.Array, r: jax.Array, table: BodyTable) -> jax.Array:
    """Geocentric acceleration (km/s^2) at position ``r`` and time ``t`` (module docstring)."""
    s = table.positions(t)
    a = -GM_EARTH * r / jnp.linalg.norm(r) ** 3
    for k, gm in ((0, GM_MOON), (1, GM_SUN)):
        d = s[k] - r
        a = a + gm * (d / jnp.linalg.norm(d) ** 3 - s[k] / jnp.linalg.norm(s[k]) ** 3)
    return a


def _vector_field(t, y, table):  # noqa: ANN001 - diffrax signature
    return jnp.concatenate([y[3:], acceleration(t, y[:3], table)])


class Propagator(eqx.Module):
    """Numerical propagation of ``(r, v)`` (module docstring) and its state transition matrix.

    Parameters
    ----------
    table
        The third-body table of the arc (:func:`make_arc`).
    rtol, atol
        Step-size controller tolerances.
    max_steps
        Solver step budget per call.
    """

    table: BodyTable
    rtol: float = eqx.field(static=True, default=1e-12)
    atol: float = eqx.field(static=True, default=1e-12)
    max_steps: int = eqx.field(static=True, default=100_000)

    def _solve(self, y0: jax.Array, t0: jax.Array, t1: jax.Array, saveat: diffrax.SaveAt) -> diffrax.Solution:
        return diffrax.diffeqsolve(
            diffrax.ODETerm(_vector_field), diffrax.Dopri8(), t0, t1, None, y0, self.table, saveat=saveat,
            stepsize_controller=diffrax.PIDController(rtol=self.rtol, atol=self.atol, dtmin=1e-3, dtmax=3.0 * _DAY_S,
                                                      force_dtmin=False),
            adjoint=diffrax.ForwardMode(), max_steps=self.max_steps)

    def step(self, y0: jax.Array, t0: jax.Array, t1: jax.Array) -> jax.Array:
        """State at ``t1`` from ``y0`` at ``t0`` (``t1 == t0`` returns ``y0``)."""
        same = t1 == t0
        t1s = jnp.where(same, t0 + 1.0, t1)  # diffrax needs t1 != t0; the result is discarded then
        y1 = self._solve(y0, t0, t1s, diffrax.SaveAt(t1=True)).ys[-1]
        return jnp.where(same, y0, y1)

    def step_with_stm(self, y0: jax.Array, t0: jax.Array, t1: jax.Array) -> tuple[jax.Array, jax.Array]:
        """``(y(t1), Phi(t1, t0))``, ``Phi = d y(t1) / d y0`` by :func:`jax.jacfwd` through the solver."""
        def f(y: jax.Array) -> tuple[jax.Array, jax.Array]:
            y1 = self.step(y, t0, t1)
            return y1, y1

        phi, y1 = jax.jacfwd(f, has_aux=True)(y0)
        return y1, phi

    def trajectory(self, y0: jax.Array, t0: jax.Array, ts: jax.Array) -> jax.Array:
        """States ``(len(ts), 6)`` at the increasing times ``ts >= t0`` from ``y0`` at ``t0``: one solve."""
        t_end = jnp.maximum(ts[-1], t0 + 1.0)
        sol = self._solve(y0, t0, t_end, diffrax.SaveAt(ts=ts))
        return sol.ys


__all__ = ["GM_EARTH", "GM_MOON", "GM_SUN", "Arc", "BodyTable", "Propagator", "acceleration", "make_arc"]
