"""Helpers shared by the irregular-body tests: mesh paths and a generated lumpy mesh."""

from __future__ import annotations

from jaxlimb._data import shared_data_dir
import numpy as np
import trimesh

from jaxlimb.irregular.mesh import Mesh, validate_mesh

THEBE = str(shared_data_dir() / "meshes" / "thebe.obj")
EROS = str(shared_data_dir() / "meshes" / "eros007790.tab")


def lumpy_ellipsoid(seed: int = 7, subdivisions: int = 4, radii=(1.6, 1.0, 0.7), offset=(0.15, -0.1, 0.05)) -> Mesh:
    """A chiral, irregular closed mesh: an ellipsoid with random bumps, shifted off its origin."""
    rng = np.random.default_rng(seed)
    ico = trimesh.creation.icosphere(subdivisions=subdivisions, radius=1.0)
    v = np.asarray(ico.vertices, dtype=float)
    bumps = np.zeros(len(v))
    for _ in range(6):
        c = rng.normal(size=3)
        c /= np.linalg.norm(c)
        bumps += rng.uniform(0.05, 0.2) * np.exp(-((v @ c - 1.0) ** 2) / 0.05)
    v = v * (1.0 + bumps)[:, None] * np.asarray(radii) + np.asarray(offset)
    return validate_mesh(v, np.asarray(ico.faces), source="lumpy")




def render_view(mesh: Mesh, camera, view_dir, size_px: float, roll: float = 0.0, offset_px=(0.0, 0.0), sun=None, **opts):
    """Render ``mesh`` seen from direction ``view_dir`` (body frame), ``size_px`` across, centre offset by ``offset_px``."""
    from jaxlimb.render.mesh import MeshRenderOptions, look_at_rotation, render_mesh

    d = np.asarray(view_dir, dtype=float)
    d = d / np.linalg.norm(d)
    D = 2.0 * mesh.max_radius * camera.focal_px / size_px
    R = look_at_rotation(d, roll_rad=roll)
    t = np.array([offset_px[1] * D / camera.focal_px, offset_px[0] * D / camera.focal_px, D])
    return render_mesh(mesh.vertices, mesh.faces, camera, R, t, sun_dir_camera=sun, options=MeshRenderOptions(**opts))
