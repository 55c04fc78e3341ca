"""Figures of the noise studies: error histograms with the CRLB Gaussian, RMS against the CRLB, and the
atomic writer every study's figure uses (:func:`save_figure`)."""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from .montecarlo import MonteCarloResult


def plot_errors(result: MonteCarloResult, keys: Sequence[str], truth: Mapping[str, float] | None = None,
                crlb: Mapping[str, float] | None = None, path: str | Path | None = None, bins: int = 40,
                title: str | None = None) -> Any:
    """Histograms of the errors of ``keys`` with the CRLB Gaussian ``N(0, crlb^2)`` overlaid.

    Parameters
    ----------
    result : MonteCarloResult
        The study; only its successful trials are plotted.
    keys : sequence of str
        Keys of ``result.values``, one panel each.
    truth : mapping of str to float, optional
        True value per key (error = value - truth; default 0: the trial returned errors).
    crlb : mapping of str to float, optional
        Cramér--Rao 1-sigma bound per key, in the key's unit; keys without one get no curve.
    path : str or Path, optional
        Where to write the figure (:func:`save_figure`); ``None`` writes nothing.
    bins : int
        Histogram bins.
    title : str, optional
        Figure title.

    Returns
    -------
    matplotlib.figure.Figure
        The figure (closed when written to ``path``).
    """
    import matplotlib

    matplotlib.use("Agg", force=False)
    import matplotlib.pyplot as plt

    truth = truth or {}
    crlb = crlb or {}
    fig, axes = plt.subplots(1, len(keys), figsize=(3.2 * len(keys), 2.8), squeeze=False)
    st = result.stats(truth, crlb, keys)
    for ax, k in zip(axes[0], keys):
        v = result.values[k][result.ok]
        e = v[np.isfinite(v)] - float(truth.get(k, 0.0))
        ax.hist(e, bins=bins, density=True, color="0.6", label="Monte Carlo")
        if k in crlb:
            x = np.linspace(e.min(), e.max(), 200)
            s = float(crlb[k])
            ax.plot(x, np.exp(-0.5 * (x / s) ** 2) / (s * math.sqrt(2 * math.pi)), "C0", label="CRLB")
        p = st["params"][k]
        txt = f"RMS {p['rms']:.3g}\nbias {p['bias']:.2g}"
        if "rms_over_crlb" in p:
            txt += f"\nRMS/CRLB {p['rms_over_crlb']:.3f}"
        ax.text(0.02, 0.97, txt, transform=ax.transAxes, va="top", fontsize=7)
        ax.set_xlabel(f"{k} error")
    axes[0][0].legend(fontsize=7, loc="upper right")
    if title:
        fig.suptitle(title, fontsize=9)
    fig.tight_layout()
    save_figure(fig, path)
    return fig


def plot_rms_vs_crlb(points: Sequence[Mapping[str, float]], path: str | Path | None = None, xlabel: str = "CRLB",
                     ylabel: str = "Monte-Carlo RMS", title: str | None = None) -> Any:
    """Scatter of RMS against CRLB (log-log) with the line RMS = CRLB.

    Parameters
    ----------
    points : sequence of mapping
        One ``{"crlb": float, "rms": float, "label": str}`` per point (``label`` optional), same unit.
    path : str or Path, optional
        Where to write the figure (:func:`save_figure`); ``None`` writes nothing.
    xlabel, ylabel, title : str
        Axis labels and an optional title.

    Returns
    -------
    matplotlib.figure.Figure
        The figure (closed when written to ``path``).
    """
    import matplotlib

    matplotlib.use("Agg", force=False)
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(3.6, 3.4))
    c = np.array([p["crlb"] for p in points], dtype=float)
    r = np.array([p["rms"] for p in points], dtype=float)
    ax.loglog(c, r, "o", ms=4)
    for p in points:
        if p.get("label"):
            ax.annotate(str(p["label"]), (p["crlb"], p["rms"]), fontsize=6, xytext=(3, 3), textcoords="offset points")
    lo, hi = min(c.min(), r.min()) / 1.5, max(c.max(), r.max()) * 1.5
    ax.plot([lo, hi], [lo, hi], "k--", lw=0.8, label="RMS = CRLB")
    ax.set(xlabel=xlabel, ylabel=ylabel, xlim=(lo, hi), ylim=(lo, hi))
    ax.legend(fontsize=7)
    if title:
        ax.set_title(title, fontsize=9)
    fig.tight_layout()
    save_figure(fig, path)
    return fig


def save_figure(fig: Any, path: str | Path | None, dpi: int = 110) -> None:
    """Write ``fig`` to ``path`` atomically (the format from its suffix) and close it; nothing for ``None``.

    Parameters
    ----------
    fig : matplotlib.figure.Figure
        The figure to write.
    path : str or Path or None
        Destination; its suffix (``.png``, ``.pdf``, ...) names the format.
    dpi : int
        Resolution of raster formats.
    """
    if path is None:
        return
    import matplotlib.pyplot as plt

    from .._io import atomic_path

    with atomic_path(str(path)) as tmp:
        fig.savefig(tmp, format=str(path).rsplit(".", 1)[-1], dpi=dpi)
    plt.close(fig)


__all__ = ["plot_errors", "plot_rms_vs_crlb", "save_figure"]
