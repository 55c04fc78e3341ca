r"""Exact ray--ellipsoid intersection and the supersampled radiance image.

Ray casting (camera frame, observer at the origin).  With :math:`q` the body
centre, :math:`R` body->camera and :math:`A = RJR^T`, the ray :math:`X = t\,d`
(:math:`d = K^{-1}[col, row, 1]^T`, i.e. ``d = ((col-cc)/f, (row-rc)/f, 1)``)
meets the ellipsoid where :math:`a t^2 - 2 b t + c = 0`, :math:`a = d^TAd`,
:math:`b = d^TAq`, :math:`c = q^TAq - 1 > 0`.  It hits iff the discriminant
:math:`\Delta = b^2 - ac = d^T M_c d \ge 0` (the tangent cone of Eq. 2 of
Mortari et al. 2016) and :math:`b > 0`; the near root is evaluated in the
cancellation-free form :math:`t = c / (b + \sqrt{\Delta})`.  The outward normal
at :math:`X` is :math:`\propto A(X - q)`; :math:`\mu = -\hat n\cdot\hat d`,
:math:`\mu_0 = \hat n\cdot\hat s`, and the phase angle of the sample is the angle
between :math:`\hat s` and :math:`-\hat d`.

Supersampling.  Each pixel ``(i, j)`` covers ``[i-0.5, i+0.5] x [j-0.5, j+0.5]``.
Pixels whose footprint may cross the limb -- those whose approximate distance
:math:`|Q|/|\nabla Q|` to the limb conic :math:`Q` of
:func:`jaxlimb.geometry.ellipsoid.image_conic` is <= 1 px (the footprint's
half-diagonal is 0.707 px) -- and pixels on either side of a lit/unlit change
between 4-neighbours (the terminator) are averaged over ``n_subsamples`` points
of a rank-1 Fibonacci lattice inside the footprint (an N-rooks set: every row
and column offset ``(k + 1/2)/n - 1/2`` occurs once, so straight edges of any
orientation are resolved to ~1/n of a pixel; the lattice's mean is exactly the
pixel centre).  Every other pixel is shaded at its centre (brightness there is
smooth).  The area-averaged (box) pixel response is what the sensor model then
blurs with the PSF.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..errors import ConfigError
from ..geometry.camera import Camera
from ..geometry.ellipsoid import ImageConic, image_conic
from ._masks import boundary_mask
from .reflectance import LUNAR_LAMBERT_MCEWEN, REFLECTANCE_MODELS, reflectance
from .scene import Scene

__all__ = ["RadianceWindow", "RayHits", "lattice_offsets", "pixel_rays", "render_radiance", "trace_rays"]

_EDGE_THRESHOLD_PX = 1.0


# =============================================================================== lattice
def lattice_offsets(n: int) -> np.ndarray:
    """``n`` sub-pixel offsets ``(n, 2)`` ``(d_row, d_col)`` in ``(-0.5, 0.5)``: a rank-1 Fibonacci lattice.

    Point ``k`` is ``((k + 1/2)/n, ((k g) mod n + 1/2)/n) - 1/2`` with ``g`` the integer
    nearest ``n / golden ratio`` that is coprime to ``n`` (for Fibonacci ``n`` this is the
    Fibonacci lattice).  ``n = 1`` gives the pixel centre.
    """
    if not (isinstance(n, (int, np.integer)) and not isinstance(n, bool) and n >= 1):
        raise ConfigError(f"`n_subsamples` must be an integer >= 1, got {n!r}")
    n = int(n)
    if n == 1:
        return np.zeros((1, 2))
    g0 = n / ((1 + math.sqrt(5)) / 2)
    cands = sorted(range(1, n), key=lambda g: abs(g - g0))
    g = next(c for c in cands if math.gcd(c, n) == 1)
    k = np.arange(n)
    return np.stack([(k + 0.5) / n - 0.5, ((k * g) % n + 0.5) / n - 0.5], axis=-1)


# =============================================================================== rays
def pixel_rays(camera: Camera, rc: np.ndarray) -> np.ndarray:
    """Camera-frame ray directions ``(..., 3)`` with ``z = 1`` for pixel positions ``(..., 2)`` ``(row, col)``."""
    rc = np.asarray(rc, dtype=float)
    r0, c0 = camera.principal_point_rc  # type: ignore[misc]
    f = camera.focal_px
    return np.stack([(rc[..., 1] - c0) / f, (rc[..., 0] - r0) / f, np.ones(rc.shape[:-1])], axis=-1)


@dataclass(frozen=True, eq=False)
class RayHits:
    """Result of :func:`trace_rays` for ``n`` rays (flat arrays).

    ``hit`` (bool), ``t`` (ray parameter of the near hit; NaN on a miss; the point is ``t d``),
    ``point_cam``/``point_body`` (km), ``normal_cam`` (unit), ``mu`` (cos emission), ``mu0``
    (cos incidence; NaN without a Sun), ``alpha`` (sample phase angle, rad), and the
    ellipsoid quadratic's ``a, b, c`` (for the atmosphere)."""

    hit: np.ndarray
    t: np.ndarray
    point_cam: np.ndarray
    point_body: np.ndarray
    normal_cam: np.ndarray
    mu: np.ndarray
    mu0: np.ndarray
    alpha: np.ndarray
    qa: np.ndarray
    qb: np.ndarray
    qc: float


