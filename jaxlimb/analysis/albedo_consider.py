r"""What an unknown albedo field would do to a ``locate`` answer: its consider covariance.

An albedo that darkens toward the limb in one part of it is, to the pixels there, the same as the edge moved: the fit's
residuals do not show it, so no model-error term built from them (the limb sectors' sandwich, the split witness) can
carry it.  Write the relative albedo as a zero-mean Gaussian field on the sphere (:mod:`jaxlimb.models.profile_columns`:
the profile's columns ``K``, prior ``tau^2 C_ell``, ``U = K C_ell^{1/2}``).  The profile fit is least squares,
``x = G z`` with ``G = (J^T J)^{-1} J^T``, so under the field its error has the consider covariance
``C_a = tau^2 G U U^T G^T`` beside the noise's (Schmidt 1966; Tapley, Schutz & Born 2004, Sec. 6.3).

The amplitude ``tau`` and correlation length ``ell`` (of :data:`~jaxlimb.pipeline.profile.albedo_field.ELL_DEG`) are
those of largest marginal likelihood (:func:`~jaxlimb.pipeline.profile.albedo_field.field_likelihood`) of what of the
residuals varies *along* the limb: the residuals and the field's columns less, at each distance from the limb (bins of
:data:`RADIAL_BIN_PX`), a quadratic in the position angle (:func:`along_limb`), where a reflectance law's or a PSF's misfit lives.  The
field's columns are taken as the residuals see them, ``U - J G U`` (the part the fit absorbs taken out, as restricted
maximum likelihood does; Patterson & Thompson 1971): with ``U`` itself the fit's absorption of a strong field reads as
more field.

:func:`albedo_consider_of` gives, for a :class:`~jaxlimb.analysis.located.LocatedFit` of the physical profile, the
term and ``locate``'s centre covariance widened by what its own model-error terms did not already carry of it
(``C + [C_a - (C - C_0)]_+``, above both), mapped to the body centre.  ``benchmarks/albedo_consider.py`` measures it
on the independent renderer's families.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..model_error import positive_part
from ..models import LimbProfileParams
from ..models.lunar_lambert import profile_model
from ..pipeline.profile.albedo_field import ELL_DEG, field_factor, field_likelihood, thin_svd
from ..pipeline.profile.model_error import signed_distance, weighted_system
from ..pipeline.report import covariance
from ..pipeline.result import covariance_block
from .located import LocatedFit

#: Width (px) of the bins of distance to the limb in :func:`along_limb`: fine against the edge's blur (a PSF sigma of
#: about a pixel), over which a reflectance law's misfit changes.
RADIAL_BIN_PX = 0.25


def along_limb(A: np.ndarray, s: np.ndarray, psi: np.ndarray) -> np.ndarray:
    """``A`` less its least-squares quadratic in the position angle, about the middle of the pixels' arc, over the
    pixels at the same distance from the limb (bins of :data:`RADIAL_BIN_PX`): what varies along the limb.

    Parameters
    ----------
    A : np.ndarray (n,) or (n, k)
        Values (residuals) or columns at the pixels.
    s : np.ndarray (n,)
        Signed distance (px) of the pixels to the limb.
    psi : np.ndarray (n,)
        Their position angle (rad) about the limb's centre.

    Returns
    -------
    np.ndarray
        Shaped as ``A``.
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
    Qb = np.linalg.qr(B[:, B.any(axis=0)])[0]
    return A - Qb @ (Qb.T @ A)


def albedo_consider(p: LimbProfileParams, coords: np.ndarray, J: np.ndarray, r: np.ndarray, w: np.ndarray,
                    s: np.ndarray) -> tuple[np.ndarray, float, float]:
    """The consider covariance ``tau^2 G U U^T G^T`` of a least-squares profile fit (module docstring).

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
        ``(C_a, tau, ell_deg)``: the term ``(q, q)`` over the free parameters, the field's amplitude and length.
    """
    q = LimbProfileParams(*[getattr(p, k) for k in LimbProfileParams.field_names()])
    psi = np.arctan2(coords[:, 0] - float(p.r0), coords[:, 1] - float(p.c0))
    rv = along_limb(r, s, psi)
    best = (math.inf, 0.0, np.zeros((J.shape[1], 1)), 0.0)
    for ell in ELL_DEG:
        U = field_factor(q, coords, math.radians(ell)) * w[:, None]
        GU = np.linalg.lstsq(J, U, rcond=None)[0]
        _, t2, nll = field_likelihood(rv, *thin_svd(along_limb(U - J @ GU, s, psi)))
        if nll < best[0]:
            best = (nll, t2, GU, ell)
    _, t2, GU, ell = best
    return t2 * (GU @ GU.T), math.sqrt(t2), ell


@dataclass(frozen=True)
class AlbedoConsider:
    """:func:`albedo_consider_of`'s answer.

    Attributes
    ----------
    tau, ell_deg : the field's amplitude (relative albedo sigma) and correlation length (deg).
    center : the term on the body centre, ``(2, 2)`` px^2.
    added : what of it ``locate``'s model-error terms did not carry, on the body centre, ``(2, 2)`` px^2.
    locate : ``locate``'s centre covariance, ``(2, 2)`` px^2.
    """

    tau: float
    ell_deg: float
    center: np.ndarray
    added: np.ndarray
    locate: np.ndarray

    @property
    def widened(self) -> np.ndarray:
        """``locate``'s centre covariance with ``added``."""
        return self.locate + self.added


def center_map(lf: LocatedFit) -> np.ndarray:
    """The body centre's derivative by the fit's free parameters: the rows ``center_r, center_c`` of the Jacobian
    ``locate``'s covariance stage maps the fit's covariance with (:func:`jaxlimb.pipeline.report.covariance`).

    Parameters
    ----------
    lf : LocatedFit
        :func:`~jaxlimb.analysis.located.located_fit`'s answer.

    Returns
    -------
    np.ndarray (2, q)
        ``d (row, col) / d x`` over ``lf.free``.
    """
    cov = covariance(lf.final, lf.geo)
    return cov.jacobian[[cov.names.index("center_r"), cov.names.index("center_c")]]


def albedo_consider_of(lf: LocatedFit) -> AlbedoConsider | None:
    """The albedo field's consider covariance of a ``locate`` answer (module docstring); ``None`` unless its final fit
    is the physical profile.

    Parameters
    ----------
    lf : LocatedFit
        :func:`~jaxlimb.analysis.located.located_fit`'s answer.

    Returns
    -------
    AlbedoConsider or None
    """
    rr = lf.final
    p = rr.fit.params
    if not isinstance(p, LimbProfileParams):
        return None
    J, r, padded, w = weighted_system(rr, profile_model(p))
    coords = np.asarray(rr.data.coords, float)
    Ca, tau, ell = albedo_consider(p, coords, J, r, w, signed_distance(p, coords, padded))
    C, C0 = np.asarray(rr.fit.covariance), rr.covariance_noise
    G = center_map(lf)
    cov = lf.measurement.covariance
    P = covariance_block(cov)
    return AlbedoConsider(tau, ell, G @ Ca @ G.T, G @ positive_part(Ca - (C - C0)) @ G.T, P)


__all__ = ["RADIAL_BIN_PX", "AlbedoConsider", "albedo_consider", "albedo_consider_of", "along_limb", "center_map"]
