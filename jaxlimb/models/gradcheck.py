"""Check every limb model's analytic Jacobian against autodiff and central differences.

For each model (the linear, circle and ellipse sigmoids; the elliptical ramp; the lunar-Lambert limb profile and
its widened variants; the limb-darkened disc) we draw random parameter points -- steep and shallow ``k``
(log-uniform over [0.05, 20] 1/px), bright-on-dark and dark-on-bright levels, any orientation, any phase -- and,
for each, pixels inside, outside and on the edge of the limb.  The analytic Jacobian (Eq. 14, Eq. 17, Sec. V-C
of Mortari et al. 2016; the models' own) is compared with ``jax.jacfwd`` of the intensity *as implemented*: the
physical profiles with the fits' own 20-node quadrature (their columns are the derivative of that rule, nodes
moving with the window's ends included: :mod:`jaxlimb.models.blur_quadrature`), so every model is held to 1e-9.

The relative error of an entry is ``|J_an - J_autodiff| / max(|J_autodiff|, floor * c)``, with ``c`` the largest
magnitude in that column at that parameter point and ``floor`` 1e-4 (:class:`_Spec`): an entry four orders of
magnitude below its column is the difference of terms of the column's size, and both Jacobians round those terms
(measured: the limb-darkened disc's ``a`` column at 1.25e-5 of its scale 23, the two Jacobians 1.1e-14 of the
scale apart -- 1.1e-8 of the entry itself; the ramp's ``r0`` at 5e-6 of its scale, 4.2e-15 apart).  So the
tolerance 1e-9 asks every entry to agree to 1e-9 of itself, or to 1e-13 of its column (~500 ulps) where it is a
cancellation.

The central-difference check steps each parameter by ``h_j = 1e-5 (ymax - ymin) / c_j`` (so the intensity moves
by at most 1e-5 of its range) and by ``h_j / 10``, and reports the largest error relative to the column scale ``c_j``
(per pixel the smaller of the two: beside a kink the step does not straddle, a window end about to reach the limb,
the first step's O(h^2) truncation can pass the tolerance, and the second's is a hundredth of it); it is limited by
the truncation and by rounding, ~1e-8.  The limb-darkened disc's intensity is tabulated (its grid moves
with ``a``): its central differences are taken of the direct quadrature at every pixel and measure the table's
own error, up to 2.3e-5 of a column (tolerance 5e-5); its columns are the table's derivative (checked against
autodiff of the table).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import asdict, dataclass
from typing import Any

import math

import jax
import jax.numpy as jnp
import numpy as np

from ._base import LimbModel
from .corona import CORONA, CoronaParams
from .ellipse_ramp import ELLIPSE_RAMP, EllipseRampParams
from .limb_darkened import LIMB_DARKENED, LimbDarkenedParams, limb_darkened_intensity_direct
from .lunar_lambert import (LIMB_PROFILE, LIMB_PROFILE_ANISO, LIMB_PROFILE_GLOW, LIMB_PROFILE_MINNAERT,
                            AnisoProfileParams, GlowProfileParams, LimbProfileParams, MinnaertProfileParams,
                            window_regime)
from .sigmoid import CIRCLE, ELLIPSE, LINEAR, CircleParams, EllipseParams, LinearParams

@dataclass(frozen=True)
class _Spec:
    """How one model is checked: tolerances, the floor of the relative error (a fraction of the column scale, module
    docstring) and the intensity whose central differences are the reference (``None``: the model's)."""

    tol: float = 1e-9
    fd_tol: float = 1e-6
    floor: float = 1e-4
    fd_intensity: Callable[..., Any] | None = None
    regime: Callable[..., Any] | None = None
    """``regime(params, coords) -> (n,) int``: the branch of a piecewise intensity; central differences are compared
    only where it is the same at ``v - e``, ``v`` and ``v + e`` (the step does not straddle a kink)."""


_RULE_FD = _Spec(fd_tol=1e-4, regime=window_regime)
#: Per-model check settings (module docstring): the limb-darkened disc's central differences are taken of the
#: quadrature at every pixel (its tabulated intensity moves its grid with ``a``); the physical profiles' central
#: differences skip the pixels whose window switches branch within the step (:func:`~jaxlimb.models.lunar_lambert.
#: window_regime`: a window end reaching the limb moves the rule's nodes as a square root, a kink of the rule's size
#: that a central difference straddling it measured as up to 0.1 of a column); elsewhere the 20-node rule of a sharp
#: integrand (a glow of scale height 0.1 px) is rough at the scale of the step: 3.3e-5 of a column (tolerance 1e-4).
SPECS: dict[str, _Spec] = {
    "limb_darkened": _Spec(fd_tol=5e-5, fd_intensity=limb_darkened_intensity_direct),
    "lunar_limb": _RULE_FD, "lunar_limb_minnaert": _RULE_FD, "lunar_limb_glow": _RULE_FD, "lunar_limb_aniso": _RULE_FD,
}

@dataclass(frozen=True)
class GradCheck:
    """One row of the report: the worst error of one column over all points."""

    model: str
    param: str
    max_rel_err: float
    max_fd_err: float
    n_points: int
    tol: float = 1e-9
    fd_tol: float = 1e-6

    @property
    def passed(self) -> bool:
        return self.max_rel_err <= self.tol and self.max_fd_err <= self.fd_tol


def _edge_offsets(rng: np.random.Generator, n_pix: int, width: float) -> np.ndarray:
    """Signed distances (px) from the limb: a third inside, a third on the edge, a third outside."""
    return np.concatenate(
        [rng.uniform(-3 * width, -0.5 * width, n_pix // 3),  # inside
         rng.uniform(-0.5 * width, 0.5 * width, n_pix // 3),  # on the edge
         rng.uniform(0.5 * width, 3 * width, n_pix - 2 * (n_pix // 3))]  # outside
    )


def _ellipse_pixels(r0, c0, a, theta, rho, offs, phi) -> np.ndarray:
    """Pixels at "ellipse distance" ``beta = rho a + offs`` along eccentric anomalies ``phi`` (Eq. 20)."""
    scale = (rho * a + offs) / (rho * a)
    x = a * np.cos(phi) * scale
    y = rho * a * np.sin(phi) * scale
    ct, st = np.cos(theta), np.sin(theta)
    return np.stack([r0 - x * st - y * ct, c0 + x * ct - y * st], -1)


def _random_case(model: LimbModel, rng: np.random.Generator, n_pix: int):  # noqa: ANN202
    """A random parameter point and pixels inside / on / outside its limb."""
    if model.name in _PHYSICAL_CASES:
        return _PHYSICAL_CASES[model.name](rng, n_pix)
    k = float(np.exp(rng.uniform(np.log(0.05), np.log(20.0))))
    ymax, ymin = rng.uniform(50, 250), rng.uniform(0, 40)
    if rng.random() < 0.2:  # dark body on a bright sky
        ymax, ymin = ymin, ymax
    width = max(4.0 / k, 1.0)  # the transition is ~4/k px wide
    offs = _edge_offsets(rng, n_pix, width)
    if model.name == "linear":
        xt = rng.uniform(-50, 50)
        return LinearParams(xt, k, ymax, ymin), jnp.asarray(xt + offs)
    radius = rng.uniform(20, 400)
    offs = np.maximum(offs, -0.9 * radius)  # stay away from the centre
    phi = rng.uniform(0, 2 * np.pi, n_pix)
    r0, c0 = rng.uniform(-100, 1000, 2)
    if model.name == "circle":
        d = radius + offs
        rc = np.stack([r0 + d * np.sin(phi), c0 + d * np.cos(phi)], -1)
        return CircleParams(r0, c0, radius, k, ymax, ymin), jnp.asarray(rc)
    rho = rng.uniform(0.5, 1.0)
    theta = rng.uniform(-np.pi, np.pi)
    rc = jnp.asarray(_ellipse_pixels(r0, c0, radius, theta, rho, offs, phi))
    if model.name == "ellipse_ramp":
        g, g2 = rng.uniform(-5, 5), rng.uniform(-10, 10)
        hs = rng.uniform(-0.1, 0.1, 4) * (ymax - ymin)
        return EllipseRampParams(r0, c0, radius, theta, rho, k, ymax, ymin, g, g2, *hs), rc
    return EllipseParams(r0, c0, radius, theta, rho, k, ymax, ymin), rc


def _profile_case(rng: np.random.Generator, n_pix: int):  # noqa: ANN202
    """The lunar-Lambert profile: any size, PSF, phase (to 125 deg), angular radius (to 0.3 rad) and
    ``L``; pixels within 55 deg of the Sun's image direction (the lit limb), +-6 sigma of the edge."""
    a, rho, theta = rng.uniform(30, 400), rng.uniform(0.9, 1.0), rng.uniform(-np.pi, np.pi)
    sigma = rng.uniform(0.3, 2.0)
    r0, c0 = rng.uniform(-100, 1000, 2)
    phi_sun = rng.uniform(-np.pi, np.pi)
    phi = phi_sun + rng.uniform(-np.radians(55), np.radians(55), n_pix)
    se = math.sqrt(sigma * sigma + 1.0 / 12.0)
    offs = np.maximum(rng.uniform(-6 * se, 6 * se, n_pix), -0.9 * rho * a)
    rc = _ellipse_pixels(r0, c0, a, theta, rho, offs, phi)
    # the Sun's image direction: the mean direction of the pixels from the centre
    d = np.mean(rc - np.array([r0, c0]), axis=0)
    d /= np.linalg.norm(d)
    inv_f = math.tan(rng.uniform(1e-3, 0.3)) / (rho * a)
    p = LimbProfileParams(r0, c0, a, theta, rho, sigma, rng.uniform(50, 250), rng.uniform(0, 40), d[0], d[1],
                          rng.uniform(0.0, np.radians(125)), inv_f, rng.uniform(0, 1), rng.uniform(-1.5, 0.5),
                          rng.uniform(0, 1))
    return p, jnp.asarray(rc)


def _limb_darkened_case(rng: np.random.Generator, n_pix: int):  # noqa: ANN202
    """The limb-darkened disc: any size, PSF and quadratic coefficients; pixels all round the limb."""
    a, sigma = rng.uniform(30, 400), rng.uniform(0.2, 2.0)
    r0, c0 = rng.uniform(-100, 1000, 2)
    offs = _edge_offsets(rng, n_pix, 2.0 * math.sqrt(sigma * sigma + 1.0 / 12.0))
    phi = rng.uniform(0, 2 * np.pi, n_pix)
    d = a + offs
    rc = np.stack([r0 + d * np.sin(phi), c0 + d * np.cos(phi)], -1)
    p = LimbDarkenedParams(r0, c0, a, sigma, rng.uniform(50, 250), rng.uniform(0, 40), rng.uniform(0.2, 0.8),
                           rng.uniform(-0.3, 0.4))
    return p, jnp.asarray(rc)


def _corona_case(rng: np.random.Generator, n_pix: int):  # noqa: ANN202
    """The EUV limb: any size, PSF 0-2 px, scale height 0.3-8 px, disc level up to 0.4 of the corona's."""
    a, sigma = rng.uniform(30, 400), rng.uniform(0.0, 2.0)
    r0, c0 = rng.uniform(-100, 1000, 2)
    h = rng.uniform(0.3, 8.0)
    offs = _edge_offsets(rng, n_pix, 2.0 * math.sqrt(sigma * sigma + 1.0 / 12.0) + h)
    phi = rng.uniform(0, 2 * np.pi, n_pix)
    d = a + offs
    rc = np.stack([r0 + d * np.sin(phi), c0 + d * np.cos(phi)], -1)
    amp = rng.uniform(50, 1000)
    return CoronaParams(r0, c0, a, sigma, math.log(h), amp, amp * rng.uniform(0, 0.4), rng.uniform(0, 40)), jnp.asarray(rc)


def _minnaert_profile_case(rng: np.random.Generator, n_pix: int):  # noqa: ANN202
    """The profile widened by the limb-brightening exponent ``kappa`` (0-0.45: Minnaert ``k`` 0.55-1)."""
    p, rc = _profile_case(rng, n_pix)
    return MinnaertProfileParams(*[getattr(p, n) for n in LimbProfileParams.field_names()], rng.uniform(0.0, 0.45)), rc


def _glow_profile_case(rng: np.random.Generator, n_pix: int):  # noqa: ANN202
    """The profile widened by a glow above the limb: ``glow`` 0.02-0.5 of ``amp``, scale height 0.1-5 px, tilt
    toward the Sun -0.9-0.9.  (The
    ``log_h`` column is proportional to ``glow``: the central-difference step, inversely proportional to the
    column, grows with a vanishing glow until its truncation error shows, 2.6e-4 at ``glow`` ~ 1e-3.)"""
    p, rc = _profile_case(rng, n_pix)
    return GlowProfileParams(*[getattr(p, n) for n in LimbProfileParams.field_names()], rng.uniform(0.02, 0.5),
                             math.log(rng.uniform(0.1, 5.0)), rng.uniform(-0.9, 0.9)), rc


def _aniso_profile_case(rng: np.random.Generator, n_pix: int):  # noqa: ANN202
    """The profile with an anisotropic blur: ``|s2c|, |s2s|`` up to 0.6 of ``sigma_e^2`` (a smear up to ~3 px)."""
    p, rc = _profile_case(rng, n_pix)
    v = float(p.sigma) ** 2 + 1.0 / 12.0
    return AnisoProfileParams(*[getattr(p, n) for n in LimbProfileParams.field_names()],
                              *(v * rng.uniform(-0.6, 0.6, 2))), rc


_PHYSICAL_CASES = {"lunar_limb": _profile_case, "lunar_limb_minnaert": _minnaert_profile_case,
                   "lunar_limb_glow": _glow_profile_case, "limb_darkened": _limb_darkened_case,
                   "lunar_limb_aniso": _aniso_profile_case, "corona": _corona_case}


def _intensity_range(p: Any) -> float:
    """The intensity range of a parameter point (levels for the sigmoids, ``amp`` for the physical profiles)."""
    if hasattr(p, "ymax"):
        return abs(float(p.ymax) - float(p.ymin))
    return abs(float(p.amp))


def check_model(model: LimbModel, n_points: int = 100, n_pix: int = 60, seed: int = 0) -> list[GradCheck]:
    """Compare ``model.jacobian`` with ``jax.jacfwd`` and central differences at ``n_points`` random points.

    Parameters
    ----------
    model : LimbModel
        The model to check (its tolerances come from :data:`SPECS`, default 1e-9 and 1e-6).
    n_points : int
        Random parameter points.
    n_pix : int
        Pixels per point: a third inside, a third on and a third outside the limb.
    seed : int
        Seed of the NumPy generator that draws the points and pixels.

    Returns
    -------
    list of GradCheck
        One row per parameter, in the model's field order: the worst relative error against autodiff and the worst
        central-difference error (relative to the column scale) over all points.
    """
    rng = np.random.default_rng(seed)
    ptype = model.params_type
    names = model.param_names
    spec = SPECS.get(model.name, _Spec())
    f_ref = spec.fd_intensity if spec.fd_intensity is not None else model.intensity
    f = jax.jit(lambda v, x: f_ref(ptype.from_vector(v), x))
    jac_ad = jax.jit(jax.jacfwd(lambda v, x: model.intensity(ptype.from_vector(v), x)))
    jac_an = jax.jit(lambda v, x: model.jacobian(ptype.from_vector(v), x))
    worst = np.zeros(len(names))
    worst_fd = np.zeros(len(names))
    for _ in range(n_points):
        p, x = _random_case(model, rng, n_pix)
        v = p.to_vector()
        a = np.asarray(jac_an(v, x))
        b = np.asarray(jac_ad(v, x))
        col = np.max(np.abs(b), axis=0)
        dy = _intensity_range(p)
        denom = np.maximum(np.abs(b), spec.floor * col[None, :])
        denom = np.where(denom > 0, denom, 1.0)
        worst = np.maximum(worst, np.max(np.abs(a - b) / denom, axis=0))
        for j in range(len(names)):
            h = 1e-5 * dy / max(col[j], 1e-300)  # moves f by at most 1e-5 of its range
            e = jnp.zeros_like(v).at[j].set(h)
            smooth = _smooth_across(spec, ptype, v, e, x)
            if smooth.any():
                err = np.minimum(*(np.abs(_central(f, v, x, e / m) - a[:, j]) for m in (1.0, 10.0)))
                worst_fd[j] = max(worst_fd[j], float(np.max(err[smooth]) / max(col[j], 1e-300)))
    return [GradCheck(model.name, n, float(worst[i]), float(worst_fd[i]), n_points, spec.tol, spec.fd_tol)
            for i, n in enumerate(names)]


def _central(f: Any, v: Any, x: Any, e: Any) -> np.ndarray:
    """The central difference of ``f(v, x)`` along the step ``e`` (a vector with one non-zero entry)."""
    return (np.asarray(f(v + e, x)) - np.asarray(f(v - e, x))) / (2.0 * float(jnp.sum(e)))


def _smooth_across(spec: _Spec, ptype: Any, v: Any, e: Any, x: Any) -> np.ndarray:
    """The pixels whose intensity keeps its branch over ``v -+ e`` (all, for a model without :attr:`_Spec.regime`)."""
    if spec.regime is None:
        return np.ones(np.shape(x)[0], dtype=bool)
    r = [np.asarray(spec.regime(ptype.from_vector(w), x)) for w in (v - e, v, v + e)]
    return (r[0] == r[1]) & (r[1] == r[2])


#: The models :func:`run_gradcheck` checks, in order (each with its own seed offset).
GRADCHECK_MODELS = (LINEAR, CIRCLE, ELLIPSE, ELLIPSE_RAMP, LIMB_PROFILE, LIMB_DARKENED, LIMB_PROFILE_MINNAERT,
                    LIMB_PROFILE_GLOW, LIMB_PROFILE_ANISO, CORONA)


def run_gradcheck(n_points: int = 100, seed: int = 0, models: tuple[str, ...] | None = None) -> list[GradCheck]:
    """Every limb model (or those named in ``models``); see :func:`check_model`.

    Parameters
    ----------
    n_points : int
        Random parameter points per model.
    seed : int
        Base seed; the ``i``-th model of :data:`GRADCHECK_MODELS` uses ``seed + i``, so a model's points do not
        depend on which others are checked.
    models : tuple of str, optional
        Model names to check (``"circle"``, ``"lunar_limb"``, ...); ``None`` checks all.

    Returns
    -------
    list of GradCheck
        The rows of every checked model, in the order of :data:`GRADCHECK_MODELS`.
    """
    out: list[GradCheck] = []
    for i, model in enumerate(GRADCHECK_MODELS):
        if models is None or model.name in models:
            out.extend(check_model(model, n_points=n_points, seed=seed + i))
    return out


def report(checks: list[GradCheck]) -> dict[str, list[dict[str, object]]]:
    """The ``jaxlimb gradcheck --json`` object.

    Parameters
    ----------
    checks : list of GradCheck
        Rows from :func:`run_gradcheck` or :func:`check_model`.

    Returns
    -------
    dict
        ``{"checks": [...]}``: each row's fields and whether it ``passed``.
    """
    return {"checks": [{**asdict(c), "passed": c.passed} for c in checks]}