class _Trace:
    """Lean per-ray results used by the renderer (only what the shading needs)."""

    __slots__ = ("a", "alpha", "b", "c", "hit", "mu", "mu0", "t", "xb")


def _trace(scene: Scene, dx: np.ndarray, dy: np.ndarray, need_alpha: bool, need_points: bool) -> _Trace:
    """Rays ``d = (dx, dy, 1)``; component-wise version of the module docstring's formulas.

    The body-frame ray is ``o + t e`` with ``o = -R^T q``, ``e = R^T d``.
    """
    R = scene.R_body_to_camera
    j = np.asarray(scene.radii) ** -2.0
    o = -(R.T @ scene.q)
    e0 = R[0, 0] * dx + R[1, 0] * dy + R[2, 0]
    e1 = R[0, 1] * dx + R[1, 1] * dy + R[2, 1]
    e2 = R[0, 2] * dx + R[1, 2] * dy + R[2, 2]
    je0, je1, je2 = j[0] * e0, j[1] * e1, j[2] * e2
    a = je0 * e0 + je1 * e1 + je2 * e2
    b = -(o[0] * je0 + o[1] * je1 + o[2] * je2)
    c = float(np.sum(o * o * j) - 1.0)
    disc = b * b - a * c
    hit = (disc >= 0) & (b > 0)
    np.maximum(disc, 0.0, out=disc)
    np.sqrt(disc, out=disc)
    disc += b
    with np.errstate(divide="ignore", invalid="ignore"):
        t = c / disc
    t[~hit] = np.nan
    # body-frame point and (unnormalised) normal n = J x
    x0 = o[0] + t * e0
    x1 = o[1] + t * e1
    x2 = o[2] + t * e2
    n0, n1, n2 = j[0] * x0, j[1] * x1, j[2] * x2
    nn = np.sqrt(n0 * n0 + n1 * n1 + n2 * n2)
    dd = np.sqrt(dx * dx + dy * dy + 1.0)
    out = _Trace()
    out.mu = -(n0 * e0 + n1 * e1 + n2 * e2) / (nn * dd)
    if scene.sun_dir_cam is not None:
        s = np.asarray(scene.sun_dir_cam)
        sb = R.T @ s
        out.mu0 = (n0 * sb[0] + n1 * sb[1] + n2 * sb[2]) / nn
        if need_alpha:
            out.alpha = np.arccos(np.clip(-(s[0] * dx + s[1] * dy + s[2]) / dd, -1.0, 1.0))
        else:
            out.alpha = None
    else:
        out.mu0 = np.full(dx.shape, np.nan)
        out.alpha = np.zeros(dx.shape)
    out.xb = np.stack([x0, x1, x2], axis=-1) if need_points else None
    out.hit, out.t, out.a, out.b, out.c = hit, t, a, b, c
    return out


