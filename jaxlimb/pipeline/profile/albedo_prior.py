r"""The surface albedo as an unknown Gaussian field: its columns, its amplitude from the residuals, and what it does
to a profile fit's covariance (the consider term ``locate``'s covariance carries).

The relative albedo is a zero-mean Gaussian field on the sphere (:mod:`jaxlimb.models.profile_columns`: the
profile's columns ``K``, prior ``tau^2 C_ell``, ``U = K C_ell^{1/2}``).  An albedo that darkens toward the limb in one
part of it is, to the pixels there, the same as the edge moved: the fit's residuals do not show it, so no model-error
term built from them (the limb sectors' sandwich, the split witness) carries it.  The profile fit is least squares,
``x = G z`` with ``G = (J^T J)^{-1} J^T``, so under the field its error has the consider covariance
``C_a = tau^2 G U U^T G^T`` beside the noise's (Schmidt 1966; Tapley, Schutz & Born 2004, Sec. 6.3).

The amplitude ``tau`` and correlation length ``ell`` (of :data:`ELL_DEG`) are those of largest marginal likelihood
(:func:`field_likelihood`; type-II maximum likelihood, Rasmussen & Williams 2006, Sec. 5.4) of what of the residuals
varies *along* the limb: the residuals and the field's columns less, at each distance from the limb (bins of
:data:`RADIAL_BIN_PX`), a quadratic in the position angle (:func:`along_limb`), where a reflectance law's or a PSF's
misfit lives.  The field's columns are taken as the residuals see them, ``U - J G U`` (the part the fit absorbs taken
out, as restricted maximum likelihood does; Patterson & Thompson 1971): with ``U`` itself the fit's absorption of a
strong field reads as more field.  A uniform albedo gives ``tau`` near 0 and no term.
"""

from __future__ import annotations

import math

import numpy as np

from ...model_error import positive_part
from ...models import LimbProfileParams
from ...models.profile_columns import albedo_field_factor
from ..sigmoid import pad_coords

TAU_MAX = 0.5
"""The largest relative albedo spread the field may take (the support of its prior): an albedo ``A (1 + a)`` stays
positive at two of the field's sigmas.  Residuals that would ask for more are not all albedo (another reflectance
law, compression artefacts): the rest is left to the noise and to the covariance's cluster-robust term."""

ELL_DEG = (8.0, 16.0, 32.0)
"""Correlation lengths (deg on the surface) among which the marginal likelihood chooses: a factor of two apart,
from features about the PSF's width in surface angle at a 30-80 px limb (``sqrt(2 sigma / R)``, 8-14 deg) to
hemispheric gradients."""

RADIAL_BIN_PX = 0.25
"""Width (px) of the bins of distance to the limb in :func:`along_limb`: fine against the edge's blur (a PSF sigma
of about a pixel), over which a reflectance law's misfit changes."""


def field_factor(p: LimbProfileParams, coords: np.ndarray, ell_rad: float) -> np.ndarray:
    """``U = K C_ell^{1/2}`` (module docstring, unit amplitude) at the profile ``p``, evaluated on the pixels padded to
    their bucket (one program per bucket).

    Parameters
    ----------
    p : LimbProfileParams
        The profile.
    coords : np.ndarray (n, 2)
        Its pixels.
    ell_rad : float
        Correlation length (rad).

    Returns
    -------
    np.ndarray (n, m)
    """
    return albedo_field_factor(p, pad_coords(coords), 1.0, ell_rad)[: coords.shape[0]]


