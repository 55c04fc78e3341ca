"""Fitting sigmoid limb models: one :func:`fit` over optimistix, the paper's iteration and SciPy."""

from .fit import (
    LimbFit as LimbFit,
    batch_core as batch_core,
    batch_problem as batch_problem,
    PrecisionWarning as PrecisionWarning,
    compile_count as compile_count,
    fit as fit,
    fit_batch as fit_batch,
)
from .pixels import bucket_size as bucket_size, pack_pixels as pack_pixels, pad_pixels as pad_pixels
from .problem import (
    AbstractLimbSolver as AbstractLimbSolver,
    FitResult as FitResult,
    LimbProblem as LimbProblem,
    result_names as result_names,
)
from .solvers import (
    SOLVERS as SOLVERS,
    NormalLM as NormalLM,
    PaperGaussNewton as PaperGaussNewton,
    ScipyLeastSquares as ScipyLeastSquares,
    solver_from_name as solver_from_name,
)


def __getattr__(name: str):  # noqa: ANN202
    """``Optimistix``, ``optimistix_normal_lm``, ``MarquardtCholeskyDescent``, ``ScaledBFGS``: imported on first use
    (:mod:`jaxlimb.fitting.optimistix_solvers`; the default path never imports optimistix)."""
    if name in ("Optimistix", "optimistix_normal_lm", "MarquardtCholeskyDescent", "ScaledBFGS"):
        return getattr(solvers, name)  # the lazy attributes of jaxlimb.fitting.solvers
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
