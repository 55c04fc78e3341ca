"""Generated small-body shapes that no template database was built from (tests and benchmarks).

Three families, all closed star-shaped meshes (radius function ``r(u)`` sampled on
the vertices of a subdivided icosahedron, so the face winding and the watertightness
of the icosphere carry over):

* :func:`gaussian_sphere` -- Muinonen's Gaussian random sphere (Muinonen 1998,
  *Astron. Astrophys.* 332, 1087): ``r(u) = a exp(s(u) - beta^2/2)`` with ``s`` a
  Gaussian random field expanded in real spherical harmonics, coefficient variance
  ``~ l^-nu`` for ``2 <= l <= l_max``, normalised to the log-radius standard deviation
  ``beta``;
* :func:`contact_binary` -- two overlapping ellipsoidal lobes (the union is
  star-shaped from the origin, which lies inside both), with Gaussian roughness;
* :func:`elongated_body` -- a 3:1:0.8-like ellipsoid with Gaussian roughness.

The mesh origin (the point whose image the line-of-sight methods locate) is the
origin of the radius function, not the centroid of the volume.
"""

from __future__ import annotations

import math
from enum import Enum

import numpy as np
import trimesh
from scipy.special import sph_harm_y

from .mesh import Mesh, validate_mesh


class ShapeFamily(str, Enum):
    """The generated shape families (names used by benchmarks and tests)."""

    GAUSSIAN_SPHERE = "gaussian-sphere"
    CONTACT_BINARY = "contact-binary"
    ELONGATED = "elongated"


def _icosphere(subdivisions: int) -> tuple[np.ndarray, np.ndarray]:
    ico = trimesh.creation.icosphere(subdivisions=subdivisions, radius=1.0)
    u = np.asarray(ico.vertices, dtype=float)
    return u / np.linalg.norm(u, axis=1, keepdims=True), np.asarray(ico.faces, dtype=np.int64)


def log_radius_field(u: np.ndarray, rng: np.random.Generator, beta: float, l_max: int = 10, nu: float = 4.0) -> np.ndarray:
    """Gaussian random field ``s(u)`` on unit vectors ``u``, standard deviation ``beta`` (Muinonen 1998).

    Real spherical harmonics of degrees ``2..l_max`` with coefficient variance ``l^-nu``, normalised so that
    the field's variance is ``beta^2``.

    Parameters
    ----------
    u : np.ndarray (n, 3)
        Unit vectors.
    rng : np.random.Generator
        Source of the coefficients.
    beta : float
        Standard deviation of the field.
    l_max, nu : int, float
        Largest degree and the power-law index of the coefficient variance.

    Returns
    -------
    np.ndarray (n,)
    """
    theta = np.arccos(np.clip(u[:, 2], -1.0, 1.0))
    phi = np.arctan2(u[:, 1], u[:, 0])
    s = np.zeros(u.shape[0])
    var = 0.0
    for ell in range(2, l_max + 1):
        c_l = float(ell) ** (-nu)
        for m in range(-ell, ell + 1):
            y = sph_harm_y(ell, abs(m), theta, phi)
            basis = math.sqrt(2.0) * (y.real if m > 0 else y.imag) if m != 0 else y.real
            s += rng.normal(0.0, math.sqrt(c_l)) * basis
        var += c_l * (2 * ell + 1) / (4.0 * math.pi)
    return beta * s / math.sqrt(var)


def gaussian_sphere(seed: int = 0, radius_km: float = 10.0, beta: float = 0.2, subdivisions: int = 4) -> Mesh:
    """A Gaussian random sphere of mean radius ``radius_km`` (log-radius deviation ``beta``).

    Parameters
    ----------
    seed : int
        Random seed.
    radius_km, beta : float
        Mean radius (km) and standard deviation of the log radius.
    subdivisions : int
        Icosphere subdivisions (4: 2562 vertices, 5120 faces).

    Returns
    -------
    Mesh
    """
    rng = np.random.default_rng(seed)
    u, f = _icosphere(subdivisions)
    r = radius_km * np.exp(log_radius_field(u, rng, beta) - 0.5 * beta**2)
    return validate_mesh(u * r[:, None], f, source=f"gaussian-sphere-{seed}")


