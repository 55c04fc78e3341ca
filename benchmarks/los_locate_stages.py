"""Where the CPU seconds of one ``jaxlimb los locate FRAME --mesh MESH`` process go, its database cached.

The frames of ``benchmarks/los_locate_speed.py``; one process per frame, as the command runs it: the imports of
the command, the cached database's load (:func:`jaxlimb.irregular.database.load_database`: read, checksum, mesh
verified), the template search (:func:`jaxlimb.irregular.locate.search_hypotheses`), the registrations
(:func:`jaxlimb.irregular.locate.register_hypotheses`) and inside them the face-index buffers
(:func:`jaxlimb.render.mesh.rasterise`, per supersampling and exact coverage) and the cast-shadow maps
(:func:`jaxlimb.render.mesh.shadow_fractions`, which rasterise the mesh seen from the Sun).  CPU seconds
(``time.process_time``); stages overlap (a shadow map's buffer is counted under ``rasterise ss=1`` too).

Run::

    JAXLIMB_CACHE=/tmp/cache nice -n 5 .venv/bin/python benchmarks/los_locate_stages.py [--only thebe_30 phobos_0]
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
ROOT = Path(__file__).resolve().parents[1]


def stages(frame: dict, d: Path) -> dict:
    """CPU seconds per stage of one frame, in this process (run by :func:`main` in a fresh one)."""
    t0 = time.process_time()
    import numpy as np

    import jaxlimb.cli  # noqa: F401  (the command's own imports)
    import jaxlimb.irregular.locate as loc
    import jaxlimb.irregular.model_render as mr
    import jaxlimb.render.mesh as rm
    from jaxlimb.cli._los import _database_for_mesh_file
    from jaxlimb.geometry.camera import Camera
    from jaxlimb.imaging import Hints
    from jaxlimb.imaging.io import load_image
    from jaxlimb.irregular.database import DatabaseOptions

    out = {"imports": time.process_time() - t0}

    def timed(fn, key):  # type: ignore[no-untyped-def]
        def run(*a, **k):  # type: ignore[no-untyped-def]
            t = time.process_time()
            try:
                return fn(*a, **k)
            finally:
                name = key(*a, **k) if callable(key) else key
                out[name] = out.get(name, 0.0) + time.process_time() - t

        return run

    raster = timed(rm.rasterise, lambda Xc, F, cam, ss, exact=True: f"rasterise ss={ss} exact={exact}")
    rm.rasterise = mr.rasterise = raster
    rm.shadow_fractions = mr.shadow_fractions = timed(rm.shadow_fractions, "shadow maps")
    loc.search_hypotheses = timed(loc.search_hypotheses, "template search")
    loc.register_hypotheses = timed(loc.register_hypotheses, "registrations")
    t = time.process_time()
    db = _database_for_mesh_file(frame["mesh"], DatabaseOptions(pole_axis=frame["pole"]), False)
    out["database load"] = time.process_time() - t
    cam = Camera.from_json(d / "camera.json")
    img, _ = load_image(str(d / f"{frame['tag']}.png"), reject_constant=False)
    hints = Hints.from_json(d / f"{frame['tag']}.json")
    t = time.process_time()
    loc.locate_los(img, db, cam, np.asarray(hints.sun_dir_camera, dtype=float), None, hints.range_prior_km)
    out["locate_los"] = time.process_time() - t
    out["process"] = time.process_time()
    return {k: round(v, 3) for k, v in out.items()}


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--only", nargs="*", help="frame tags (e.g. thebe_30)")
    ap.add_argument("--frame", help=argparse.SUPPRESS)  # JSON of one frame and its directory: the child process
    args = ap.parse_args(argv)
    if args.frame:
        frame, d = json.loads(args.frame)
        print(json.dumps(stages(frame, Path(d))))
        return 0
    from los_locate_speed import frames

    d = Path(tempfile.mkdtemp(prefix="los_locate_stages_"))
    for f in frames(d):
        if args.only and f["tag"] not in args.only:
            continue
        cmd = [sys.executable, __file__, "--frame", json.dumps([f, str(d)])]
        env = {**os.environ, "PYTHONPATH": str(ROOT)}
        subprocess.run(cmd, capture_output=True, check=True, env=env)  # warm-up: the database built or cached
        p = subprocess.run(cmd, capture_output=True, text=True, check=True, env=env)
        print(json.dumps({"frame": f["tag"], "load": os.getloadavg()[0], **json.loads(p.stdout.strip().splitlines()[-1])}), flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
