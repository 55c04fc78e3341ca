"""The physical limb profile (jaxlimb.pipeline.profile): quadrature, one-pass Jacobian, cos/sin series."""

from __future__ import annotations

import math

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from jaxlimb.models import (
    LIMB_PROFILE,
    LIMB_PROFILE_MINNAERT,
    LimbProfileParams,
    MinnaertProfileParams,
    limb_profile_intensity,
)
from jaxlimb.models.blur_quadrature import quadrature_nodes
from jaxlimb.models.profile_glow import glow_inside, glow_outside
from jaxlimb.models.profile_radiance import cos_sin_small

jax.config.update("jax_enable_x64", True)


def _params(phase: float, rho: float = 0.995, sigma: float = 0.9, kappa: float | None = None) -> LimbProfileParams:
    """The lunar-Lambert profile; with ``kappa``, the Minnaert-widened one (MinnaertProfileParams)."""
    p = LimbProfileParams(r0=500.0, c0=600.0, a=200.0, theta=0.3, rho=rho, sigma=sigma, amp=150.0, ymin=3.0,
                          sun_r=0.6, sun_c=0.8, phase=phase, inv_f=1 / 7272.7, L=0.5, L_slope=-0.9, L_ref=0.6)
    fields = [getattr(p, n) for n in LimbProfileParams.field_names()]
    return p if kappa is None else MinnaertProfileParams(*fields, kappa)


def _model(p):
    return LIMB_PROFILE_MINNAERT if isinstance(p, MinnaertProfileParams) else LIMB_PROFILE


def _ring(seed: int, n: int = 2048, half_width: float = 6.0) -> tuple[np.ndarray, np.ndarray]:
    rng = np.random.default_rng(seed)
    ang = rng.uniform(-math.pi, math.pi, n)
    d = 200.0 + rng.uniform(-half_width, half_width, n)
    rc = np.stack([500.0 + d * np.cos(ang), 600.0 + d * np.sin(ang)], axis=1)
    cpsi = np.cos(ang) * 0.6 + np.sin(ang) * 0.8  # cos of the angle from the Sun's image direction
    return rc, cpsi


@pytest.mark.parametrize("kappa", [None, 0.0, 0.3])
@pytest.mark.parametrize("phase_deg", [0.0, 40.0, 90.0, 120.0])
def test_one_pass_jacobian_matches_autodiff_on_the_lit_limb(phase_deg, kappa):
    # the columns are the integrals of the differentiated integrand; jax.jacfwd differentiates the
    # quadrature rule itself: they agree to the quadrature error on the lit side (the fitted
    # pixels), checked here with 48 nodes (at 20 nodes the rule's own derivative is off by ~5e-4);
    # kappa > 0: the Minnaert-like brightening (mu0 mu)^-kappa and its column
    p = _params(math.radians(phase_deg), kappa=kappa)
    rc, cpsi = _ring(1)
    lit = cpsi > 0.3
    with quadrature_nodes(48):
        f, cols = _model(p).value_and_columns(p, jnp.asarray(rc))
        vec = p.to_vector()
        J = np.asarray(jax.jacfwd(lambda t: limb_profile_intensity(type(p).from_vector(t), rc))(vec))
    assert np.all(np.isfinite(np.asarray(f)))
    assert len(cols) == len(type(p).field_names())
    for i, name in enumerate(type(p).field_names()):
        col = np.asarray(cols[i])[lit]
        scale = np.abs(J[lit, i]).max()
        if scale == 0.0:
            assert np.abs(col).max() < 1e-9, name
            continue
        tol = 1e-4 if name == "sigma" else 1e-5
        assert np.abs(col - J[lit, i]).max() <= tol * scale, name


@pytest.mark.parametrize("kappa", [None, 0.3])
def test_columns_match_central_differences_of_the_exact_integral(kappa):
    # against the model itself at 96 quadrature nodes (the exact integral to ~1e-9)
    p = _params(math.radians(60.0), kappa=kappa)
    rc, cpsi = _ring(2, n=512)
    lit = cpsi > 0.3
    with quadrature_nodes(96):
        _, cols = _model(p).value_and_columns(p, jnp.asarray(rc))
        names = type(p).field_names()
        for name, h in (("r0", 1e-5), ("a", 1e-5), ("sigma", 1e-6), ("phase", 1e-6), ("L", 1e-6), ("kappa", 1e-6)):
            if name not in names:
                continue
            up = limb_profile_intensity(p.replace(**{name: float(getattr(p, name)) + h}), rc)
            dn = limb_profile_intensity(p.replace(**{name: float(getattr(p, name)) - h}), rc)
            fd = np.asarray(up - dn) / (2 * h)
            col = np.asarray(cols[names.index(name)])
            assert np.abs(col - fd)[lit].max() <= 1e-5 * np.abs(fd[lit]).max(), name


