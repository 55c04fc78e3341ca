"""Names of the solvers accepted by ``--solver`` (importable without JAX, for the command line's help).

:data:`jaxlimb.fitting.SOLVERS` maps each of these names to its constructor; a test checks that
the two agree.
"""

SOLVER_NAMES: tuple[str, ...] = (
    "lm", "optx-lm", "optx-normal-lm", "dogleg", "gauss-newton", "bfgs", "paper", "scipy",
)
