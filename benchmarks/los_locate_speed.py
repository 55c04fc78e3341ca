"""Wall and CPU time of one ``jaxlimb los locate FRAME --mesh MESH`` process, its database cached.

Frames of ``benchmarks/irregular_los.py`` (:func:`irregular_los.make_view`: Lommel-Seeliger, 2 DN noise, 1024^2,
focal 1500 px): Thebe, Phobos and Eros at phase 0, 30 and 60 deg, 3x the long axis, off-centre; and a cratered body
the pipeline was never developed on, rendered by the independent ray caster (:func:`unseen_frames`); the hints give the
Sun direction and a range prior (attitude unknown: the template search).  Every process is run ``--repeats``
times after one warm-up (which builds the database of a body once, in ``$JAXLIMB_CACHE``); with ``--before DIR``
(e.g. ``git archive BASE | tar -x -C /tmp/BASE``: the directory's name is recorded) the processes of that checkout
run interleaved with this one's, on the same frames, so that both see the same machine load.  Medians per frame; CPU is user + system of the process
(less sensitive to other jobs on a shared machine).  The processes run as from an installed package: Python's
bytecode cached (a per-run ``PYTHONPYCACHEPREFIX`` per checkout, filled by the warm-up, whatever
``PYTHONDONTWRITEBYTECODE`` says); ``--no-bytecode-cache`` keeps the environment as it is (with
``PYTHONDONTWRITEBYTECODE=1`` every process then compiles the package from source).  A run over every frame writes
``benchmarks/results/los_locate_speed.json`` (a run with ``--only`` writes nothing).

Run::

    JAXLIMB_CACHE=/tmp/cache nice -n 5 .venv/bin/python benchmarks/los_locate_speed.py --repeats 3 [--before DIR]
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _common import environment, process_environment, save  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
BODIES = (("thebe", "thebe.obj", "y"), ("phobos", "phobos.obj", "y"), ("eros", "eros007790.tab", "z"))


def frames(d: Path) -> list[dict]:
    """Write the frames, hints and camera; ``[{"tag", "mesh", "pole", "png", "hints", "truth"}]``."""
    import cv2
    from irregular_los import camera, make_view

    from jaxlimb._data import shared_data_dir
    from jaxlimb.irregular.mesh import load_mesh

    cam = camera()
    (d / "camera.json").write_text(json.dumps(cam.to_dict()))
    out = []
    for i, (name, fname, pole) in enumerate(BODIES):
        path = shared_data_dir() / "meshes" / fname
        mesh = load_mesh(path)
        for ph in (0, 30, 60):
            img, truth, _, t, sun = make_view(mesh, cam, ph, 3.0, True, 2.0, np.random.default_rng([7, i, ph]))
            tag = f"{name}_{ph}"
            cv2.imwrite(str(d / f"{tag}.png"), np.clip(np.round(img), 0, 65535).astype(np.uint16))
            (d / f"{tag}.json").write_text(json.dumps({"sun_dir_camera": [float(v) for v in sun],
                                                       "range_prior_km": float(np.linalg.norm(t)) * 1.05}))  # fmt: skip
            out.append({"tag": tag, "mesh": str(path), "pole": pole, "truth": [float(v) for v in truth]})
    return out + unseen_frames(d, cam)


def unseen_frames(d: Path, cam) -> list[dict]:
    """A cratered body no part of the pipeline was developed on, rendered by the independent ray caster.

    The body, the photometric law, PSF and sensor are those of ``benchmarks/irregular_independent.py`` (seed 101,
    its ``new:cratered-a``); phases 0/30/60 at 3x the long axis, off-centre."""
    import cv2
    import trimesh
    from irregular_independent import draw_scene

    from jaxlimb.irregular.mesh import validate_mesh
    from jaxlimb.render.independent.geometry import Pinhole
    from jaxlimb.render.independent.mesh_rays import cratered_body, render_mesh_frame

    V, F = cratered_body(101, subdivisions=4)
    path = d / "cratered-a.obj"
    trimesh.Trimesh(V, F, process=False).export(path)
    model, out = validate_mesh(V, F, source="cratered-a"), []
    for ph in (0, 30, 60):
        rng = np.random.default_rng([7, 9, ph])
        scene, _ = draw_scene(V, F, model.max_radius, cam, ph, 3.0, True, rng)
        img, truth = render_mesh_frame(scene, Pinhole.from_camera(cam), rng)
        tag = f"cratered-a_{ph}"
        cv2.imwrite(str(d / f"{tag}.png"), np.clip(np.round(img), 0, 65535).astype(np.uint16))
        (d / f"{tag}.json").write_text(json.dumps({"sun_dir_camera": [float(v) for v in scene.sun_dir_camera],
                                                   "range_prior_km": float(np.linalg.norm(scene.t_camera_km)) * 1.05}))  # fmt: skip
        out.append({"tag": tag, "mesh": str(path), "pole": "z", "truth": [float(v) for v in truth]})
    return out


def run(cmd: list[str], env: dict[str, str]) -> tuple[float, float, dict]:
    """Wall and CPU seconds of one process (environment ``env``) and its JSON answer."""
    ru0 = resource.getrusage(resource.RUSAGE_CHILDREN)
    t0 = time.perf_counter()
    p = subprocess.run(cmd, check=False, capture_output=True, text=True, cwd=tempfile.gettempdir(), env=env)
    wall = time.perf_counter() - t0
    ru1 = resource.getrusage(resource.RUSAGE_CHILDREN)
    if p.returncode not in (0, 3):
        raise RuntimeError(f"{' '.join(cmd)} -> {p.returncode}: {p.stderr[-400:]}")
    cpu = (ru1.ru_utime - ru0.ru_utime) + (ru1.ru_stime - ru0.ru_stime)
    return wall, cpu, json.loads(p.stdout.strip().splitlines()[-1])


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--before", metavar="DIR", help="an earlier checkout, run interleaved")
    ap.add_argument("--only", nargs="*", help="frame tags (e.g. thebe_30)")
    ap.add_argument("--no-bytecode-cache", action="store_true", help="run the processes in this environment as it is")
    args = ap.parse_args(argv)
    d = Path(tempfile.mkdtemp(prefix="los_locate_speed_"))
    roots = {"after": str(ROOT)} | ({"before": str(Path(args.before).resolve())} if args.before else {})
    versions = {v: process_environment(None if args.no_bytecode_cache else d / f"pycache-{v}", PYTHONPATH=root) for v, root in roots.items()}
    rows = []
    for f in frames(d):
        if args.only and f["tag"] not in args.only:
            continue
        cmd = [sys.executable, "-m", "jaxlimb.cli", "los", "locate", str(d / f"{f['tag']}.png"), "--mesh", f["mesh"], "--pole-axis",
               f["pole"], "--camera", str(d / "camera.json"), "--hints", str(d / f"{f['tag']}.json"), "--json", "--no-progress"]  # fmt: skip
        times: dict[str, list[tuple[float, float]]] = {v: [] for v in versions}
        answers = {}
        for v, env in versions.items():
            answers[v] = run(cmd, env)[2]  # warm-up (database built or cached)
        for _ in range(args.repeats):
            for v, env in versions.items():
                times[v].append(run(cmd, env)[:2])
        row = {"frame": f["tag"], "load": os.getloadavg()[0]}
        for v in versions:
            a = answers[v]
            row[v] = {"wall_s": statistics.median(t[0] for t in times[v]), "cpu_s": statistics.median(t[1] for t in times[v]),
                      "status": a.get("status"), "error_px": float(np.linalg.norm(np.subtract(a["center_rc"], f["truth"]))) if "center_rc" in a else None}  # fmt: skip
        rows.append(row)
        print(json.dumps(row), flush=True)
    print("| frame | " + " | ".join(f"{v} wall / CPU s" for v in versions) + " | " + " | ".join(f"{v} error px" for v in versions) + " |")
    print("|---|" + "---|" * 2 * len(versions))
    for r in rows:
        cells = " | ".join(f"{r[v]['wall_s']:.2f} / {r[v]['cpu_s']:.2f}" for v in versions)
        errors = " | ".join("-" if r[v]["error_px"] is None else f"{r[v]['error_px']:.3f}" for v in versions)
        print(f"| {r['frame']} | {cells} | {errors} |")
    summary = {v: {k: statistics.median(r[v][k] for r in rows) for k in ("wall_s", "cpu_s")} for v in versions}
    for v, m in summary.items():
        print(f"{v}: median over frames wall {m['wall_s']:.2f} s, CPU {m['cpu_s']:.2f} s")
    if not args.only:
        save("los_locate_speed", {"environment": environment(), "args": {"repeats": args.repeats, "before": args.before and Path(args.before).name,
                                                                          "bytecode_cache": not args.no_bytecode_cache},
                                  "rows": rows, "median": summary, "load_after": os.getloadavg()[0]})  # fmt: skip
    return 0


if __name__ == "__main__":
    sys.exit(main())
