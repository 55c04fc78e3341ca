"""The frame pyramid, the pixel window and the model rendered at one level (render-and-register, coarse to fine).

A blur of ``sigma`` px makes detail finer than ``sigma / 2`` useless: such iterations run on the frame
box-averaged by ``k = floor(sigma / PYRAMID_BLUR_PX)`` (:mod:`jaxlimb.irregular.model_render`) against the
model rendered by the camera of ``k`` times larger pixels, as long as the figure stays
``_PYRAMID_MIN_SIZE_PX`` across.  The body centre sits at ``t = D u(P)`` (Eq. 4 of Wu et al.).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import NamedTuple

import numpy as np

from ..._identity_cache import IdentityCache
from ..mesh import Mesh
from ..model_render import ModelImage, clustered_mesh, downsample, level_camera, render_window
from .options import RegisterOptions

#: Blur (px) per pyramid factor: an iteration blurred by ``sigma`` runs at factor ``floor(sigma / PYRAMID_BLUR_PX)``.
PYRAMID_BLUR_PX = 2.0
_PYRAMID_MIN_SIZE_PX = 48.0  # smallest figure (px across) on a pyramid level
COARSE_MIN_LEVEL = 4  # the coarse stage of a template hypothesis stops before the first iteration below this factor
_BLUR_PX = (3.0, 1.5)  # Gaussian blur (px) of frame and model in the first iterations (a wider basin)
# with the attitude fitted: blurs in fractions of the figure size (a template a few degrees off moves the
# outline by a few percent of the size), those below _ATTITUDE_BLUR_MIN_PX dropped
_ATTITUDE_BLUR_FRAC = (0.04, 0.025, 0.015, 0.008, 0.004)
_ATTITUDE_BLUR_MIN_PX = 1.0
MARGIN_PX = 4  # pixels added around the union of the predicted and observed figures
SUPERSAMPLE = 4  # sub-pixels per pixel side of the model rendering


class Level(NamedTuple):
    """One pyramid level: the box-averaged frame, its camera and the lit figure."""

    image: np.ndarray
    camera: object
    mask: np.ndarray


class Pyramid:
    """The frame, camera and lit figure box-averaged by integer factors, made on demand."""

    def __init__(self, image: np.ndarray, camera: object, mask: np.ndarray) -> None:
        self.levels = {1: Level(image, camera, mask)}

    def __getitem__(self, k: int) -> Level:
        if k not in self.levels:
            image, camera, mask = self.levels[1]
            self.levels[k] = Level(downsample(image, k), level_camera(camera, k), downsample(mask.astype(np.float32), k) > 0)
        return self.levels[k]


_PYRAMIDS = IdentityCache(maxsize=1)


def frame_pyramid(image: np.ndarray, camera: object, mask: np.ndarray) -> Pyramid:
    """The :class:`Pyramid` of a frame, shared by the registrations of its template hypotheses (kept for the last
    frame): each level is box-averaged once, and its figure keeps one ``mask`` object (:func:`bbox` remembers it).

    Parameters
    ----------
    image, camera, mask : np.ndarray (rows, cols), Camera, np.ndarray (rows, cols) of bool
        The frame (float), its camera and its lit figure; the same objects give the same pyramid.

    Returns
    -------
    Pyramid
    """
    return _PYRAMIDS.get((image, camera, mask), lambda: Pyramid(image, camera, mask))


_BBOX = IdentityCache(maxsize=17)


def bbox(mask: np.ndarray) -> np.ndarray:
    """``(r0, c0, r1, c1)`` of a figure, remembered for the last few masks (the pyramid's, asked every iteration).

    Parameters
    ----------
    mask : np.ndarray (rows, cols) of bool
        The figure; not empty.

    Returns
    -------
    np.ndarray (4,) of int
        First and last row and column of the figure (inclusive).
    """

    def box() -> np.ndarray:
        rr, cc = np.nonzero(mask.any(axis=1))[0], np.nonzero(mask.any(axis=0))[0]
        return np.array([rr[0], cc[0], rr[-1], cc[-1]])

    return _BBOX.get((mask,), box)


def figure_size(mask: np.ndarray) -> float:
    """Largest side (px) of the figure's bounding box.

    Parameters
    ----------
    mask : np.ndarray (rows, cols) of bool
        The figure; not empty.

    Returns
    -------
    float
        ``max(rows, cols)`` spanned by the figure, px.
    """
    box = bbox(mask)
    return float(max(box[2] - box[0], box[3] - box[1]) + 1)


def level_of(sigma: float, size: float) -> int:
    """Pyramid factor of an iteration with blur ``sigma`` (px) on a figure ``size`` px across.

    Parameters
    ----------
    sigma : float
        Gaussian blur of the iteration (full-resolution px).
    size : float
        Figure size (px, :func:`figure_size`); the level keeps it at least ``_PYRAMID_MIN_SIZE_PX`` across.

    Returns
    -------
    int
        Box-averaging factor ``k >= 1``, ``floor(sigma / PYRAMID_BLUR_PX)`` at most.
    """
    k = int(sigma // PYRAMID_BLUR_PX)
    return max(1, min(k, int(size // _PYRAMID_MIN_SIZE_PX)))


def half_resolution_allowed(size: float) -> bool:
    """Whether a figure ``size`` px across stays large enough on the 2x2-averaged frame.

    Parameters
    ----------
    size : float
        Figure size (px, full resolution).

    Returns
    -------
    bool
        ``size >= 2 _PYRAMID_MIN_SIZE_PX``.
    """
    return size >= 2 * _PYRAMID_MIN_SIZE_PX


def blur_schedule(mask: np.ndarray, wide: bool) -> tuple[float, ...]:
    """Blurs (px) of the first iterations: fixed, or (``wide``, attitude fitted) fractions of the figure size.

    Parameters
    ----------
    mask : np.ndarray (rows, cols) of bool
        Observed lit figure (its size scales the ``wide`` schedule).
    wide : bool
        Attitude fitted: blurs of ``_ATTITUDE_BLUR_FRAC`` times the figure size, those below
        ``_ATTITUDE_BLUR_MIN_PX`` dropped; otherwise ``_BLUR_PX``.

    Returns
    -------
    tuple of float
        Gaussian blur (px, full resolution) of each blurred iteration, widest first.
    """
    if not wide:
        return _BLUR_PX
    size = figure_size(mask)
    return tuple(f * size for f in _ATTITUDE_BLUR_FRAC if f * size >= _ATTITUDE_BLUR_MIN_PX)


def pose(camera: object, P: np.ndarray, D: float) -> np.ndarray:
    """Body centre ``t = D u(P)`` in the camera frame (Eq. 4 of Wu et al.).

    Parameters
    ----------
    camera : Camera
        Pinhole camera (its ``los``).
    P : np.ndarray (2,)
        Image of the body centre, px ``(row, col)``.
    D : float
        Range to the body centre, km.

    Returns
    -------
    np.ndarray (3,)
        Body-centre position in the camera frame, km.
    """
    return D * np.asarray(camera.los(P), dtype=float)  # type: ignore[attr-defined]


def window(camera: object, P: np.ndarray, D: float, mesh: Mesh, mask: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Pixel window holding the predicted body (bounding sphere) and the observed figure, plus ``MARGIN_PX``.

    Parameters
    ----------
    camera : Camera
        Camera of the level.
    P : np.ndarray (2,)
        Body-centre image, px ``(row, col)`` of that camera.
    D : float
        Range, km.
    mesh : Mesh
        Shape model (its bounding radius ``max_radius``).
    mask : np.ndarray (rows, cols) of bool
        Observed lit figure.

    Returns
    -------
    lo, hi : np.ndarray (2,) of int
        First and last pixel ``(row, col)`` of the window (inclusive), clipped to the frame.
    """
    rad = camera.focal_px * mesh.max_radius / max(D - mesh.max_radius, 1e-9 * D)  # type: ignore[attr-defined]
    box = bbox(mask)
    lo = np.minimum(np.floor(P - rad), box[:2]) - MARGIN_PX
    hi = np.maximum(np.ceil(P + rad), box[2:]) + MARGIN_PX
    shape = np.array(camera.shape)  # type: ignore[attr-defined]
    return np.maximum(lo, 0).astype(int), np.minimum(hi, shape - 1).astype(int)


def render_model(
    mesh: Mesh, camera: object, R: np.ndarray, t: np.ndarray, sun: np.ndarray | None, lo: np.ndarray, hi: np.ndarray,
    options: RegisterOptions,
) -> tuple[np.ndarray, np.ndarray]:
    """Radiance (unit albedo, zero background) and coverage of the mesh at pose ``(R, t)`` in the window ``lo..hi``.

    Parameters
    ----------
    mesh : Mesh
        Shape model (km, body frame).
    camera : Camera
        Camera of the frame.
    R : np.ndarray (3, 3)
        Body-to-camera rotation.
    t : np.ndarray (3,)
        Body centre in the camera frame, km (:func:`pose`).
    sun : np.ndarray (3,) or None
        Unit vector toward the Sun, camera frame; ``None``: zero phase.
    lo, hi : np.ndarray (2,) of int
        Window, first and last pixel ``(row, col)``.
    options : RegisterOptions
        ``reflectance`` and ``exact_coverage``.

    Returns
    -------
    M, C : np.ndarray (hi - lo + 1)
        Model radiance and the fraction of each pixel covered by the body.
    """
    m = render_window(mesh, camera, R, t, sun, lo, hi, SUPERSAMPLE, options.reflectance, exact=options.exact_coverage)
    return m.M, m.C


@dataclass(frozen=True)
class LevelModel:
    """The model rendered at one pyramid level: image, window ``lo..hi`` and centre ``Pk`` in level pixels."""

    model: ModelImage
    lo: np.ndarray
    hi: np.ndarray
    Pk: np.ndarray


def level_center(P: np.ndarray, k: int) -> np.ndarray:
    """Full-resolution pixel ``P`` in the pixels of pyramid factor ``k`` (``x = k X + (k - 1) / 2``).

    Parameters
    ----------
    P : np.ndarray (2,)
        Pixel ``(row, col)`` at full resolution.
    k : int
        Box-averaging factor.

    Returns
    -------
    np.ndarray (2,)
        The same point in level-``k`` pixels ``(row, col)``.
    """
    return (P - (k - 1) / 2.0) / k


def render_level(
    pyr: Pyramid, mesh: Mesh, sun: np.ndarray | None, options: RegisterOptions, k: int,
    pose_RPD: tuple[np.ndarray, np.ndarray, float], jacobian: bool, mix: np.ndarray | None,
) -> LevelModel:  # fmt: skip
    """The model at pyramid factor ``k`` for the pose ``(R, P, D)``; ``jacobian``: with the attitude derivatives.

    Parameters
    ----------
    pyr : Pyramid
        Frame pyramid (cameras and lit figures of the levels).
    mesh : Mesh
        Shape model; above level 1 its facets are clustered to the level's pixel size.
    sun : np.ndarray (3,) or None
        Unit vector toward the Sun, camera frame; ``None``: zero phase.
    options : RegisterOptions
        Reflectance, cast shadows and exact coverage.
    k : int
        Pyramid factor.
    pose_RPD : (np.ndarray (3, 3), np.ndarray (2,), float)
        Attitude, full-resolution centre image ``P`` (px) and range ``D`` (km).
    jacobian : bool
        Also render the derivatives with respect to a small rotation (attitude columns).
    mix : np.ndarray or None
        Photometric mix of :func:`~jaxlimb.irregular.model_render.render_window`.

    Returns
    -------
    LevelModel
        The rendered model, its window ``lo..hi`` and ``Pk`` (level pixels).
    """
    R, P, D = pose_RPD
    camera = pyr[1].camera
    cam, mask = pyr[k].camera, pyr[k].mask
    Pk = level_center(P, k)
    lo, hi = window(cam, Pk, D, mesh, mask)
    facets = mesh if k == 1 else clustered_mesh(mesh, 2.0 * k * D / camera.focal_px)  # type: ignore[attr-defined]
    shadows = options.cast_shadows and sun is not None and (options.coarse_cast_shadows or k < COARSE_MIN_LEVEL)
    model = render_window(facets, cam, R, pose(camera, P, D), sun, lo, hi, SUPERSAMPLE, options.reflectance,  # type: ignore[arg-type]
                          jacobian, mix, shadows, k == 1 and options.exact_coverage)  # fmt: skip
    return LevelModel(model, lo, hi, Pk)


__all__ = [
    "COARSE_MIN_LEVEL", "MARGIN_PX", "PYRAMID_BLUR_PX", "SUPERSAMPLE", "Level", "LevelModel", "Pyramid", "bbox",
    "blur_schedule", "figure_size", "frame_pyramid", "half_resolution_allowed", "level_center", "level_of", "pose", "render_level",
    "render_model", "window",
]  # fmt: skip
