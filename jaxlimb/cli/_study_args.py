"""What ``jaxlimb montecarlo`` and ``jaxlimb compare`` share: the problem's arguments, the devices, ``--out``."""

from __future__ import annotations

import argparse

from .._validate import Range, arg_number

#: Argument ranges (exit 2 outside them); memory is estimated before allocating too.
RANGES = {"radius": Range(5.0, 5000.0), "sigma": Range(0.0, 1e6, lo_open=True), "n": Range(2, 10_000_000),
          "seed": Range(0, 2**32 - 1), "k": Range(0.0, 1e3, lo_open=True), "annulus": Range(0.5, 1000.0),
          "batch": Range(1, 100_000), "range_km": Range(2000.0, 1e9), "phase_deg": Range(0.0, 170.0),
          "workers": Range(1, 1024), "devices": Range(1, 256), "repeats": Range(1, 100)}
#: The models of the standard problems (:data:`jaxlimb.analysis.problems.STUDY_MODELS`, importable without JAX).
MODELS = ("linear", "circle", "ellipse", "ellipse_ramp", "lunar_limb", "limb_darkened")


def num(name: str, integer: bool = False):  # noqa: ANN201
    """The ``type=`` of the flag ``name`` (its range in :data:`RANGES`)."""
    return arg_number(RANGES[name], integer=integer)


def add_problem_args(p: argparse.ArgumentParser) -> None:
    """``--model --radius --sigma --n --seed --k --annulus --fix --devices``: the standard problem of a model."""
    p.add_argument("--model", choices=MODELS, default="circle",
                   help="limb model of the rendered limb and of the fit (default circle)")
    p.add_argument("--radius", type=num("radius"), default=150.0, help="radius / semi-axis a in px (default 150)")
    p.add_argument("--sigma", type=num("sigma"), default=10.0, help="Gaussian noise in DN (default 10)")
    p.add_argument("--n", type=num("n", True), default=1000, help="realisations (default 1000)")
    p.add_argument("--seed", type=num("seed", True), default=0, help="seed of the noise realisations (default 0)")
    p.add_argument("--k", type=num("k"), default=3.0, help="sigmoid steepness (default 3)")
    p.add_argument("--annulus", type=num("annulus"), default=6.0, help=f"half-width of the pixel band, px {RANGES['annulus']} (default 6; a narrower band holds no pixel of some rows)")
    p.add_argument("--fix", default="", help="comma-separated parameters held at truth, e.g. k,ymax,ymin")
    p.add_argument("--devices", type=num("devices", True), default=None,
                   help="XLA CPU devices the batches are split over (default: one per usable core; "
                   "ignored when XLA_FLAGS already sets xla_force_host_platform_device_count)")


def study_options(args: argparse.Namespace, batch: int) -> object:
    """The :class:`~jaxlimb.analysis.problems.ModelStudyOptions` of the problem arguments."""
    from ..analysis.problems import ModelStudyOptions

    size = int(max(400, 2 * args.radius + 100))
    return ModelStudyOptions(
        model=args.model, shape=(size, size), radius=args.radius, sigma=args.sigma, n=args.n, seed=args.seed,
        k=args.k, annulus=args.annulus, batch=batch, fixed=tuple(s.strip() for s in args.fix.split(",") if s.strip()),
    )


def host_devices(args: argparse.Namespace) -> int:
    """CPU devices of the compiled studies (read before JAX starts): ``--devices`` or one per usable core.

    The studies' programs split their seeds over the local devices (each device on its own thread;
    :func:`jaxlimb.analysis.sharding.per_device`), so on a 2-core CPU two devices halve the wall time of the fits.
    """
    from .._jaxcache import usable_cores

    return int(args.devices) if getattr(args, "devices", None) is not None else usable_cores()


def check_out(args: argparse.Namespace) -> None:
    """--out DIR must be new (or an existing study with --resume); checked before any work."""
    from pathlib import Path

    from ..errors import ConfigError

    if args.out is None:
        if args.resume:
            raise ConfigError("--resume needs --out DIR (the directory of the study to continue)")
        return
    out = Path(args.out)
    if out.exists() and not out.is_dir():
        raise ConfigError(f"--out {args.out!r} exists and is not a directory")
    has_study = (out / "manifest.json").exists()
    if has_study and not args.resume:
        raise ConfigError(f"--out {args.out!r} already holds a study: pass --resume to continue it, or choose a new directory")
    if out.is_dir() and not has_study and any(out.iterdir()):
        raise ConfigError(f"--out {args.out!r} is a non-empty directory without a study; choose a new or empty directory")


def solver_list(text: str) -> tuple[str, ...]:
    """``--solvers a,b,...`` (``all``: every registered solver) as names, checked (exit 2 on an unknown one)."""
    from .._solver_names import SOLVER_NAMES
    from ..errors import LimbInputError

    names = tuple(SOLVER_NAMES) if text.strip() == "all" else tuple(s.strip() for s in text.split(",") if s.strip())
    bad = [s for s in names if s not in SOLVER_NAMES]
    if bad or not names or len(set(names)) != len(names):
        raise LimbInputError(f"--solvers must be distinct names of {list(SOLVER_NAMES)} (or 'all'), got {text!r}")
    return names