def trace_rays(scene: Scene, d: np.ndarray) -> RayHits:
    """Intersect camera rays ``d`` ``(n, 3)`` (pointing forward, any length) with the scene's ellipsoid."""
    d = np.asarray(d, dtype=float).reshape(-1, 3)
    dz = d[:, 2:3]
    if np.any(dz <= 0):
        raise ConfigError("`d` must point forward (z > 0)")
    dn = d / dz  # rescale to z = 1 (t is then per unit z)
    tr = _trace(scene, dn[:, 0].copy(), dn[:, 1].copy(), need_alpha=True, need_points=True)
    R = scene.R_body_to_camera
    nb = tr.xb / np.asarray(scene.radii) ** 2
    nb /= np.linalg.norm(nb, axis=1, keepdims=True)
    t = tr.t / dz[:, 0]
    return RayHits(
        hit=tr.hit,
        t=t,
        point_cam=t[:, None] * d,
        point_body=tr.xb,
        normal_cam=nb @ R.T,
        mu=tr.mu,
        mu0=tr.mu0,
        alpha=tr.alpha,
        qa=tr.a,
        qb=tr.b,
        qc=tr.c,
    )


# =============================================================================== shading
def _shade(scene: Scene, h: _Trace, model: str, coeffs: tuple[float, float, float]) -> np.ndarray:
    """Radiance of each ray (0 on a miss), including albedo and albedo patches (no atmosphere)."""
    out = np.zeros(len(h.hit))
    m = h.hit
    if not np.any(m):
        return out
    if model != "uniform" and scene.sun_dir_cam is None:
        raise ConfigError(f"reflectance {model!r} needs a Sun direction; the scene has `sun_dir_cam=None`")
    alpha = h.alpha[m] if h.alpha is not None else 0.0
    val = reflectance(model, h.mu0[m], h.mu[m], alpha, coeffs)
    if scene.albedo != 1.0:
        val *= scene.albedo
    if scene.albedo_patches is not None:
        x = h.xb[m]
        val = val * scene.albedo_patches.factor(x / np.linalg.norm(x, axis=1, keepdims=True))
    out[m] = val
    return out


def _glow(scene: Scene, h: _Trace, dx: np.ndarray, dy: np.ndarray) -> np.ndarray:
    """Atmosphere radiance along each ray (see :class:`jaxlimb.render.scene.Atmosphere`)."""
    atm = scene.atmosphere
    if atm is None:
        return np.zeros(len(h.hit))
    H = atm.scale_height_km
    Rm = scene.mean_radius_km
    norm = math.sqrt(2 * math.pi * Rm * H)
    g = np.zeros(len(h.hit))
    miss = ~h.hit
    if np.any(miss):
        a, b = h.a[miss], h.b[miss]
        tstar = b / a
        rho2 = np.where(tstar > 0, (h.c + 1.0) - b * b / a, h.c + 1.0)
        rho = np.sqrt(np.maximum(rho2, 1.0))
        # local radius at the closest-approach point (body frame)
        R = scene.R_body_to_camera
        o = -(R.T @ scene.q)
        d = np.stack([dx[miss], dy[miss], np.ones(int(miss.sum()))], axis=-1)
        e = d @ R
        x = o + np.maximum(tstar, 0.0)[:, None] * e
        Rloc = np.linalg.norm(x, axis=1) / rho
        ht = (rho - 1.0) * Rloc
        g[miss] = np.where(ht <= atm.height_km, np.exp(-ht / H), 0.0)
    if np.any(h.hit):
        mu = np.maximum(h.mu[h.hit], 1e-12)
        Rl = np.linalg.norm(h.xb[h.hit], axis=1)
        col = np.minimum(H / mu, np.sqrt(np.pi * Rl * H / 2.0))
        g[h.hit] = col / norm
    return atm.brightness * g


_RAY_CHUNK = 1 << 18


def _eval_rays(
    scene: Scene, dx: np.ndarray, dy: np.ndarray, model: str, coeffs: tuple[float, float, float]
) -> tuple[np.ndarray, np.ndarray]:
    """Radiance (surface + atmosphere) and the lit flag of rays ``(dx, dy, 1)``, in cache-sized chunks."""
    n = len(dx)
    val = np.empty(n)
    lit = np.empty(n, bool)
    need_alpha = model == "lunar-lambert"
    need_pts = scene.albedo_patches is not None or scene.atmosphere is not None
    for s0 in range(0, n, _RAY_CHUNK):
        sl = slice(s0, s0 + _RAY_CHUNK)
        h = _trace(scene, dx[sl], dy[sl], need_alpha, need_pts)
        v = _shade(scene, h, model, coeffs)
        if scene.atmosphere is not None:
            v += _glow(scene, h, dx[sl], dy[sl])
        val[sl] = v
        lit[sl] = h.hit & (h.mu0 > 0)
    return val, lit


