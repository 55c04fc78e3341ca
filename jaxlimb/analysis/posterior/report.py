"""The posterior beside the fit's Laplace covariance and the Cramér--Rao bound: per-parameter numbers and a table."""

from __future__ import annotations

from collections.abc import Mapping

from ...fitting import LimbFit
from ...models import LimbParams
from ..crlb import CramerRao
from .sampler import Posterior


def compare_uncertainties(post: Posterior, fit: LimbFit | None = None, bound: CramerRao | None = None,
                          truth: LimbParams | None = None) -> dict[str, dict[str, float | None]]:
    """Per parameter: posterior mean and sd, Laplace sd, CRLB sd and their ratios.

    Parameters
    ----------
    post : Posterior
        The samples.
    fit : LimbFit, optional
        The fit whose Laplace sd is compared.
    bound : CramerRao, optional
        The Cramér--Rao bound (:func:`~jaxlimb.analysis.crlb.crlb`).
    truth : LimbParams, optional
        True parameters.

    Returns
    -------
    dict
        ``{name: {"post_mean", "post_std", "laplace_std", "crlb", "post_over_crlb", "post_over_laplace",
        "laplace_over_crlb", "truth"}}`` per sampled parameter (``None`` where not available).
    """
    lap = {} if fit is None else {k: float(v) for k, v in fit.std.items()}
    cr = {} if bound is None else bound.std
    out: dict[str, dict[str, float | None]] = {}
    for i, n in enumerate(post.names):
        ps = float(post.std[i])
        ls, cs = lap.get(n), cr.get(n)
        out[n] = {
            "post_mean": float(post.mean[i]),
            "post_std": ps,
            "laplace_std": ls,
            "crlb": cs,
            "post_over_crlb": ps / cs if cs else None,
            "post_over_laplace": ps / ls if ls else None,
            "laplace_over_crlb": ls / cs if (ls and cs) else None,
            "truth": float(getattr(truth, n)) if (truth is not None and n in truth.field_names()) else None,
        }
    return out


def comparison_table(cmp: Mapping[str, Mapping[str, float | None]]) -> str:
    """Text table of :func:`compare_uncertainties`.

    Parameters
    ----------
    cmp : mapping
        The output of :func:`compare_uncertainties`.

    Returns
    -------
    str
        A header line and one line per parameter.
    """

    def f(v: float | None, w: int = 11, p: int = 5) -> str:
        return f"{'-':>{w}}" if v is None else f"{v:{w}.{p}g}"

    lines = [f"{'param':>9} {'post mean':>11} {'post sd':>11} {'Laplace sd':>11} {'CRLB':>11} {'post/CRLB':>9} {'post/Lapl':>9}"]
    for n, r in cmp.items():
        lines.append(f"{n:>9} {f(r['post_mean'])} {f(r['post_std'])} {f(r['laplace_std'])} {f(r['crlb'])} "
                     f"{f(r['post_over_crlb'], 9, 4)} {f(r['post_over_laplace'], 9, 4)}")
    return "\n".join(lines)


__all__ = ["compare_uncertainties", "comparison_table"]
