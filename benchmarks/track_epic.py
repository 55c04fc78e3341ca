"""DSCOVR's position from each real EPIC frame against the position in its metadata.

Per frame (``../shared/data/epic/``): ``locate`` with the frame's camera and hints gives the Earth's range ``D``
and its centre; the metadata's attitude quaternion (``q0..q3``, scalar last: it maps the J2000 direction from
DSCOVR to the Earth onto the instrument's ``+x`` axis) gives the boresight in J2000, ``b = A(q)^T e_x``; the L1B
product centres the Earth on the boresight (to about 2 px, ``product_center_quality_px``), so the position is
``r = -D b`` with the measured centre's offset from the principal point (``|d|/f`` rad, direction unknown: the
L1B image's roll is not in the metadata) counted as a lateral error.  Sigma: the range's from ``locate``, the
lateral one ``D sqrt(sigma_att^2 + (|d| / f)^2 + (quality / f)^2)``.  ``sigma_att``, the quaternion's accuracy
per axis, is not published: it is estimated for each frame from the *other* frames (leave one out), as the root
mean square of their angles between the quaternion's boresight and the metadata's direction to the Earth over
``sqrt(2)`` (two axes), so no frame's own error sizes its sigma; ``--attitude-sigma-rad`` sets it instead (the
earlier default, 2e-5 rad, was the quaternion's five decimals: a rounding step, not an accuracy).  A frame
``locate`` refuses is reported with its check.  "Within 3 sigma": the squared Mahalanobis distance of the
position error (range and the two lateral axes) below chi-square's 99.73 % quantile with 3 degrees of freedom.
``locate`` runs with no tolerance on the centre's sigma (``--max-center-sigma-px``; ``locate``'s default refuses a
centre whose sigma exceeds 1 px): a position with a wide sigma is still a measurement a filter can weigh, and the
test is whether the metadata lies inside it.

``python benchmarks/track_epic.py`` -> ``benchmarks/results/track_epic.json``.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _common import environment, save  # noqa: E402

DATA = Path(__file__).resolve().parents[1] / ".." / "shared" / "data" / "epic"
#: The chi-square (3 degrees of freedom) quantile of the one-dimensional 3-sigma probability, 99.73 %.
CHI2_3_AT_3_SIGMA = 14.156


def metadata_geometry(stem: Path) -> tuple[dict, np.ndarray, np.ndarray]:
    """``(meta, r_meta, b)``: the frame's metadata, DSCOVR's J2000 position (km) and the quaternion's boresight."""
    from jaxlimb.geometry.attitude import quat_to_dcm

    meta = json.loads(Path(f"{stem}.metadata.json").read_text())
    em = meta["epic_metadata"]
    p = em["dscovr_j2000_position"]
    q = em["attitude_quaternions"]
    qv = np.array([q["q0"], q["q1"], q["q2"], q["q3"]])
    b = quat_to_dcm(qv / np.linalg.norm(qv), order="xyzw").T @ np.array([1.0, 0.0, 0.0])
    return meta, np.array([p["x"], p["y"], p["z"]]), b


def boresight_angle(stem: Path) -> float:
    """The angle (rad) between the quaternion's boresight and the metadata's direction from DSCOVR to the Earth."""
    _, r_meta, b = metadata_geometry(stem)
    return float(np.arccos(np.clip(-b @ r_meta / np.linalg.norm(r_meta), -1, 1)))


def leave_one_out_sigma(angles: np.ndarray) -> np.ndarray:
    """Per frame, the attitude sigma per axis from the other frames' boresight angles: ``sqrt(mean(theta^2) / 2)``."""
    a2 = np.asarray(angles, float) ** 2
    n = a2.size
    return np.sqrt((a2.sum() - a2) / max(n - 1, 1) / 2.0)


def one_frame(stem: Path, att_sigma: float, max_center_sigma_px: float | None = 1.0) -> dict:
    from jaxlimb.errors import JaxlimbError
    from jaxlimb.geometry.camera import Camera
    from jaxlimb.imaging import Hints, load_image
    from jaxlimb.pipeline import LocateOptions, locate

    meta, r_meta, b = metadata_geometry(stem)
    em = meta["epic_metadata"]
    out = {"frame": stem.name, "date": em["date"], "metadata_position_km": r_meta.tolist(),
           "boresight_vs_metadata_rad": boresight_angle(stem), "attitude_sigma_rad": att_sigma}
    cam = Camera.from_json(f"{stem}.camera.json")
    try:
        m = locate(load_image(f"{stem}.png")[0], cam, Hints.from_json(f"{stem}.hints.json"),
                   LocateOptions(max_center_sigma_px=max_center_sigma_px))
    except JaxlimbError as e:
        return {**out, "status": "error", "check": e.check, "message": " ".join(str(e).split())}
    D = float(m.range_km)
    off = float(np.hypot(*(np.asarray(m.center_rc) - np.asarray(cam.principal_point_rc)))) / cam.focal_px
    qual = float(meta.get("product_center_quality_px", 2.0)) / cam.focal_px
    s_lat = D * float(np.sqrt(att_sigma**2 + off**2 + qual**2))
    s_rng = float(np.sqrt(m.covariance["range_km"]["range_km"]))
    r = -D * b
    e = r - r_meta
    e_rng = float(e @ b * -1)
    e_lat = float(np.linalg.norm(e + e_rng * b))
    d2 = float((e_rng / s_rng) ** 2 + (e_lat / s_lat) ** 2)  # range and two lateral axes: chi-square, 3 dof
    return {**out, "status": "ok", "position_km": r.tolist(), "range_km": D, "sigma_range_km": s_rng,
            "sigma_lateral_km": s_lat, "error_range_km": e_rng, "error_lateral_km": e_lat,
            "mahalanobis_sq": d2, "within_3_sigma": bool(d2 <= CHI2_3_AT_3_SIGMA)}


def main(argv: list[str] | None = None) -> int:
    import jax

    jax.config.update("jax_enable_x64", True)
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--attitude-sigma-rad", type=float, default=None,
                    help="the quaternion's accuracy per axis (default: from the other frames, leave one out)")
    ap.add_argument("--max-center-sigma-px", type=float, default=None,
                    help="locate's tolerance on the centre's sigma (default: none, every answer with its sigma; "
                    "locate's own default is 1 px)")
    a = ap.parse_args(argv)
    stems = [p.with_suffix("").with_suffix("") for p in sorted(DATA.resolve().glob("*.metadata.json"))]
    angles = np.array([boresight_angle(s) for s in stems])
    sig = np.full(len(stems), a.attitude_sigma_rad) if a.attitude_sigma_rad is not None else leave_one_out_sigma(angles)
    frames = [one_frame(s, float(sg), a.max_center_sigma_px) for s, sg in zip(stems, sig)]
    ok = [f for f in frames if f["status"] == "ok"]
    out = {"environment": environment(),
           "attitude_sigma_rad": a.attitude_sigma_rad if a.attitude_sigma_rad is not None else "leave-one-out",
           "max_center_sigma_px": a.max_center_sigma_px, "frames": frames,
           "measured": len(ok), "within_3_sigma": sum(f["within_3_sigma"] for f in ok)}
    for f in frames:
        print(f["frame"], f["status"], f.get("check", ""), f.get("error_range_km", ""), f.get("sigma_range_km", ""))
    print(save("track_epic", out))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
