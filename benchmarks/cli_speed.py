"""What a user of the command line feels: start-up of repeated commands, and many frames per call.

Same run, interleaved (so that every ratio compares commands under the same machine load):

* ``python -c "import jax; jax.numpy.zeros(1)"`` -- the cost of starting JAX itself (baseline);
* ``jaxlimb --help`` (must not import JAX);
* ``jaxlimb locate`` on a rendered 1944x2592 Moon frame, second and later processes (the
  persistent compilation cache filled by the first);
* ``jaxlimb locate --body sun`` on the SDO/HMI 512x512 PNG (shared data);
* ``jaxlimb los locate`` on a rendered Thebe frame (``--db`` of the shared Thebe mesh, 10 deg);
* ``jaxlimb locate DIR --out F.jsonl`` on N Moon frames: frames per second after the first,
  ``(N - 1) / (t_N - t_1)`` from a one-frame and an N-frame call.

Each command runs ``--repeats`` times after one warm-up; medians are reported with the ratio to
the JAX start-up median and the load average before and after, for the wall time and for the
CPU time of the process (user + system: less sensitive to other jobs on a shared machine).  The compile cache of the runs is
a fresh directory (``JAXLIMB_CACHE_DIR``), filled by the warm-ups, and so is Python's bytecode cache
(``PYTHONPYCACHEPREFIX``, for JAX and jaxlimb alike, as an installed package has it; ``--no-bytecode-cache``: the
environment as it is).

Run:  python benchmarks/cli_speed.py [--repeats 5] [--frames 30] [--only locate_sun]
Writes benchmarks/results/cli_speed.json.
"""

from __future__ import annotations

import argparse
import json
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from _common import environment, process_environment, save

JAXLIMB = [sys.executable, "-m", "jaxlimb.cli"]


def _load() -> list[float]:
    return [float(v) for v in Path("/proc/loadavg").read_text().split()[:3]]


_CPU: dict[str, list[float]] = {}


def _children_cpu() -> float:
    r = resource.getrusage(resource.RUSAGE_CHILDREN)
    return r.ru_utime + r.ru_stime


def _time(cmd: list[str], env: dict[str, str], ok_codes=(0,), key: str | None = None) -> float:
    """Wall time of ``cmd`` (its CPU time, user + system, is appended to ``_CPU[key]``)."""
    c0, t0 = _children_cpu(), time.perf_counter()
    p = subprocess.run(cmd, capture_output=True, text=True, env=env)
    dt = time.perf_counter() - t0
    if key is not None:
        _CPU.setdefault(key, []).append(_children_cpu() - c0)
    if p.returncode not in ok_codes:
        raise RuntimeError(f"{' '.join(cmd)} -> {p.returncode}: {p.stdout[-400:]} {p.stderr[-400:]}")
    return dt


def _make_inputs(d: Path, n_frames: int, only: set[str] | None = None) -> dict[str, list[str]]:
    """Moon frames + camera + hints, the Thebe database + frame; returns the commands (those in ``only``)."""
    if only is not None and not only & {"locate_moon", "los_locate"}:
        from jaxlimb._data import shared_data_dir
        from jaxlimb.imaging.sdo import HMI_512_PNG

        sun = [*JAXLIMB, "locate", str(shared_data_dir() / "sun" / HMI_512_PNG), "--body", "sun", "--json"]
        cmds = {"jax_start": [sys.executable, "-c", "import jax; jax.numpy.zeros(1)"], "help": [*JAXLIMB, "--help"],
                "locate_sun": sun}
        return {k: v for k, v in cmds.items() if k in only}
    import jax

    jax.config.update("jax_enable_x64", True)
    import cv2

    from jaxlimb._data import shared_data_dir
    from jaxlimb.geometry.camera import Camera
    from jaxlimb.imaging.sdo import HMI_512_PNG
    from jaxlimb.irregular.mesh import load_mesh
    from jaxlimb.render import RenderOptions, moon_scene, render_body
    from jaxlimb.render.mesh import MeshRenderOptions, look_at_rotation, render_mesh

    cam = Camera.default()
    (d / "frames").mkdir()
    for i in range(n_frames):
        sc = moon_scene(150_000.0 + 1500 * i, 45.0, center_rc=(900.0 + 3 * i, 1400.0 - 2 * i), camera=cam,
                        sun_angle_deg=30.0)
        img, truth = render_body(sc, cam, RenderOptions(reflectance="lunar-lambert", psf_sigma_px=1.0, bit_depth=8), seed=i)
        cv2.imwrite(str(d / "frames" / f"moon_{i:03d}.png"), np.asarray(img).astype(np.uint8))
        if i == 0:
            (d / "hints.json").write_text(json.dumps({"body": "moon", "sun_dir_camera": [float(v) for v in truth.sun_dir_cam]}))
    (d / "cam.json").write_text(json.dumps(cam.to_dict()))
    data = shared_data_dir()
    mesh_path = data / "meshes" / "thebe.obj"
    mesh = load_mesh(mesh_path)
    small = Camera(rows=400, cols=500)
    (d / "small.json").write_text(json.dumps(small.to_dict()))
    dist = 2.0 * mesh.max_radius * small.focal_px / 160.0
    r = render_mesh(mesh.vertices, mesh.faces, small, look_at_rotation(np.array([0.3, -0.5, 0.8]) / np.linalg.norm([0.3, -0.5, 0.8])),
                    np.array([0.0, 0.0, dist]), options=MeshRenderOptions())
    cv2.imwrite(str(d / "thebe.png"), np.clip(np.asarray(r.image), 0, 255).astype(np.uint8))
    subprocess.run([*JAXLIMB, "los", "build-db", str(mesh_path), "--step-deg", "10", "--out", str(d / "thebe.npz"),
                    "--no-progress"], check=True, capture_output=True)
    first = str(d / "frames" / "moon_000.png")
    return {
        "jax_start": [sys.executable, "-c", "import jax; jax.numpy.zeros(1)"],
        "help": [*JAXLIMB, "--help"],
        "locate_moon": [*JAXLIMB, "locate", first, "--camera", str(d / "cam.json"), "--hints", str(d / "hints.json"), "--json"],
        "locate_sun": [*JAXLIMB, "locate", str(data / "sun" / HMI_512_PNG), "--body", "sun", "--json"],
        "los_locate": [*JAXLIMB, "los", "locate", str(d / "thebe.png"), "--db", str(d / "thebe.npz"),
                       "--camera", str(d / "small.json"), "--json"],
    }


