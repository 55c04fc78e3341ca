"""The fault bounds of docs/guarantees.md, measured: bombs, a damaged and locked cache, mesh memory per face.

* ``bombs``: ``jaxlimb locate FILE`` on a file per format whose header declares 100 000 x 100 000 px (JPEG:
  65 535 x 65 535), and on a valid 882 kB PNG that inflates to 30 000 x 30 000 px: exit code, wall and CPU
  seconds and peak RSS of the whole process (targets: exit 2, < 1 s, < 300 MB);
* ``cache``: a small program compiled and exported into a fresh cache, then every entry damaged (one flipped
  bit each), junk entries added, JAX's ``-atime`` files deleted and its ``.lockfile`` held by a stopped
  process: the answer (bit for bit), the warnings, and the run's wall time against an undamaged warm run
  (target: no wait on the cache beyond 15 s);
* ``mesh``: peak RSS per face while a shape model is read, validated and its templates built (20 deg), for
  the shared ``phobos.obj`` and a 327 680-face icosphere: the basis of ``irregular.mesh.BYTES_PER_FACE``;
* ``signals``: SIGINT and SIGTERM to the whole process group of ``montecarlo --pipeline --workers 2`` on
  120x160 frames, 3, 6 and 20 s after its start (the cluster starting, then running): exit code (130 / 143)
  and the stderr lines (target: one; the Dask workers printed a traceback each).

Run:  python benchmarks/faults.py [--only bombs|cache|mesh|signals]
Writes benchmarks/results/faults.json.
"""

from __future__ import annotations

import argparse
import json
import os
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from _common import environment, save

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tests"))
from fuzz._hostile import (CACHED_PROGRAM, MAKERS, damage_cache, inflating_png,  # noqa: E402
                           stopped_lock_holder, write_bomb)

_MEASURE = """
import resource, subprocess, sys, time
t0 = time.perf_counter()
p = subprocess.run(sys.argv[1:], capture_output=True, text=True)
wall = time.perf_counter() - t0
u = resource.getrusage(resource.RUSAGE_CHILDREN)
print(p.returncode, wall, u.ru_utime + u.ru_stime, u.ru_maxrss / 1024, len(p.stderr.splitlines()), sep="|")
"""


def _env(**extra: str) -> dict[str, str]:
    env = {k: v for k, v in os.environ.items() if k != "JAXLIMB_DEBUG"}
    env["PYTHONPATH"] = os.pathsep.join([str(ROOT), env.get("PYTHONPATH", "")]).rstrip(os.pathsep)
    env.update(extra)
    return env


def bombs(folder: Path) -> dict:
    files = {kind: write_bomb(folder, kind) for kind in sorted(MAKERS)}
    files["png-inflating-30000"] = folder / "inflates.png"
    files["png-inflating-30000"].write_bytes(inflating_png(30_000, 30_000))
    out = {}
    for kind, path in files.items():
        res = subprocess.run([sys.executable, "-c", _MEASURE, sys.executable, "-m", "jaxlimb.cli", "locate", str(path)],
                             capture_output=True, text=True, env=_env(), check=True).stdout.strip().split("|")
        out[kind] = {"file_bytes": path.stat().st_size, "exit": int(res[0]), "wall_s": round(float(res[1]), 3),
                     "cpu_s": round(float(res[2]), 3), "peak_rss_mb": round(float(res[3]), 1),
                     "stderr_lines": int(res[4])}
        print(kind, out[kind], flush=True)
    return out


def _cached_run(env: dict) -> dict:
    t0 = time.perf_counter()
    out = json.loads(subprocess.run([sys.executable, "-c", CACHED_PROGRAM], capture_output=True, text=True, env=env,
                                    check=True).stdout)
    out["wall_s"] = round(time.perf_counter() - t0, 2)
    return out


