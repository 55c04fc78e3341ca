"""Same answers across a refactor: ``locate``'s full output on frames of every body strategy, and the comparison of two
such runs.

    python benchmarks/same_answers.py run OUT.json [NAME,...]     # on the code to compare (PYTHONPATH)
    python benchmarks/same_answers.py compare BEFORE.json AFTER.json

Frames (``JAXLIMB_SAME_ANSWERS_FRAMES``, default ``/tmp/jaxlimb-same-answers``) are rendered once and pickled, so two
runs compare ``locate`` only.  Cases: the demo's rendered Moon (sigmoid, profile, scan lines, free ellipse, no
camera), the SDO/HMI and AIA Suns (disc), the Cassini Enceladus frames with SPICE (whole limb), two limb arcs of a
body larger than the frame, ``benchmarks/families.py`` frames (Moon ``own``, ``maria``, ``stars``; Earth ``own``,
``clouds``, ``glow``, with and without ``R_body_to_camera``), an EPIC Earth, a Voyager Europa and the Mimas frame.
``compare`` prints, per case, the largest difference of the centre, covariance, radius, range and line of sight
(``key``) and of every other number, and the keys added or removed.
"""
from __future__ import annotations

import json
import os
import pickle
import sys
import time
from pathlib import Path

import jax
import numpy as np

jax.config.update("jax_enable_x64", True)

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO / "benchmarks"))
sys.path.insert(0, str(REPO / "tests" / "pipeline"))
FR = Path(os.environ.get("JAXLIMB_SAME_ANSWERS_FRAMES", "/tmp/jaxlimb-same-answers"))
_UNTIMED = ("timings", "timings_s", "time_s", "seconds")
_KEY = ("center_rc", "covariance", "radius_px", "range_km", "los_camera", "ellipse", "status", "check")
_KEY_ADDED = ("center_rc", "covariance", "radius_px", "range_km")


def cached(name, make):
    """``make()``, pickled under ``FR / name`` the first time."""
    FR.mkdir(parents=True, exist_ok=True)
    p = FR / name
    if p.exists():
        return pickle.loads(p.read_bytes())
    v = make()
    p.write_bytes(pickle.dumps(v))
    return v


def clean(o):
    """``o`` as plain JSON values, without timings."""
    if isinstance(o, dict):
        return {k: clean(v) for k, v in o.items() if k not in _UNTIMED}
    if isinstance(o, (list, tuple)):
        return [clean(v) for v in o]
    if isinstance(o, (np.floating, np.integer)):
        return o.item()
    if isinstance(o, np.ndarray):
        return clean(o.tolist())
    return o


def run_locate(img, cam, hints, opts=None, mask=None):
    """``locate``'s measurement as JSON, or the check that refused."""
    from jaxlimb.errors import JaxlimbError
    from jaxlimb.pipeline import locate

    try:
        m = locate(img, cam, hints, opts, mask=mask)
    except JaxlimbError as e:
        return {"status": "error", "check": e.check, "message": str(e)}
    return clean(m.to_json())