def _only(cmds: dict[str, list[str]], env: dict[str, str], repeats: int) -> dict:
    """The start-up rows of ``cmds`` alone (``--only``): medians, ratios to the JAX start, load; printed only."""
    load_before = _load()
    for c in cmds.values():
        _time(c, env, ok_codes=(0, 3))  # warm-up: fills the cache
    times: dict[str, list[float]] = {k: [] for k in cmds}
    for _ in range(repeats):
        for k, c in cmds.items():
            times[k].append(_time(c, env, ok_codes=(0, 3), key=k))
    med = {k: float(np.median(v)) for k, v in times.items()}
    cpu = {k: float(np.median(_CPU[k])) for k in cmds}
    print(f"load average before {load_before}, after {_load()}")
    for k in cmds:
        print(f"{k:12s} median {med[k]:6.2f} s  = {med[k] / med['jax_start']:4.2f}x JAX start-up   "
              f"CPU {cpu[k]:5.2f} s = {cpu[k] / cpu['jax_start']:4.2f}x")
    return {"median_s": med, "median_cpu_s": cpu, "all_s": times}


def main(argv: list[str] | None = None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--frames", type=int, default=30)
    ap.add_argument("--only", default=None, help="comma-separated rows (jax_start is always run), e.g. "
                    "locate_sun: no many-frame part, nothing written to results/")
    ap.add_argument("--no-bytecode-cache", action="store_true", help="run the processes in this environment as it is "
                    "(by default Python's bytecode is cached, as an installed package has it)")
    args = ap.parse_args(argv)
    d = Path(tempfile.mkdtemp(prefix="cli_speed_"))
    env = process_environment(None if args.no_bytecode_cache else d / "pycache", JAXLIMB_CACHE_DIR=str(d / "jaxcache"))
    only = None if args.only is None else {"jax_start", *args.only.split(",")}
    cmds = _make_inputs(d, args.frames, only)
    if only is not None:
        cmds = {k: v for k, v in cmds.items() if k in only}
        return _only(cmds, env, args.repeats)
    load_before = _load()
    first_call = {k: _time(c, env, ok_codes=(0, 3)) for k, c in cmds.items()}  # warm-up: fills the cache
    times: dict[str, list[float]] = {k: [] for k in cmds}
    for _ in range(args.repeats):
        for k, c in cmds.items():
            times[k].append(_time(c, env, ok_codes=(0, 3), key=k))
    many = [*JAXLIMB, "locate", str(d / "frames"), "--camera", str(d / "cam.json"), "--hints", str(d / "hints.json")]
    one = [*JAXLIMB, "locate", "@" + str(d / "one.txt"), "--camera", str(d / "cam.json"), "--hints", str(d / "hints.json")]
    (d / "one.txt").write_text(str(d / "frames" / "moon_000.png") + "\n")
    t_many, t_one = [], []
    for i in range(max(2, args.repeats // 2)):
        t_one.append(_time([*one, "--out", str(d / f"one{i}.jsonl")], env))
        t_many.append(_time([*many, "--out", str(d / f"many{i}.jsonl")], env))
    load_after = _load()
    med = {k: float(np.median(v)) for k, v in times.items()}
    cpu = {k: float(np.median(v)) for k, v in _CPU.items()}
    base = med["jax_start"]
    fps = (args.frames - 1) / (float(np.median(t_many)) - float(np.median(t_one)))
    out = {
        "median_s": med, "all_s": times, "first_call_s": first_call,
        "ratio_to_jax_start": {k: v / base for k, v in med.items()},
        "median_cpu_s": cpu, "cpu_ratio_to_jax_start": {k: v / cpu["jax_start"] for k, v in cpu.items()},
        "many_frames": {"n": args.frames, "one_frame_call_s": t_one, "n_frame_call_s": t_many,
                        "frames_per_s_after_first": fps, "frame": [1944, 2592]},
        "loadavg_before": load_before, "loadavg_after": load_after, "commands": {k: " ".join(c) for k, c in cmds.items()},
        "environment": environment(), "bytecode_cache": not args.no_bytecode_cache,
    }
    print(f"load average before {load_before}, after {load_after}")
    for k in cmds:
        print(f"{k:12s} median {med[k]:6.2f} s  = {med[k] / base:4.2f}x JAX start-up   (first call {first_call[k]:6.2f} s)"
              f"   CPU {cpu[k]:5.2f} s = {cpu[k] / cpu['jax_start']:4.2f}x")
    print(f"many frames: {args.frames} frames of 1944x2592 -> {fps:.1f} frames/s after the first "
          f"(one-frame call {np.median(t_one):.2f} s, {args.frames}-frame call {np.median(t_many):.2f} s)")
    path = save("cli_speed", out)
    print(f"wrote {path}")
    return out


if __name__ == "__main__":
    main()
