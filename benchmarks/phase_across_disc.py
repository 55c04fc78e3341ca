"""Why a close Moon's centre comes out displaced away from the Sun: the phase angle changes across the disc.

Each point of a body is seen at its own phase angle.  Seen from a finite range, the observer is ``alpha0`` (the
body's angular radius) farther from the Sun as seen from the limb on the Sun's side than as seen from the centre,
and ``alpha0`` nearer as seen from the opposite limb.  Under a law whose brightness depends on the phase angle
(lunar-Lambert's weight ``L(g)``, Hapke's opposition surge and phase function) the rim on the Sun's side is then
dimmer than the opposite rim.  A profile that holds the phase (and ``L``) at the body's value across the disc reads
the dimmer rim as an edge moved inward there, so the fitted centre moves away from the Sun.  ``locate``'s limb profile
(:mod:`jaxlimb.models.lunar_lambert`) computes the incidence and emission at each point and gives each point the
lunar-Lambert weight of its own phase angle (McEwen's ``dL/dg``); a law whose brightness falls faster with the phase
(Hapke's) keeps part of the displacement.

What is rendered: Moon frames of the rendered cislunar transfer (``benchmarks/track_render.py``: the same
geometry, camera, Gaussian PSF, 12-bit sensor and noise seeds).  The independent renderer renders them under three
laws, each twice:

* ``per point``: each point at its own phase angle, as in the world and in both renderers;
* ``held``: the phase angle held at the body centre's across the disc: the same frame without the effect.

Lambert's law does not depend on the phase angle and is the control.  Each render is scaled to the peak of the
transfer's own (Hapke) radiance of that frame, so the signal is the transfer's.

Measured: ``locate``'s error of the body centre's image along the Sun's image direction (``along``, px; negative:
away from the Sun) and across it, and of the apparent size (px), each the mean over ``--draws`` noise draws.  Per
law and variant: the mean over the frames, and ``along`` as a fraction of the apparent radius (the ``sun_offset`` of
:mod:`jaxlimb.track.bias`).  Per frame: the phase angle and ``alpha0``.

``python benchmarks/phase_across_disc.py [--frames 103,111,... --draws 2]`` ->
``benchmarks/results/phase_across_disc.json``.
"""

from __future__ import annotations

import argparse
import math
import sys
from dataclasses import dataclass
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _common import environment, save  # noqa: E402

LAWS = ("lambert", "lunar-lambert", "hapke")
VARIANTS = ("per point", "held")
#: Every eighth frame of the transfer's second half (odd frames are the Moon's), up to its closest.
DEFAULT_FRAMES = tuple(range(103, 200, 8))


def held_photometry(law: str, cos_phase: float):  # noqa: ANN201
    """A photometry of ``law`` whose phase angle is ``acos(cos_phase)`` at every point (the ``held`` variant)."""
    from jaxlimb.render.independent import Photometry, Reflectance

    @dataclass(frozen=True)
    class Held(Photometry):
        cos_phase: float = 1.0

        def radiance(self, mu0: np.ndarray, mu: np.ndarray, cos_g: np.ndarray) -> np.ndarray:
            return super().radiance(mu0, mu, np.full(np.shape(cos_g), self.cos_phase))

    return Held(law=Reflectance(law), cos_phase=cos_phase)


def frame_truth(arc, tr, k: int) -> dict:  # noqa: ANN001
    """The Sun's image direction, the phase angle and the angular radius of frame ``k``'s Moon at the truth."""
    from jaxlimb.track.measurement import BODY_RADIUS_KM, sun_direction_px

    r = tr.states[k, :3]
    body = arc.body_position("moon", tr.t[k : k + 1])[0]
    sun = arc.body_position("sun", tr.t[k : k + 1])[0]
    d = np.asarray(sun_direction_px(tr.C_true[k] @ (body - r), tr.C_true[k] @ (sun - r)))
    u, s = body - r, sun - body
    cos_phase = float(np.dot(-u, s) / np.linalg.norm(u) / np.linalg.norm(s))
    return {"d": d, "cos_phase": cos_phase, "phase_deg": math.degrees(math.acos(cos_phase)),
            "alpha0_deg": math.degrees(math.asin(BODY_RADIUS_KM["moon"] / np.linalg.norm(u)))}


