"""The limb models that moved out of the pipeline (ramp, lunar-Lambert profile, limb-darkened disc):
their analytic Jacobians against jax.jacfwd and central differences, as ``jaxlimb gradcheck`` runs them."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from jaxlimb.models import (
    ALL_MODELS,
    ELLIPSE_RAMP,
    LIMB_DARKENED,
    LIMB_PROFILE,
    LIMB_PROFILE_ANISO,
    LIMB_PROFILE_GLOW,
    LIMB_PROFILE_MINNAERT,
    EllipseRampParams,
    LimbModel,
    ellipse_ramp_intensity,
    ellipse_ramp_intensity_jac,
)
from jaxlimb.models.gradcheck import SPECS, check_model
from jaxlimb.models.blur_quadrature import quadrature_nodes

jax.config.update("jax_enable_x64", True)


@pytest.mark.parametrize("model, n_points", [(ELLIPSE_RAMP, 30), (LIMB_PROFILE, 12), (LIMB_PROFILE_MINNAERT, 12),
                                             (LIMB_PROFILE_GLOW, 12), (LIMB_DARKENED, 8), (LIMB_PROFILE_ANISO, 12)],
                         ids=lambda m: getattr(m, "name", ""))
def test_analytic_jacobian_matches_autodiff_and_fd(model, n_points):
    checks = check_model(model, n_points=n_points, seed=11)
    assert [c.param for c in checks] == list(model.param_names)
    for c in checks:
        assert c.passed, c
    assert checks[0].tol == SPECS.get(model.name).tol if model.name in SPECS else checks[0].tol == 1e-9


def test_every_model_is_in_the_registry_with_its_jacobian():
    assert set(ALL_MODELS) == {"linear", "circle", "ellipse", "ellipse_ramp", "lunar_limb", "lunar_limb_minnaert",
                               "lunar_limb_glow", "limb_darkened", "lunar_limb_aniso", "corona"}
    for m in ALL_MODELS.values():
        assert m.value_and_columns is not None, m.name  # the fits' one-pass path, not autodiff


def test_gradcheck_catches_a_wrong_ramp_column():
    """A factor error in one column of the ramp (dk) shows up as an O(1) relative error."""
    bad_jac = lambda p, x: ellipse_ramp_intensity_jac(p, x).at[:, 5].multiply(1.01)  # noqa: E731
    bad = LimbModel("ellipse_ramp", EllipseRampParams, ellipse_ramp_intensity, bad_jac, ELLIPSE_RAMP.jacobian_columns)
    errs = {c.param: c.max_rel_err for c in check_model(bad, n_points=3)}
    assert errs["k"] > 1e-3 and errs["r0"] < 1e-9


def test_quadrature_nodes_is_scoped():
    import jaxlimb.models.blur_quadrature as bq

    n0 = bq._GL_X.size
    with quadrature_nodes(64):
        assert bq._GL_X.size == 64
    assert bq._GL_X.size == n0 == bq.N_NODES


def test_ramp_jacobian_at_the_table_edges():
    """The blurred square root switches from its table to its asymptote at k u = 16 and is flat below -10."""
    p = EllipseRampParams(0.0, 0.0, 100.0, 0.2, 0.95, 2.0, 200.0, 10.0, 1.5, 7.0, 3.0, -2.0, 1.0, 0.5)
    us = np.array([-6.0, -5.0, -0.3, 0.0, 4.0, 7.99, 8.01, 9.0])  # k u from -12 to 18
    rc = jnp.asarray(np.column_stack([np.zeros_like(us), 95.0 - us]))
    J = np.asarray(ellipse_ramp_intensity_jac(p, rc))
    Ja = np.asarray(jax.jacfwd(lambda v: ellipse_ramp_intensity(EllipseRampParams.from_vector(v), rc))(p.to_vector()))
    np.testing.assert_allclose(J, Ja, rtol=1e-10, atol=1e-10 * np.abs(Ja).max())


def test_default_gradcheck_points_pass_for_the_ramp_and_the_tabulated_disc():
    """``jaxlimb gradcheck`` (100 points, seed 0: the ramp is model 3, the disc model 5) failed on rounding:
    a relative floor of 1e-8 with a tolerance of 1e-9 asked for 1e-17 of a column."""
    from jaxlimb.models import ELLIPSE_RAMP, LIMB_DARKENED
    from jaxlimb.models.gradcheck import check_model

    for model, seed in ((ELLIPSE_RAMP, 3), (LIMB_DARKENED, 5)):
        checks = check_model(model, n_points=100, seed=seed)
        assert all(c.passed for c in checks), [c for c in checks if not c.passed]


def _horn_case():
    """The crescent horn that ``check_model(LIMB_PROFILE, seed=0)`` drew: a 117 deg crescent of a 51 px body,
    PSF 1.8 px; the pixel 11.5 px inside the limb whose blur window crosses the terminator."""
    from jaxlimb.models import LimbProfileParams

    p = LimbProfileParams(986.7117841365805, -48.44758935793053, 51.37286329287892, -1.756239652202241,
                          0.9658746783347828, 1.8415169935795987, 216.985133647483, 12.917940108061243,
                          -0.06789053476112748, 0.9976927760036395, 2.044383538438516, 0.004325641481886696,
                          0.19551697442706573, 0.0, 1.0)
    return p, jnp.asarray([[954.29136402, -25.71476801], [960.0, -20.0], [975.0, -5.0]])


def test_profile_across_the_terminator_is_integrated_on_the_lit_segment_only():
    """Across the terminator's kink a Gauss-Legendre rule converged slowly: 20 nodes put this pixel 0.17 DN
    off and the analytic columns disagreed with autodiff of the 64-node rule by 5.8 % of a column.  Cut to
    the lit segment (``profile_radiance.lit_limits``), 20 nodes are within 1e-3 DN of 2048 and the columns agree."""
    p, x = _horn_case()
    with quadrature_nodes(2048):
        ref = np.asarray(LIMB_PROFILE.intensity(p, x))
    i20 = np.asarray(LIMB_PROFILE.intensity(p, x))
    assert np.max(np.abs(i20 - ref)) < 1e-3
    v = p.to_vector()
    with quadrature_nodes(64):
        an = np.asarray(LIMB_PROFILE.jacobian(p, x))
        ad = np.asarray(jax.jacfwd(lambda t: LIMB_PROFILE.intensity(type(p).from_vector(t), x))(v))
    scale = np.max(np.abs(ad), axis=0)
    assert np.max(np.abs(an - ad) / np.where(scale > 0, scale, 1.0)) < 1e-5  # was 0.12 on these 3 pixels


def test_anisotropic_blur_is_the_isotropic_profile_at_zero_and_widens_across_the_smear():
    """``LIMB_PROFILE_ANISO`` at ``s2c = s2s = 0`` is ``LIMB_PROFILE``; with ``s2c > 0`` (more blur where the limb normal
    runs along ``+col``) the edge there is wider than where the normal runs along ``row``."""
    from jaxlimb.models import AnisoProfileParams, LimbProfileParams

    p = LimbProfileParams(r0=0.0, c0=0.0, a=200.0, theta=0.0, rho=1.0, sigma=0.8, amp=100.0, ymin=0.0, sun_r=0.0,
                          sun_c=1.0, phase=0.3, inv_f=1e-4, L=0.5, L_slope=-1.0, L_ref=0.6)
    d = np.linspace(195.0, 205.0, 41)
    along_c = jnp.asarray(np.column_stack([np.zeros_like(d), d]))
    along_r = jnp.asarray(np.column_stack([-d, np.zeros_like(d)]))
    q0 = AnisoProfileParams(*[getattr(p, n) for n in LimbProfileParams.field_names()], 0.0, 0.0)
    np.testing.assert_allclose(LIMB_PROFILE_ANISO.intensity(q0, along_c), LIMB_PROFILE.intensity(p, along_c), rtol=1e-12)
    q = q0.replace(s2c=0.4)

    def width(rc):
        f = np.asarray(LIMB_PROFILE_ANISO.intensity(q, rc)) / np.asarray(LIMB_PROFILE_ANISO.intensity(q, rc)).max()
        return np.interp(0.2, f[::-1], d[::-1]) - np.interp(0.8, f[::-1], d[::-1])

    assert width(along_c) > 1.15 * width(along_r)
