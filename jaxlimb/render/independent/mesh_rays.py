r"""Ray-traced images of a triangle mesh: the independent check of the irregular-body line of sight.

Written apart from the package's own mesh renderer (:mod:`jaxlimb.render.mesh`: painter's
algorithm, flat-shaded facets, no cast shadows, Lommel-Seeliger or Lambert, Gaussian PSF) and from
the model the registration fits (:mod:`jaxlimb.irregular.model_render`).  Here:

* **geometry**: every pixel of the body's window is sampled by ``s x s`` jittered rays from the
  pinhole, intersected with the mesh by Embree (``trimesh`` with ``embreex``); a pixel is the mean
  of its rays (area coverage of the silhouette and of the shadows);
* **shading**: normals interpolated across each facet from the vertex normals of ``trimesh``
  (facet normals weighted by their angle at the vertex; smooth shading, no facet edges), and the
  facet must face the Sun as well;
* **cast shadows**: a ray toward the Sun from every lit hit; a hit on the body is a shadow
  (concavities, the neck of a contact binary, crater walls);
* **reflectance**: the independent laws of :class:`~.surface.Photometry` (Hapke, Minnaert,
  Lommel-Seeliger with opposition surge, lunar-Lambert, Lambert) at the local phase angle;
* **albedo**: variegated, ``1 + depth * noise(u)`` with :class:`~.surface.ValueNoise` on the
  body-fixed direction of the hit point;
* **optics and sensor**: the independent PSFs (Gaussian, Airy, defocus, motion) integrated over
  each pixel (:func:`~.raster.pixel_kernel`), then :func:`~.sensor.digitise` (photon and read
  noise, 8 or 12 bits, stars, hot pixels, JPEG).

Truth: the image of the mesh origin (the body centre, docs/design.md) through the pinhole,
:meth:`~.geometry.Pinhole.project` of ``t``.  Pixel ``(0, 0)`` is the centre of the top-left pixel.

:func:`cratered_body` makes shapes unlike :mod:`jaxlimb.irregular.shapes`' radius functions:
a triaxial ellipsoid with bowl-shaped craters (raised rims) and a flattened facet.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
from scipy.signal import fftconvolve

from .optics import Psf
from .raster import pixel_kernel
from .sensor import SensorSpec, digitise
from .surface import Photometry, ValueNoise


@dataclass(frozen=True)
class MeshScene:
    """What to render: mesh (body frame, km), pose (``x_cam = R x_body + t``), Sun, surface, optics."""

    vertices: np.ndarray
    faces: np.ndarray
    R_body_to_camera: np.ndarray
    t_camera_km: np.ndarray
    sun_dir_camera: np.ndarray
    photometry: Photometry = Photometry()
    albedo_depth: float = 0.0
    albedo_seed: int = 0
    psf: Psf = Psf()
    sensor: SensorSpec = field(default_factory=lambda: SensorSpec(bits=12, read_noise_dn=2.0, background_dn=20.0))
    shadows: bool = True
    smooth_normals: bool = True


def _camera_mesh(scene: MeshScene):
    import trimesh

    V = np.asarray(scene.vertices, float) @ np.asarray(scene.R_body_to_camera, float).T + np.asarray(scene.t_camera_km, float)
    return trimesh.Trimesh(V, np.asarray(scene.faces), process=False)


def _window(tm, pin, margin: int) -> tuple[int, int, int, int]:
    V = tm.vertices
    if np.any(V[:, 2] <= 0):
        raise ValueError("part of the body is behind the camera")
    r = pin.principal_point_rc[0] + pin.focal_px * V[:, 1] / V[:, 2]
    c = pin.principal_point_rc[1] + pin.focal_px * V[:, 0] / V[:, 2]
    r0, r1 = max(0, int(math.floor(r.min())) - margin), min(pin.rows, int(math.ceil(r.max())) + margin + 1)
    c0, c1 = max(0, int(math.floor(c.min())) - margin), min(pin.cols, int(math.ceil(c.max())) + margin + 1)
    if r1 <= r0 or c1 <= c0:
        raise ValueError("the body is entirely outside the frame")
    return r0, r1, c0, c1


def _rays(pin, win, s: int, rng: np.random.Generator) -> np.ndarray:
    """Unit ray directions ``(h, w, s*s, 3)``: stratified sub-pixel samples, jittered in every pixel independently.

    Why per pixel: one jitter pattern shared by all pixels samples every pixel at the same mean offset (~0.03 px
    per axis for ``s = 3``), which displaces the whole frame from its truth: a bias of the renderer that a
    registration against that truth would report as the measurement's."""
    r0, r1, c0, c1 = win
    h, w = r1 - r0, c1 - c0
    cell = (np.arange(s) + 0.5) / s - 0.5
    jr = (cell[:, None] + rng.uniform(-0.5, 0.5, (h, w, s, s)) / s).reshape(h, w, s * s)
    jc = (cell[None, :] + rng.uniform(-0.5, 0.5, (h, w, s, s)) / s).reshape(h, w, s * s)
    rows = np.arange(r0, r1, dtype=float)[:, None, None] + jr
    cols = np.arange(c0, c1, dtype=float)[None, :, None] + jc
    d = pin.directions(rows, cols)
    return d / np.linalg.norm(d, axis=-1, keepdims=True)


def _smooth_normals(tm, tri: np.ndarray, loc: np.ndarray) -> np.ndarray:
    """Normals interpolated across each hit facet from the vertex normals (barycentric weights)."""
    from trimesh.triangles import points_to_barycentric

    bary = points_to_barycentric(tm.triangles[tri], loc)
    vn = tm.vertex_normals[tm.faces[tri]]  # (n, 3 vertices, 3)
    n = np.einsum("nk,nkj->nj", bary, vn)
    return n / np.linalg.norm(n, axis=1, keepdims=True)