def cache(folder: Path) -> dict:
    c = folder / "cache"
    env = _env(JAXLIMB_CACHE_DIR=str(c))
    cold, warm = _cached_run(env), _cached_run(env)
    entries = damage_cache(c)
    with stopped_lock_holder(c / ".lockfile"):
        damaged = _cached_run(env)
        locked_warm = _cached_run(env)  # repaired entries, lock still held by the stopped process
    same = all(r[k] == cold[k] for r in (warm, damaged, locked_warm) for k in ("y", "n", "z"))
    out = {"entries_damaged": len(entries), "same_answer_bit_for_bit": same, "warnings": damaged["warnings"],
           "wall_s": {"cold": cold["wall_s"], "warm": warm["wall_s"], "damaged_and_locked": damaged["wall_s"],
                      "warm_locked": locked_warm["wall_s"]}}
    print(out, flush=True)
    return out


# peak RSS of this process image (VmHWM: ru_maxrss would carry the parent's peak over fork + exec)
_MESH = """
import sys
import trimesh, scipy.sparse.csgraph  # noqa: F401
from jaxlimb.irregular.mesh import load_mesh
from jaxlimb.irregular.database import DatabaseOptions, build_database
def rss():
    line = next(s for s in open("/proc/self/status") if s.startswith("VmHWM:"))
    return int(line.split()[1]) * 1024
base = rss()
m = load_mesh(sys.argv[1])
loaded = rss()
build_database(m, DatabaseOptions(step_deg=20.0), progress=False)
print(m.n_faces, (loaded - base) / m.n_faces, (rss() - base) / m.n_faces)
"""


def mesh(folder: Path) -> dict:
    import trimesh

    ico = folder / "icosphere7.obj"
    trimesh.creation.icosphere(subdivisions=7, radius=10.0).export(ico)
    out = {}
    for name, path in (("phobos.obj", ROOT / ".." / "shared" / "data" / "meshes" / "phobos.obj"), ("icosphere7", ico)):
        n, load_b, build_b = subprocess.run([sys.executable, "-c", _MESH, str(path)], capture_output=True, text=True,
                                            env=_env(), check=True).stdout.split()
        out[name] = {"faces": int(n), "bytes_per_face_load": round(float(load_b)),
                     "bytes_per_face_load_and_build": round(float(build_b))}
        print(name, out[name], flush=True)
    return out


_CAMERA = {"focal_length_mm": 0.9876543209876543, "pixel_pitch_mm": 0.0022, "rows": 120, "cols": 160,
           "principal_point_rc": [59.5, 79.5]}


def signals(folder: Path) -> dict:
    """SIGINT / SIGTERM to the process group of ``montecarlo --pipeline --workers 2`` (as a terminal's Ctrl-C
    does) after a delay: while the cluster starts, while it runs; the exit code and the stderr lines."""
    (folder / "cam.json").write_text(json.dumps(_CAMERA))
    out = {}
    for sig in (signal.SIGINT, signal.SIGTERM):
        for delay in (3.0, 6.0, 20.0):
            study = folder / f"mc-{sig.name}-{delay:g}"
            cmd = [sys.executable, "-m", "jaxlimb.cli", "montecarlo", "--pipeline", "--workers", "2", "--n", "2000",
                   "--out", str(study), "--camera", str(folder / "cam.json"), "--range-km", "20000"]
            p = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=_env(),
                                 start_new_session=True)
            time.sleep(delay)
            os.killpg(p.pid, sig)
            _, err = p.communicate(timeout=300)
            lines = [ln for ln in err.replace("\r", "\n").splitlines() if ln.strip() and "%|" not in ln]
            out[f"{sig.name}@{delay:g}s"] = {"exit": p.returncode, "stderr_lines": len(lines), "first": lines[:2]}
            print(sig.name, delay, out[f"{sig.name}@{delay:g}s"], flush=True)
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--only", choices=("bombs", "cache", "mesh", "signals"), default=None)
    args = ap.parse_args()
    res: dict = {"environment": environment(), "load_before": os.getloadavg()}
    with tempfile.TemporaryDirectory() as tmp:
        for name, fn in (("bombs", bombs), ("cache", cache), ("mesh", mesh), ("signals", signals)):
            if args.only in (None, name):
                (Path(tmp) / name).mkdir()
                res[name] = fn(Path(tmp) / name)
    res["load_after"] = os.getloadavg()
    print("wrote", save("faults" if args.only is None else f"faults_{args.only}", res))


if __name__ == "__main__":
    main()
