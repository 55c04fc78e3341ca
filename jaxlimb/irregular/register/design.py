r"""The linear least-squares problem of one photometric Gauss-Newton step (render-and-register).

The frame is modelled as ``I(x) ~ a M(x; P, s) + b (1 - C) [+ radiance terms]`` with
``M(x; P + delta, s + delta_s) ~ M - delta . grad M - delta_s (x - P) . grad M``: linear in
``(a, b, a delta, a delta_s)``, plus the attitude (three columns from the same render,
:func:`jaxlimb.irregular.model_render.attitude_columns`), an albedo field, the opposition surge, a
pedestal and the photometric mix.  ``P`` is the image of the body centre, placed at ``t = D u(P)``
(Eq. 4 of Wu et al.), so the solve moves the estimate itself.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import cv2
import numpy as np

from ...errors import ConvergenceError
from ..model_render import ModelImage, attitude_columns
from .pyramid import LevelModel

_CHUNK = 4096  # columns per product: 8 x 8 x 4096 stays below OpenBLAS's threading threshold
N_POSE = 5  # rows before the attitude: contrast, sky, centre (2), scale


def blur(a: np.ndarray, sigma: float) -> np.ndarray:
    """Gaussian blur (``sigma`` px, replicated border); ``a`` itself for ``sigma <= 0``.

    Parameters
    ----------
    a : np.ndarray (h, w)
        Image.
    sigma : float
        Standard deviation of the Gaussian, px.

    Returns
    -------
    np.ndarray (h, w)
        The blurred image.
    """
    return a if sigma <= 0 else cv2.GaussianBlur(a, (0, 0), sigma, borderType=cv2.BORDER_REPLICATE)


def pose_rows(M: np.ndarray, C: np.ndarray, ratio: float, P_win: np.ndarray, n_rows: int = N_POSE) -> np.ndarray:
    """Transposed design matrix ``(n_rows, n)`` of the linearised model ``a M + b (1 - C)`` (the body hides the sky).

    Rows: ``M``, ``1 - C``, ``-dG/dr``, ``-dG/dc``, ``-(x - P).grad G`` with ``G = M - ratio C`` (``ratio = b/a``
    of the previous solve); rows 5.. are left for the other columns.  Rows, not columns: each is written in one
    contiguous pass and the normal matrix is ``At At^T``.

    Parameters
    ----------
    M, C : np.ndarray (h, w)
        Model radiance (unit albedo) and coverage in the window.
    ratio : float
        ``b / a`` of the previous solve.
    P_win : np.ndarray (2,)
        Body-centre image in window pixels ``(row, col)``.
    n_rows : int
        Rows allocated (``>= 5``); rows 5.. are left unset.

    Returns
    -------
    np.ndarray (n_rows, h * w)
        ``At``, the transposed design matrix.
    """
    h, w = M.shape
    At = np.empty((n_rows, h * w))
    gr, gc = np.gradient(M - ratio * C)
    At[0] = M.ravel()
    np.subtract(1.0, C.ravel(), out=At[1])
    np.negative(gr.ravel(), out=At[2])
    np.negative(gc.ravel(), out=At[3])
    radial = At[4].reshape(h, w)
    np.multiply(P_win[0] - np.arange(h, dtype=float)[:, None], gr, out=radial)
    radial -= (np.arange(w, dtype=float) - P_win[1])[None, :] * gc
    return At


def albedo_rows(M: np.ndarray, P_win: np.ndarray, order: int, harmonics: int) -> list[np.ndarray]:
    """``M`` times the monomials of degree 1..``order`` of the offsets from ``P_win`` (units of the window size)
    and times ``cos k theta``, ``sin k theta`` (``k = 1..harmonics``, ``theta`` the position angle about ``P_win``).

    Parameters
    ----------
    M : np.ndarray (h, w)
        Model radiance (blurred like the frame).
    P_win : np.ndarray (2,)
        Body-centre image in window pixels ``(row, col)``.
    order, harmonics : int
        Polynomial degree and number of position-angle harmonics (:attr:`.RegisterOptions.albedo_order`).

    Returns
    -------
    list of np.ndarray (h * w,)
        The albedo columns, polynomial ones first.
    """
    h, w = M.shape
    y = (np.arange(h)[:, None] - P_win[0]) / max(h, w) * np.ones((1, w))
    x = (np.arange(w)[None, :] - P_win[1]) / max(h, w) * np.ones((h, 1))
    rows = [M * y**i * x ** (d - i) for d in range(1, order + 1) for i in range(d + 1)]
    th = np.arctan2(y, x)
    rows += [M * f(k * th) for k in range(1, harmonics + 1) for f in (np.cos, np.sin)]
    return [r.ravel() for r in rows]


def surge_fields(cam, lo, hi, Pk, sun, widths, min_range: float = 0.0) -> list[np.ndarray]:  # type: ignore[no-untyped-def]
    """``1 / (1 + tan(g/2) / h)`` over the window ``lo..hi`` of ``cam`` for each width ``h`` of ``widths``, with
    ``g`` the phase angle (Sun -- surface -- camera) of each pixel's ray.

    The shadow-hiding opposition surge (Hapke 1986, Eq. 11: ``B(g) = B_0 / (1 + tan(g/2) / h)``) brightens the
    part of the body nearest zero phase, and the phase angle varies by ~10 deg across a body at 3x its long
    axis.  ``M`` times these fields are linear columns; each field is zero at ``Pk`` (the body centre), so that
    the coefficient of ``M`` stays the contrast there.  A field that varies by less than ``min_range`` over
    the window is left out: a gentle gradient the surge hardly shows, which a free column would spend on
    other misfits.

    Parameters
    ----------
    cam : Camera
        Camera of the pyramid level (``focal_px``, ``principal_point_rc``).
    lo, hi : np.ndarray (2,) of int
        Window, first and last pixel ``(row, col)``.
    Pk : np.ndarray (2,)
        Body-centre image, level pixels ``(row, col)``.
    sun : np.ndarray (3,) or None
        Unit vector toward the Sun, camera frame; ``None``: the Sun behind the camera, along the ray through ``Pk``.
    widths : sequence of float
        Surge widths ``h`` (rad).
    min_range : float
        Smallest variation over the window of a field that is kept.

    Returns
    -------
    list of np.ndarray (hi - lo + 1)
        One field per kept width.
    """
    f = cam.focal_px  # type: ignore[attr-defined]
    pr, pc = cam.principal_point_rc  # type: ignore[attr-defined]
    yn = ((lo[0] + np.arange(hi[0] - lo[0] + 1)) - pr)[:, None] / f
    xn = ((lo[1] + np.arange(hi[1] - lo[1] + 1)) - pc)[None, :] / f
    ray = np.array([(Pk[1] - pc) / f, (Pk[0] - pr) / f, 1.0])
    s = -ray if sun is None else np.asarray(sun, dtype=float)
    s = s / np.linalg.norm(s)
    cos_g = -(s[0] * xn + s[1] * yn + s[2]) / np.sqrt(xn * xn + yn * yn + 1.0)
    t = np.tan(0.5 * np.arccos(np.clip(cos_g, -1.0, 1.0)))
    t0 = math.tan(0.5 * math.acos(max(-1.0, min(1.0, -float(s @ ray) / float(np.linalg.norm(ray))))))
    fields = [1.0 / (1.0 + t / h) - 1.0 / (1.0 + t0 / h) for h in widths]
    return [f for f in fields if float(f.max() - f.min()) >= min_range]


def has_dark_side(model: ModelImage, min_frac: float) -> bool:
    """Whether at least ``min_frac`` (and 16 pixels) of the model's covered pixels are unlit (the pedestal
    column of :func:`system` is then identifiable; ``min_frac = 0``: never).

    Parameters
    ----------
    model : ModelImage
        Rendered model (radiance ``M``, coverage ``C``).
    min_frac : float
        Smallest fraction of fully covered pixels that are unlit.

    Returns
    -------
    bool
    """
    body = model.C > 0.99
    n = int(np.count_nonzero(body))
    dark = int(np.count_nonzero(body & (model.M <= 1e-6)))
    return min_frac > 0 and n > 0 and dark >= max(min_frac * n, 16)


@dataclass(frozen=True)
class Columns:
    """The columns of a solve beyond contrast, sky, centre and scale.

    ``attitude``: three rotation columns; ``mix``: ``dM/dmix`` of the photometric mix (last);
    ``albedo``: ``(order, harmonics)`` of :func:`albedo_rows`; ``fields``: ``M`` times each surge field;
    ``pedestal``: a constant column where :func:`has_dark_side` with this fraction (0: never).
    """

    attitude: bool = False
    mix: bool = False
    albedo: tuple[int, int] = (0, 0)
    fields: tuple[np.ndarray, ...] = ()
    pedestal: float = 0.0

    @property
    def n_pose(self) -> int:
        """Rows up to the radiance terms (contrast, sky, centre, scale and the attitude)."""
        return N_POSE + 3 if self.attitude else N_POSE  # the attitude: 3 rows


def system(lm: LevelModel, image: np.ndarray, s: float, psf: float, ratio: float, cols: Columns) -> tuple[np.ndarray, np.ndarray]:
    """Transposed design matrix and data of one solve: the frame (level pixels) blurred by ``s``, the model by
    ``hypot(s, psf)`` (the camera's PSF).  Rows: :func:`pose_rows`, then those of ``cols``.

    Parameters
    ----------
    lm : LevelModel
        The model rendered at the level, its window and centre.
    image : np.ndarray (rows, cols)
        Frame at the level (DN).
    s : float
        Blur of the iteration (level px).
    psf : float
        Gaussian PSF sigma of the camera (level px).
    ratio : float
        ``b / a`` of the previous solve (:func:`pose_rows`).
    cols : Columns
        The columns beyond the pose.

    Returns
    -------
    At : np.ndarray (n_columns, n)
        Transposed design matrix over the ``n`` window pixels.
    y : np.ndarray (n,)
        Blurred frame in the window.
    """
    model, lo, hi = lm.model, lm.lo, lm.hi
    sm = math.hypot(s, psf)
    Mb = blur(model.M, sm)
    extra = albedo_rows(Mb, lm.Pk - lo, *cols.albedo) if (cols.albedo[0] or cols.albedo[1]) else []
    extra += [blur(model.M * fld, sm).ravel() for fld in cols.fields]
    extra += [np.ones(Mb.size)] if has_dark_side(model, cols.pedestal) else []
    extra += [blur(d, sm).ravel() for d in model.dM_dmix] if cols.mix else []  # type: ignore[union-attr]
    n5 = cols.n_pose
    At = pose_rows(Mb, blur(model.C, sm), ratio, lm.Pk - lo, n5 + len(extra))
    if cols.attitude:
        attitude_columns(model, ratio, lambda a: blur(a, sm), out=At[5:8])
    for i, row in enumerate(extra):
        At[n5 + i] = row
    y = blur(image[lo[0] : hi[0] + 1, lo[1] : hi[1] + 1], s).ravel()
    return At, y


def normal_equations(At: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``(At At^T, At y)`` in column chunks single-threaded BLAS handles (``einsum`` for the vector).

    One product over all the window's pixels wakes OpenBLAS's thread pool, whose threads then spin for
    every later call (twice the CPU time of a locate on two busy cores).

    Parameters
    ----------
    At : np.ndarray (p, n)
        Transposed design matrix.
    y : np.ndarray (n,)
        Data.

    Returns
    -------
    N : np.ndarray (p, p)
        Normal matrix ``At At^T``.
    r : np.ndarray (p,)
        ``At y``.
    """
    N = np.zeros((At.shape[0], At.shape[0]))
    for j in range(0, At.shape[1], _CHUNK):
        blk = At[:, j : j + _CHUNK]
        N += blk @ blk.T
    return N, np.einsum("ij,j->i", At, y)


@dataclass(frozen=True)
class Solve:
    """One linear solve: ``beta``, residual sum of squares, normal matrix ``N = At At^T``, the transposed
    design matrix ``At``, the data ``y`` and the window ``lo..hi`` (level pixels)."""

    beta: np.ndarray
    rss: float
    N: np.ndarray
    At: np.ndarray
    y: np.ndarray
    lo: np.ndarray
    hi: np.ndarray
    n_pose: int = N_POSE

    def fitted_radiance(self) -> np.ndarray:
        """The fitted image without the pose columns: contrast, sky and the radiance terms after them.

        Returns
        -------
        np.ndarray (n,)
            Fitted radiance (DN) over the window pixels, row-major.
        """
        n = self.n_pose
        return np.einsum("i,ij->j", self.beta[:2], self.At[:2]) + np.einsum("i,ij->j", self.beta[n:], self.At[n:])


def solve(At: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, float, np.ndarray]:
    """Linear least squares ``At^T beta ~ y`` by the (column-scaled) normal equations: a few columns, many rows.

    Parameters
    ----------
    At : np.ndarray (p, n)
        Transposed design matrix.
    y : np.ndarray (n,)
        Data.

    Returns
    -------
    beta : np.ndarray (p,)
        Coefficients.
    rss : float
        Residual sum of squares ``|y|^2 - 2 beta.At y + beta.N beta`` (no residual vector: ~1e-12 relative, the
        residual is >= 1e-6 of ``|y|^2`` here).
    N : np.ndarray (p, p)
        Normal matrix ``At At^T``.

    Raises
    ------
    ConvergenceError
        Singular normal matrix (the model has no texture or edge).
    """
    N, r = normal_equations(At, y)
    sc = np.maximum(np.sqrt(np.diag(N)), 1e-300)
    try:
        beta = np.linalg.solve(N / np.outer(sc, sc), r / sc) / sc
    except np.linalg.LinAlgError:
        raise ConvergenceError("registration: singular normal matrix (the model has no texture or edge)") from None
    return beta, max(float(np.einsum("i,i->", y, y)) - 2.0 * float(beta @ r) + float(beta @ N @ beta), 0.0), N


__all__ = [
    "N_POSE", "Columns", "Solve", "albedo_rows", "blur", "has_dark_side", "normal_equations",
    "pose_rows", "solve", "surge_fields", "system",
]  # fmt: skip
