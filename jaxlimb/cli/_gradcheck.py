"""``jaxlimb gradcheck``: the paper's analytic Jacobians vs autodiff and central differences."""

from __future__ import annotations

import argparse


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "gradcheck",
        help="check every limb model's analytic Jacobian against autodiff and central differences",
        description="Compare the analytic Jacobians of the limb models (linear, circular and elliptical "
        "sigmoids, Eq. 14, 17, Sec. V-C; the elliptical ramp; the lunar-Lambert limb profile; the "
        "limb-darkened disc) with jax.jacfwd and central differences at random parameter points.",
    )
    p.add_argument("--n-points", type=int, default=100, help="random parameter points per model (default 100)")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--tol", type=float, default=None,
                   help="fail (exit 3) if any max_rel_err exceeds this (default: each model's own tolerance, "
                   "jaxlimb.models.gradcheck.SPECS: 1e-9, 1e-6 for the quadrature of the lunar-Lambert profile)")
    p.add_argument("--json", action="store_true", help="print one JSON object")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from ..errors import CheckFailed, LimbInputError
    from ..models.gradcheck import report, run_gradcheck
    from . import emit_json

    if args.n_points < 1:
        raise LimbInputError(f"`--n-points` must be >= 1, got {args.n_points}")
    if args.tol is not None and not args.tol > 0:
        raise LimbInputError(f"`--tol` must be > 0, got {args.tol}")
    checks = run_gradcheck(n_points=args.n_points, seed=args.seed)
    if args.json:
        emit_json(report(checks))
    else:
        print(f"{'model':13} {'param':7} {'max_rel_err':>12} {'max_fd_err':>11} {'tol':>8} {'points':>6}")
        for c in checks:
            print(f"{c.model:13} {c.param:7} {c.max_rel_err:12.2e} {c.max_fd_err:11.2e} {c.tol:8.0e} {c.n_points:6d}")
    failed = [c for c in checks if (c.max_rel_err > args.tol if args.tol is not None else not c.passed)]
    if failed:
        worst = max(failed, key=lambda c: c.max_rel_err / (args.tol or c.tol))
        tol = args.tol if args.tol is not None else worst.tol
        err = CheckFailed(f"{worst.model}.{worst.param}: max_rel_err {worst.max_rel_err:.3e} (max_fd_err "
                          f"{worst.max_fd_err:.3e}) above its tolerance {tol:g}")
        if not args.json:
            raise err
        return err.exit_code
    return 0