def render(arc, tr, k: int, law: str, cos_phase: float | None) -> np.ndarray:  # noqa: ANN001
    """Frame ``k``'s Moon under ``law``, blurred radiance; with ``cos_phase``, the phase held at ``acos(cos_phase)``
    across the disc."""
    from jaxlimb.render.independent import Body, Photometry, Pinhole, Psf, PsfKind, Reflectance, Surface, render_radiance
    from jaxlimb.track.measurement import BODY_RADIUS_KM
    from track_render import THETA_TRUE, camera, frame_geometry

    g = frame_geometry(arc, tr, k)
    phot = Photometry(law=Reflectance(law)) if cos_phase is None else held_photometry(law, cos_phase)
    return render_radiance(Body((BODY_RADIUS_KM["moon"],) * 3, g["center_cam"], g["R"], g["sun"]), Surface(phot),
                           Pinhole.from_camera(camera(THETA_TRUE)), Psf(PsfKind.GAUSSIAN, 0.8))


def errors(arc, tr, k: int, rad: np.ndarray, truth: tuple[np.ndarray, np.ndarray], draws: int,  # noqa: ANN001
           seed: int) -> dict:
    """``locate``'s mean errors (along and across the Sun, size; px) over ``draws`` noise draws of ``rad``; ``truth``:
    the Sun's image direction and the true measurement of frame ``k``."""
    from track_render import THETA_TRUE, measure
    from track_transfer import as_frames

    d, z_true = truth
    out = []
    for draw in range(draws):
        m = measure(arc, tr, k, rad, draw, THETA_TRUE, seed)
        if m.get("status") != "ok":
            continue
        e = as_frames(arc, tr, [m], tr.C_true[[k]], THETA_TRUE, 0.0).z[0] - z_true
        out.append((float(e[:2] @ d), float(-e[0] * d[1] + e[1] * d[0]), float(e[2])))
    if not out:
        return {"ok": 0}
    a = np.mean(out, axis=0)
    return {"ok": len(out), "along_px": float(a[0]), "across_px": float(a[1]), "size_px": float(a[2])}


def summary(rows: list[dict]) -> dict:
    """Per law and variant, the means over the frames (``along / radius``: the ``sun_offset``)."""
    out = {}
    for law in LAWS:
        for var in VARIANTS:
            e = [r[law][var] | {"radius_px": r["radius_px"]} for r in rows if r[law][var].get("ok")]
            if e:
                out[f"{law}, {var}"] = {
                    "frames": len(e), "along_px": float(np.mean([x["along_px"] for x in e])),
                    "along_over_radius": float(np.mean([x["along_px"] / x["radius_px"] for x in e])),
                    "abs_across_px": float(np.mean([abs(x["across_px"]) for x in e])),
                    "size_px": float(np.mean([x["size_px"] for x in e]))}
    return out


def main(argv: list[str] | None = None) -> int:
    import jax
    from tqdm import tqdm

    jax.config.update("jax_enable_x64", True)
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--frames", default=",".join(map(str, DEFAULT_FRAMES)), help="comma-separated Moon frames (odd)")
    ap.add_argument("--draws", type=int, default=2)
    ap.add_argument("--seed", type=int, default=38)
    a = ap.parse_args(argv)
    from jaxlimb.track.scenario import true_measurements
    from track_render import scenario

    env = environment()  # the tree as the run starts
    arc, _, tr = scenario(200, a.seed)
    frames = [int(k) for k in a.frames.split(",")]
    if any(tr.bodies[k] != "moon" for k in frames):
        ap.error("every frame must be one of the Moon's (odd)")
    z = true_measurements(tr)
    rows = []
    with tqdm(total=len(frames) * len(LAWS) * len(VARIANTS), desc="phase across the disc") as bar:
        for k in frames:
            t = frame_truth(arc, tr, k)
            rads = {(law, var): render(arc, tr, k, law, t["cos_phase"] if var == "held" else None)
                    for law in LAWS for var in VARIANTS}
            peak = float(rads["hapke", "per point"].max())  # the transfer's own radiance of this frame
            row = {"frame": k, "phase_deg": t["phase_deg"], "alpha0_deg": t["alpha0_deg"], "radius_px": float(z[k, 2])}
            for law in LAWS:
                row[law] = {}
                for var in VARIANTS:
                    rad = rads[law, var]
                    row[law][var] = errors(arc, tr, k, rad * (peak / rad.max()), (t["d"], z[k]), a.draws, a.seed)
                    bar.update()
            rows.append(row)
    out = {"environment": env, "seed": a.seed, "draws": a.draws, "summary": summary(rows), "frames": rows}
    print(out["summary"])
    print(save("phase_across_disc", out))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
