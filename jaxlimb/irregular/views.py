"""View-sphere sampling and the template cameras (Eq. 5-7 and 9 of Wu et al.).

Viewpoints lie on a sphere of radius ``R`` centred on the body centre (the mesh
origin) at latitude-like angle ``alpha`` (angle from the pole, 0..180 deg) and
longitude ``beta``, Eq. (5)::

    (x, y, z) = R (sin a cos b, sin a sin b, cos a)

in the *sampling frame*, whose +z is the body axis named by
``ViewSphereOptions.pole_axis``.  The paper's pole is +z (Eq. 5); Celestia
models (``thebe.obj``, ``phobos.obj``) are y-up, so pass ``pole_axis="y"`` for
them to get the densest sampling around their true pole.  The pole choice only
changes *where* the views are; every result is expressed in the mesh's own
body-fixed frame.

Viewpoint count -- a decision.  Eq. (6) gives
``N = ([180/D] - 2) [360/D] + 2`` (6962 for D = 3 deg, the number the paper
reports), but the enumeration printed under Eq. (5),
``alpha = n1 D, n1 = 0..[180/D]`` with the two poles counted once, has
``[180/D] - 1`` interior rings, i.e. 7082 views for D = 3 deg.  The two do not
agree.  We reproduce the paper's count (``rings="paper"``, the default): the two
poles plus ``[180/D] - 2`` rings spread *evenly* over the open interval
(0, 180) deg, i.e. ring spacing ``180 / ([180/D] - 1)`` (3.05 deg for D = 3),
each ring with ``[360/D]`` longitudes ``beta = n2 * 360/[360/D]``,
``n2 = 0..[360/D]-1`` (``beta = 360`` duplicates ``beta = 0`` and is dropped).
``rings="grid"`` gives the enumeration under Eq. (5) instead (``alpha = n1 D``).

Camera frame of a template (Eq. 7): the optical axis points from the viewpoint
to the body centre; the columns of the rotation part of ``T_T_C`` are the camera
axes in the sampling frame::

    x_c = ( cos a cos b,  cos a sin b, -sin a)    (= e_alpha)
    y_c = ( sin b,       -cos b,        0    )    (= -e_beta)
    z_c = (-sin a cos b, -sin a sin b, -cos a)    (= -e_r, toward the centre)

which is right-handed (``x_c x y_c = z_c``), so it matches the docs/design.md camera
(+x toward +col, +y toward +row, +z boresight).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from .._validate import Range, number
from ..errors import ConfigError

_POLE_PERMUTATION = {
    # rows map body coordinates to sampling coordinates (sampling z = body pole axis)
    "z": np.eye(3),
    "y": np.array([[0.0, 0.0, 1.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]]),  # (x,y,z)_s = (z,x,y)_b
    "x": np.array([[0.0, 1.0, 0.0], [0.0, 0.0, 1.0], [1.0, 0.0, 0.0]]),  # (x,y,z)_s = (y,z,x)_b
}


@dataclass(frozen=True)
class ViewSphereOptions:
    """Options of the view sphere (Eq. 5-7 of Wu et al.).

    Parameters
    ----------
    step_deg
        Sampling interval ``Delta`` in degrees, ``0 < step_deg <= 90``.
    pole_axis
        Body axis used as the sampling pole: ``"z"`` (paper), ``"y"`` (Celestia
        y-up models) or ``"x"``.
    rings
        ``"paper"`` (Eq. 6 count, default) or ``"grid"`` (``alpha = n1*Delta``).
    """

    step_deg: float = 3.0
    pole_axis: str = "z"
    rings: str = "paper"

    def __post_init__(self) -> None:
        s = number(self.step_deg, "view sphere `step_deg`", Range(0.0, 90.0, lo_open=True))
        if self.pole_axis not in _POLE_PERMUTATION:
            raise ConfigError(f"view sphere `pole_axis` must be 'x', 'y' or 'z', got {self.pole_axis!r}")
        if self.rings not in ("paper", "grid"):
            raise ConfigError(f"view sphere `rings` must be 'paper' or 'grid', got {self.rings!r}")
        if int(math.floor(180.0 / s + 1e-9)) < 3:
            raise ConfigError(f"view sphere `step_deg` {s} leaves no ring between the poles; use <= 60")


def view_count(step_deg: float, rings: str = "paper") -> int:
    """Number of viewpoints, Eq. (6) of Wu et al.: ``([180/D] - 2) [360/D] + 2``.

    With ``rings="grid"`` the count of the enumeration under Eq. (5) is returned
    (``([180/D] - 1) [360/D] + 2``).  ``[.]`` is the floor.

    Parameters
    ----------
    step_deg : float
        Sampling interval ``D``, degrees.
    rings : str
        ``"paper"`` or ``"grid"`` (:class:`ViewSphereOptions`).

    Returns
    -------
    int
        6962 for ``D = 3`` (the paper's count).
    """
    opts = ViewSphereOptions(step_deg=step_deg, rings=rings)
    n_lat = int(math.floor(180.0 / opts.step_deg + 1e-9))
    n_lon = int(math.floor(360.0 / opts.step_deg + 1e-9))
    n_rings = n_lat - 2 if rings == "paper" else n_lat - 1
    return n_rings * n_lon + 2


def view_angles(options: ViewSphereOptions) -> tuple[np.ndarray, np.ndarray]:
    """Angles ``(alpha, beta)`` in radians of every viewpoint (Eq. 5-6).

    Order: north pole, rings from north to south (longitude fastest), south pole.

    Parameters
    ----------
    options : ViewSphereOptions
        Step and ring layout.

    Returns
    -------
    alpha, beta : np.ndarray (N,)
        Angle from the pole and longitude, rad, in the sampling frame.
    """
    n_lat = int(math.floor(180.0 / options.step_deg + 1e-9))
    n_lon = int(math.floor(360.0 / options.step_deg + 1e-9))
    if options.rings == "paper":
        n_rings = n_lat - 2
        ring_alpha = np.arange(1, n_rings + 1) * (math.pi / (n_rings + 1))
    else:
        n_rings = n_lat - 1
        ring_alpha = np.arange(1, n_rings + 1) * math.radians(options.step_deg)
    betas = np.arange(n_lon) * (2.0 * math.pi / n_lon)
    a = np.concatenate([[0.0], np.repeat(ring_alpha, n_lon), [math.pi]])
    b = np.concatenate([[0.0], np.tile(betas, n_rings), [0.0]])
    return a, b


def camera_to_sampling(alpha: np.ndarray, beta: np.ndarray) -> np.ndarray:
    """Rotation part of ``T_T_C`` (Eq. 7): camera axes as columns.

    Parameters
    ----------
    alpha, beta : np.ndarray (...)
        Viewpoint angles, rad.

    Returns
    -------
    np.ndarray (..., 3, 3)
        Columns ``x_c, y_c, z_c`` (module docstring) in the sampling frame: camera -> sampling.
    """
    a = np.asarray(alpha, dtype=float)
    b = np.asarray(beta, dtype=float)
    ca, sa, cb, sb = np.cos(a), np.sin(a), np.cos(b), np.sin(b)
    z = np.zeros_like(a)
    return np.stack(
        [
            np.stack([ca * cb, sb, -sa * cb], axis=-1),
            np.stack([ca * sb, -cb, -sa * sb], axis=-1),
            np.stack([-sa, z, -ca], axis=-1),
        ],
        axis=-2,
    )


def camera_transform(alpha: float, beta: float, radius: float) -> np.ndarray:
    """The 4x4 homogeneous transform ``T_T_C`` of Eq. (7) (camera -> sampling frame).

    Parameters
    ----------
    alpha, beta : float
        Viewpoint angles, rad.
    radius : float
        Viewpoint distance from the body centre (km).

    Returns
    -------
    np.ndarray (4, 4)
        Rotation :func:`camera_to_sampling` and the viewpoint position (Eq. 5) as translation.
    """
    T = np.eye(4)
    T[:3, :3] = camera_to_sampling(alpha, beta)
    T[:3, 3] = radius * np.array(
        [math.sin(alpha) * math.cos(beta), math.sin(alpha) * math.sin(beta), math.cos(alpha)]
    )
    return T


def pole_permutation(pole_axis: str) -> np.ndarray:
    """Rotation ``P`` with ``x_sampling = P @ x_body`` (sampling +z = body pole axis).

    Parameters
    ----------
    pole_axis : str
        ``"x"``, ``"y"`` or ``"z"``.

    Returns
    -------
    np.ndarray (3, 3)
        A cyclic permutation of the axes.

    Raises
    ------
    ConfigError
        Another axis name.
    """
    if pole_axis not in _POLE_PERMUTATION:
        raise ConfigError(f"`pole_axis` must be 'x', 'y' or 'z', got {pole_axis!r}")
    return _POLE_PERMUTATION[pole_axis].copy()


def template_rotations(options: ViewSphereOptions) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Per-view body->camera rotations of the view sphere (Eq. 5-7).

    Parameters
    ----------
    options : ViewSphereOptions
        Step, pole axis and ring layout.

    Returns
    -------
    alpha, beta
        Sampling angles (rad), shape ``(N,)``.
    R_body_to_camera
        ``(N, 3, 3)``: ``x_cam = R @ x_body`` (the inverse of Eq. 7's rotation,
        composed with the pole permutation).
    """
    a, b = view_angles(options)
    R_cs = camera_to_sampling(a, b)  # camera -> sampling
    P = pole_permutation(options.pole_axis)  # body -> sampling
    R_bc = np.einsum("nji,jk->nik", R_cs, P)  # (R_cs^T P): body -> camera
    return a, b, R_bc


def viewpoint_directions(alpha: np.ndarray, beta: np.ndarray, pole_axis: str = "z") -> np.ndarray:
    """Unit vectors from the body centre to the viewpoints, body frame, Eq. (5) with ``R = 1``.

    Parameters
    ----------
    alpha, beta : np.ndarray (N,)
        Viewpoint angles, rad.
    pole_axis : str
        Body axis of the sampling pole.

    Returns
    -------
    np.ndarray (N, 3)
    """
    s = np.stack([np.sin(alpha) * np.cos(beta), np.sin(alpha) * np.sin(beta), np.cos(alpha)], axis=-1)
    return s @ pole_permutation(pole_axis)  # P^T s


def project_points(
    points_body: np.ndarray,
    R_body_to_camera: np.ndarray,
    t_camera: np.ndarray,
    focal_px: float,
    principal_rc: tuple[float, float],
) -> tuple[np.ndarray, np.ndarray]:
    """Pinhole projection of body-frame points, Eq. (9) of Wu et al.

    ``X_c = R X_b + t``; ``row = rc + f y_c / z_c``, ``col = cc + f x_c / z_c``
    (docs/design.md convention; ``k_x = k_y = f`` in the paper's notation).

    Parameters
    ----------
    points_body : np.ndarray (..., 3)
        Points in the body frame (km).
    R_body_to_camera : np.ndarray (3, 3)
        Body-to-camera rotation.
    t_camera : np.ndarray (3,)
        Body centre in the camera frame (km).
    focal_px : float
        Focal length, px.
    principal_rc : (float, float)
        Principal point (row, col), px.

    Returns
    -------
    rc
        ``(..., 2)`` pixel coordinates ``(row, col)``.
    z
        ``(...)`` depths along the boresight.
    """
    Xc = points_body @ np.asarray(R_body_to_camera).T + np.asarray(t_camera)
    z = Xc[..., 2]
    rc = np.stack([principal_rc[0] + focal_px * Xc[..., 1] / z, principal_rc[1] + focal_px * Xc[..., 0] / z], axis=-1)
    return rc, z


__all__ = [
    "ViewSphereOptions",
    "camera_to_sampling",
    "camera_transform",
    "pole_permutation",
    "project_points",
    "template_rotations",
    "view_angles",
    "view_count",
    "viewpoint_directions",
]
