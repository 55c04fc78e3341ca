"""The navigation prior a filter supplies with a frame (the hints of ``docs/design.md``): body, radii, range,
Sun direction, attitude, predicted centre.  Every field is optional; a bad value is a
:class:`~jaxlimb.errors.ConfigError` naming the key."""

from __future__ import annotations

import os
import warnings
from dataclasses import dataclass
from typing import Any

import numpy as np

from .._io import read_json_file
from .._schema import explain, schema_keys
from .._validate import Range, matrix, near_key, number, vector
from ..errors import ConfigError, HintsKeyWarning
from .bodies import BODY_TABLE


def _num(key: str, v: Any, *, lo: float | None = None, hi: float | None = None, lo_open: bool = False) -> float:
    return number(v, f"hints `{key}`", Range(lo, hi, lo_open=lo_open))


def _vec(key: str, v: Any, n: int) -> tuple[float, ...]:
    return vector(v, f"hints `{key}`", n)


@dataclass(frozen=True)
class Hints:
    """The navigation prior of ``docs/design.md`` (every field optional).

    Attributes
    ----------
    body
        ``"moon"``, ``"earth"`` or another name (lower-cased).
    body_radii_km
        Triaxial radii ``(a, b, c)`` in km (> 0).  Default from ``body``.
    expected_radius_px
        Expected apparent radius (px, > 0), from a rough range.
    expected_radius_uncertainty_frac
        Relative 1-sigma-ish uncertainty of the expected radius, in (0, 10].
    range_prior_km
        Rough observer-to-body-centre distance (km, > 0).
    sun_dir_camera
        Unit vector from the body toward the Sun, camera frame (normalised on input).
    atmosphere_km
        Limb height above the solid body (km, >= 0).
    bit_depth
        Bits per pixel of the image (1..32).
    R_body_to_camera
        3x3 rotation (proper, orthonormal to 1e-6) body-fixed -> camera.
    expected_center_rc
        Predicted image ``(row, col)`` of the body centre (px), e.g. from SPICE; with a camera,
        the range and the radii it places the predicted limb (:mod:`jaxlimb.imaging.predicted`).
    """

    body: str | None = None
    body_radii_km: tuple[float, float, float] | None = None
    expected_radius_px: float | None = None
    expected_radius_uncertainty_frac: float | None = None
    range_prior_km: float | None = None
    sun_dir_camera: tuple[float, float, float] | None = None
    atmosphere_km: float | None = None
    bit_depth: int | None = None
    R_body_to_camera: tuple[tuple[float, float, float], ...] | None = None
    expected_center_rc: tuple[float, float] | None = None

    def __post_init__(self) -> None:
        s = object.__setattr__
        if self.expected_center_rc is not None:
            s(self, "expected_center_rc", _vec("expected_center_rc", self.expected_center_rc, 2))
        if self.body is not None:
            if not isinstance(self.body, str) or not self.body.strip():
                raise ConfigError(f"hints `body` must be a non-empty string, got {self.body!r}")
            s(self, "body", self.body.strip().lower())
        if self.body_radii_km is not None:
            r = _vec("body_radii_km", self.body_radii_km, 3)
            if min(r) <= 0:
                raise ConfigError(f"hints `body_radii_km` must be three radii > 0 km, got {self.body_radii_km!r}")
            s(self, "body_radii_km", r)
        if self.expected_radius_px is not None:
            s(self, "expected_radius_px", _num("expected_radius_px", self.expected_radius_px, lo=0, lo_open=True))
        if self.expected_radius_uncertainty_frac is not None:
            s(
                self,
                "expected_radius_uncertainty_frac",
                _num("expected_radius_uncertainty_frac", self.expected_radius_uncertainty_frac, lo=0, hi=10, lo_open=True),
            )
        if self.range_prior_km is not None:
            s(self, "range_prior_km", _num("range_prior_km", self.range_prior_km, lo=0, lo_open=True))
        if self.sun_dir_camera is not None:
            v = np.array(_vec("sun_dir_camera", self.sun_dir_camera, 3))
            nv = float(np.linalg.norm(v))
            if nv < 1e-9:
                raise ConfigError(f"hints `sun_dir_camera` must be a non-zero (unit) vector, got {self.sun_dir_camera!r}")
            s(self, "sun_dir_camera", tuple(float(x) for x in v / nv))
        if self.atmosphere_km is not None:
            s(self, "atmosphere_km", _num("atmosphere_km", self.atmosphere_km, lo=0))
        if self.bit_depth is not None:
            s(self, "bit_depth", number(self.bit_depth, "hints `bit_depth`", Range(1, 32), integer=True))
        if self.R_body_to_camera is not None:
            R = np.asarray(matrix(self.R_body_to_camera, "hints `R_body_to_camera`", (3, 3)))
            err = float(np.abs(R @ R.T - np.eye(3)).max())
            if err > 1e-6 or np.linalg.det(R) < 0:
                raise ConfigError(
                    f"hints `R_body_to_camera` must be a proper rotation (R R^T = I to 1e-6, det = +1); "
                    f"got |R R^T - I| = {err:.3g}, det = {np.linalg.det(R):.6g}"
                )
            s(self, "R_body_to_camera", tuple(tuple(float(x) for x in row) for row in R))

    # ------------------------------------------------------------------ constructors
    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> Hints:
        """Build from the hints JSON object (``jaxlimb/schemas/hints.schema.json``; a wrong type or range is a
        ConfigError naming the key).  Unknown keys are ignored (a filter may carry its own); one that resembles a
        known key is named in a :class:`~jaxlimb.errors.HintsKeyWarning`.  A camera file is refused."""
        if not isinstance(d, dict):
            raise ConfigError(f"hints must be a JSON object, got {type(d).__name__}")
        known, camera_keys = schema_keys("hints"), [k for k in d if k in schema_keys("camera")]
        if d and not set(d) & set(known) and len(camera_keys) >= 2:
            raise ConfigError(f"the hints hold a camera's keys ({', '.join(camera_keys)}): this is a camera file; "
                              "pass it as the camera")
        for k in sorted(set(d) - set(known), key=str):
            near = near_key(k, known)
            if near:
                warnings.warn(f"hints key {k!r} is not known and is ignored; did you mean {near!r}?",
                              HintsKeyWarning, stacklevel=2)
        try:
            return cls(**{k: d[k] for k in known if k in d and d[k] is not None})
        except ConfigError as e:  # the schema's message, with the key path, when the file breaks the schema
            explain(d, "hints", "hints", e)

    @classmethod
    def from_json(cls, path: str | os.PathLike[str]) -> Hints:
        """Read a hints JSON file."""
        return cls.from_dict(read_json_file(path, "hints file"))

    def radius_km(self) -> float | None:
        """Nominal limb radius (km): mean of ``body_radii_km`` (or the named body's,
        :data:`jaxlimb.geometry.bodies.BODY_TABLE`) plus ``atmosphere_km``."""
        radii = self.body_radii_km
        if radii is None and self.body is not None and self.body in BODY_TABLE:
            radii = BODY_TABLE[self.body].radii_km
        if radii is None:
            return None
        return float(np.mean(radii)) + float(self.atmosphere_km or 0.0)


__all__ = ["Hints"]