def thin_svd(U: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``Q, S`` of ``U = Q S V^T`` through the Gram matrix (``n m^2``, not an SVD's ``n m^2`` with a QR); directions with
    ``S`` below 1e-6 of the largest are dropped (noise only there: ``d ~ 0``).

    Parameters
    ----------
    U : np.ndarray (n, m)
        Columns.

    Returns
    -------
    Q : np.ndarray (n, k)
    S : np.ndarray (k,)
    """
    V, S = gram_basis(U.T @ U)
    return (U @ V) / S, S


def gram_basis(gram: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The right singular vectors and singular values of columns known by their Gram matrix (:func:`thin_svd`).

    Parameters
    ----------
    gram : np.ndarray (m, m)
        ``U^T U`` of the columns ``U``.

    Returns
    -------
    tuple of np.ndarray
        ``V`` ``(m, k)`` and ``S`` ``(k,)``, directions with ``S`` below 1e-6 of the largest dropped.
    """
    w, V = np.linalg.eigh(gram)
    keep = w > 1e-12 * w.max()
    return V[:, keep], np.sqrt(w[keep])


def _grid_argmin(f, lo: float, hi: float, n: int = 121, zooms: int = 3) -> float:  # noqa: ANN001
    """The minimiser of a scalar function ``f`` (vectorised over a grid) on ``[lo, hi]``: a grid, then ``zooms``
    finer grids over the best point's neighbours."""
    for _ in range(zooms + 1):
        x = np.linspace(lo, hi, n)
        k = int(np.argmin(f(x)))
        lo, hi = x[max(k - 1, 0)], x[min(k + 1, n - 1)]
    return float(x[k])


def field_likelihood(r: np.ndarray, Q: np.ndarray, S: np.ndarray) -> tuple[float, float, float]:
    """Type-II maximum likelihood of the noise variance and the albedo field's amplitude for residuals ``r``, the
    amplitude at most :data:`TAU_MAX` (:func:`projected_likelihood` of ``|r|^2`` and ``Q^T r``).

    Parameters
    ----------
    r : np.ndarray (n,)
        Residuals of the one-albedo fit (DN).
    Q, S : np.ndarray
        :func:`thin_svd` of the field's columns.

    Returns
    -------
    tuple of float
        ``(s2, tau2, nll)``: the noise variance (DN^2), the field's variance and the negative log marginal
        likelihood (up to a constant).
    """
    return projected_likelihood(float(r @ r), Q.T @ r, S, r.size)


def projected_likelihood(rr: float, y: np.ndarray, S: np.ndarray, n: int) -> tuple[float, float, float]:
    """:func:`field_likelihood` from the residuals' squared norm ``rr``, their projections ``y = Q^T r`` on the
    field's directions of singular values ``S``, and their number ``n``.

    With ``y = Q^T r`` the pixels' covariance ``s2 I + t2 Q S^2 Q^T`` has eigenvalues ``s2 (1 + phi S^2)`` on ``Q``
    (``phi = t2 / s2``) and ``s2`` elsewhere; at fixed ``phi`` the best ``s2`` is ``(|r|^2 - |y|^2 + sum y^2 / (1 + phi
    S^2)) / n``, so the likelihood is searched over ``log phi`` alone, and over ``log s2`` at ``t2 = TAU_MAX^2`` when
    the amplitude reaches its bound.

    Parameters
    ----------
    rr : float
        ``|r|^2`` (DN^2).
    y : np.ndarray (m,)
        ``Q^T r``.
    S : np.ndarray (m,)
        The field's singular values.
    n : int
        The number of residuals.

    Returns
    -------
    tuple of float
        ``(s2, tau2, nll)`` as :func:`field_likelihood`'s.
    """
    y2 = np.asarray(y, float) ** 2
    rest, S2, t2_max = max(rr - float(y2.sum()), 1e-300), S * S, TAU_MAX**2

    def nll(s2, t2):  # noqa: ANN001, ANN202
        lam = s2[:, None] + t2[:, None] * S2
        return 0.5 * (rest / s2 + np.sum(y2 / lam, 1) + (n - S.size) * np.log(s2) + np.sum(np.log(lam), 1))

    def s2_of(phi):  # noqa: ANN001, ANN202
        return (rest + np.sum(y2 / (1.0 + phi[:, None] * S2), 1)) / n

    def profiled(u):  # noqa: ANN001, ANN202
        phi = np.exp(u)
        return nll(s2_of(phi), phi * s2_of(phi))

    top = math.log(1e8 / float(S2.max()))
    u = _grid_argmin(profiled, top - 40.0, top)
    s2 = float(s2_of(np.array([math.exp(u)]))[0])
    t2 = math.exp(u) * s2
    if t2 > t2_max:  # the bound is active: the noise variance at t2 = TAU_MAX^2
        t2 = t2_max
        v = _grid_argmin(lambda v: nll(np.exp(v), np.full(v.shape, t2_max)), math.log(s2) - 20.0, math.log(s2) + 20.0)
        s2 = math.exp(v)
    return s2, t2, float(nll(np.array([s2]), np.array([t2]))[0])


def along_basis(s: np.ndarray, psi: np.ndarray) -> np.ndarray:
    """Orthonormal columns ``(n, k)`` spanning a quadratic in the position angle, about the middle of the pixels' arc,
    per bin of distance to the limb (:data:`RADIAL_BIN_PX`): what :func:`along_limb` takes out.

    Parameters
    ----------
    s : np.ndarray (n,)
        Signed distance (px) of the pixels to the limb.
    psi : np.ndarray (n,)
        Their position angle (rad) about the limb's centre.

    Returns
    -------
    np.ndarray (n, k)
    """
    b = np.floor(np.asarray(s, float) / RADIAL_BIN_PX).astype(np.int64)
    b -= b.min()
    ps = np.sort(psi)
    gaps = np.diff(np.concatenate([ps, ps[:1] + 2.0 * np.pi]))
    k = int(np.argmax(gaps))
    x = np.angle(np.exp(1j * (psi - ps[k] - 0.5 * gaps[k] - np.pi)))
    x = x / max(float(np.max(np.abs(x))), 1e-12)
    onehot = np.zeros((b.size, b.max() + 1))
    onehot[np.arange(b.size), b] = 1.0
    B = np.concatenate([onehot, onehot * x[:, None], onehot * (x * x)[:, None]], axis=1)
    return np.linalg.qr(B[:, B.any(axis=0)])[0]


def along_limb(A: np.ndarray, s: np.ndarray, psi: np.ndarray) -> np.ndarray:
    """``A`` less its least-squares quadratic in the position angle over the pixels at the same distance from the
    limb (:func:`along_basis`): what varies along the limb.

    Parameters
    ----------
    A : np.ndarray (n,) or (n, k)
        Values (residuals) or columns at the pixels.
    s, psi : np.ndarray (n,)
        As :func:`along_basis`.

    Returns
    -------
    np.ndarray
        Shaped as ``A``.
    """
    Qb = along_basis(s, psi)
    return A - Qb @ (Qb.T @ A)


def residual_field(p: LimbProfileParams, coords: np.ndarray, J: np.ndarray, r: np.ndarray, w: np.ndarray,
                   s: np.ndarray) -> tuple[float, float, float, np.ndarray, np.ndarray]:
    """The albedo field of largest restricted marginal likelihood of a least-squares profile fit's residuals along the
    limb (module docstring), with its consider factor.

    Parameters
    ----------
    p : LimbProfileParams
        The fitted profile (any law; the field is taken under its lunar-Lambert base).
    coords : np.ndarray (n, 2)
        Its pixels.
    J, r, w : np.ndarray
        Its weighted Jacobian ``(n, q)`` by the free parameters, weighted residuals ``(n,)`` and weights ``(n,)``.
    s : np.ndarray (n,)
        Signed distance (px) of the pixels to the fitted limb.

    Returns
    -------
    tuple
        ``(s2, tau2, ell_deg, U, GU)``: the noise's and the field's variances, its length, its weighted columns
        ``(n, m)`` and ``G U`` ``(q, m)`` (the consider term is ``tau2 GU GU^T``).
    """
    q = LimbProfileParams(*[getattr(p, k) for k in LimbProfileParams.field_names()])
    psi = np.arctan2(coords[:, 0] - float(p.r0), coords[:, 1] - float(p.c0))
    Qb = along_basis(s, psi)
    rv = r - Qb @ (Qb.T @ r)
    QJ, RJ = np.linalg.qr(J)
    QbJ, QJr = Qb.T @ QJ, QJ.T @ rv
    best = (math.inf, float(rv @ rv) / max(rv.size, 1), 0.0, ELL_DEG[0], np.zeros((J.shape[0], 1)),
            np.zeros((J.shape[1], 1)))
    for ell in ELL_DEG:
        U = field_factor(q, coords, math.radians(ell)) * w[:, None]
        Uj = QJ.T @ U  # U's part in the fit's span (the fit absorbs it), then what is left of it along the limb:
        X = Qb.T @ U - QbJ @ Uj  # the Gram of (I - P_B)(I - P_J) U without forming it (n m^2 once, for U^T U)
        V, S = gram_basis(U.T @ U - Uj.T @ Uj - X.T @ X)
        s2, t2, nll = projected_likelihood(float(rv @ rv), V.T @ (U.T @ rv - Uj.T @ QJr) / S, S, rv.size)
        if nll < best[0]:
            best = (nll, s2, t2, ell, U, Uj)
    _, s2, t2, ell, U, Uj = best
    return s2, t2, ell, U, np.linalg.solve(RJ, Uj)


def albedo_consider(p: LimbProfileParams, coords: np.ndarray, J: np.ndarray, r: np.ndarray, w: np.ndarray,
                    s: np.ndarray) -> tuple[np.ndarray, float, float]:
    """The consider covariance ``tau^2 G U U^T G^T`` of a least-squares profile fit (module docstring) under the field
    of :func:`residual_field`.

    Parameters
    ----------
    p, coords, J, r, w, s
        As :func:`residual_field`'s.

    Returns
    -------
    tuple
        ``(C_a, tau, ell_deg)``: the term ``(q, q)`` over the free parameters, the field's amplitude and length.
    """
    _, t2, ell, _, GU = residual_field(p, coords, J, r, w, s)
    return t2 * (GU @ GU.T), math.sqrt(t2), ell


def with_albedo_term(C: np.ndarray, C0: np.ndarray, Ca: np.ndarray) -> np.ndarray:
    """A fit's covariance widened by what its model-error terms did not already carry of the albedo's consider term:
    ``C + [Ca - (C - C0)]_+``, above both.

    Parameters
    ----------
    C, C0 : np.ndarray (q, q)
        The fit's covariance with its model-error terms, and its noise-only part.
    Ca : np.ndarray (q, q)
        The consider term (:func:`albedo_consider`).

    Returns
    -------
    np.ndarray (q, q)
    """
    return C + positive_part(Ca - (C - C0))


__all__ = ["ELL_DEG", "RADIAL_BIN_PX", "TAU_MAX", "albedo_consider", "along_basis", "along_limb", "field_factor",
           "field_likelihood", "gram_basis", "projected_likelihood", "residual_field", "thin_svd", "with_albedo_term"]
