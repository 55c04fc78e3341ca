r"""Monte Carlo of the whole pipeline: rendered frames through :func:`jaxlimb.pipeline.locate` with its defaults.

Two kinds of trial (both picklable, for Dask workers: :mod:`jaxlimb.analysis.distributed`):

* :class:`LocateTrial` -- one rendered Moon (the package's renderer: lunar-Lambert, PSF 1 px) with new Gaussian
  noise per trial: the noise study of one scene;
* :class:`FamilyTrial` -- a new frame per trial from the independent renderer's scene families
  (:mod:`jaxlimb.render.independent`: ``own`` is what the physical profile assumes, every other family
  changes one thing it does not), cycling through the chosen families.

Each trial returns the errors of ``locate``'s answer against the render's truth (centre of the body's image,
apparent radius, range), the covariance ``locate`` reported for them, its Cramér--Rao sigmas and the
normalised errors: the centre's NEES :math:`e^\top P^{-1} e` (2 degrees of freedom: expectation 2) and the
range's :math:`z = e/\sigma`.  :func:`pipeline_summary` reports per family: bias, RMS, the mean reported sigma
and CRLB, the mean NEES and the coverage of the reported 68 % / 95 % ellipses (the fraction of trials with
NEES below the chi-square quantiles 2.28 / 5.99).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from ..errors import LimbInputError
from ..pipeline.result import covariance_block
from .figures import save_figure
from .montecarlo import MonteCarloResult

#: chi-square quantiles with 2 degrees of freedom: the 68.27 % and 95.45 % (1 and 2 sigma) ellipses.
CHI2_2 = {"68": -2.0 * math.log(1.0 - 0.6827), "95": -2.0 * math.log(1.0 - 0.9545)}

_BASE: dict[Any, Any] = {}  # per worker process: the noise-free frame of each LocateTrial


@dataclass(frozen=True)
class TrialTruth:
    """What a trial's numbers are measured against: the body centre's image, the apparent radius, the range."""

    body_center_rc: tuple[float, float]
    apparent_radius_px: float
    range_km: float


def measurement_errors(m: Any, truth: Any) -> dict[str, float]:
    """The numbers of one trial (module docstring) from ``locate``'s answer and the render's truth.

    Parameters
    ----------
    m : LimbMeasurement
        ``locate``'s answer.
    truth : TrialTruth or LimbTruth
        Anything with ``body_center_rc`` ((row, col) px), ``apparent_radius_px`` and ``range_km``.

    Returns
    -------
    dict of str to float
        ``row``, ``col`` errors (px) and ``iterations``; when reported: ``sigma_row``, ``sigma_col`` and the centre
        ``nees``; ``radius`` error and ``sigma_radius`` (px); ``range_pct`` error and ``range_z``; ``crlb_row``,
        ``crlb_col``, ``crlb_radius``.
    """
    e = np.asarray(m.center_rc, float) - np.asarray(truth.body_center_rc, float)
    c = m.covariance
    out = {"row": float(e[0]), "col": float(e[1]), "iterations": float(m.iterations)}
    try:
        P = covariance_block(c)
        out.update(sigma_row=math.sqrt(P[0, 0]), sigma_col=math.sqrt(P[1, 1]), nees=float(e @ np.linalg.solve(P, e)))
    except (KeyError, np.linalg.LinAlgError, ValueError):
        pass
    if m.radius_px is not None:
        out["radius"] = float(m.radius_px - truth.apparent_radius_px)
        if "radius" in c:
            out["sigma_radius"] = math.sqrt(max(c["radius"]["radius"], 0.0))
    if m.range_km is not None:
        out["range_pct"] = float(100.0 * (m.range_km - truth.range_km) / truth.range_km)
        var = c.get("range_km", {}).get("range_km")
        if var:
            out["range_z"] = float((m.range_km - truth.range_km) / math.sqrt(var))
    for k, name in (("center_r", "crlb_row"), ("center_c", "crlb_col"), ("radius", "crlb_radius")):
        if m.crlb is not None and k in m.crlb:
            out[name] = float(m.crlb[k])
    return out


def _options(profile: str | None) -> Any:
    from ..pipeline import LocateOptions

    return LocateOptions(keep_pixels=False) if profile is None else LocateOptions(keep_pixels=False, profile=profile)


@dataclass(frozen=True)
class LocateTrial:
    """One trial of the one-scene study: a rendered Moon + noise through ``locate`` (module docstring).

    The Moon is rendered once per process without noise (lunar-Lambert, PSF 1 px) and scaled to 80 % of the
    8-bit range; trial ``seed`` adds Gaussian noise of ``sigma_dn``, rounds and clips to 8 bits, and runs
    :func:`jaxlimb.pipeline.locate` with the Sun direction as hint and its defaults (``profile``: another
    limb profile).  A :class:`~jaxlimb.errors.JaxlimbError` (a failed check) is a failed trial.
    """

    camera: Any = None
    """A :class:`~jaxlimb.geometry.camera.Camera` (default: ``Camera.default()``, 1944x2592)."""
    range_km: float = 150_000.0
    phase_deg: float = 45.0
    sigma_dn: float = 10.0
    profile: str | None = None
    """``LocateOptions.profile`` (``None``: ``locate``'s default)."""

    def _base(self) -> tuple[np.ndarray, Any, Any, Any]:
        if self not in _BASE:
            from .dask_worker import wait_started

            wait_started()  # a worker's preload thread may still be importing the package
            from .._jaxcache import start_jax

            start_jax()
            from ..geometry.camera import Camera
            from ..imaging import Hints
            from ..render import RenderOptions, moon_scene, render_body

            cam = self.camera if self.camera is not None else Camera.default()
            center = (cam.rows * 0.46, cam.cols * 0.54)
            scene = moon_scene(self.range_km, self.phase_deg, center_rc=center, camera=cam, sun_angle_deg=30.0)
            clean, truth = render_body(scene, cam, RenderOptions(reflectance="lunar-lambert", psf_sigma_px=1.0,
                                                                 bit_depth=None, noise=False), seed=0)
            base = np.asarray(clean) * (255.0 * 0.8 / float(np.max(clean)))
            hints = Hints(body="moon", sun_dir_camera=tuple(float(v) for v in truth.sun_dir_cam))
            rc = tuple(float(v) for v in truth.center_rc)
            _BASE[self] = (base, TrialTruth(rc, float(truth.apparent_radius_px), float(truth.range_km)), hints, cam)
        return _BASE[self]

    def __call__(self, seed: int, i: int) -> dict[str, float]:
        from ..pipeline import locate

        del i
        base, truth, hints, cam = self._base()
        img = np.random.default_rng(seed).standard_normal(base.shape)  # in place below: the same values as
        img *= self.sigma_dn  # clip(round(base + sigma * noise)), without four 40 MB temporaries
        img += base
        np.round(img, out=img)
        np.clip(img, 0, 255, out=img)
        return measurement_errors(locate(img, cam, hints, _options(self.profile)), truth)


@dataclass(frozen=True)
class FamilyTrial:
    """One trial of the families study: frame ``i`` of family ``families[i % len(families)]`` of ``body``, drawn
    from the trial's seed by the independent renderer, through ``locate`` with the hints a filter has (body, Sun
    direction, a range prior 5 % off; the Earth's attitude) and its defaults (``profile``: another)."""

    families: tuple[str, ...] = ("own",)
    body: str = "moon"
    profile: str | None = None

    def __post_init__(self) -> None:
        from ..render.independent import EARTH_FAMILIES, MOON_FAMILIES

        known = {"moon": MOON_FAMILIES, "earth": EARTH_FAMILIES}.get(self.body)
        if known is None:
            raise LimbInputError(f"`body` must be 'moon' or 'earth', got {self.body!r}")
        bad = [f for f in self.families if f not in known]
        if bad or not self.families:
            raise LimbInputError(f"unknown {self.body} families {bad}; choose from {list(known)}")

    def case(self, seed: int, i: int) -> Any:
        """The rendered frame of trial ``i`` (:class:`jaxlimb.render.independent.Case`).

        Parameters
        ----------
        seed : int
            The trial's seed (draws the frame of the family).
        i : int
            Trial index; picks the family ``families[i % len(families)]``.

        Returns
        -------
        jaxlimb.render.independent.Case
            Image, camera, hints and truth of the frame.
        """
        from .dask_worker import wait_started

        wait_started()
        from ..render.independent import earth_case, moon_case

        family = self.families[i % len(self.families)]
        rng = np.random.default_rng(seed)
        return moon_case(family, rng) if self.body == "moon" else earth_case(family, rng)

    def __call__(self, seed: int, i: int) -> dict[str, float]:
        from .._jaxcache import start_jax

        start_jax()
        from ..imaging import Hints
        from ..pipeline import locate

        case = self.case(seed, i)
        m = locate(case.image, case.camera, Hints.from_dict(case.hints), _options(self.profile))
        return {**measurement_errors(m, case.truth), "family": float(i % len(self.families))}


def _group_stats(values: dict[str, np.ndarray], ok: np.ndarray) -> dict[str, Any]:
    out: dict[str, Any] = {"n": int(ok.size), "n_ok": int(ok.sum())}
    for k in ("row", "col", "radius", "range_pct"):
        v = values.get(k, np.full(ok.size, np.nan))[ok]
        v = v[np.isfinite(v)]
        if v.size:
            out[k] = {"bias": float(v.mean()), "rms": float(np.sqrt(np.mean(v * v))), "n": int(v.size)}
    for k in ("sigma_row", "sigma_col", "sigma_radius", "crlb_row", "crlb_col", "crlb_radius"):
        v = values.get(k, np.full(ok.size, np.nan))[ok]
        v = v[np.isfinite(v)]
        if v.size:
            out[f"{k}_mean"] = float(v.mean())
    nees = values.get("nees", np.full(ok.size, np.nan))[ok]
    nees = nees[np.isfinite(nees)]
    if nees.size:
        out.update(nees_mean=float(nees.mean()), nees_median=float(np.median(nees)),
                   coverage={q: float(np.mean(nees <= t)) for q, t in CHI2_2.items()})
    z = values.get("range_z", np.full(ok.size, np.nan))[ok]
    z = z[np.isfinite(z)]
    if z.size:
        out["range_nees_mean"] = float(np.mean(z * z))
    return out


def pipeline_summary(res: MonteCarloResult, families: tuple[str, ...] | None = None) -> dict[str, Any]:
    """Per family and over all trials: the statistics of the module docstring and the failures by check.

    Parameters
    ----------
    res : MonteCarloResult
        A study of :class:`LocateTrial` or :class:`FamilyTrial`.
    families : tuple of str, optional
        Names of the trials' ``family`` values (index ``j`` names value ``j``); ``None``: all trials only.

    Returns
    -------
    dict
        ``{"all": {...}, family: {...}}``, each with ``n``, ``n_ok``, bias/RMS of ``row``, ``col``, ``radius``,
        ``range_pct``, the mean reported sigmas and CRLB, ``nees_mean``, ``nees_median``, ``coverage`` of the
        68 % / 95 % ellipses, ``range_nees_mean`` and ``failures``.
    """
    out: dict[str, Any] = {"all": {**_group_stats(res.values, res.ok), "failures": res.failure_counts()}}
    if families:
        fam = res.values.get("family", np.full(res.n, np.nan))
        for j, name in enumerate(families):
            sel = fam == j
            if sel.any():
                sub = {k: v[sel] for k, v in res.values.items()}
                fails = {str(a): int(b) for a, b in zip(*np.unique(res.error[sel & ~res.ok], return_counts=True))}
                out[name] = {**_group_stats(sub, res.ok[sel]), "failures": fails}
    return out


def plot_pipeline(res: MonteCarloResult, summary: dict[str, Any], path: Any = None, title: str | None = None) -> Any:
    """Centre errors normalised by the reported sigmas (``e_row / sigma_row`` against ``e_col / sigma_col``) with
    the 68 % / 95 % circles, and per family the coverage of the reported ellipses (grey: 68 +- 7 %, 95 +- 4 %)
    and the mean NEES.

    Parameters
    ----------
    res : MonteCarloResult
        The study.
    summary : dict
        Its :func:`pipeline_summary`.
    path : str or Path, optional
        Where to write the figure (:func:`~jaxlimb.analysis.figures.save_figure`); ``None`` writes nothing.
    title : str, optional
        Figure title.

    Returns
    -------
    matplotlib.figure.Figure
    """
    import matplotlib

    matplotlib.use("Agg", force=False)
    import matplotlib.pyplot as plt

    groups = [g for g in summary if "nees_mean" in summary[g]]
    fig, (ax1, ax2) = plt.subplots(1, 2, figsize=(8.2, 3.6))
    v, ok = res.values, res.ok
    if "sigma_row" in v:
        ax1.plot(v["col"][ok] / v["sigma_col"][ok], v["row"][ok] / v["sigma_row"][ok], ".", ms=3, alpha=0.6)
    t = np.linspace(0, 2 * np.pi, 200)
    for q, ls in (("68", "-"), ("95", "--")):
        r = math.sqrt(CHI2_2[q])
        ax1.plot(r * np.cos(t), r * np.sin(t), "k", ls=ls, lw=0.8, label=f"{q} % (uncorrelated)")
    ax1.set(xlabel="col error / reported sigma", ylabel="row error / reported sigma", aspect="equal")
    ax1.legend(fontsize=6)
    y = np.arange(len(groups))
    for q, band, marker in (("68", (61.0, 75.0), "o"), ("95", (91.0, 99.0), "s")):
        ax2.axvspan(*band, color="0.9")
        ax2.plot([100 * summary[g]["coverage"][q] for g in groups], y, marker, ms=4, label=f"{q} % ellipse")
    ax2.set(yticks=y, yticklabels=[f"{g} ({summary[g]['n_ok']}) NEES {summary[g]['nees_mean']:.2f}" for g in groups],
            xlabel="trials inside the reported ellipse, %", xlim=(0, 100))
    ax2.legend(fontsize=6, loc="lower left")
    if title:
        fig.suptitle(title, fontsize=8)
    fig.tight_layout()
    save_figure(fig, path)
    return fig


__all__ = ["CHI2_2", "FamilyTrial", "LocateTrial", "TrialTruth", "measurement_errors", "pipeline_summary", "plot_pipeline"]