def cases():
    """``(name, thunk)`` for every case; the thunk returns the case's JSON."""
    from jaxlimb._data import shared_data_dir
    from jaxlimb.geometry.camera import Camera
    from jaxlimb.imaging import Hints
    from jaxlimb.pipeline import LocateOptions

    SH = shared_data_dir()

    # 1 demo rendered moon (sphere physical + sigmoid + scanline)
    def demo():
        from jaxlimb.render import RenderOptions, moon_scene, render_body
        camera = Camera.default()
        sc = moon_scene(150_000.0, 45.0, center_rc=(620.0, 1830.0), camera=camera, sun_angle_deg=30.0)
        o = RenderOptions(reflectance="lunar-lambert", psf_sigma_px=0.8, bit_depth=8,
                          read_noise_e=2.0 * 20000.0 / 255.0)
        img, truth = render_body(sc, camera, o, seed=1)
        return img, tuple(float(v) for v in truth.sun_dir_cam)

    img, sun = cached("demo.pkl", demo)
    cam = Camera.default()
    h = Hints(body="moon", sun_dir_camera=sun)
    yield "demo_sigmoid", lambda: run_locate(img, cam, h, LocateOptions(profile="sigmoid"))
    yield "demo_default", lambda: run_locate(img, cam, h, LocateOptions())
    yield "demo_scanline", lambda: run_locate(img, cam, h, LocateOptions(front_end="scanline", profile="sigmoid"))
    yield "demo_ellipse_model", lambda: run_locate(img, cam, h, LocateOptions(model="ellipse"))
    yield "demo_nocam", lambda: run_locate(img, None, Hints(body="moon"), None)
    # 2 SDO sun (disc)
    from jaxlimb.imaging import load_image
    for f in ("2023_01_31__03_39_23_200__SDO_HMI_HMI_continuum.png", "resampled_hmi.fits", "aia_171_level1.fits"):
        def sun(f=f):
            im, _ = load_image(SH / "sun" / f)
            return run_locate(im, None, Hints(body="sun"))

        yield "sun_" + f.split(".")[0][-14:], sun
    # 3 Cassini Enceladus (whole limb, SPICE)
    from jaxlimb.geometry.spice import spice_geometry
    from jaxlimb.imaging.formats import read_frame
    K = sorted(str(p) for p in (SH / "cassini" / "kernels").iterdir())
    for name in ("N1511803932_1", "N1511803965_3"):
        def cas(name=name):
            fr = read_frame(SH / "cassini" / f"{name}.IMG")
            g = spice_geometry(K, fr.meta.image_time, fr.meta.instrument_id, fr.meta.target_name)
            return run_locate(fr.data, g.camera, g.hints(), mask=fr.mask_or_none)

        yield "cassini_" + name, cas
    # 4 arc (limb_arc geometry 0 and 2, seed 1)
    from _scenes import SMALL_CAMERA, scene
    for gi, (center, sa) in enumerate((((-40.0, 250.0), -90.0), ((200.0, -30.0), 0.0))):
        def arc(center=center, sa=sa, gi=gi):
            img, truth = cached(f"arc{gi}.pkl", lambda: scene(7386.0, 30.0, center, sun_angle_deg=sa, seed=1))
            sun = tuple(float(v) for v in truth.sun_dir_cam)
            hh = Hints(body="moon", range_prior_km=7386.0 * 1.01, sun_dir_camera=sun)
            return run_locate(img, SMALL_CAMERA, hh)

        yield f"arc_{gi}", arc
    # 5 families quick (moon own, maria; earth own, clouds, with and without R)
    import families as F
    for body, fams in (("moon", ("own", "maria", "stars")), ("earth", ("own", "clouds", "glow"))):
        for fam in fams:
            def fcase(body=body, fam=fam):
                case = F._case(body, fam, 0, 2026, FR / "families")
                out = {body: run_locate(case.image, case.camera, Hints.from_dict(case.hints))}
                if body == "earth":
                    no_r = {k: v for k, v in case.hints.items() if k != "R_body_to_camera"}
                    out["noR"] = run_locate(case.image, case.camera, Hints.from_dict(no_r))
                return out

            yield f"fam_{body}_{fam}", fcase
    # 6 EPIC real earth
    for d in ("20220110",):
        def epic(d=d):
            im, _ = load_image(SH / "epic" / f"epic_earth_{d}.png")
            cam = Camera.from_dict(json.loads((SH / "epic" / f"epic_earth_{d}.camera.json").read_text()))
            hh = Hints.from_dict(json.loads((SH / "epic" / f"epic_earth_{d}.hints.json").read_text()))
            return run_locate(im, cam, hh)

        yield "epic_" + d, epic
    # 7 Voyager Europa (sphere, no geometry)
    def voy():
        fr = read_frame(SH / "voyager" / "C1636902_CALIB.IMG")
        return run_locate(fr.data, None, None, mask=fr.mask_or_none)

    yield "voyager_C1636902", voy
    # 8 Mimas (limb cut by edges, no geometry)
    def mimas():
        fr = read_frame(SH / "cassini" / "N1644787857_1.IMG")
        return run_locate(fr.data, None, None, mask=fr.mask_or_none)

    yield "mimas", mimas


def run(argv):
    """Run the cases (all, or the comma-separated names in ``argv[1]``) into the JSON file ``argv[0]``."""
    out_path = Path(argv[0])
    only = set(argv[1].split(",")) if len(argv) > 1 else None
    res = json.loads(out_path.read_text()) if out_path.exists() else {}
    for name, fn in cases():
        if only and name not in only:
            continue
        t0 = time.perf_counter()
        try:
            res[name] = fn()
        except Exception as e:  # record internal errors too
            res[name] = {"status": "exception", "type": type(e).__name__, "message": str(e)[:300]}
        print(f"{name}: {time.perf_counter()-t0:.1f}s {str(res[name])[:150]}", flush=True)
        out_path.write_text(json.dumps(res, indent=1))


def leaves(o, path=""):
    """``(dotted path, value)`` of every scalar in ``o``."""
    if isinstance(o, dict):
        for k, v in o.items():
            yield from leaves(v, f"{path}.{k}" if path else k)
    elif isinstance(o, list):
        for i, v in enumerate(o):
            yield from leaves(v, f"{path}[{i}]")
    else:
        yield path, o


def _is_key(path):
    return any(s in path for s in _KEY)


def compare(before, after):
    """Print, per case, the largest differences between the runs ``before`` and ``after``."""
    b, a = (json.loads(Path(p).read_text()) for p in (before, after))
    for case in b:
        if case not in a:
            print(f"{case}: missing after")
            continue
        lb, la = dict(leaves(b[case])), dict(leaves(a[case]))
        worst_key, worst_other, changed = 0.0, 0.0, []
        for k, v in lb.items():
            if k not in la:
                if _is_key(k):
                    changed.append(f"-{k}")
                continue
            w = la[k]
            if isinstance(v, (int, float)) and isinstance(w, (int, float)) and not isinstance(v, bool):
                d = abs(v - w)
                if _is_key(k):
                    worst_key = max(worst_key, d)
                    if d > 1e-9: changed.append(f"{k}: {v} -> {w}")
                else:
                    worst_other = max(worst_other, d)
            elif v != w and _is_key(k):
                changed.append(f"{k}: {v} -> {w}")
        added = [k for k in la if k not in lb and any(s in k for s in _KEY_ADDED)]
        note = f"CHANGED {changed[:6]}" if changed else ""
        if added:
            note += f" added {len(added)} key leaves"
        print(f"{case:28s} key max|d| {worst_key:.3g}  other max|d| {worst_other:.3g}  {note}")


if __name__ == "__main__":
    if sys.argv[1:2] == ["run"]:
        run(sys.argv[2:])
    elif sys.argv[1:2] == ["compare"]:
        compare(*sys.argv[2:4])
    else:
        sys.exit(__doc__)
