r"""Model images for render-and-register (:mod:`.register`): radiance, coverage, attitude derivatives.

The coarse pyramid levels (simplified mesh, level cameras, box-averaged frames) are in :mod:`.model_levels`.

**Model image.**  The shape model at pose ``(R, t)`` is rasterised in a pixel window
(:func:`jaxlimb.render.mesh.rasterise`, flat facets, ``supersample`` sub-pixels per side, box filter): the
radiance ``M`` (unit albedo, zero sky) and the coverage ``C``.

**Attitude derivatives without extra renders.**  A small rotation ``omega`` (camera frame) of the body about its
centre ``t`` moves the surface point ``X`` by ``dX = omega x (X - t)`` and turns the facet normals by
``omega x n``.  With the visible point ``X = Z (x_n, y_n, 1)`` of each pixel (the ray through the pixel centre
meets the plane of the facet seen there) the pinhole image moves by

.. math::  \dot c = f\,(\dot X_x - x_n \dot X_z)/Z, \qquad
           \dot r = f\,(\dot X_y - y_n \dot X_z)/Z,

so ``dM/domega_i = -grad M . flow_i + dM_shading/domega_i``: one render gives the three columns the finite
differences took three more renders for.  For Lommel-Seeliger ``rho = 2 mu0 / (mu0 + mu)``:
``d rho = 2 (mu d mu0 - mu0 d mu) / (mu0 + mu)^2`` with ``d mu0 = omega . (n x s)``, ``d mu = omega . (n x e)``.
The outline is not a material line: within 2 px of it the flow is that of the nearest limb vertex (the contour
generator).
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from .._identity_cache import IdentityCache
from .._validate import Range, number
from ..render.mesh import cross_rows, rasterise, shade, shadow_fractions
from .mesh import Mesh
from .model_levels import clustered_mesh, downsample, level_camera, window_camera


@dataclass(frozen=True)
class ModelImage:
    """The model in the window ``lo..hi`` (:func:`render_window`).

    Attributes
    ----------
    M, C
        Radiance (unit albedo) and coverage, ``(h, w)``.
    flow
        ``(3, 2, h, w)``: image motion (row, col px per rad) of the visible surface for a
        rotation about each camera axis; ``None`` unless asked for.  Zero off the body.
    shading
        ``(3, h, w)``: derivative of the radiance for the same rotations (facet normals).
    on_body
        ``(h, w)`` bool: pixels whose centre sees a facet (where ``flow`` is defined).
    dM_dmix
        ``(len(mix), h, w)``: derivatives of ``M`` for the photometric mix (the laws, then smooth shading)
        (:func:`render_window`); ``None`` unless ``mix`` was given.
    """

    M: np.ndarray
    C: np.ndarray
    flow: np.ndarray | None = None
    shading: np.ndarray | None = None
    on_body: np.ndarray | None = None
    dM_dmix: np.ndarray | None = None


def render_window(
    mesh: Mesh, camera: object, R: np.ndarray, t: np.ndarray, sun: np.ndarray | None, lo, hi, supersample: int,
    reflectance: str = "lommel-seeliger", jacobian: bool = False, mix: np.ndarray | None = None,
    shadows: bool = False, exact: bool = True,
) -> ModelImage:  # fmt: skip
    """The model image in the window ``lo..hi`` of ``camera`` (module docstring).

    Parameters
    ----------
    mesh, camera, R, t, sun
        Shape model, camera, pose ``x_cam = R x_body + t`` (km), unit Sun vector (camera frame; ``None``: zero phase).
    lo, hi, supersample, reflectance, jacobian
        Window (first, last pixel (row, col)), sub-pixels per side, base law; also the attitude derivatives.
    mix, shadows, exact
        ``(m_1, .., m_n, m_s)``: radiance ``LS + sum_j m_j (law_j - LS) + m_s (smooth - flat)`` over the first ``n``
        laws of :data:`MIX_LAWS` (:func:`_smooth_minus_flat`), with ``dM_dmix``; each facet scaled by its lit fraction
        (:func:`shadow_fractions`); every sub-pixel shows the facet containing its centre (off on pyramid levels).

    Returns
    -------
    ModelImage
    """
    cam = window_camera(camera, lo, hi)
    h, w = cam.shape  # type: ignore[attr-defined]
    M, C = np.zeros((h, w)), np.zeros((h, w))
    t = np.asarray(t, dtype=float)
    Xc = np.asarray(mesh.vertices, dtype=float) @ np.asarray(R, dtype=float).T + t
    F = np.asarray(mesh.faces, dtype=np.int64)
    ras = rasterise(Xc, F, cam, supersample, exact)
    if ras is None:
        return ModelImage(M, C, np.zeros((3, 2, h, w)) if jacobian else None, np.zeros((3, h, w)) if jacobian else None)
    s = -t / np.linalg.norm(t) if sun is None else np.asarray(sun, dtype=float)
    mu0 = np.einsum("ij,j->i", ras.normals, s)  # not BLAS: see register.design.normal_equations
    lit = shadow_fractions(mesh.vertices, mesh.faces, np.asarray(R, dtype=float).T @ s) if shadows else np.ones(F.shape[0])
    flat = shade(mu0, ras.mu, reflectance)  # per facet
    win = (slice(ras.r0, ras.r0 + ras.h), slice(ras.c0, ras.c0 + ras.w))
    laws = () if mix is None else mix_laws(len(mix) - 1)
    dflat = [_basis(mu0, ras.mu, law) - flat for law in laws]
    drho = [d * lit for d in dflat]
    rho = flat * lit
    for j, d in enumerate(drho):
        rho = rho + mix[j] * d  # type: ignore[index]
    pix = _facet_means(ras, [rho, *drho, np.ones(F.shape[0])])  # radiance, mix columns, coverage
    M[win], C[win] = pix[0], pix[-1]
    D = None
    if mix is not None:
        D = np.zeros((len(laws) + 1, h, w))
        for j in range(len(laws)):
            D[j][win] = pix[1 + j]
        flat_mix = flat + sum(mix[j] * d for j, d in enumerate(dflat))  # the fitted mix's flat radiance
        vn = body_vertex_normals(mesh) @ np.asarray(R, dtype=float).T  # the camera frame's: rotation-equivariant
        D[-1][win] = _smooth_minus_flat(ras, Xc, F, vn, cam, s, MixedLaw(reflectance, tuple(mix[:-1])), supersample,
                                        flat_mix, lit, pix[-1])
        M += mix[-1] * D[-1]
    if not jacobian:
        return ModelImage(M, C, dM_dmix=D)
    flow, shading, on = np.zeros((3, 2, h, w)), np.zeros((3, h, w)), np.zeros((h, w), dtype=bool)
    out = (flow[:, :, win[0], win[1]], shading[:, win[0], win[1]], on[win])  # written in place
    _pixel_derivatives(ras, Xc, F, cam, t, s, mu0, supersample, reflectance, C[win] >= 0.5, out, mix, lit if shadows else None)
    return ModelImage(M, C, flow, shading, on, D)


def _facet_means(ras, values: list) -> list:  # type: ignore[no-untyped-def]
    """Pixel means (box filter over the sub-pixels) of per-facet ``values`` (0 on the sky): ``(h, w)`` float32 each.

    One gather of a ``(facets + 1, channels)`` table by the face-index buffer and one area resize of all
    channels (up to four per resize): the sub-pixel buffer is read once, not once per quantity."""
    out = []
    for j in range(0, len(values), 4):
        tab = np.zeros((len(values[0]) + 1, len(values[j : j + 4])), np.float32)
        for i, v in enumerate(values[j : j + 4]):
            tab[1:, i] = v
        sub = np.take(tab, ras.buf, axis=0)
        res = cv2.resize(sub if tab.shape[1] > 1 else sub[..., 0], (ras.w, ras.h), interpolation=cv2.INTER_AREA)
        out += [res] if tab.shape[1] == 1 else [res[..., i] for i in range(tab.shape[1])]
    return out


#: The laws mixed into the model radiance by ``render_window(mix=...)``.
MIX_LAWS = ("lambert", "minnaert-half", "minnaert-3/4")
_MINNAERT_K = {"minnaert-half": 0.5, "minnaert-3/4": 0.75}
_MU_MIN = 0.05  # Minnaert's mu^(k-1) is held finite at grazing emission (flat facets at the outline)


@dataclass(frozen=True)
class MixedLaw:
    """The model's reflectance ``base + sum_j weights_j (MIX_LAWS_j - base)`` as a function of ``(mu0, mu)``.

    The smooth-shading column (:func:`_smooth_minus_flat`) is the smooth minus the flat radiance *of the
    fitted mix*: with the base law's (Lommel-Seeliger) instead, a ray-traced Lambert Thebe at 60 deg
    phase was registered 0.51 px off (smooth-shading weight fitted 0.49, PSF 1.6 px for 0.8); with the
    mix's, 0.11 px (weight 0.98).
    """

    base: str
    weights: tuple = ()

    def __call__(self, mu0: np.ndarray, mu: np.ndarray) -> np.ndarray:
        flat = shade(mu0, mu, self.base)
        out = flat
        for w, law in zip(self.weights, MIX_LAWS):
            out = out + float(w) * (_basis(mu0, mu, law) - flat)
        return out


def mix_laws(n: int) -> tuple[str, ...]:
    """The first ``n`` laws of :data:`MIX_LAWS` (a mix of ``n + 1`` weights: those laws, then smooth shading).

    Parameters
    ----------
    n : int
        ``0 <= n <= len(MIX_LAWS)``, else a :class:`~jaxlimb.errors.ConfigError`.

    Returns
    -------
    tuple of str
    """
    return MIX_LAWS[: number(n, "mix_laws", Range(0, len(MIX_LAWS)), integer=True)]


def _basis(mu0: np.ndarray, mu: np.ndarray, law: str) -> np.ndarray:
    """Radiance per unit albedo of a :data:`MIX_LAWS` law (0 where unlit or unseen): Lambert ``mu0``, or
    Minnaert ``mu0^k mu^(k - 1)`` (Minnaert 1941) with ``k`` of :data:`_MINNAERT_K`."""
    if law == "lambert":
        return shade(mu0, mu, "lambert")
    k = _MINNAERT_K[law]
    if k == 0.5:  # the square root of the ratio: the same floats as before the other exponents
        return np.where((mu0 > 0) & (mu > 0), np.sqrt(np.maximum(mu0, 0.0) / np.maximum(mu, _MU_MIN)), 0.0)
    return np.where((mu0 > 0) & (mu > 0), np.maximum(mu0, 0.0) ** k * np.maximum(mu, _MU_MIN) ** (k - 1.0), 0.0)


def _basis_derivative(mu0, mu, dmu0, dmu, law):  # type: ignore[no-untyped-def]
    """``(nf, 3)`` derivative of :func:`_basis` for the rotations (``dmu0``, ``dmu``: ``(nf, 3)``)."""
    if law == "lambert":
        return dmu0
    k = _MINNAERT_K[law]
    m = np.maximum(mu, _MU_MIN)
    r = np.sqrt(np.maximum(mu0, 1e-12) / m) if k == 0.5 else np.maximum(mu0, 1e-12) ** k * m ** (k - 1.0)
    return r[:, None] * (k * dmu0 / np.maximum(mu0, 1e-12)[:, None] + (k - 1.0) * np.where(mu > _MU_MIN, 1.0 / m, 0.0)[:, None] * dmu)


def _safe(x: np.ndarray) -> np.ndarray:
    return np.where(np.abs(x) > 1e-12, x, 1e-12)


def _vertex_normals(Xc: np.ndarray, F: np.ndarray) -> np.ndarray:
    """Unit vertex normals: the facets' unit normals weighted by their angle at the vertex (Thurmer & Wuthrich
    1998, "Computing vertex normals from polygonal facets", J. Graphics Tools 3(1), Eq. 1).

    Angle weights do not depend on how the surface round the vertex is cut into triangles; area weights
    lean toward the large facets.  On a ray-traced elongated body at 90 deg phase (smooth shading,
    lunar-Lambert, uniform albedo; ``benchmarks/irregular_independent.py``'s view) the registration
    moved 0.131 -> 0.089 px with them (the independent renderer's normals are these, from ``trimesh``)."""
    P = [np.take(Xc, F[:, i], axis=0) for i in range(3)]
    n = cross_rows(P[1] - P[0], P[2] - P[0])
    n /= np.maximum(np.linalg.norm(n, axis=1, keepdims=True), 1e-300)
    w = np.empty((len(F), 3))
    for i in range(3):
        a, b = P[(i + 1) % 3] - P[i], P[(i + 2) % 3] - P[i]
        cos = np.einsum("ij,ij->i", a, b) / np.maximum(np.linalg.norm(a, axis=1) * np.linalg.norm(b, axis=1), 1e-300)
        w[:, i] = np.arccos(np.clip(cos, -1.0, 1.0))
    idx = F.ravel()  # (face, corner) order
    vn = np.stack([np.bincount(idx, weights=(w * n[:, j : j + 1]).ravel(), minlength=len(Xc)) for j in range(3)], axis=1)
    return vn / np.maximum(np.linalg.norm(vn, axis=1, keepdims=True), 1e-300)


_NORMALS = IdentityCache(maxsize=9)


def body_vertex_normals(mesh: Mesh) -> np.ndarray:
    """:func:`_vertex_normals` of the mesh in its body frame, computed once per mesh (rotating the vertices rotates
    the normals: ``R`` applied to these equals them recomputed from the rotated vertices to ~1e-16).

    Parameters
    ----------
    mesh : Mesh

    Returns
    -------
    np.ndarray (N, 3)
        Unit normals, one per vertex.
    """
    return _NORMALS.get((mesh.vertices, mesh.faces), lambda: _vertex_normals(np.asarray(mesh.vertices, float),
                                                                             np.asarray(mesh.faces, np.int64)))


def _smooth_minus_flat(ras, Xc, F, vn, cam, s, reflectance, ss, flat, lit, cover):  # type: ignore[no-untyped-def]
    """``(h, w)``: radiance with normals interpolated across each facet (barycentric weights of
    the vertex normals, Phong) minus the facet's flat radiance ``flat`` (per facet), times its lit
    fraction ``lit`` (``cover``: the raster's pixel coverage).

    A real body is smooth where its shape model is faceted: the registration fits the mix of
    the two (one more linear column, :class:`~.register.RegisterOptions`); ``vn``: the unit vertex normals
    (camera frame, :func:`body_vertex_normals` rotated).  The smooth radiance of
    interior pixels is computed at every other pixel and interpolated (it varies slowly; the flat
    radiance it is compared with is each pixel's own); pixels the outline crosses are sampled at
    every sub-pixel (area average), where smooth normals graze the line of sight and the two
    differ most.
    """
    buf = ras.buf
    center = buf[ss // 2 :: ss, ss // 2 :: ss][: ras.h, : ras.w]
    inner = (center > 0) & (cover > 0.999)
    out = np.zeros((ras.h, ras.w))
    smooth = _interior_smooth(ras, Xc, F, vn, cam, s, reflectance, center, inner)
    rr, cc = np.nonzero(inner)
    face = center[rr, cc] - 1
    out[rr, cc] = (smooth[rr, cc] - flat[face]) * lit[face]
    er, ec = np.nonzero((cover > 0) & ~inner)
    if er.size:
        o = np.arange(ss)
        sr = (er[:, None, None] * ss + o[None, :, None]) * np.ones((1, 1, ss), int)
        sc = (ec[:, None, None] * ss + o[None, None, :]) * np.ones((1, ss, 1), int)
        face = buf[sr, sc]
        hit = face > 0
        diff = np.zeros(face.shape)
        fh = face[hit] - 1
        diff[hit] = (_smooth_samples(ras, Xc, F, vn, cam, s, reflectance, (sr[hit] + 0.5) / ss - 0.5, (sc[hit] + 0.5) / ss - 0.5, fh)
                     - flat[fh]) * lit[fh]
        out[er, ec] = diff.reshape(er.size, -1).mean(axis=1)
    return out


def _interior_smooth(ras, Xc, F, vn, cam, s, reflectance, center, inner):  # type: ignore[no-untyped-def]
    """``(h, w)`` smooth radiance on the ``inner`` pixels: exact at every other pixel, bilinear (normalised by
    the sampled weight) in between, exact where fewer than half of the neighbours were sampled."""
    h, w = inner.shape
    hr, hc = np.nonzero(inner[::2, ::2])
    S = np.zeros(((h + 1) // 2, (w + 1) // 2), np.float32)
    W = np.zeros_like(S)
    r2, c2 = 2 * hr, 2 * hc
    S[hr, hc] = _smooth_samples(ras, Xc, F, vn, cam, s, reflectance, r2.astype(float), c2.astype(float), center[r2, c2] - 1)
    W[hr, hc] = 1.0
    my, mx = np.meshgrid(np.arange(h, dtype=np.float32) / 2, np.arange(w, dtype=np.float32) / 2, indexing="ij")
    Si = cv2.remap(S, mx, my, cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT, borderValue=0)
    Wi = cv2.remap(W, mx, my, cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT, borderValue=0)
    out = np.where(Wi > 0.5, Si / np.maximum(Wi, 1e-6), 0.0).astype(float)
    er, ec = np.nonzero(inner & (Wi <= 0.5))
    if er.size:
        out[er, ec] = _smooth_samples(ras, Xc, F, vn, cam, s, reflectance, er.astype(float), ec.astype(float), center[er, ec] - 1)
    return out


def _smooth_samples(ras, Xc, F, vn, cam, s, reflectance, r, c, face):  # type: ignore[no-untyped-def]
    """Smooth (vertex-normal interpolated) radiance at raster pixel coordinates ``(r, c)`` seeing ``face``
    (``reflectance``: a law name of :func:`~jaxlimb.render.mesh.shade` or a :class:`MixedLaw`)."""
    f = cam.focal_px  # type: ignore[attr-defined]
    pr, pc = cam.principal_point_rc  # type: ignore[attr-defined]
    ray = np.stack([(ras.c0 + c - pc) / f, (ras.r0 + r - pr) / f, np.ones(r.size)], axis=1)
    v0, v1, v2 = (np.take(Xc, F[face, i], axis=0) for i in range(3))  # take: a faster gather
    n = ras.normals[face]
    X = (np.einsum("ij,ij->i", n, v0) / _safe(np.einsum("ij,ij->i", n, ray)))[:, None] * ray
    e0, e1, q = v1 - v0, v2 - v0, X - v0
    d00, d01, d11 = (e0 * e0).sum(1), (e0 * e1).sum(1), (e1 * e1).sum(1)
    d20, d21 = (q * e0).sum(1), (q * e1).sum(1)
    den = _safe(d00 * d11 - d01**2)
    b1 = np.clip((d11 * d20 - d01 * d21) / den, 0.0, 1.0)
    b2 = np.clip((d00 * d21 - d01 * d20) / den, 0.0, 1.0 - b1)
    n0, n1, n2 = (np.take(vn, F[face, i], axis=0) for i in range(3))
    ns = (1.0 - b1 - b2)[:, None] * n0 + b1[:, None] * n1 + b2[:, None] * n2
    ns /= np.maximum(np.linalg.norm(ns, axis=1, keepdims=True), 1e-300)
    eye = -X / np.linalg.norm(X, axis=1, keepdims=True)
    mu0, mu = np.einsum("ij,j->i", ns, s), np.maximum(np.einsum("ij,ij->i", ns, eye), 1e-3)
    return reflectance(mu0, mu) if callable(reflectance) else shade(mu0, mu, reflectance)


def _pixel_derivatives(ras, Xc, F, cam, t, s, mu0, ss, reflectance, cover, out, mix=None, shadow=None) -> None:  # type: ignore[no-untyped-def]
    """Flow ``(3, 2, h, w)``, shading derivative ``(3, h, w)`` and on-body mask of the raster's pixels, written
    in ``out`` (views of the window's arrays); ``cover``: pixels at least half covered; ``mix``, ``shadow``:
    :func:`render_window`'s photometric mix and lit fractions."""
    flow, shading, on = out
    idx = ras.buf[ss // 2 :: ss, ss // 2 :: ss][: ras.h, : ras.w]
    np.greater(idx, 0, out=on)
    face = np.maximum(idx - 1, 0)
    n = ras.normals
    d = np.einsum("ij,ij->i", n, np.take(Xc, F[:, 0], axis=0))  # facet planes n . X = d
    f = cam.focal_px  # type: ignore[attr-defined]
    pr, pc = cam.principal_point_rc  # type: ignore[attr-defined]
    yn = ((ras.r0 + np.arange(ras.h)) - pr)[:, None] / f  # (h, 1), broadcast against (1, w)
    xn = ((ras.c0 + np.arange(ras.w)) - pc)[None, :] / f
    den = np.take(n[:, 0], face) * xn + np.take(n[:, 1], face) * yn + np.take(n[:, 2], face)
    Z = np.where(on, np.take(d, face) / np.where(np.abs(den) > 1e-12, den, 1e-12), 1.0)
    _rotation_flow(Z * xn - t[0], Z * yn - t[1], Z - t[2], xn, yn, f / Z * on, out=flow)  # zero off the body
    _limb_flow(flow, ras, Xc, F, cam, t, cover)
    cen = (np.take(Xc, F[:, 0], axis=0) + np.take(Xc, F[:, 1], axis=0) + np.take(Xc, F[:, 2], axis=0)) / 3.0
    e = -cen / np.linalg.norm(cen, axis=1, keepdims=True)
    dmu0, dmu = cross_rows(n, s), cross_rows(n, e)  # (nf, 3): d mu0 / d omega, d mu / d omega
    mu = ras.mu
    lit = (mu0 > 0) & (mu > 0)
    if reflectance == "lommel-seeliger":
        drho = 2.0 * (mu[:, None] * dmu0 - mu0[:, None] * dmu) / np.maximum(mu0 + mu, 1e-12)[:, None] ** 2
    else:
        drho = dmu0
    if mix is not None:
        base = drho
        for j, law in enumerate(mix_laws(len(mix) - 1)):  # (the smooth-shading column, mix[-1], is left out here)
            drho = drho + mix[j] * (_basis_derivative(mu0, mu, dmu0, dmu, law) - base)
    drho = np.where(lit[:, None], drho, 0.0) * (1.0 if shadow is None else shadow[:, None])
    drho = np.concatenate([np.zeros((1, 3)), drho])  # row 0: off the body
    np.take(drho.T, idx, axis=1, out=shading)


def _rotation_flow(qx, qy, qz, xn, yn, f_over_z, out=None):  # type: ignore[no-untyped-def]
    """``(3, 2, ...)`` image motion (row, col) of points ``Q = X - t`` seen along ``(xn, yn, 1)`` for a rotation
    about each camera axis: ``dX = e_i x Q``, ``dr = f (dX_y - yn dX_z) / Z``, ``dc = f (dX_x - xn dX_z) / Z``
    (in ``out`` if given)."""
    if out is None:
        out = np.empty((3, 2) + np.broadcast_shapes(*(np.shape(a) for a in (qx, qy, qz, xn, yn, f_over_z))))
    out[0, 0], out[0, 1] = (-qz - yn * qy) * f_over_z, -xn * qy * f_over_z  # e_x x Q = (0, -qz, qy)
    out[1, 0], out[1, 1] = yn * qx * f_over_z, (qz + xn * qx) * f_over_z  # e_y x Q = (qz, 0, -qx)
    out[2, 0], out[2, 1] = qx * f_over_z, -qy * f_over_z  # e_z x Q = (-qy, qx, 0)
    return out


def _limb_flow(flow, ras, Xc, F, cam, t, cover) -> None:  # type: ignore[no-untyped-def]
    """Within 2 px of the outline, the flow of the nearest limb vertex (in place).

    The outline of a smooth body is not a material line: it moves with the contour
    generator (vertices shared by a facet turned to the camera and one turned away), whose
    image velocity, not that of the grazing facet behind the pixel, moves the edge.
    """
    front = ras.mu > 0
    seen, unseen = np.zeros(len(Xc), bool), np.zeros(len(Xc), bool)
    seen[F[front].ravel()] = True
    unseen[F[~front].ravel()] = True
    limb = np.nonzero(seen & unseen)[0]
    k5 = np.ones((5, 5), np.uint8)
    band = (cv2.dilate(cover.astype(np.uint8), k5) > 0) & ~(cv2.erode(cover.astype(np.uint8), k5) > 0)
    if limb.size == 0 or not band.any():
        return
    X = Xc[limb]
    f = cam.focal_px  # type: ignore[attr-defined]
    pr, pc = cam.principal_point_rc  # type: ignore[attr-defined]
    ri = np.clip(np.rint(pr + f * X[:, 1] / X[:, 2] - ras.r0), 0, ras.h - 1).astype(int)
    ci = np.clip(np.rint(pc + f * X[:, 0] / X[:, 2] - ras.c0), 0, ras.w - 1).astype(int)
    # nearest limb vertex of every pixel: Voronoi labels of the distance transform (C speed)
    seeds = np.ones((ras.h, ras.w), np.uint8)
    seeds[ri, ci] = 0
    _, labels = cv2.distanceTransformWithLabels(seeds, cv2.DIST_L2, 5, labelType=cv2.DIST_LABEL_PIXEL)
    vertex_of_label = np.zeros(int(labels.max()) + 1, dtype=int)
    vertex_of_label[labels[ri, ci]] = np.arange(limb.size)
    rr, cc = np.nonzero(band)
    j = vertex_of_label[labels[rr, cc]]
    Q, Z = X[j] - t, X[j, 2]
    flow[:, :, rr, cc] = _rotation_flow(Q[:, 0], Q[:, 1], Q[:, 2], X[j, 0] / Z, X[j, 1] / Z, f / Z)


def attitude_columns(model: ModelImage, ratio: float, blur, out: np.ndarray | None = None) -> np.ndarray:  # type: ignore[no-untyped-def]
    """``(n, 3)`` derivatives of the blurred ``G = M - ratio C`` for rotations about the camera axes (rad).

    Parameters
    ----------
    model, ratio : ModelImage, float
        A model rendered with ``jacobian=True``; ``b / a`` of the previous solve.
    blur, out : callable, np.ndarray (3, n), optional
        The blur of the iteration; an array to write the columns in (rows of a transposed design matrix).

    Returns
    -------
    np.ndarray (n, 3)
        The transposed view of ``out`` when given.
    """
    G = model.M - ratio * model.C
    gr, gc = np.gradient(G)
    out = np.empty((3, G.size)) if out is None else out
    for i in range(3):
        d = model.shading[i] - gr * model.flow[i, 0] - gc * model.flow[i, 1]  # type: ignore[index]
        out[i] = blur(d).ravel()
    return out.T


__all__ = ["MIX_LAWS", "mix_laws", "ModelImage", "attitude_columns", "clustered_mesh", "downsample", "level_camera", "render_window", "window_camera"]
