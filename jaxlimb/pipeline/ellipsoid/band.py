"""The band of pixels about the current limb ellipse that the ellipsoid's edge fit uses (lit window, half-width
``band_px``; level-normalised per traced ray on a patchy limb), the edge model's start, and edits of an edge fit's
ellipse."""

from __future__ import annotations

import math
from dataclasses import replace
from typing import Any

import equinox as eqx
import numpy as np

from ...geometry.conic import ellipse_signed_distance
from ...models import EllipseParams, EllipseRampParams
from ..options import EllipsoidOptions
from ..sigmoid import K_INIT
from ..stages import EllipsePixels, EllipsoidEdge, FitData
from .trace_fit import normalised_band


# =============================================================================== pixel selection
def band_pixels(shape, ell: tuple, band: float, lit_dir, half_angle: float) -> np.ndarray:
    """Pixels ``(row, col)`` within ``band`` px of the ellipse and inside the lit arc.

    Parameters
    ----------
    shape : tuple of int
        The image's ``(rows, cols)``; pixels outside it are not returned.
    ell : tuple
        The ellipse ``((r0, c0), (a, b), theta)``: centre (px, ``(row, col)``), semi-axes (px), orientation (rad).
    band : float
        Half-width (px) of the band, in the signed distance of :func:`~jaxlimb.geometry.conic.ellipse_signed_distance`.
    lit_dir : tuple of float or None
        Direction ``(d_row, d_col)`` from the centre toward the middle of the lit arc; ``None``: all round.
    half_angle : float
        Half-angle (rad) of the lit arc about ``lit_dir``.

    Returns
    -------
    np.ndarray (n, 2)
        The selected pixel centres ``(row, col)`` (float).
    """
    (r0, c0), (a, b), th = ell
    R = a + band + 2
    rows = np.arange(max(0, int(math.floor(r0 - R))), min(shape[0], int(math.ceil(r0 + R)) + 1))
    cols = np.arange(max(0, int(math.floor(c0 - R))), min(shape[1], int(math.ceil(c0 + R)) + 1))
    if rows.size == 0 or cols.size == 0:
        return np.zeros((0, 2))
    rr, cc = np.meshgrid(rows.astype(float), cols.astype(float), indexing="ij")
    dr, dc = rr - r0, cc - c0
    m = np.abs(ellipse_signed_distance(np.stack([rr, cc], axis=-1), ell)) <= band
    if lit_dir is not None:
        d = np.array(lit_dir, float)
        d /= np.linalg.norm(d)
        nrm = np.hypot(dr, dc)
        cosang = (dr * d[0] + dc * d[1]) / np.maximum(nrm, 1e-300)
        m &= cosang >= math.cos(half_angle)
    return np.column_stack([rr[m], cc[m]])


def band_data(img: np.ndarray, ell: tuple, band: float, pix: "EllipsePixels") -> FitData:
    """The band's pixels and values; with a trace, level-normalised per ray (rays without a limb against the
    sky, or with a cloud edge inside the band, left out: :func:`~jaxlimb.pipeline.ellipsoid.trace_fit.normalised_band`).

    Parameters
    ----------
    img : np.ndarray (rows, cols)
        The grey image.
    ell : tuple
        The current ellipse ``((r0, c0), (a, b), theta)`` (px, rad).
    band : float
        Half-width (px) of the band about ``ell``.
    pix : EllipsePixels
        The lit window (``lit_dir``, ``half``) and, on a patchy limb, the traced rays.

    Returns
    -------
    FitData
        Pixels ``(row, col)`` and intensities in DN (``offset = 0``, ``scale = 1``, no weights), or on a patchy
        limb the per-ray normalised values, weights and the DN scale.
    """
    pts = band_pixels(img.shape, ell, band, pix.lit_dir, pix.half)
    if pix.patchy:

        return normalised_band(img, pts, pix.trace)[1]
    return FitData(pts, np.asarray(img[pts[:, 0].astype(int), pts[:, 1].astype(int)], float), None, 0.0, 1.0)