# =============================================================================== image
@dataclass(frozen=True, eq=False)
class RadianceWindow:
    """Noiseless, unblurred radiance over a window of pixels.

    ``image[i, j]`` is the mean radiance over the footprint of pixel
    ``(row0 + i, col0 + j)`` (may extend beyond the frame by ``pad``).  ``limb`` is the
    image conic; ``n_supersampled`` counts the pixels averaged over sub-samples.
    """

    image: np.ndarray
    row0: int
    col0: int
    limb: ImageConic
    n_supersampled: int
    supersampled: np.ndarray  # bool mask, same shape as image


def _conic_distance(C: np.ndarray, rows: np.ndarray, cols: np.ndarray) -> np.ndarray:
    """First-order signed distance ``Q / |grad Q|`` (px) of the grid ``rows x cols`` to a conic.

    Separable evaluation: ``Q = f(c) + g(r) + 2 C01 r c``.
    """
    r = rows[:, None]
    c = cols[None, :]
    Q = (C[0, 0] * c + 2 * C[0, 2]) * c + ((C[1, 1] * r + 2 * C[1, 2]) * r + C[2, 2])
    Q += (2 * C[0, 1]) * r * c
    gc = 2 * (C[0, 0] * c + C[0, 2]) + (2 * C[0, 1]) * r
    gr = 2 * (C[1, 1] * r + C[1, 2]) + (2 * C[0, 1]) * c
    g = np.hypot(gc, gr)
    with np.errstate(divide="ignore", invalid="ignore"):
        Q /= g
    return Q


def _window(camera: Camera, ext: ImageConic, pad: int) -> tuple[int, int, int, int]:
    rmin, rmax, cmin, cmax = ext.bbox_rc()
    # the body's pixels plus a margin of ``pad`` for the PSF, within the frame grown by ``pad``
    r0 = max(math.floor(rmin) - 1 - pad, -pad)
    r1 = min(math.ceil(rmax) + 1 + pad, camera.rows - 1 + pad)
    c0 = max(math.floor(cmin) - 1 - pad, -pad)
    c1 = min(math.ceil(cmax) + 1 + pad, camera.cols - 1 + pad)
    return r0, r1, c0, c1


def _terminator_band(inside: np.ndarray, ir: np.ndarray, ic: np.ndarray, lit_in: np.ndarray) -> np.ndarray:
    """Interior pixels whose lit state differs from a 4-neighbour's (they are supersampled)."""
    lit = np.zeros(inside.shape, bool)
    lit[ir, ic] = lit_in
    return boundary_mask(lit, inside)