@pytest.mark.parametrize("phase_deg, sigma, kappa", [(0.0, 0.3, None), (0.0, 1.2, None), (90.0, 0.6, None),
                                                     (90.0, 0.6, 0.45), (30.0, 0.3, 0.45)])
def test_quadrature_is_converged(phase_deg, sigma, kappa):
    # 20 nodes vs 96: below 0.02 DN on a 150 DN limb (2 DN is the benchmarks' read noise); kappa = 0.45 is
    # Minnaert k = 0.55, the sharpest rim of benchmarks/families.py
    p = _params(math.radians(phase_deg), sigma=sigma, kappa=kappa)
    rc, cpsi = _ring(3)
    lit = cpsi > 0.3
    f20 = np.asarray(limb_profile_intensity(p, rc))
    with quadrature_nodes(96):
        f96 = np.asarray(limb_profile_intensity(p, rc))
    # (a Minnaert rim is 2-3x brighter than a lunar-Lambert one: the bound scales with the peak past 300 DN)
    assert np.abs(f20 - f96)[lit].max() < 0.02 * max(1.0, float(f96[lit].max()) / 300.0)


def test_small_angle_series():
    x = jnp.linspace(-0.2, 0.2, 1001)
    c, s = cos_sin_small(x, jnp.asarray(True))
    np.testing.assert_allclose(np.asarray(c), np.cos(np.asarray(x)), rtol=0, atol=2e-16)
    np.testing.assert_allclose(np.asarray(s), np.sin(np.asarray(x)), rtol=0, atol=2e-16)
    c, s = cos_sin_small(jnp.asarray([1.0]), jnp.asarray(False))
    assert float(c[0]) == pytest.approx(math.cos(1.0), abs=1e-16)


def test_l_band_widens_with_the_fits_own_uncertainty():
    from types import SimpleNamespace

    from jaxlimb.models.lunar_lambert import PHYSICAL_L
    from jaxlimb.pipeline.profile.passes import l_band

    free = ("r0", "c0", "a", "sigma", "amp", "ymin", "L")
    cov = np.diag([1e-4] * 6 + [0.05**2])
    lo, hi = l_band(SimpleNamespace(free=free, covariance=cov))
    assert (lo, hi) == pytest.approx((PHYSICAL_L[0] - 0.15, PHYSICAL_L[1] + 0.15))
    assert l_band(SimpleNamespace(free=free[:-1], covariance=cov[:-1, :-1])) == (-math.inf, math.inf)  # L held


def test_brightening_column_is_the_kappa_column_at_zero():
    """The score test's column (lunar-Lambert params) equals the widened model's ``kappa`` column at 0, and
    the widened model at ``kappa = 0`` is the lunar-Lambert profile."""
    from jaxlimb.models.lunar_lambert import brightening_column

    p, q = _params(math.radians(70.0)), _params(math.radians(70.0), kappa=0.0)
    rc, _ = _ring(4, n=256)
    _, cols = LIMB_PROFILE_MINNAERT.value_and_columns(q, jnp.asarray(rc))
    np.testing.assert_allclose(np.asarray(brightening_column(p, jnp.asarray(rc))), np.asarray(cols[-1]), rtol=1e-12,
                               atol=1e-9)
    np.testing.assert_allclose(np.asarray(limb_profile_intensity(q, rc)), np.asarray(limb_profile_intensity(p, rc)),
                               rtol=1e-14, atol=1e-12)
    assert np.abs(np.asarray(cols[-1])).max() > 1.0  # the brightening moves a 150 DN limb by DN per unit kappa


def _glow_params(glow: float, h: float, sigma: float = 0.9):
    from jaxlimb.models import GlowProfileParams

    p = _params(math.radians(70.0), sigma=sigma)
    return GlowProfileParams(*[getattr(p, n) for n in LimbProfileParams.field_names()], glow, math.log(h))


