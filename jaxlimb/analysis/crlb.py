r"""Fisher information and Cramér--Rao lower bounds for the sigmoid limb models.

For pixel intensities :math:`z_i = f(\theta, x_i) + \epsilon_i` with independent
Gaussian noise of standard deviation :math:`\sigma_i`, the Fisher information of
the free parameters is

.. math:: F = J^\top \Sigma^{-1} J, \qquad J_{ij} = \partial f(\theta, x_i)/\partial\theta_j,

and any unbiased estimator has :math:`\mathrm{Cov}(\hat\theta) \succeq F^{-1}`.
``J`` is the paper's analytic Jacobian (Eq. 14, 17, Sec. V-C of Mortari et al.
2016), evaluated at the *true* parameters.  With Poisson (shot) noise the
per-pixel variance is :math:`\sigma_{read}^2 + f_i / g` (``gain`` in DN per
electron), which the optional ``poisson_gain`` adds.

Bounds on derived quantities (delta method)
-------------------------------------------

A smooth function :math:`g(\theta)` of an estimate with covariance :math:`C` has, to first
order, the covariance :math:`G C G^\top` with :math:`G = \partial g/\partial\theta` (the
delta method).  Applied to the Cramér--Rao bound it gives the bound on :math:`g` for
unbiased estimators of :math:`g` (the CRLB transforms the same way), and applied to the
Laplace covariance of a fit it gives the reported uncertainty of the line of sight and
range.  For a circle fit, :math:`g` maps ``(r0, c0, radius)`` to the body-centre line of
sight in the camera frame and the range of a sphere of radius :math:`R`
(:func:`jaxlimb.geometry.navigation.sphere_from_circle`: exact off-axis geometry, not the
boresight-only Eq. 36 of the Aerospace 2015 paper).  That map is not written in JAX, so
its Jacobian is taken by central differences (:func:`numerical_jacobian`); on the
boresight the range part reduces to Eq. 38 of the 2015 paper, which the tests check.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from ..errors import LimbInputError
from ..fitting import bucket_size
from ..numerics import numerical_jacobian
from ..geometry.navigation import sphere_from_circle
from ..models import LIMB_PROFILE, PROFILE_FIXED, LimbModel, LimbParams
from ..models.profile_columns import albedo_field_factor


@dataclass(frozen=True)
class CramerRao:
    """The bound: names of the free parameters, Fisher matrix, its inverse and the 1-sigma bounds."""

    free: tuple[str, ...]
    fisher: np.ndarray
    covariance: np.ndarray

    @property
    def std(self) -> dict[str, float]:
        return {n: float(np.sqrt(self.covariance[i, i])) for i, n in enumerate(self.free)}


def pixel_variance(model: LimbModel, coords: np.ndarray, truth: LimbParams, sigma: float,
                   poisson_gain: float | None = None) -> np.ndarray:
    """Per-pixel noise variance: read noise ``sigma**2`` plus shot noise ``f / gain`` if given.

    Parameters
    ----------
    model : LimbModel
        The limb model (its intensity at ``truth`` is the expected signal ``f``).
    coords : np.ndarray (n, 2)
        Pixels as (row, col) (``(n,)`` for the linear model).
    truth : LimbParams
        True parameters.
    sigma : float
        Read-noise standard deviation (DN).
    poisson_gain : float, optional
        Gain ``g`` in DN per electron: adds the shot noise ``max(f, 0) / g``; ``None`` for read noise alone.

    Returns
    -------
    np.ndarray (n,)
        Noise variance of each pixel (DN^2).

    Raises
    ------
    LimbInputError
        ``poisson_gain`` <= 0.
    """
    var = np.full(np.shape(coords)[0], float(sigma) ** 2)
    if poisson_gain is not None:
        if poisson_gain <= 0:
            raise LimbInputError(f"`poisson_gain` must be > 0, got {poisson_gain!r}")
        f = _padded_eval(model, "intensity", truth, np.asarray(coords, dtype=float))
        var = var + np.maximum(f, 0.0) / poisson_gain
    return var


def _padded_eval(model: LimbModel, what: str, params: LimbParams, coords: np.ndarray) -> np.ndarray:
    """``model.intensity`` / ``model.jacobian`` at ``coords``, jitted on pixel sets padded to a bucket.

    Padding to :func:`jaxlimb.fitting.bucket_size` (copies of the first pixel, dropped
    afterwards) means pixel sets of similar size share one compiled program: a pipeline that
    calls :func:`crlb` on every frame (whose pixel count varies by a few) does not recompile.
    """
    n = coords.shape[0]
    size = bucket_size(n)
    if size > n:
        coords = np.concatenate([coords, np.repeat(coords[:1], size - n, axis=0)], axis=0)
    fn = _EVAL[what]
    return np.asarray(fn(model, params, jnp.asarray(coords)))[:n]


def _eval_intensity(model: LimbModel, params: LimbParams, coords: jax.Array) -> jax.Array:
    return model.intensity(params, coords)


def _eval_jacobian(model: LimbModel, params: LimbParams, coords: jax.Array) -> jax.Array:
    return model.jacobian(params, coords)


_EVAL = {"intensity": eqx.filter_jit(_eval_intensity), "jacobian": eqx.filter_jit(_eval_jacobian)}


def crlb(model: LimbModel, coords: np.ndarray, truth: LimbParams, sigma: float, *,
         fixed: Sequence[str] = (), poisson_gain: float | None = None) -> CramerRao:
    """Cramér--Rao bound of the free parameters of ``model`` for these pixels and noise.

    The Fisher information ``F = J^T diag(1/var) J`` from the model's Jacobian at the truth (for the sigmoids
    the paper's analytic one: Eq. 14, 17, Sec. V-C of Mortari et al. 2016; module docstring) and its inverse.

    Parameters
    ----------
    model : LimbModel
        The limb model, e.g. ``CIRCLE`` (Eq. 16), ``ELLIPSE``, ``LINEAR``.
    coords : np.ndarray (n, 2)
        Pixels as (row, col) (``(n,)`` for the linear model).
    truth : LimbParams
        True parameters, where the Jacobian is evaluated.
    sigma : float
        Read-noise standard deviation of every pixel (DN), finite and > 0.
    fixed : sequence of str
        Parameters held known (not estimated): their rows and columns leave the Fisher matrix.
    poisson_gain : float, optional
        Gain in DN per electron, to add shot noise (:func:`pixel_variance`).

    Returns
    -------
    CramerRao
        ``free`` names, ``fisher`` and ``covariance`` ``(p, p)``; ``std`` the 1-sigma bounds in the parameters'
        units (px for centre and radius).

    Raises
    ------
    LimbInputError
        ``sigma`` not finite and > 0, or ``poisson_gain`` <= 0.

    Examples
    --------
    The package's standard problem: a circular sigmoid of radius 150 px, ``k = 3``, 200 / 20 DN, noise
    10 DN, the pixels within 6 px of the limb:

    >>> import jax
    >>> jax.config.update("jax_enable_x64", True)
    >>> from jaxlimb.analysis.posterior import synthetic_circle
    >>> from jaxlimb.models import CIRCLE
    >>> limb = synthetic_circle(radius=150.0, k=3.0, ymax=200.0, ymin=20.0, sigma=10.0)
    >>> bound = crlb(CIRCLE, limb.coords, limb.truth, 10.0)
    >>> {n: round(s, 4) for n, s in bound.std.items()}
    {'r0': 0.0036, 'c0': 0.0036, 'radius': 0.0028, 'k': 0.0218, 'ymax': 0.1508, 'ymin': 0.1474}
    """
    if not (np.isfinite(sigma) and sigma > 0):
        raise LimbInputError(f"`sigma` must be a finite number > 0, got {sigma!r}")
    free_idx = model.free_indices(fixed)
    jac = _padded_eval(model, "jacobian", truth, np.asarray(coords, dtype=float))[:, list(free_idx)]
    var = pixel_variance(model, coords, truth, sigma, poisson_gain)
    fisher = jac.T @ (jac / var[:, None])
    cov = np.linalg.inv(fisher)
    return CramerRao(tuple(model.param_names[i] for i in free_idx), fisher, cov)


def albedo_field_crlb(coords: np.ndarray, truth, var: np.ndarray, tau: float, ell_rad: float, *,
                      fixed: Sequence[str] | None = None) -> CramerRao:
    r"""Cramér--Rao bound of the physical limb profile's free parameters when the surface albedo varies: a
    zero-mean Gaussian field of relative standard deviation ``tau`` and correlation length ``ell_rad``
    (:mod:`jaxlimb.models.profile_columns`), marginalised.

    The Bayesian bound of a linear-Gaussian nuisance (Van Trees 1968, Sec. 2.4):
    ``F = J^T Sigma^-1 J`` with ``Sigma = diag(var) + K C K^T`` (``K`` the albedo field's columns, ``C`` its
    prior), computed through ``C = L L^T`` as ``J^T D^-1 J - B^T (I + L^T K^T D^-1 K L)^-1 B``,
    ``B = L^T K^T D^-1 J``.  ``tau = 0`` gives :func:`crlb`'s bound.  No estimator that treats the albedo as
    unknown within this prior does better; a one-albedo fit has a smaller variance but a bias the bound counts.

    Parameters
    ----------
    coords : np.ndarray (n, 2)
        Pixels as (row, col).
    truth : LimbProfileParams
        True profile (lunar-Lambert radiance).
    var : np.ndarray (n,)
        Noise variance of each pixel (DN^2), e.g. :func:`pixel_variance`.
    tau : float
        Relative albedo standard deviation (>= 0).
    ell_rad : float
        Its correlation length on the sphere (rad, > 0).
    fixed : sequence of str, optional
        Parameters held known (default: :data:`jaxlimb.models.PROFILE_FIXED`).

    Returns
    -------
    CramerRao
        As :func:`crlb`.

    Raises
    ------
    LimbInputError
        ``tau < 0``, ``ell_rad <= 0`` or a variance not > 0.
    """
    var = np.asarray(var, float)
    if not (tau >= 0 and ell_rad > 0 and np.all(var > 0)):
        raise LimbInputError(f"albedo field: need tau >= 0, ell_rad > 0, var > 0; got {tau!r}, {ell_rad!r}")
    coords = np.asarray(coords, float)
    free_idx = LIMB_PROFILE.free_indices(PROFILE_FIXED if fixed is None else fixed)
    jac = _padded_eval(LIMB_PROFILE, "jacobian", truth, coords)[:, list(free_idx)]
    fisher = jac.T @ (jac / var[:, None])
    if tau > 0:
        KL = albedo_field_factor(truth, coords, tau, ell_rad)
        B = KL.T @ (jac / var[:, None])
        inner = np.eye(KL.shape[1]) + KL.T @ (KL / var[:, None])
        fisher = fisher - B.T @ np.linalg.solve(inner, B)
    fisher = 0.5 * (fisher + fisher.T)
    return CramerRao(tuple(LIMB_PROFILE.param_names[i] for i in free_idx), fisher, np.linalg.inv(fisher))


# =============================================================================== derived quantities


def delta_method(cov: np.ndarray, jacobian: np.ndarray) -> np.ndarray:
    """Covariance ``G C G^T`` of ``g(theta)`` for ``Cov(theta) = cov`` and ``G = dg/dtheta``.

    Parameters
    ----------
    cov : np.ndarray (p, p)
        Symmetric covariance of the parameters.
    jacobian : np.ndarray (m, p)
        Jacobian of the derived quantities (``(p,)`` for a scalar ``g``).

    Returns
    -------
    np.ndarray (m, m)
        Covariance of ``g``, symmetrised (``(1, 1)`` for a scalar ``g``).

    Raises
    ------
    LimbInputError
        Shapes that do not match, or non-finite entries.
    """
    c = np.asarray(cov, dtype=float)
    g = np.atleast_2d(np.asarray(jacobian, dtype=float))
    if c.ndim != 2 or c.shape[0] != c.shape[1]:
        raise LimbInputError(f"`cov` must be a square (p, p) matrix, got shape {c.shape}")
    if g.shape[-1] != c.shape[0]:
        raise LimbInputError(f"`jacobian` must have {c.shape[0]} columns to match `cov`, got shape {g.shape}")
    if not (np.all(np.isfinite(c)) and np.all(np.isfinite(g))):
        raise LimbInputError("`cov` and `jacobian` must be finite")
    out = g @ c @ g.T
    return 0.5 * (out + out.T)


@dataclass(frozen=True)
class LosRangeBound:
    """Line of sight and range of a sphere from a circle fit, with their delta-method covariance.

    Attributes
    ----------
    los_camera : unit vector toward the body centre, camera frame.
    range_km : range to the body centre.
    covariance : ``(4, 4)`` covariance of ``(los_x, los_y, los_z, range_km)``.
    jacobian : ``(4, 3)`` ``d(los, range)/d(r0, c0, radius)``.
    """

    los_camera: np.ndarray
    range_km: float
    covariance: np.ndarray
    jacobian: np.ndarray

    @property
    def sigma_range_km(self) -> float:
        return float(np.sqrt(self.covariance[3, 3]))

    @property
    def sigma_los_rad(self) -> float:
        """Total angular 1-sigma of the LOS: ``sqrt(trace(Cov(u)))`` (u is unit, so this is the
        root-sum-square of the two tangential angle sigmas, radians)."""
        return float(np.sqrt(np.trace(self.covariance[:3, :3])))

    def as_dict(self) -> dict[str, object]:
        """JSON-ready: the LOS, the range, their sigmas and the covariance.

        Returns
        -------
        dict
            ``los_camera`` (unit vector, camera frame), ``range_km``, ``sigma_range_km``, ``sigma_los_rad``,
            ``sigma_los_arcsec`` and ``covariance`` (4 x 4 nested lists).
        """
        return {
            "los_camera": self.los_camera.tolist(),
            "range_km": self.range_km,
            "sigma_range_km": self.sigma_range_km,
            "sigma_los_rad": self.sigma_los_rad,
            "sigma_los_arcsec": self.sigma_los_rad * 180.0 / np.pi * 3600.0,
            "covariance": self.covariance.tolist(),
        }


def los_range_bound(camera, center_rc, radius_px: float, cov_center_radius: np.ndarray,  # noqa: ANN001
                    body_radius_km: float, step_px: float = 1e-3) -> LosRangeBound:
    """Delta-method covariance of the body-centre LOS and range from a circle fit.

    Parameters
    ----------
    camera : Camera
        The pinhole camera (:class:`~jaxlimb.geometry.camera.Camera`).
    center_rc : tuple of float
        Centre of the fitted circle (the image of the limb), (row, col) px.
    radius_px : float
        Its radius (px).
    cov_center_radius : np.ndarray (3, 3)
        Covariance of ``(r0, c0, radius)`` (px^2): the CRLB (:func:`crlb` ``.covariance`` restricted to these)
        or a fit's Laplace covariance.
    body_radius_km : float
        Radius of the sphere (km).
    step_px : float
        Central-difference step (px); the map is smooth on the pixel scale, so the truncation error
        ``O(step^2)`` is far below the rounding of ``sphere_from_circle``.

    Returns
    -------
    LosRangeBound
        LOS (camera frame), range (km), their ``(4, 4)`` covariance and the ``(4, 3)`` Jacobian.

    Raises
    ------
    LimbInputError
        ``cov_center_radius`` is not ``(3, 3)``.
    """
    x0 = np.array([float(center_rc[0]), float(center_rc[1]), float(radius_px)])
    cov = np.asarray(cov_center_radius, dtype=float)
    if cov.shape != (3, 3):
        raise LimbInputError(f"`cov_center_radius` must be (3, 3) over (r0, c0, radius), got shape {cov.shape}")

    def g(x: np.ndarray) -> np.ndarray:
        u, d = sphere_from_circle(camera, (x[0], x[1]), x[2], body_radius_km)
        return np.concatenate([u, [d]])

    val = g(x0)
    jac = numerical_jacobian(g, x0, step_px)
    return LosRangeBound(val[:3], float(val[3]), delta_method(cov, jac), jac)


def crlb_los_range(bound: CramerRao, truth: LimbParams, camera, body_radius_km: float) -> LosRangeBound:  # noqa: ANN001
    """Cramér--Rao bound on the LOS and range implied by a circle-model bound (delta method).

    ``r0``, ``c0`` and ``radius`` must be free in ``bound``; the other parameters (``k``,
    ``ymax``, ``ymin``) enter through the correlations already folded into
    ``bound.covariance``.

    Parameters
    ----------
    bound : CramerRao
        The bound of a circle model (:func:`crlb` with ``CIRCLE``).
    truth : LimbParams
        The true circle (``r0``, ``c0``, ``radius`` in px), where the mapping is linearised.
    camera : Camera
        The pinhole camera.
    body_radius_km : float
        Radius of the sphere (km).

    Returns
    -------
    LosRangeBound
        The bound on the LOS (camera frame) and the range (km).

    Raises
    ------
    LimbInputError
        ``r0``, ``c0`` or ``radius`` is not free in ``bound``.
    """
    need = ("r0", "c0", "radius")
    missing = [n for n in need if n not in bound.free]
    if missing:
        raise LimbInputError(f"`bound` must have {list(need)} free for the LOS/range bound, missing {missing}")
    idx = [bound.free.index(n) for n in need]
    sub = bound.covariance[np.ix_(idx, idx)]
    return los_range_bound(camera, (float(truth.r0), float(truth.c0)), float(truth.radius), sub, body_radius_km)