def _ray_exit(u: np.ndarray, center: np.ndarray, radii: np.ndarray) -> np.ndarray:
    """Distance from the origin along ``u`` to where the ray leaves an axis-aligned ellipsoid (origin inside)."""
    a = np.sum((u / radii) ** 2, axis=1)
    b = -2.0 * np.sum(u * center / radii**2, axis=1)
    c = float(np.sum((center / radii) ** 2)) - 1.0
    return (-b + np.sqrt(b * b - 4.0 * a * c)) / (2.0 * a)


def contact_binary(seed: int = 0, size_km: float = 10.0, beta: float = 0.06, subdivisions: int = 4) -> Mesh:
    """Two ellipsoidal lobes overlapping at the origin (a bilobed body, long axis ~ ``size_km``).

    Parameters
    ----------
    seed : int
        Random seed (lobe axes and roughness).
    size_km, beta : float
        Long axis (km) and the log-radius deviation of the roughness.
    subdivisions : int
        Icosphere subdivisions.

    Returns
    -------
    Mesh
    """
    rng = np.random.default_rng(seed)
    u, f = _icosphere(subdivisions)
    s = size_km / 4.0
    r1 = s * np.array([1.2, 1.0, 0.9]) * rng.uniform(0.9, 1.1, 3)
    r2 = s * np.array([0.9, 0.8, 0.7]) * rng.uniform(0.9, 1.1, 3)
    c1 = np.array([-0.8 * r1[0], 0.0, 0.0])
    c2 = np.array([0.75 * r2[0], 0.05 * s * rng.normal(), 0.05 * s * rng.normal()])
    r = np.maximum(_ray_exit(u, c1, r1), _ray_exit(u, c2, r2))
    r = r * np.exp(log_radius_field(u, rng, beta) - 0.5 * beta**2)
    return validate_mesh(u * r[:, None], f, source=f"contact-binary-{seed}")


def elongated_body(seed: int = 0, size_km: float = 10.0, beta: float = 0.08, subdivisions: int = 4) -> Mesh:
    """A rough elongated ellipsoid (axes about 3 : 1.1 : 0.8), long axis ~ ``size_km``.

    Parameters
    ----------
    seed : int
        Random seed (axes and roughness).
    size_km, beta : float
        Long axis (km) and the log-radius deviation of the roughness.
    subdivisions : int
        Icosphere subdivisions.

    Returns
    -------
    Mesh
    """
    rng = np.random.default_rng(seed)
    u, f = _icosphere(subdivisions)
    radii = 0.5 * size_km * np.array([1.0, 0.37, 0.27]) * rng.uniform(0.9, 1.1, 3)
    r = _ray_exit(u, np.zeros(3), radii) * np.exp(log_radius_field(u, rng, beta) - 0.5 * beta**2)
    return validate_mesh(u * r[:, None], f, source=f"elongated-{seed}")


_MAKERS = {
    ShapeFamily.GAUSSIAN_SPHERE: gaussian_sphere,
    ShapeFamily.CONTACT_BINARY: contact_binary,
    ShapeFamily.ELONGATED: elongated_body,
}


def generate_shape(family: ShapeFamily | str, seed: int = 0) -> Mesh:
    """A generated body of the given family and seed (see the module docstring).

    Parameters
    ----------
    family : ShapeFamily or str
        ``"gaussian-sphere"``, ``"contact-binary"`` or ``"elongated"``.
    seed : int
        Random seed.

    Returns
    -------
    Mesh
        At the family's default size (10 km: mean radius of the Gaussian sphere, long axis of the others).
    """
    return _MAKERS[ShapeFamily(family)](seed=seed)


__all__ = ["ShapeFamily", "contact_binary", "elongated_body", "gaussian_sphere", "generate_shape", "log_radius_field"]
