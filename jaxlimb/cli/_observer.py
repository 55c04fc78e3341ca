r"""The observer's position from a limb measurement (Mortari, D'Souza & Zanetti 2016, step 7) for ``jaxlimb navigate``:
the attitude argument, the map from the measured ``(centre, X)`` to the observer-to-body vector ``r_om = D u_c``
(``X`` the range for the ellipsoid strategy's measurement -- the Earth, a giant planet --, the on-axis-equivalent
radius for a round body's), and the position

.. math:: r_o = r_b - C^\top r_{om}

with its covariance: the measurement's through the central-difference Jacobian of that map, rotated by
``C^T``, plus the attitude term of :func:`jaxlimb.geometry.navigation.navigate`, plus the camera's scale: a
range from an apparent size is ``D ~ R f / r``, so a relative focal-length error ``s = sigma_f / f`` (the IK's
stated uncertainty) is one of the range, ``(s D)^2 u u^T`` along the line of sight."""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from .._io import loads_strict, read_json_file
from .._validate import real_array
from ..errors import CheckFailed, ConfigError
from ..geometry.attitude import quat_to_dcm, validate_dcm
from ..geometry.navigation import navigate
from ..numerics import numerical_jacobian


def parse_attitude(text: str) -> tuple[np.ndarray, str]:
    """``C_ci`` from the ``--attitude`` argument (module docstring); returns ``(C_ci, description)``.

    Raises
    ------
    ConfigError
        Unreadable file / invalid JSON / unknown layout.
    AttitudeError
        Not a unit quaternion or not a proper orthonormal matrix (tolerance 1e-6).
    """
    src = text.strip()
    if src.startswith("{") or src.startswith("["):
        obj = loads_strict(src, "--attitude")  # a key twice, absurd nesting or digits: ConfigError
    else:
        obj = read_json_file(src, "--attitude file")
    order = "xyzw"
    if isinstance(obj, dict):
        keys = {k.lower(): k for k in obj}
        if "order" in keys:
            order = obj[keys["order"]]
            if order not in ("xyzw", "wxyz"):
                raise ConfigError(f"--attitude `order` must be 'xyzw' (scalar-last) or 'wxyz' (scalar-first), got {order!r}")
        for name in ("quaternion", "q"):
            if name in keys:
                obj = obj[keys[name]]
                break
        else:
            for name in ("c_ci", "dcm"):
                if name in keys:
                    obj = obj[keys[name]]
                    break
            else:
                raise ConfigError(f"--attitude object needs a `quaternion` or a `C_ci` key, got keys {sorted(obj)}")
    a = real_array(obj, "--attitude")  # numbers only: `true` or "0" is not a quaternion component
    if a.shape == (4,):
        return quat_to_dcm(a, order=order), f"quaternion ({order})"
    if a.shape == (3, 3):
        return validate_dcm(a, name="C_ci"), "C_ci"
    raise ConfigError(f"--attitude must be a quaternion (4 numbers) or a 3x3 C_ci, got shape {a.shape}")


def ranged(body: str, meas) -> bool:  # noqa: ANN001
    """The measurement's third quantity is the range (the ellipsoid strategy's: the Earth, any spheroid it measured),
    not the radius."""
    return body == "earth" or ("range_km" in meas.covariance and "radius" not in meas.covariance)


def measurement_map(body: str, camera, meas) -> tuple[list[str], Any]:
    """Names of the measured quantities and ``x -> r_om`` (camera frame, km): ``(center_r, center_c, range_km)`` for
    the Earth or any spheroid the ellipsoid strategy measured (:func:`ranged`), ``(center_r, center_c, radius)`` for
    any other body (the range from the radius, the body's size fixed)."""

    cov = meas.covariance
    if ranged(body, meas):
        names = ["center_r", "center_c", "range_km"]

        def fn(x: np.ndarray) -> np.ndarray:
            return x[2] * camera.los(x[:2])

        return names, fn
    names = ["center_r", "center_c", "radius"]
    if not all(n in cov for n in names):
        raise ConfigError(f"the Moon measurement has no covariance of {names} (got {sorted(cov)})")
    R_km = meas.range_km * math.sin(math.atan(float(meas.radius_px) / camera.focal_px))

    def fn_moon(x: np.ndarray) -> np.ndarray:
        D = R_km / math.sin(math.atan(x[2] / camera.focal_px))
        return D * camera.los(x[:2])

    return names, fn_moon


def observer_position(body: str, meas, camera, C_ci: np.ndarray, r_body: np.ndarray,  # noqa: ANN001
                      attitude_sigma_rad: float = 0.0, scale_sigma_frac: float = 0.0) -> dict[str, Any]:
    """The observer position ``r_b - C^T r_om`` (the frame of ``C_ci``, km), its covariance and parts
    (``measurement``, ``attitude``, ``camera_scale``: ``scale_sigma_frac`` the camera's relative focal-length
    sigma), the range, the line of sight and the measured centre (module docstring).

    Raises
    ------
    CheckFailed
        The measurement has no line of sight or range (camera or body size unknown).
    """
    from ..pipeline.result import covariance_block  # here: the pipeline stays out of the CLI's start-up

    if meas.los_camera is None or meas.range_km is None:
        raise CheckFailed("the limb measurement has no line of sight / range (camera or body size unknown)")
    names, fn = measurement_map(body, camera, meas)
    rng = ranged(body, meas)
    x0 = np.array([meas.center_rc[0], meas.center_rc[1], meas.range_km if rng else meas.radius_px], float)
    P = covariance_block(meas.covariance, names)
    G = numerical_jacobian(fn, x0, np.array([1e-3, 1e-3, 1e-3 * max(1.0, x0[2] * 1e-6) if rng else 1e-3]))
    r_om = fn(x0)
    D = float(np.linalg.norm(r_om))
    sol = navigate(r_body, C_ci, r_om / D, D, attitude_cov_rad2=attitude_sigma_rad if attitude_sigma_rad > 0 else None)
    C = np.asarray(C_ci, float)
    P_meas = C.T @ G @ P @ G.T @ C
    u_i = C.T @ (r_om / D)
    P_scale = (scale_sigma_frac * D) ** 2 * np.outer(u_i, u_i)
    Ptot = P_meas + sol.contributions_km2["attitude"] + P_scale
    Ptot = 0.5 * (Ptot + Ptot.T)

    def m(a: np.ndarray) -> list[list[float]]:
        return [[float(v) for v in row] for row in a]

    return {
        "position_km": [float(v) for v in sol.position_km], "covariance_km2": m(Ptot),
        "sigma_km": [float(math.sqrt(max(Ptot[i, i], 0.0))) for i in range(3)], "range_km": D,
        "los_camera": [float(v) for v in r_om / D], "center_rc": [float(v) for v in meas.center_rc],
        "covariance_parts_km2": {"measurement": m(P_meas), "attitude": m(sol.contributions_km2["attitude"]),
                                 "camera_scale": m(P_scale)},
    }


__all__ = ["measurement_map", "observer_position", "parse_attitude", "ranged"]
