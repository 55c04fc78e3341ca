"""Synthetic images with exact truth: ray-traced ellipsoids (Moon, Earth), PSF, noise, stars.

Public API (see each docstring)::

    moon_scene(range_km, phase_deg, center_rc=None, camera=None, sun_angle_deg=0.0, ...) -> Scene
    earth_scene(range_km, latitude_deg, phase_deg, center_rc=None, camera=None, sun_angle_deg=0.0,
                north_angle_deg=90.0, atmosphere=None, ...) -> Scene
    Scene(radii, center_cam, R_body_to_camera, sun_dir_cam, albedo, albedo_patches, atmosphere)
    RenderOptions(reflectance, n_subsamples, psf_sigma_px, exposure_e, full_well_e, bit_depth, ...)
    render_body(scene, camera=None, options=None, seed=None) -> (image, RenderTruth)
    render_radiance(scene, camera, reflectance_model, n_subsamples, pad) -> RadianceWindow
    trace_rays(scene, d) -> RayHits
    limb_accuracy(window, conic=None) -> dict   # rendered limb vs a conic (strip integrals)

Example::

    from jaxlimb.render import moon_scene, render_body
    image, truth = render_body(moon_scene(60000.0, 30.0, center_rc=(900, 1200)), seed=1)
    truth.center_rc, truth.limb.semi_axes_px, truth.limb.angle_rad

Image-plane angles (``sun_angle_deg``, ``north_angle_deg``, ``truth.limb.angle_rad``) are
measured from ``+col`` toward ``-row`` (counter-clockwise as displayed): direction
``(d_row, d_col) = (-sin, cos)``.  The mesh renderer for irregular bodies lives in
``jaxlimb.render.mesh`` (imported separately).
"""

# numpy only (and ``reflectance`` is both a module and a function: bound here, as before)
from .reflectance import LUNAR_LAMBERT_MCEWEN, REFLECTANCE_MODELS, lunar_lambert_L, reflectance

# the rest imported on first use (PEP 562): ``jaxlimb.render.mesh`` (irregular bodies, the CLI's
# ``los locate``) must not pay for the ellipsoid renderer's SciPy imports
_WHERE = {
    "AlbedoPatches": "scene",
    "Atmosphere": "scene",
    "EARTH_RADII_KM": "scene",
    "MOON_RADIUS_KM": "scene",
    "RadianceWindow": "raytrace",
    "RayHits": "raytrace",
    "RenderOptions": "body",
    "RenderTruth": "body",
    "Scene": "scene",
    "add_point_sources": "sensor",
    "digitise": "sensor",
    "earth_scene": "scene",
    "gaussian_psf": "sensor",
    "image_direction_camera": "scene",
    "lattice_offsets": "raytrace",
    "limb_accuracy": "validate",
    "limb_strip_errors": "validate",
    "moon_scene": "scene",
    "pixel_rays": "raytrace",
    "psf_pad": "sensor",
    "render_body": "body",
    "render_radiance": "raytrace",
    "sun_direction_for_phase": "scene",
    "trace_rays": "raytrace",
}


def __getattr__(name: str):  # noqa: ANN202
    if name in _WHERE:
        import importlib

        return getattr(importlib.import_module(f".{_WHERE[name]}", __name__), name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


__all__ = [
    "EARTH_RADII_KM",
    "LUNAR_LAMBERT_MCEWEN",
    "MOON_RADIUS_KM",
    "REFLECTANCE_MODELS",
    "AlbedoPatches",
    "Atmosphere",
    "RadianceWindow",
    "RayHits",
    "RenderOptions",
    "RenderTruth",
    "Scene",
    "add_point_sources",
    "digitise",
    "earth_scene",
    "gaussian_psf",
    "image_direction_camera",
    "lattice_offsets",
    "limb_accuracy",
    "limb_strip_errors",
    "lunar_lambert_L",
    "moon_scene",
    "pixel_rays",
    "psf_pad",
    "reflectance",
    "render_body",
    "render_radiance",
    "sun_direction_for_phase",
    "trace_rays",
]
