"""Speed of ``jaxlimb los locate`` with the attitude unknown (target: <= 3 s per call, process start included).

Frames of ``benchmarks/irregular_los.py`` (same renderer, camera and noise): Thebe
and a generated contact binary at phase 30 deg and 3x / 10x the long axis, plus Phobos
(49 152 facets) at 3x unless ``--quick``.  For each frame:

* **in process** (warm: the database loaded, one call made before):
  :func:`jaxlimb.irregular.locate.locate_los` median of ``--repeats`` calls, and the
  stages (phase-aware template search, coarse stage of every hypothesis,
  full-resolution stage and checks);
* **CLI**: wall time of ``jaxlimb los locate FRAME --db DB.npz --camera C --hints H
  --json`` (Sun direction and range prior in the hints, attitude unknown), first
  process and the median of the later ones, beside ``python -c "import jax;
  jax.numpy.zeros(1)"`` measured in the same run, every process with Python's bytecode cached as an installed
  package has it (``_common.process_environment``; ``--no-bytecode-cache``: as the environment is);
* the centre error of the answer (px).

Run::

    nice -n 5 .venv/bin/python benchmarks/irregular_speed.py
    # the CLI of an earlier commit on the same frames (in-process columns: this checkout)
    git archive 40f223a | tar -x -C /tmp/before
    nice -n 5 .venv/bin/python benchmarks/irregular_speed.py --cli-pythonpath /tmp/before

Writes ``benchmarks/results/irregular_speed.json``.
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

JAXLIMB = [sys.executable, "-m", "jaxlimb.cli"]
CASES = (("thebe", 30, 3.0), ("thebe", 30, 10.0), ("gen:contact-binary", 30, 3.0), ("phobos", 30, 3.0))


def _cpu_children() -> float:
    ru = resource.getrusage(resource.RUSAGE_CHILDREN)
    return ru.ru_utime + ru.ru_stime


def _wall(cmd: list[str], env: dict[str, str]) -> tuple[float, float, dict | None]:
    """Wall time, CPU time (user + system: what a quiet machine would take, about) and the JSON answer."""
    t0, c0 = time.perf_counter(), _cpu_children()
    # from the temporary directory: `python -m` puts the working directory first on sys.path
    p = subprocess.run(cmd, capture_output=True, text=True, env=env, cwd=tempfile.gettempdir())
    dt, cpu = time.perf_counter() - t0, _cpu_children() - c0
    if p.returncode not in (0, 3):
        raise RuntimeError(f"{' '.join(cmd)} -> {p.returncode}: {p.stderr[-400:]}")
    try:
        return dt, cpu, json.loads(p.stdout.strip().splitlines()[-1])
    except (json.JSONDecodeError, IndexError):
        return dt, cpu, None


def _stages(img, db, cam, sun, range_km) -> dict[str, float]:
    """Wall time of each stage of the template search (same code path as ``locate_los``)."""
    from jaxlimb.irregular.locate import Frame, LosOptions, register_hypotheses, search_hypotheses
    from jaxlimb.irregular.register import lit_figure

    o = LosOptions()
    t0 = time.perf_counter()
    frame = Frame(np.asarray(img, dtype=float), lit_figure(img), cam, sun)
    t1 = time.perf_counter()
    hyps = search_hypotheses(frame, db, o)
    t2 = time.perf_counter()
    n = min(len(hyps), o.n_verify)  # the retry set is registered only when none of these explains the frame
    register_hypotheses(frame, db, hyps[:n], o)
    t3 = time.perf_counter()
    return {"segment_s": t1 - t0, "template_search_s": t2 - t1, "register_s": t3 - t2}


def _frame(name, ph, df, bodies, cam, d: Path, rng) -> dict:
    """Write the frame, database, camera and hints of one case; the in-process timings."""
    import cv2

    from irregular_los import make_view
    from jaxlimb.irregular.database import DatabaseOptions, cached_database, save_database
    from jaxlimb.irregular.locate import locate_los

    mesh, pole = bodies[name]
    db = cached_database(mesh, DatabaseOptions(step_deg=3.0, pole_axis=pole), progress=False)
    img, truth, _, t, sun = make_view(mesh, cam, ph, df, True, 2.0, rng)
    img = np.clip(np.round(img), 0, 65535)
    tag = f"{name.replace(':', '_')}_{ph}_{int(df)}"
    cv2.imwrite(str(d / f"{tag}.png"), img.astype(np.uint16))
    dbp = d / f"{name.replace(':', '_')}.npz"
    if not dbp.exists():
        save_database(db, dbp)
    rng_km = float(np.linalg.norm(t)) * 1.05
    (d / f"{tag}.hints.json").write_text(json.dumps({"sun_dir_camera": [float(v) for v in sun], "range_prior_km": rng_km}))
    row = {"case": tag, "truth_rc": [float(v) for v in truth]}
    row["cmd"] = [*JAXLIMB, "los", "locate", str(d / f"{tag}.png"), "--db", str(dbp), "--camera", str(d / "camera.json"),
                  "--hints", str(d / f"{tag}.hints.json"), "--json"]  # fmt: skip
    if not IN_PROCESS:
        return row
    locate_los(img, db, cam, sun, None, rng_km)  # warm-up
    times, err = [], float("nan")
    for _ in range(REPEATS):
        t0 = time.perf_counter()
        res = locate_los(img, db, cam, sun, None, rng_km)
        times.append(time.perf_counter() - t0)
        err = float(np.linalg.norm(res.center_rc - truth))
    row.update(in_process_s=statistics.median(times), error_px=err, **_stages(img, db, cam, sun, rng_km))
    return row


REPEATS = 3
IN_PROCESS = True


def main(argv: list[str] | None = None) -> dict:
    global REPEATS, IN_PROCESS
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="Thebe 3x and the contact binary only, no Phobos")
    ap.add_argument("--repeats", type=int, default=3, help="in-process calls and later CLI processes per frame")
    ap.add_argument("--cli-pythonpath", metavar="DIR", help="run the CLI from this checkout (e.g. `git archive` of an"
                    " earlier commit: the 'before' column); results saved as irregular_speed_before.json")
    ap.add_argument("--no-bytecode-cache", action="store_true",
                    help="time the processes without the bytecode cache (the environment as it is)")
    args = ap.parse_args(argv)
    REPEATS, IN_PROCESS = args.repeats, not args.cli_pythonpath
    os.environ.setdefault("JAXLIMB_CACHE", str(Path(__file__).resolve().parent / "results" / ".db-cache"))
    from irregular_los import bodies, camera
    from jaxlimb._data import shared_data_dir

    cam = camera()
    d = Path(tempfile.mkdtemp(prefix="irregular_speed_"))
    (d / "camera.json").write_text(json.dumps(cam.to_dict()))
    cases = [c for c in CASES if not (args.quick and (c[0] == "phobos" or c[2] == 10.0))]
    allb = bodies(quick=False)
    rows = [_frame(n, ph, df, allb, cam, d, np.random.default_rng([2026, i])) for i, (n, ph, df) in enumerate(cases)]
    env = process_environment(None if args.no_bytecode_cache else d / "pycache", JAXLIMB_CACHE_DIR=str(d / "jaxcache"))
    if args.cli_pythonpath:
        env["PYTHONPATH"] = str(Path(args.cli_pythonpath).resolve())
        env["JAXLIMB_SHARED_DATA"] = str(shared_data_dir())
    jax_cmd = [sys.executable, "-c", "import jax; jax.numpy.zeros(1)"]
    _wall(jax_cmd, env)
    jax = [_wall(jax_cmd, env) for _ in range(args.repeats)]
    jax_s, jax_cpu = statistics.median(j[0] for j in jax), statistics.median(j[1] for j in jax)
    for r in rows:
        first, _, out = _wall(r["cmd"], env)
        later = [_wall(r["cmd"], env) for _ in range(args.repeats)]
        r.update(cli_first_s=first, cli_s=statistics.median(w[0] for w in later), cli_cpu_s=statistics.median(w[1] for w in later),
                 cli_status=(out or {}).get("status", "?"))  # fmt: skip
        if out and "center_rc" in out:
            r["cli_error_px"] = float(np.linalg.norm(np.asarray(out["center_rc"]) - np.asarray(r["truth_rc"])))
        r["cli_vs_jax_start"] = r["cli_s"] / jax_s
        r["cmd"] = " ".join(r["cmd"][2:]).replace(str(d), "$TMP")
    print(f"python -c 'import jax; jax.numpy.zeros(1)': {jax_s:.2f} s wall, {jax_cpu:.2f} s CPU (load {os.getloadavg()[0]:.1f})")
    print("| frame | in process s | search / register s | CLI first / later s | CLI CPU s | CLI / jax start | CLI error px | CLI status |")
    print("|---|---|---|---|---|---|---|---|")
    nan = float("nan")
    for r in rows:
        print(f"| {r['case']} | {r.get('in_process_s', nan):.2f} | {r.get('template_search_s', nan):.2f} / {r.get('register_s', nan):.2f} |"
              f" {r['cli_first_s']:.2f} / {r['cli_s']:.2f} | {r['cli_cpu_s']:.2f} | {r['cli_vs_jax_start']:.2f} | {r.get('cli_error_px', nan):.3f} | {r['cli_status']} |")
    out = {"environment": environment(), "jax_start_s": jax_s, "jax_start_cpu_s": jax_cpu, "load_after": os.getloadavg()[0], "rows": rows,
           "cli_pythonpath": args.cli_pythonpath, "bytecode_cache": not args.no_bytecode_cache}  # fmt: skip
    print("wrote", save("irregular_speed_before" if args.cli_pythonpath else "irregular_speed", out))
    return out


if __name__ == "__main__":
    main()