def _shade(scene: MeshScene, tm, loc, tri, d) -> np.ndarray:
    """Radiance of every hit: reflectance x albedo, 0 in shadow or facing away from the Sun."""
    s = np.asarray(scene.sun_dir_camera, float)
    s = s / np.linalg.norm(s)
    ng = tm.face_normals[tri]
    n = _smooth_normals(tm, tri, loc) if scene.smooth_normals else ng
    mu0, mu = n @ s, np.clip(-(n * d).sum(axis=1), 1e-6, 1.0)
    lit = (mu0 > 0) & (ng @ s > 0)
    idx = np.nonzero(lit)[0]
    if idx.size and scene.shadows:
        # shadow rays in a frame centred on the body: Embree works in float32, and at the camera's
        # distance its rounding (1e-7 of the range) would put the ray origins below the surface
        import trimesh

        t = np.asarray(scene.t_camera_km, float)
        centered = trimesh.Trimesh(tm.vertices - t, tm.faces, process=False)
        eps = 1e-5 * float(np.linalg.norm(tm.extents))
        blocked = centered.ray.intersects_any(loc[idx] - t + eps * ng[idx], np.ascontiguousarray(np.broadcast_to(s, (idx.size, 3))))
        lit[idx[blocked]] = False
    rad = scene.photometry.radiance(np.where(lit, mu0, 0.0), mu, -(d @ s))
    if scene.albedo_depth:
        u_body = (loc - np.asarray(scene.t_camera_km, float)) @ np.asarray(scene.R_body_to_camera, float)
        u_body /= np.linalg.norm(u_body, axis=1, keepdims=True)
        rad = rad * np.clip(1.0 + scene.albedo_depth * ValueNoise(scene.albedo_seed, octaves=4)(u_body), 0.05, None)
    return rad


def render_radiance(scene: MeshScene, pin, supersample: int = 3, seed: int = 0) -> tuple[np.ndarray, tuple]:
    """The blurred, pixel-integrated radiance image ``(rows, cols)`` and the body's window."""
    tm = _camera_mesh(scene)
    E = scene.psf.extent_px()
    win = _window(tm, pin, 2)
    r0, r1, c0, c1 = win
    d = _rays(pin, win, supersample, np.random.default_rng(seed)).reshape(-1, 3)
    loc, iray, itri = tm.ray.intersects_location(np.zeros_like(d), d, multiple_hits=False)
    vals = np.zeros(d.shape[0])
    if iray.size:
        vals[iray] = _shade(scene, tm, loc, itri, d[iray])
    pix = vals.reshape(r1 - r0, c1 - c0, supersample * supersample).mean(axis=2)
    img = np.zeros((pin.rows, pin.cols))
    big = np.pad(pix, E)
    blurred = fftconvolve(big, pixel_kernel(scene.psf), mode="same")
    R0, C0 = r0 - E, c0 - E
    rs, cs = max(R0, 0), max(C0, 0)
    re, ce = min(R0 + big.shape[0], pin.rows), min(C0 + big.shape[1], pin.cols)
    img[rs:re, cs:ce] = np.maximum(blurred[rs - R0: re - R0, cs - C0: ce - C0], 0.0)
    return img, win


def render_mesh_frame(scene: MeshScene, pin, rng: np.random.Generator, supersample: int = 3) -> tuple[np.ndarray, np.ndarray]:
    """Digitised frame and the truth: image ``(row, col)`` of the mesh origin (module docstring)."""
    rad, win = render_radiance(scene, pin, supersample, int(rng.integers(1 << 31)))
    img = digitise(rad, scene.sensor, rng, (win[0], win[1] - 1, win[2], win[3] - 1))
    return img, np.array(pin.project(np.asarray(scene.t_camera_km, float)))


def cratered_body(seed: int = 0, size_km: float = 10.0, n_craters: int = 14, subdivisions: int = 5):
    """A triaxial ellipsoid with bowl craters (raised rims) and one flattened side: ``(V, F)``.

    Axes ``size_km * (1, 0.6-0.85, 0.45-0.7)``; crater radii 10-35 deg, depth 4-12 % of the local
    radius; the flat side cuts 5-12 % off one axis.  Not a radius function of the kind
    :mod:`jaxlimb.irregular.shapes` draws (those are smooth Gaussian fields)."""
    import trimesh

    rng = np.random.default_rng(seed)
    ico = trimesh.creation.icosphere(subdivisions=subdivisions)
    u = ico.vertices / np.linalg.norm(ico.vertices, axis=1, keepdims=True)
    axes = size_km * np.array([1.0, rng.uniform(0.6, 0.85), rng.uniform(0.45, 0.7)])
    r = 1.0 / np.sqrt(((u / axes) ** 2).sum(axis=1))
    for _ in range(n_craters):
        c = rng.normal(size=3)
        c /= np.linalg.norm(c)
        rad = math.radians(rng.uniform(10.0, 35.0))
        x = np.arccos(np.clip(u @ c, -1.0, 1.0)) / rad
        bowl = np.where(x < 1.0, x**2 - 1.0, 0.0)
        rim = 0.25 * np.exp(-(((x - 1.0) / 0.15) ** 2))
        r = r * (1.0 + rng.uniform(0.04, 0.12) * (bowl + rim))
    k = int(rng.integers(3))
    cut = axes[k] * (1.0 - rng.uniform(0.05, 0.12))
    sgn = 1.0 if rng.uniform() < 0.5 else -1.0
    along = sgn * u[:, k] * r
    over = along > cut
    r[over] *= cut / along[over]
    return u * r[:, None], np.asarray(ico.faces)


__all__ = ["MeshScene", "cratered_body", "render_mesh_frame", "render_radiance"]
