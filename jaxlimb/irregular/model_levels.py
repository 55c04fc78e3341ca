r"""The coarse levels of render-and-register (:mod:`.register`): simplified mesh, level and window cameras, box average.

**Pyramid.**  A blur of ``sigma`` px makes detail finer than ``sigma / 2`` useless: those iterations run on the
frame box-averaged by an integer factor ``k`` (``cv2.INTER_AREA``) against the model rendered by the camera whose
pixels are ``k`` times larger (:func:`level_camera`), whose pixel ``(R, C)`` is the mean of the fine pixels
``k R .. k R + k - 1``: fine coordinate ``x = k X + (k - 1) / 2``.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass

import cv2
import numpy as np

from .._identity_cache import IdentityCache
from .mesh import Mesh


@dataclass(frozen=True)
class _Facets:
    vertices: np.ndarray
    faces: np.ndarray


_CLUSTERED = IdentityCache(maxsize=9)


def clustered_mesh(mesh: Mesh, cell_km: float) -> Mesh | _Facets:
    """The mesh simplified by vertex clustering on a grid of ``cell_km`` (kept for the last few cells).

    Vertices in one grid cell merge into their mean; facets that collapse are dropped, the others keep their
    winding.  Used on the coarse pyramid levels only, with cells of two level pixels: the outline moves by about a
    pixel there, under a blur of at least two; the full-resolution iterations use the full mesh.  The cell is
    rounded down to a power of 2**0.5 so that successive iterations reuse the same simplified mesh.

    Parameters
    ----------
    mesh, cell_km : Mesh, float
        The shape model (km) and the grid cell (km).

    Returns
    -------
    Mesh or _Facets
        The simplified ``vertices`` and ``faces``; ``mesh`` itself when fewer than 20 facets would remain.
    """
    q = 2.0 ** (math.floor(2.0 * math.log2(cell_km)) / 2.0)

    def cluster() -> "Mesh | _Facets":
        V = np.asarray(mesh.vertices, dtype=float)
        F = np.asarray(mesh.faces, dtype=np.int64)
        cell = np.floor(V / q).astype(np.int64)
        cell -= cell.min(axis=0)
        span = cell.max(axis=0) + 1
        # one int64 key per cell, ordered like the rows (x, y, z): np.unique's labels of axis=0, without its row sort
        _, inv = np.unique((cell[:, 0] * span[1] + cell[:, 1]) * span[2] + cell[:, 2], return_inverse=True)
        inv = inv.ravel()
        counts = np.bincount(inv).astype(float)
        Vn = np.stack([np.bincount(inv, weights=V[:, i]) for i in range(3)], axis=1) / counts[:, None]
        Fn = inv[F]
        Fn = Fn[(Fn[:, 0] != Fn[:, 1]) & (Fn[:, 1] != Fn[:, 2]) & (Fn[:, 0] != Fn[:, 2])]
        return _Facets(Vn, Fn) if len(Fn) >= 20 else mesh

    return _CLUSTERED.get((mesh,), cluster, q)


def window_camera(camera: object, lo: np.ndarray, hi: np.ndarray) -> object:
    """The camera restricted to pixels ``lo..hi`` (inclusive, (row, col)).

    Parameters
    ----------
    camera, lo, hi : Camera, np.ndarray (2,), np.ndarray (2,)

    Returns
    -------
    Camera
    """
    r0, c0 = camera.principal_point_rc  # type: ignore[attr-defined]
    shape = (int(hi[0] - lo[0] + 1), int(hi[1] - lo[1] + 1))
    return dataclasses.replace(camera, rows=shape[0], cols=shape[1], principal_point_rc=(r0 - lo[0], c0 - lo[1]))  # type: ignore[type-var]


def level_camera(camera: object, k: int) -> object:
    """The camera of the frame box-averaged ``k x k`` (pixels ``k`` times larger; module docstring).

    Parameters
    ----------
    camera, k : Camera, int

    Returns
    -------
    Camera
    """
    if k == 1:
        return camera
    r0, c0 = camera.principal_point_rc  # type: ignore[attr-defined]
    rows, cols = camera.shape  # type: ignore[attr-defined]
    return dataclasses.replace(camera, rows=rows // k, cols=cols // k, pixel_pitch_mm=camera.pixel_pitch_mm * k,  # type: ignore[type-var, attr-defined]
                               principal_point_rc=((r0 - (k - 1) / 2.0) / k, (c0 - (k - 1) / 2.0) / k))  # fmt: skip


def downsample(image: np.ndarray, k: int) -> np.ndarray:
    """``k x k`` box average (the last rows/cols that do not fill a block are dropped).

    Parameters
    ----------
    image, k : np.ndarray (h, w), int
        The frame and the block size (``1``: ``image`` itself).

    Returns
    -------
    np.ndarray (h // k, w // k)
    """
    if k == 1:
        return image
    h, w = image.shape[0] // k, image.shape[1] // k
    return cv2.resize(np.ascontiguousarray(image[: h * k, : w * k], dtype=np.float32), (w, h), interpolation=cv2.INTER_AREA).astype(np.float64)
