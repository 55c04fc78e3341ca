"""``jaxlimb gradcheck``: the paper's analytic Jacobians vs autodiff and central differences.

``--json`` prints one object: ``{"status": "ok", "tol", "worst", "checks": [...]}`` when every
``max_rel_err`` is within ``--tol``; else exit 3 with the error object of the CLI contract,
``{"status": "error", "check": "gradient_mismatch", "message", "tol", "worst", "checks"}``.
"""

from __future__ import annotations

import argparse
import math

from .._validate import Range, arg_number

#: ``--tol``: a relative error; 0 and negative values cannot pass, above 1 cannot fail.
TOL_RANGE = Range(0.0, 1.0, lo_open=True)
N_POINTS_RANGE = Range(1, 10_000)
SEED_RANGE = Range(0, 2**32 - 1)


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "gradcheck",
        help="check the paper's Jacobians (Eq. 14, 17, Sec. V-C) against autodiff",
        description="Compare the analytic Jacobians of the linear, circular and elliptical sigmoid "
        "models with jax.jacfwd and central differences at random parameter points.  Exit 0 when "
        "every relative error is within --tol, 3 otherwise, 2 for bad arguments.",
    )
    p.add_argument("--n-points", type=arg_number(N_POINTS_RANGE, integer=True), default=100,
                   help=f"random parameter points per model, integer {N_POINTS_RANGE} (default 100)")
    p.add_argument("--seed", type=arg_number(SEED_RANGE, integer=True), default=0,
                   help=f"random seed, integer {SEED_RANGE} (default 0)")
    p.add_argument("--tol", type=arg_number(TOL_RANGE), default=1e-9,
                   help=f"fail (exit 3) if any max_rel_err exceeds this; {TOL_RANGE} (default 1e-9)")
    p.add_argument("--json", action="store_true", help="print one JSON object")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from ..errors import GradientMismatchError
    from ..models.gradcheck import report, run_gradcheck
    from . import emit_json

    checks = run_gradcheck(n_points=args.n_points, seed=args.seed)
    worst = max(checks, key=lambda c: (math.isnan(c.max_rel_err), c.max_rel_err))  # a NaN error is the worst
    ok = worst.max_rel_err <= args.tol  # False for NaN: never a pass
    message = f"{worst.model}.{worst.param}: max_rel_err {worst.max_rel_err:.3e} > --tol {args.tol:g}"
    if args.json:
        head = {"status": "ok"} if ok else {"status": "error", "check": GradientMismatchError.check, "message": message}
        emit_json({**head, "tol": args.tol, "worst": f"{worst.model}.{worst.param}", **report(checks)})
        return 0 if ok else GradientMismatchError.exit_code
    print(f"{'model':8} {'param':7} {'max_rel_err':>12} {'max_fd_err':>11} {'points':>6}")
    for c in checks:
        print(f"{c.model:8} {c.param:7} {c.max_rel_err:12.2e} {c.max_fd_err:11.2e} {c.n_points:6d}")
    if not ok:
        raise GradientMismatchError(message)
    return 0
