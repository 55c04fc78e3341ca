"""Figures of a posterior: the corner plot of the samples with the fit's Laplace 1-sigma."""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np

from ...fitting import LimbFit
from .sampler import Posterior


def corner_plot(post: Posterior, path: Any | None = None, truths: Mapping[str, float] | None = None,
                laplace: LimbFit | None = None, title: str | None = None) -> Any:
    """Corner plot of the samples (``corner``), with the truth and the Laplace 1-sigma if given.

    Parameters
    ----------
    post : Posterior
        The samples.
    path : str or Path, optional
        Where to write the figure (atomically; the format from the suffix); ``None`` writes nothing.
    truths : mapping of str to float, optional
        True value per parameter name, drawn as lines.
    laplace : LimbFit, optional
        The fit, whose Laplace ``estimate +- 1 sigma`` is drawn dashed on the diagonal.
    title : str, optional
        Figure title.

    Returns
    -------
    matplotlib.figure.Figure
        The figure (closed when written to ``path``).
    """
    import corner
    import matplotlib

    matplotlib.use("Agg", force=False)
    import matplotlib.pyplot as plt

    from ..._io import atomic_path

    tr = None if truths is None else [truths.get(n) for n in post.names]
    fig = corner.corner(post.samples, labels=list(post.names), truths=tr, show_titles=True, title_fmt=".4f",
                        quantiles=(0.16, 0.5, 0.84))
    if laplace is not None:
        axes = np.asarray(fig.axes).reshape(len(post.names), len(post.names))
        est = np.asarray(laplace.params.to_vector())
        names = laplace.params.field_names()
        for i, n in enumerate(post.names):
            if n in laplace.free:
                s = float(laplace.std[n])
                m = float(est[names.index(n)])
                for v in (m - s, m + s):
                    axes[i, i].axvline(v, color="C1", ls="--", lw=1)
        axes[0, -1].text(0.0, 0.5, "dashed: Laplace $\\pm1\\sigma$", color="C1", transform=axes[0, -1].transAxes)
    if title:
        fig.suptitle(title, fontsize=9)
    if path is not None:
        with atomic_path(str(path)) as tmp:
            fig.savefig(tmp, format=str(path).rsplit(".", 1)[-1], dpi=90)
        plt.close(fig)
    return fig


def _ellipse(ax: Any, mean: np.ndarray, cov: np.ndarray, k: float, **kw: Any) -> None:
    w, v = np.linalg.eigh(cov)
    t = np.linspace(0, 2 * np.pi, 200)
    pts = mean[:, None] + v @ (np.sqrt(np.maximum(w, 0.0))[:, None] * k * np.array([np.cos(t), np.sin(t)]))
    ax.plot(pts[0], pts[1], **kw)


def plot_measured(mp: Any, path: Any | None = None, truth: Mapping[str, float] | None = None,
                  title: str | None = None) -> Any:
    """The posterior of ``locate``'s centre: the samples of the body centre, raw and adjusted, with ``locate``'s 1- and
    2-sigma ellipses (and the truth if given), and the radius's samples against ``locate``'s sigma.

    Parameters
    ----------
    mp : MeasuredPosterior
        From :func:`~jaxlimb.analysis.posterior.measured_posterior`.
    path : str or Path, optional
        Where to write the figure (:func:`~jaxlimb.analysis.figures.save_figure`); ``None`` writes nothing.
    truth : mapping of str to float, optional
        ``center_r``, ``center_c`` and optionally ``radius`` (px).
    title : str, optional
        Figure title.

    Returns
    -------
    matplotlib.figure.Figure
    """
    import matplotlib

    matplotlib.use("Agg", force=False)
    import matplotlib.pyplot as plt

    from ..figures import save_figure

    lf = mp.located
    fig, (ax1, ax2) = plt.subplots(1, 2, figsize=(8.0, 3.6))
    c0 = np.array(lf.measurement.center_rc)[::-1]  # (col, row)
    for key, color, label in (("mapped", "C0", "posterior"), ("mapped_adjusted", "C1", "adjusted (model error)")):
        m = getattr(mp, key)
        ax1.plot(m["center_c"] - c0[0], m["center_r"] - c0[1], ".", ms=2, alpha=0.4, color=color, label=label)
    idx = [lf.names.index("center_c"), lf.names.index("center_r")]
    for k, ls in ((1.0, "-"), (2.0, "--")):
        _ellipse(ax1, np.zeros(2), lf.matrix[np.ix_(idx, idx)], k, color="k", ls=ls, lw=0.8)
    if truth is not None:
        ax1.plot(truth["center_c"] - c0[0], truth["center_r"] - c0[1], "r*", ms=10, label="truth")
    ax1.set(xlabel="col - locate's (px)", ylabel="row - locate's (px)", aspect="equal")
    ax1.legend(fontsize=6)
    if "radius" in mp.mapped:
        r0 = float(lf.measurement.radius_px)
        ax2.hist(mp.mapped["radius"] - r0, bins=40, density=True, alpha=0.6, color="C0", label="posterior")
        ax2.hist(mp.mapped_adjusted["radius"] - r0, bins=40, density=True, alpha=0.6, color="C1", label="adjusted")
        sd = float(np.sqrt(lf.matrix[lf.names.index("radius"), lf.names.index("radius")]))
        ax2.axvspan(-sd, sd, color="0.85", zorder=0, label="locate 1 sigma")
        if truth is not None and "radius" in truth:
            ax2.axvline(truth["radius"] - r0, color="r", label="truth")
        ax2.set(xlabel="radius - locate's (px)")
        ax2.legend(fontsize=6)
    if title:
        fig.suptitle(title, fontsize=8)
    fig.tight_layout()
    save_figure(fig, path, dpi=100)
    return fig


__all__ = ["corner_plot", "plot_measured"]