def first_levels(img: np.ndarray, pts: np.ndarray, z: np.ndarray, ell: tuple, band: float) -> tuple[float, float]:
    """The first edge fit's start levels: the medians of the pixels more than ``band / 2`` px inside and
    outside the ellipse.

    Parameters
    ----------
    img : np.ndarray (rows, cols)
        The image (unused: the levels come from ``z``).
    pts : np.ndarray (n, 2)
        The band's pixels ``(row, col)``.
    z : np.ndarray (n,)
        Their values.
    ell : tuple
        The ellipse ``((r0, c0), (a, b), theta)`` (px, rad) the band is about.
    band : float
        The band's half-width (px).

    Returns
    -------
    tuple of float
        ``(ymax, ymin)``, the inside and outside levels; the 90th and 10th percentiles of ``z`` where a side is empty.
    """
    F = ellipse_signed_distance(pts, ell)
    inner, outer = z[F < -0.5 * band], z[F > 0.5 * band]
    ymax = float(np.median(inner)) if inner.size else float(np.percentile(z, 90))
    ymin = float(np.median(outer)) if outer.size else float(np.percentile(z, 10))
    return ymax, ymin


def edge_start(eo: EllipsoidOptions, ell: tuple, prev: Any, levels: tuple[float, float]) -> Any:
    """The edge model's start: the current ellipse, the previous fit's other parameters (or the levels).

    Parameters
    ----------
    eo : EllipsoidOptions
        ``interior_ramp`` chooses :class:`~jaxlimb.models.EllipseRampParams` over
        :class:`~jaxlimb.models.EllipseParams` for a first fit.
    ell : tuple
        The ellipse ``((r0, c0), (a, b), theta)`` (px, rad); sets ``r0, c0, a, rho = b / a, theta``.
    prev : EllipseParams or EllipseRampParams or None
        The previous fit's parameters (their ``k``, levels and ramp kept), ``None`` for the first fit.
    levels : tuple of float
        ``(ymax, ymin)`` of a first fit (:func:`first_levels`); ``k`` starts at ``K_INIT`` and the ramp at 0.

    Returns
    -------
    EllipseParams or EllipseRampParams
        The start of the elliptical sigmoid fit (Mortari et al. 2016 §V-C).
    """
    (r0, c0), (a, b), th = ell
    geo = dict(r0=r0, c0=c0, a=a, theta=th, rho=b / a)
    if prev is not None:
        return prev.replace(**geo)
    kw = dict(**geo, k=K_INIT, ymax=levels[0], ymin=levels[1])
    return EllipseRampParams(**kw, g=0.0, g2=0.0, h1=0.0, h2=0.0, h3=0.0, h4=0.0) if eo.interior_ramp else EllipseParams(**kw)


def with_ellipse(edge: EllipsoidEdge, fitted: tuple) -> EllipsoidEdge:
    """``edge`` answering ellipse ``fitted`` (``fitted`` and its final fit's ``r0, c0, a, rho, theta``).

    Parameters
    ----------
    edge : EllipsoidEdge
        The edge fit to edit.
    fitted : tuple
        The new ellipse ``((r0, c0), (a, b), theta)`` (px, rad).

    Returns
    -------
    EllipsoidEdge
        A copy whose ``fitted`` and final fit's parameters are the new ellipse (levels, ``k`` and covariance unchanged).
    """
    (r0, c0), (a, b), th = fitted
    P = edge.final.fit.params.replace(r0=r0, c0=c0, a=a, rho=b / a, theta=th)
    return replace(edge, final=replace(edge.final, fit=eqx.tree_at(lambda x: x.params, edge.final.fit, P)), fitted=fitted)


def shifted(edge: EllipsoidEdge, shift: tuple | None) -> EllipsoidEdge:
    """``edge`` with its ``(r0, c0, a)`` moved by ``shift`` (the rays' shading correction,
    :func:`~jaxlimb.pipeline.ellipsoid.patchy.ray_geometry`): the band fit of the level-normalised pixels assumes the
    same flat inside as the rays' half-level crossings.

    Parameters
    ----------
    edge : EllipsoidEdge
        The band fit.
    shift : tuple of float or None
        ``(d_r0, d_c0, d_a)`` (px) added to the ellipse's centre and semi-major axis (``b`` scaled with ``a``);
        ``None``: no shift.

    Returns
    -------
    EllipsoidEdge
        The shifted edge (``edge`` itself when ``shift`` is ``None``).
    """
    if shift is None:
        return edge
    (r0, c0), (a, b), th = edge.fitted
    return with_ellipse(edge, ((r0 + shift[0], c0 + shift[1]), (a + shift[2], (a + shift[2]) * b / a), th))


__all__ = ["band_data", "band_pixels", "edge_start", "first_levels", "shifted", "with_ellipse"]
