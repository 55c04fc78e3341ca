"""Hostile inputs for the fuzz suite (small files made once per session)."""

from __future__ import annotations

import json
from pathlib import Path

import cv2
import numpy as np
import pytest

from ._cli import CASES

ROWS, COLS = 120, 160

#: A valid camera for the 120x160 frames (the default camera's field of view, scaled).
CAMERA = {"focal_length_mm": 16.0 * COLS / 2592, "pixel_pitch_mm": 2.2e-3, "rows": ROWS, "cols": COLS,
          "principal_point_rc": [(ROWS - 1) / 2, (COLS - 1) / 2]}
HINTS = {"body": "moon", "sun_dir_camera": [0.3, -0.2, -0.93], "range_prior_km": 30000.0}

_OCTAHEDRON = ("v 1 0 0\nv -1 0 0\nv 0 1 0\nv 0 -1 0\nv 0 0 1\nv 0 0 -1\n"
               "f 1 3 5\nf 3 2 5\nf 2 4 5\nf 4 1 5\nf 3 1 6\nf 2 3 6\nf 4 2 6\nf 1 4 6\n")


def _disk() -> np.ndarray:
    rr, cc = np.mgrid[0:ROWS, 0:COLS]
    d = np.hypot(rr - 60.3, cc - 80.7) - 30.0
    return np.clip(20 + 180 / (1 + np.exp(2.0 * d)), 0, 255).astype(np.uint8)


@pytest.fixture(scope="session")
def inputs(tmp_path_factory) -> dict[str, Path]:
    """Named files: valid ones (moon, camera, hints, mesh) and hostile ones."""
    d = tmp_path_factory.mktemp("fuzz")
    f = {name: d / name for name in ("moon.png", "black.png", "white.png", "noise.png", "noise.npy", "camera.json",
                                     "hints.json", "mesh.obj", "garbage.obj", "nan.obj", "empty.png", "garbage.png",
                                     "truncated.png", "text.txt", "db.npz", "garbage.npz", "list.json", "bad.json")}
    cv2.imwrite(str(f["moon.png"]), _disk())
    cv2.imwrite(str(f["black.png"]), np.zeros((ROWS, COLS), np.uint8))
    cv2.imwrite(str(f["white.png"]), np.full((ROWS, COLS), 255, np.uint8))
    rng = np.random.default_rng(14)
    cv2.imwrite(str(f["noise.png"]), rng.integers(0, 256, (ROWS, COLS)).astype(np.uint8))
    np.save(f["noise.npy"], 100.0 + 10.0 * rng.standard_normal((ROWS, COLS)))
    f["camera.json"].write_text(json.dumps(CAMERA))
    f["hints.json"].write_text(json.dumps(HINTS))
    f["mesh.obj"].write_text(_OCTAHEDRON)
    f["garbage.obj"].write_bytes(rng.bytes(4000))
    f["nan.obj"].write_text(_OCTAHEDRON.replace("v 0 0 -1", "v 0 0 nan"))
    f["empty.png"].write_bytes(b"")
    f["garbage.png"].write_bytes(rng.bytes(3000))
    f["truncated.png"].write_bytes(f["moon.png"].read_bytes()[:200])
    f["text.txt"].write_text("not a directory\n")
    f["db.npz"].write_bytes(b"")  # an existing --db file: refused cases never reach it
    f["garbage.npz"].write_bytes(rng.bytes(2000))
    f["list.json"].write_text("[1, 2, 3]")
    f["bad.json"].write_text("{not json")
    f["dir"] = d / "a_directory"
    f["dir"].mkdir()
    f["missing"] = d / "missing" / "nothing.png"
    f["under_file"] = f["text.txt"] / "x.png"  # a path whose "directory" is a regular file
    return f


def pytest_terminal_summary(terminalreporter) -> None:  # noqa: ANN001
    if CASES["n"]:
        terminalreporter.write_line(f"fuzz suite: {CASES['n']} hostile CLI cases run in-process")
