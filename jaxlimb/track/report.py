"""The trajectory as JSON records (one per frame epoch) and the picture of its error and 3-sigma envelope."""

from __future__ import annotations

from typing import Any

import numpy as np

from .batch import ArcFit
from .filter import FilterResult
from .measurement import Frames


def _state(x: np.ndarray, P: np.ndarray) -> dict[str, Any]:
    return {"state_km_kms": [float(v) for v in x], "sigma_km_kms": [float(np.sqrt(max(P[i, i], 0.0))) for i in range(6)],
            "covariance": [[float(v) for v in row] for row in P]}


def epoch_records(frames: Frames, filt: FilterResult, fit: ArcFit | None, jd0: float,
                  batch_states: tuple[np.ndarray, np.ndarray] | None = None,
                  truth: np.ndarray | None = None) -> list[dict[str, Any]]:
    """One JSON object per frame: epoch (TDB Julian date and seconds after the arc's reference), the frame, its
    NIS and whether the gate kept it, the filtered and smoothed states (geocentric ICRF, km and km/s) with their
    covariances, the batch fit's state there and, when the truth is known, the errors."""
    out = []
    for k in range(len(frames)):
        rec: dict[str, Any] = {
            "image": frames.labels[k], "jd_tdb": jd0 + frames.t[k] / 86400.0, "t_s": float(frames.t[k]),
            "used": bool(filt.used[k]), "nis": float(filt.nis[k]),
            "innovation": [float(v) for v in filt.innovation[k]],
            "filtered": _state(filt.x_filt[k], filt.P_filt[k]), "smoothed": _state(filt.x_smooth[k], filt.P_smooth[k]),
        }
        if batch_states is not None:
            rec["batch"] = {**_state(batch_states[0][k], batch_states[1][k]),
                            "used": bool(fit.used[k]) if fit is not None else None}
        if truth is not None:
            rec["error_smoothed_km_kms"] = [float(v) for v in filt.x_smooth[k] - truth[k]]
            rec["error_filtered_km_kms"] = [float(v) for v in filt.x_filt[k] - truth[k]]
        out.append(rec)
    return out


def plot_track(path: str, t_s: np.ndarray, filt: FilterResult, truth: np.ndarray | None = None,
               title: str = "") -> None:
    """Position error of the filter and the smoother per axis with their 3-sigma envelopes (against the truth
    when given; else the smoother's 3-sigma envelope and the filter's departure from the smoothed trajectory)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    hours = np.asarray(t_s) / 3600.0
    ref = filt.x_smooth if truth is None else truth
    fig, axes = plt.subplots(3, 1, figsize=(8, 7), sharex=True)
    for i, (ax, name) in enumerate(zip(axes, "xyz")):
        s_s = 3 * np.sqrt(filt.P_smooth[:, i, i])
        s_f = 3 * np.sqrt(filt.P_filt[:, i, i])
        ax.fill_between(hours, -s_f, s_f, color="tab:orange", alpha=0.15, lw=0, label="filter 3$\\sigma$")
        ax.fill_between(hours, -s_s, s_s, color="tab:blue", alpha=0.25, lw=0, label="smoother 3$\\sigma$")
        ax.plot(hours, filt.x_filt[:, i] - ref[:, i], ".", color="tab:orange", ms=3, label="filter error")
        if truth is not None:
            ax.plot(hours, filt.x_smooth[:, i] - ref[:, i], "-", color="tab:blue", lw=1, label="smoother error")
        bad = ~filt.used
        if np.any(bad):
            ax.plot(hours[bad], np.zeros(bad.sum()), "x", color="red", label="gated frame")
        lim = np.percentile(np.abs(s_f), 90) * 1.5
        ax.set_ylim(-lim, lim)
        ax.set_ylabel(f"{name} (km)")
    axes[0].legend(loc="upper right", fontsize=7, ncol=3)
    axes[-1].set_xlabel("hours after the first frame")
    axes[0].set_title(title or ("position error (ICRF, geocentric)" if truth is not None else
                                "filter minus smoother, and 3-sigma envelopes (ICRF, geocentric)"))
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


__all__ = ["epoch_records", "plot_track"]
