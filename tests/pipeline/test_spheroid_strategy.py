"""A body measured by its shape: a spheroid whose flattening the frame resolves takes the ellipsoid strategy, a
near-sphere stays round (jaxlimb.pipeline.bodies); the Cassini Jupiter frame located on its limb."""

from __future__ import annotations

import jax
import numpy as np
import pytest

from jaxlimb._data import shared_data_dir
from jaxlimb.geometry.camera import Camera
from jaxlimb.pipeline import LocateOptions
from jaxlimb.pipeline.bodies import body_strategy, spheroid_departure_px
from jaxlimb.pipeline.ellipsoid import Ellipsoid
from jaxlimb.pipeline.frame import prepare
from jaxlimb.pipeline.sphere import PredictedLimbSphere, Sphere
from jaxlimb.pipeline.sphere.predicted import EDGE_MODEL_SIGMA_PX

jax.config.update("jax_enable_x64", True)

JUPITER = shared_data_dir() / "cassini" / "jupiter"
#: The centre of the limb one sees on the frame (``benchmarks/_limb_trace.py``, the real-frame benchmark's truth:
#: the median over its level crossings and lit windows, spread 0.01 / 0.06 px).
JUPITER_LIMB_TRACE_RC = (516.573, 456.508)


def _pick(hints: dict, options: LocateOptions | None = None):
    img = np.zeros((1024, 1024), np.uint8)
    cam = Camera(focal_length_mm=2000.0, pixel_pitch_mm=0.012, rows=1024, cols=1024)
    frame = prepare(img, cam, hints, options)
    return body_strategy(frame), spheroid_departure_px(frame)


def test_an_oblate_planet_is_an_ellipsoid_a_near_sphere_stays_round():
    # Jupiter at 53 million km in a 2000 mm camera: ~225 px, its poles ~14.6 px inside the equator's circle
    body, dep = _pick({"body": "jupiter", "range_prior_km": 5.3e7})
    assert isinstance(body, Ellipsoid) and dep == pytest.approx(14.6, abs=0.2)
    assert (body.model.equatorial_km, body.model.polar_km, body.model.atmosphere_km) == (71492.0, 66854.0, 0.0)
    # the same spheroid from the hints' radii, and the size from the expected radius instead of the range
    body, dep = _pick({"body": "gas giant", "body_radii_km": [60268.0, 60268.0, 54364.0], "expected_radius_px": 50.0})
    assert isinstance(body, Ellipsoid) and dep == pytest.approx(50.0 * (1 - 54364.0 / 60268.0))
    # Mercury (8 px) a spheroid whose 2.3 km flattening is 0.008 px: below the edge model's error, round
    body, dep = _pick({"body": "mercury", "range_prior_km": 5.0e7})
    assert type(body) is Sphere and 0.0 < dep < EDGE_MODEL_SIGMA_PX
    # spheres and triaxial bodies stay round (a triaxial limb is held by the predicted-limb sphere under SPICE)
    for hints in ({"body": "moon", "range_prior_km": 4.0e5}, {"body": "enceladus", "range_prior_km": 1.4e5},
                  {"body": "europa", "range_prior_km": 1.0e6}, {"body": "mimas"}):
        body, dep = _pick(hints)
        assert type(body) is Sphere and dep == 0.0, hints
    predicted = {"body": "enceladus", "range_prior_km": 1.4e5, "expected_center_rc": [512.0, 512.0]}
    assert _pick(predicted)[0] == PredictedLimbSphere(arc=False)
    # what the ellipsoid cannot do keeps the sphere: the papers' fixed-k setting
    assert type(_pick({"body": "jupiter", "range_prior_km": 5.3e7}, LocateOptions(estimate_k=False))[0]) is Sphere


@pytest.mark.skipif(not (JUPITER / "n1352037683.2").exists(), reason="shared Cassini Jupiter frame not present")
def test_jupiter_frame_is_located_on_its_limb_by_the_ellipsoid():
    # the edge fit's answer (profile="sigmoid": seconds); the default answer, with the lunar-Lambert profile refit,
    # is benchmarks/real_frames.py's (docs/validation/real-frames.md)
    from jaxlimb.geometry.spice import spice_geometry
    from jaxlimb.imaging.formats import read_frame
    from jaxlimb.pipeline import locate

    kernels = sorted(str(p) for p in (JUPITER / "kernels").iterdir())
    kernels += sorted(str(p) for p in (JUPITER.parent / "kernels").iterdir())
    frame = read_frame(str(JUPITER / "n1352037683.2"))
    geom = spice_geometry(kernels, frame.meta.image_time, frame.meta.instrument_id, frame.meta.target_name)
    opt = LocateOptions(profile="sigmoid", max_center_sigma_px=2.0)
    m = locate(frame.data, geom.camera, geom.hints(), opt, mask=frame.mask_or_none)
    assert m.front_end == "predicted" and m.extras["free_ellipse"] is False  # the ellipsoid, its shape predicted
    assert m.radius_px is None and m.ellipse.semi_axes_px[1] / m.ellipse.semi_axes_px[0] < 0.94
    err = np.asarray(m.center_rc) - JUPITER_LIMB_TRACE_RC
    P = np.array([[m.covariance[a][b] for b in ("center_r", "center_c")] for a in ("center_r", "center_c")])
    assert np.hypot(*err) < 1.0
    assert float(err @ np.linalg.solve(P, err)) < 25.0  # within 5 sigma


def test_navigate_maps_a_spheroid_measurement_through_its_range():
    # a giant planet's measurement (the ellipsoid's: centre and range, no radius) gives the observer from the range
    from types import SimpleNamespace

    from jaxlimb.cli._observer import measurement_map, ranged

    cam = Camera(focal_length_mm=2000.0, pixel_pitch_mm=0.012, rows=1024, cols=1024)
    names = ("center_r", "center_c", "range_km")
    meas = SimpleNamespace(covariance={a: {b: float(a == b) for b in names} for a in names}, range_km=5.3e7,
                           radius_px=None)
    assert ranged("jupiter", meas) and ranged("earth", meas)
    got, fn = measurement_map("jupiter", cam, meas)
    x = np.array([500.0, 520.0, 5.3e7])
    assert got == list(names) and np.allclose(fn(x), 5.3e7 * cam.los(x[:2]))
    # a round body's: centre and radius
    names = ("center_r", "center_c", "radius")
    moon = SimpleNamespace(covariance={a: {b: float(a == b) for b in names} for a in names}, range_km=4.0e5,
                           radius_px=100.0)
    assert not ranged("moon", moon) and measurement_map("moon", cam, moon)[0] == list(names)
