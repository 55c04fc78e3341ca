"""Shared fixtures for the irregular-body tests: small meshes and tiny databases."""

from __future__ import annotations

import pytest
from irregular_helpers import THEBE, lumpy_ellipsoid

from jaxlimb.geometry.camera import Camera
from jaxlimb.irregular.database import DatabaseOptions, build_database
from jaxlimb.irregular.mesh import Mesh, load_mesh


@pytest.fixture(scope="session")
def lumpy() -> Mesh:
    return lumpy_ellipsoid()


@pytest.fixture(scope="session")
def thebe() -> Mesh:
    return load_mesh(THEBE)


@pytest.fixture(scope="session")
def lumpy_db(lumpy):
    return build_database(lumpy, DatabaseOptions(step_deg=10.0, template_size_px=256), progress=False)


@pytest.fixture(scope="session")
def thebe_db(thebe):
    return build_database(thebe, DatabaseOptions(step_deg=6.0, pole_axis="y", template_size_px=384), progress=False)


@pytest.fixture(scope="session")
def small_camera() -> Camera:
    return Camera(focal_length_mm=16.0, pixel_pitch_mm=2.2e-3, rows=480, cols=640)