def _supersampled(scene: Scene, pr_all: np.ndarray, pc_all: np.ndarray, offs: np.ndarray, camera: Camera,
                  reflectance_model: str, coeffs) -> np.ndarray:  # type: ignore[no-untyped-def]
    """Mean radiance over the sub-sample lattice ``offs`` of the pixels ``(pr_all, pc_all)``, in ray chunks."""
    f = camera.focal_px
    rpp, cpp = camera.principal_point_rc  # type: ignore[misc]
    vals = np.empty(len(pr_all))
    m = len(offs)
    step = max(1, _RAY_CHUNK // m)
    for s0 in range(0, len(pr_all), step):
        pr = pr_all[s0 : s0 + step]
        pc = pc_all[s0 : s0 + step]
        sdy = ((pr[:, None] + offs[None, :, 0]).ravel() - rpp) / f
        sdx = ((pc[:, None] + offs[None, :, 1]).ravel() - cpp) / f
        v, _ = _eval_rays(scene, sdx, sdy, reflectance_model, coeffs)
        vals[s0 : s0 + step] = v.reshape(-1, m).mean(axis=1)
    return vals


def _subsample_offsets(reflectance_model: str, n_subsamples: int, pad: int) -> np.ndarray:
    """The sub-pixel offsets of :func:`render_radiance`'s supersampling, after checking its options."""
    if reflectance_model not in REFLECTANCE_MODELS:
        raise ConfigError(f"`reflectance` must be one of {list(REFLECTANCE_MODELS)}, got {reflectance_model!r}")
    offs = lattice_offsets(n_subsamples)
    if not (isinstance(pad, (int, np.integer)) and pad >= 0):
        raise ConfigError(f"`pad` must be an integer >= 0, got {pad!r}")
    return offs


def _limb_and_extent(scene: Scene, camera: Camera) -> tuple[ImageConic, ImageConic]:
    """The limb's image conic and that of the body's outer extent (the atmosphere's shell, else the limb)."""
    R = scene.R_body_to_camera
    limb = image_conic(camera, scene.radii, scene.center_cam, R)
    ext = limb
    if scene.atmosphere is not None:
        ext = image_conic(
            camera, np.asarray(scene.radii) + scene.atmosphere.height_km, scene.center_cam, R
        )
    return limb, ext


def _edge_and_inside(limb: ImageConic, rows: np.ndarray, cols: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The window's pixels to supersample (near the limb; all of a tiny or very flat body) and those wholly
    inside the limb."""
    dist = _conic_distance(limb.conic, rows, cols)
    a_px, b_px = limb.semi_axes_px
    if b_px * b_px / a_px < 4.0:  # tiny or very flat: supersample everything
        edge = np.ones((len(rows), len(cols)), bool)
    else:
        edge = np.abs(dist) <= _EDGE_THRESHOLD_PX
    inside = (dist < 0) & ~edge
    return edge, inside


def render_radiance(
    scene: Scene, camera: Camera, reflectance_model: str = "lommel-seeliger", n_subsamples: int = 89, pad: int = 0,
    lunar_lambert_coeffs: tuple[float, float, float] = LUNAR_LAMBERT_MCEWEN,
) -> RadianceWindow:
    """Render the noiseless radiance of ``scene`` over the pixels that can be non-zero.

    Parameters
    ----------
    scene, camera
        What and how.
    reflectance_model
        One of ``"lommel-seeliger"``, ``"lunar-lambert"``, ``"lambert"``, ``"uniform"``.
    n_subsamples
        Sub-samples per edge pixel (module docstring); 1 disables supersampling.
    pad
        Margin (px) kept around the body and beyond the frame edges, so that a PSF of
        half-width ``pad`` can be applied to the window before cropping.
    """
    offs = _subsample_offsets(reflectance_model, n_subsamples, pad)
    limb, ext = _limb_and_extent(scene, camera)
    r0, r1, c0, c1 = _window(camera, ext, pad)
    if r0 > r1 or c0 > c1:
        empty = np.zeros((0, 0))
        return RadianceWindow(empty, r0, c0, limb, 0, np.zeros((0, 0), bool))
    rows = np.arange(r0, r1 + 1, dtype=float)
    cols = np.arange(c0, c1 + 1, dtype=float)
    nr, nc = len(rows), len(cols)
    edge, inside = _edge_and_inside(limb, rows, cols)
    img = np.zeros((nr, nc))
    f = camera.focal_px
    rpp, cpp = camera.principal_point_rc  # type: ignore[misc]
    dyg = (rows - rpp) / f
    dxg = (cols - cpp) / f
    ir, ic = np.nonzero(inside)
    coeffs = lunar_lambert_coeffs

    # ---- centre samples of interior pixels
    rad_in, lit_in = _eval_rays(scene, dxg[ic], dyg[ir], reflectance_model, coeffs)

    # ---- terminator band: lit/unlit changes between 4-neighbours of interior pixels
    ss = edge.copy()
    if reflectance_model != "uniform" and scene.sun_dir_cam is not None and len(ir):
        ss |= _terminator_band(inside, ir, ic, lit_in)
    img[ir, ic] = rad_in  # the band pixels are overwritten below
    del rad_in, lit_in, ir, ic
    if scene.atmosphere is not None:
        # pixels outside the solid limb but inside (or within 1 px of) the shell's conic
        shell = _conic_distance(ext.conic, rows, cols) <= _EDGE_THRESHOLD_PX
        orr, occ = np.nonzero(shell & ~inside & ~ss)
        img[orr, occ] = _eval_rays(scene, dxg[occ], dyg[orr], reflectance_model, coeffs)[0]

    # ---- supersampled pixels
    idx_r, idx_c = np.nonzero(ss)
    n_ss = len(idx_r)
    if n_ss:
        img[idx_r, idx_c] = _supersampled(scene, rows[idx_r], cols[idx_c], offs, camera, reflectance_model, coeffs)
    return RadianceWindow(img, r0, c0, limb, n_ss, ss)