@pytest.mark.parametrize("h, se", [(0.05, 1.0), (0.3, 1.0), (0.7, 0.6), (3.0, 1.2)])
def test_glow_above_the_limb_is_the_blurred_exponential(h, se):
    """The closed form of the sky side (exp(-s/H), s > 0, convolved with N(0, se)) against numerical convolution,
    from 4 se inside to 6 se outside; a scale height 20x below se does not overflow; the curvature term is 0 at
    d -> inf."""
    from scipy import integrate

    p = _glow_params(1.0, h)
    for s in (-4.0 * se, -1.0, 0.0, 0.4, 2.0, 6.0 * se):
        num = integrate.quad(lambda t: math.exp(-t / h - 0.5 * ((s - t) / se) ** 2) / (se * math.sqrt(2 * math.pi)),
                             0.0, 60.0 * h + 20.0 * se, points=[max(s, 0.0)], limit=200)[0]
        got = float(glow_outside(p, jnp.asarray(s), se, 1e15, False)[0])
        assert got == pytest.approx(num, rel=1e-8, abs=1e-13)


@pytest.mark.parametrize("h, radius, depth", [(0.2, 200.0, 0.05), (0.5, 200.0, 3.0), (2.0, 80.0, 0.7)])
def test_glow_on_the_disc_is_half_the_grazing_column(h, radius, depth):
    """The disc side: the shell's column along a ray that leaves the surface ``depth`` px inside the limb
    (altitude mu t + t^2 / 2R), over the grazing column sqrt(2 pi R H), by quadrature."""
    from scipy import integrate

    mu = math.sqrt(2.0 * depth / radius)
    num = integrate.quad(lambda t: math.exp(-(mu * t + t * t / (2 * radius)) / h), 0.0, np.inf)[0]
    got = float(glow_inside(_glow_params(1.0, h), jnp.asarray(math.sqrt(depth)))[0])
    assert got == pytest.approx(num / math.sqrt(2 * math.pi * radius * h), rel=1e-10)


@pytest.mark.parametrize("tilt", [-0.5, 0.9, 2.0])
def test_glow_tilt_scales_the_glow_with_the_cosine_toward_the_sun(tilt):
    """``glow_tilt`` (GlowProfileParams): the glow's part of the radiance, disc side and sky side, is the untilted
    glow's times ``1 + glow_tilt cpsi``, ``cpsi`` the cosine between the pixel's direction from the centre and the
    Sun's image direction; the profile itself is unchanged."""
    p = _params(math.radians(70.0))  # the profile of _glow_params
    base = _glow_params(0.0, 0.8)
    flat = _glow_params(0.3, 0.8)
    tilted = flat.replace(glow_tilt=tilt)
    rc, cpsi = _ring(5, n=512)
    f = jax.jit(limb_profile_intensity)
    i0, i_flat, i_tilt = (np.asarray(f(q, rc)) for q in (base, flat, tilted))
    np.testing.assert_allclose(np.asarray(f(p, rc)), i0, rtol=1e-14, atol=1e-12)
    np.testing.assert_allclose(i_tilt - i0, (1.0 + tilt * cpsi) * (i_flat - i0), rtol=1e-9, atol=1e-9)
    assert np.abs(i_flat - i0).max() > 1.0  # the glow is there to scale


def test_glow_column_is_the_glow_column_at_zero():
    """The score test's column equals the widened model's ``glow`` column at ``glow = 0``, and the widened model at
    ``glow = 0`` is the lunar-Lambert profile (its columns against autodiff and central differences:
    tests/models/test_physical_models.py)."""
    from jaxlimb.models import LIMB_PROFILE_GLOW, GlowProfileParams
    from jaxlimb.models.profile_columns import glow_column

    p, q = _params(math.radians(70.0)), _glow_params(0.0, 0.8)
    rc, _ = _ring(4, n=256)
    _, cols = jax.jit(LIMB_PROFILE_GLOW.value_and_columns)(q, jnp.asarray(rc))
    names = GlowProfileParams.field_names()
    np.testing.assert_allclose(np.asarray(glow_column(p, jnp.asarray(rc), math.log(0.8))),
                               np.asarray(cols[names.index("glow")]), rtol=1e-12, atol=1e-9)
    f = jax.jit(limb_profile_intensity)
    np.testing.assert_allclose(np.asarray(f(q, rc)), np.asarray(f(p, rc)), rtol=1e-14, atol=1e-12)
