"""View sphere, camera transform and projection (Eq. 5-7, 9 of Wu et al.)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from jaxlimb.errors import ConfigError
from jaxlimb.irregular.views import (
    ViewSphereOptions,
    camera_transform,
    project_points,
    template_rotations,
    view_angles,
    view_count,
    viewpoint_directions,
)


def test_paper_count_6962_at_3_degrees():
    assert view_count(3.0) == 6962
    a, b = view_angles(ViewSphereOptions(step_deg=3.0))
    assert a.shape == b.shape == (6962,)


@pytest.mark.parametrize("step", [3.0, 5.0, 10.0, 15.0, 30.0, 7.0])
def test_count_matches_eq6_and_sampling(step):
    n_lat, n_lon = math.floor(180 / step), math.floor(360 / step)
    assert view_count(step) == (n_lat - 2) * n_lon + 2
    assert len(view_angles(ViewSphereOptions(step))[0]) == view_count(step)
    assert view_count(step, "grid") == (n_lat - 1) * n_lon + 2
    assert len(view_angles(ViewSphereOptions(step, rings="grid"))[0]) == view_count(step, "grid")


def test_views_distinct_and_cover_sphere():
    a, b = view_angles(ViewSphereOptions(10.0))
    d = viewpoint_directions(a, b)
    assert np.allclose(np.linalg.norm(d, axis=1), 1.0)
    # distinct directions
    g = d @ d.T - 2 * np.eye(len(d))
    assert g.max() < math.cos(math.radians(1.0))
    # every direction on the sphere is within ~ a step of some viewpoint
    rng = np.random.default_rng(0)
    q = rng.normal(size=(2000, 3))
    q /= np.linalg.norm(q, axis=1, keepdims=True)
    worst = np.degrees(np.arccos(np.clip((q @ d.T).max(axis=1), -1, 1))).max()
    assert worst < 10.0


def test_eq7_transform_points_camera_at_origin():
    for alpha, beta in [(0.3, 1.1), (1.2, -2.0), (2.9, 0.4)]:
        T = camera_transform(alpha, beta, 5.0)
        R = T[:3, :3]
        assert np.allclose(R.T @ R, np.eye(3), atol=1e-12)
        assert np.linalg.det(R) == pytest.approx(1.0)  # right-handed camera frame
        # the boresight (camera +z) points from the viewpoint to the origin
        assert np.allclose(R[:, 2], -T[:3, 3] / 5.0)
        # the origin maps to the camera frame's z axis at distance R
        origin_cam = np.linalg.inv(T) @ np.array([0, 0, 0, 1.0])
        assert np.allclose(origin_cam[:3], [0, 0, 5.0])


@pytest.mark.parametrize("pole", ["x", "y", "z"])
def test_pole_axis(pole):
    a, b, R = template_rotations(ViewSphereOptions(30.0, pole_axis=pole))
    north = -R[0, 2, :]  # first view: camera looks from the north pole toward the centre
    axis = {"x": [1, 0, 0], "y": [0, 1, 0], "z": [0, 0, 1]}[pole]
    assert np.allclose(north, axis)
    d = viewpoint_directions(a, b, pole)
    assert np.allclose(R[:, 2, :], -d)


def test_eq9_projection_matches_camera_convention():
    pts = np.array([[1.0, 2.0, 0.0], [0.0, 0.0, 0.0]])
    rc, z = project_points(pts, np.eye(3), np.array([0.0, 0.0, 10.0]), 100.0, (50.0, 60.0))
    assert np.allclose(z, 10.0)
    assert np.allclose(rc[1], [50.0, 60.0])  # body centre -> principal point
    assert np.allclose(rc[0], [50.0 + 100 * 2 / 10, 60.0 + 100 * 1 / 10])  # +y -> +row, +x -> +col


@pytest.mark.parametrize("bad", [0.0, -3.0, 91.0, float("nan")])
def test_bad_step_refused(bad):
    with pytest.raises(ConfigError, match="step_deg"):
        ViewSphereOptions(step_deg=bad)


def test_bad_pole_refused():
    with pytest.raises(ConfigError, match="pole_axis"):
        ViewSphereOptions(pole_axis="w")
