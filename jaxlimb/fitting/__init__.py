"""Fitting sigmoid limb models: one :func:`fit` over optimistix, the paper's iteration and SciPy."""

from .fit import (
    LimbFit as LimbFit,
    batch_core as batch_core,
    batch_problem as batch_problem,
    PrecisionWarning as PrecisionWarning,
    bucket_size as bucket_size,
    compile_count as compile_count,
    fit as fit,
    fit_batch as fit_batch,
    pack_pixels as pack_pixels,
    pad_pixels as pad_pixels,
)
from .solvers import (
    SOLVERS as SOLVERS,
    AbstractLimbSolver as AbstractLimbSolver,
    FitResult as FitResult,
    LimbProblem as LimbProblem,
    MarquardtCholeskyDescent as MarquardtCholeskyDescent,
    optimistix_normal_lm as optimistix_normal_lm,
    NormalLM as NormalLM,
    Optimistix as Optimistix,
    PaperGaussNewton as PaperGaussNewton,
    ScipyLeastSquares as ScipyLeastSquares,
    solver_from_name as solver_from_name,
)
