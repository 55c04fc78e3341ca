"""The model-error terms of a least-squares covariance, for the analysis tools and the irregular body
(they live in :mod:`jaxlimb.fitting.model_error`, beside the fits whose covariances they widen)."""

from ..fitting.model_error import (
    cluster_robust_bias_reduced as cluster_robust_bias_reduced,
    cluster_robust_covariance as cluster_robust_covariance,
    cluster_robust_from_normal as cluster_robust_from_normal,
    hausman_term as hausman_term,
    positive_part as positive_part,
    sector_groups as sector_groups,
    with_model_error as with_model_error,
)

__all__ = ["cluster_robust_bias_reduced", "cluster_robust_covariance", "cluster_robust_from_normal", "hausman_term",
           "positive_part", "sector_groups", "with_model_error"]
