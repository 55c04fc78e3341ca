"""``jaxlimb gradcheck``: the paper's analytic Jacobians vs autodiff and central differences."""

from __future__ import annotations

import argparse


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "gradcheck",
        help="check the paper's Jacobians (Eq. 14, 17, Sec. V-C) against autodiff",
        description="Compare the analytic Jacobians of the linear, circular and elliptical sigmoid "
        "models with jax.jacfwd and central differences at random parameter points.",
    )
    p.add_argument("--n-points", type=int, default=100, help="random parameter points per model (default 100)")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--tol", type=float, default=1e-9, help="fail (exit 3) if any max_rel_err exceeds this")
    p.add_argument("--json", action="store_true", help="print one JSON object")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from ..errors import CheckFailed, LimbInputError
    from ..models.gradcheck import report, run_gradcheck
    from . import emit_json

    if args.n_points < 1:
        raise LimbInputError(f"`--n-points` must be >= 1, got {args.n_points}")
    checks = run_gradcheck(n_points=args.n_points, seed=args.seed)
    if args.json:
        emit_json(report(checks))
    else:
        print(f"{'model':8} {'param':7} {'max_rel_err':>12} {'max_fd_err':>11} {'points':>6}")
        for c in checks:
            print(f"{c.model:8} {c.param:7} {c.max_rel_err:12.2e} {c.max_fd_err:11.2e} {c.n_points:6d}")
    worst = max(checks, key=lambda c: c.max_rel_err)
    if worst.max_rel_err > args.tol:
        err = CheckFailed(f"{worst.model}.{worst.param}: max_rel_err {worst.max_rel_err:.3e} > {args.tol:g}")
        if not args.json:
            raise err
        return err.exit_code
    return 0
