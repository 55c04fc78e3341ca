"""``jaxlimb gradcheck``: every limb model's analytic Jacobian vs autodiff and central differences.

``--json`` prints one object: ``{"status": "ok", "tol", "checks": [...]}`` when every check
passes; else exit 3 with the error object of the CLI contract,
``{"status": "error", "check": "gradient_mismatch", "message", "tol", "worst", "checks"}``.
A NaN error never passes.
"""

from __future__ import annotations

import argparse
import math

from .._validate import Range, arg_number

#: ``--tol``: a relative error; 0 and negative values cannot pass, above 1 cannot fail.
TOL_RANGE = Range(0.0, 1.0, lo_open=True)
N_POINTS_RANGE = Range(1, 10_000)
SEED_RANGE = Range(0, 2**32 - 1)
#: The models' names (:data:`jaxlimb.models.gradcheck.GRADCHECK_MODELS`; written here: ``--help`` imports no JAX).
MODEL_NAMES = ("linear", "circle", "ellipse", "ellipse_ramp", "lunar_limb", "limb_darkened", "lunar_limb_minnaert",
               "lunar_limb_glow", "lunar_limb_aniso", "corona")


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "gradcheck",
        help="check every limb model's analytic Jacobian against autodiff and central differences",
        description="Compare the analytic Jacobians of the limb models (linear, circular and elliptical "
        "sigmoids, Eq. 14, 17, Sec. V-C; the elliptical ramp; the lunar-Lambert limb profile and its widened "
        "variants; the limb-darkened disc; the EUV corona's limb) with jax.jacfwd of the intensity as computed (the same quadrature "
        "nodes) and with central differences, at random parameter points.  Exit 0 when every check passes, 3 "
        "otherwise, 2 for bad arguments.",
    )
    p.add_argument("--n-points", type=arg_number(N_POINTS_RANGE, integer=True), default=100,
                   help=f"random parameter points per model, integer {N_POINTS_RANGE} (default 100)")
    p.add_argument("--seed", type=arg_number(SEED_RANGE, integer=True), default=0,
                   help=f"random seed, integer {SEED_RANGE} (default 0)")
    p.add_argument("--tol", type=arg_number(TOL_RANGE), default=None,
                   help=f"fail (exit 3) if any max_rel_err exceeds this, {TOL_RANGE} (default 1e-9 for every model: the "
                   "analytic Jacobians are the derivatives of the intensities as computed, the physical profiles' "
                   "quadrature included)")
    p.add_argument("--model", action="append", choices=MODEL_NAMES, default=None, metavar="NAME",
                   help=f"check only this model (repeatable; default every model): {', '.join(MODEL_NAMES)}")
    p.add_argument("--json", action="store_true", help="print one JSON object")
    p.set_defaults(func=run)


def _failure(checks: list, tol: float | None) -> str | None:
    """The message naming the worst failed check (``None`` when all pass; NaN fails)."""
    failed = [c for c in checks if not (c.max_rel_err <= tol if tol is not None else c.passed)]
    if not failed:
        return None
    worst = max(failed, key=lambda c: (math.isnan(c.max_rel_err), c.max_rel_err / (tol or c.tol)))
    return (f"{worst.model}.{worst.param}: max_rel_err {worst.max_rel_err:.3e} (max_fd_err {worst.max_fd_err:.3e}) "
            f"above its tolerance {tol if tol is not None else worst.tol:g}")


def run(args: argparse.Namespace) -> int:
    from ..errors import GradientMismatchError
    from ..models.gradcheck import report, run_gradcheck
    from . import emit_json

    checks = run_gradcheck(n_points=args.n_points, seed=args.seed,
                           models=None if args.model is None else tuple(args.model))
    message = _failure(checks, args.tol)
    if args.json:
        head = ({"status": "ok"} if message is None else
                {"status": "error", "check": GradientMismatchError.check, "message": message,
                 "worst": message.split(":")[0]})
        emit_json({**head, "tol": args.tol, **report(checks)})
        return 0 if message is None else GradientMismatchError.exit_code
    print(f"{'model':13} {'param':7} {'max_rel_err':>12} {'max_fd_err':>11} {'tol':>8} {'points':>6}")
    for c in checks:
        print(f"{c.model:13} {c.param:7} {c.max_rel_err:12.2e} {c.max_fd_err:11.2e} {c.tol:8.0e} {c.n_points:6d}")
    if message is not None:
        raise GradientMismatchError(message)
    return 0
