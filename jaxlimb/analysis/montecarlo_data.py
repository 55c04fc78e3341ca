"""The settings and the result of a Monte-Carlo study of :mod:`jaxlimb.analysis.montecarlo` (which re-exports
both): :class:`MonteCarloOptions` and :class:`MonteCarloResult` with its error statistics."""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from ..errors import LimbInputError


@dataclass(frozen=True)
class MonteCarloOptions:
    """Settings of :func:`~jaxlimb.analysis.montecarlo.run_monte_carlo`."""

    n_trials: int
    """Number of trials (>= 1)."""
    chunk_size: int = 100
    """Trials per chunk (the unit of checkpointing and of a batched call)."""
    seed: int = 0
    """Study seed; trial ``i`` gets :func:`~jaxlimb.analysis.montecarlo.trial_seed` ``(seed, i)``."""
    out_dir: str | None = None
    """Directory for chunk files and the manifest (``None``: keep everything in memory)."""
    name: str = "montecarlo"
    """Study name (stored in the manifest; a resume must match it)."""
    progress: bool = True
    """Show a tqdm progress bar."""
    batched: bool = False
    """``trial`` takes whole chunks: ``trial(seeds (b,), indices (b,)) -> {key: (b,)}``."""
    shard: tuple[int, int] = (0, 1)
    """``(p, P)``: this process computes only the chunks ``c`` with ``c % P == p`` (multi-host or
    multi-process runs into one shared ``out_dir``; other processes' chunks are read if present)."""

    def __post_init__(self) -> None:
        p_, n_ = self.shard
        if not (isinstance(p_, (int, np.integer)) and isinstance(n_, (int, np.integer)) and 0 <= p_ < n_):
            raise LimbInputError(f"`shard` must be (p, P) with 0 <= p < P, got {self.shard!r}")
        if n_ > 1 and self.out_dir is None:
            raise LimbInputError("`shard` with P > 1 needs a shared `out_dir`")
        for nm in ("n_trials", "chunk_size"):
            v = getattr(self, nm)
            if isinstance(v, bool) or not isinstance(v, (int, np.integer)) or v < 1:
                raise LimbInputError(f"`{nm}` must be an integer >= 1, got {v!r}")
        if isinstance(self.seed, bool) or not isinstance(self.seed, (int, np.integer)) or self.seed < 0:
            raise LimbInputError(f"`seed` must be an integer >= 0, got {self.seed!r}")

    @property
    def n_chunks(self) -> int:
        return math.ceil(self.n_trials / self.chunk_size)


@dataclass(frozen=True)
class MonteCarloResult:
    """All trials of a study, in trial order.

    With ``shard=(p, P)``, P > 1, only the chunks available to this process are included; read the whole study
    with :func:`~jaxlimb.analysis.montecarlo.load_monte_carlo` once every process has finished.

    Attributes
    ----------
    values : dict of str to np.ndarray (n,)
        The numbers each trial returned, per key (NaN where missing or failed).
    ok : np.ndarray (n,) of bool
        Success flags.
    error : np.ndarray (n,) of str
        Error names of the failed trials ("" for successes).
    seeds : np.ndarray (n,) of int
        Per-trial seeds.
    wall_s : float
        Wall time of this call (s; skipped chunks cost nothing).
    chunks_run, chunks_skipped : int
        Chunks computed now / found on disk.
    options : MonteCarloOptions
        The study's settings.
    """

    values: dict[str, np.ndarray]
    ok: np.ndarray
    error: np.ndarray
    seeds: np.ndarray
    wall_s: float
    chunks_run: int
    chunks_skipped: int
    options: MonteCarloOptions

    @property
    def n(self) -> int:
        return int(self.ok.size)

    def stats(self, truth: Mapping[str, float] | None = None, crlb: Mapping[str, float] | None = None,
              keys: Sequence[str] | None = None, percentiles: Sequence[float] = (2.5, 16, 50, 84, 97.5)) -> dict[str, Any]:
        """Error statistics over the successful trials: ``error = value - truth[key]``.

        Parameters
        ----------
        truth, crlb : mapping of str to float, optional
            True value (default 0: the trial returned errors) and 1-sigma Cramér--Rao bound per key.
        keys : sequence of str, optional
            Keys to summarise; default all.
        percentiles : sequence of float
            Percentiles of the error to report.

        Returns
        -------
        dict
            ``n``, ``n_ok``, ``failures`` and ``params``: per key ``n`` (finite values), ``rms``, ``bias``,
            ``bias_se``, ``std``, ``max_abs``, ``percentiles``, and ``crlb``, ``rms_over_crlb`` with a bound.
        """
        truth = truth or {}
        crlb = crlb or {}
        keys = list(keys) if keys is not None else list(self.values)
        out: dict[str, Any] = {"n": self.n, "n_ok": int(self.ok.sum()), "failures": self.failure_counts(), "params": {}}
        for k in keys:
            if k not in self.values:
                raise LimbInputError(f"no trial returned {k!r}; keys are {sorted(self.values)}")
            v = self.values[k][self.ok]
            e = v[np.isfinite(v)] - float(truth.get(k, 0.0))
            if e.size == 0:
                out["params"][k] = {"n": 0}
                continue
            rms = float(np.sqrt(np.mean(e**2)))
            d: dict[str, Any] = {
                "n": int(e.size), "rms": rms, "bias": float(e.mean()),
                "std": float(e.std(ddof=1)) if e.size > 1 else 0.0, "max_abs": float(np.abs(e).max()),
                "bias_se": float(e.std(ddof=1) / math.sqrt(e.size)) if e.size > 1 else None,
                "percentiles": {str(p): float(np.percentile(e, p)) for p in percentiles},
            }
            if k in crlb and crlb[k]:
                d["crlb"] = float(crlb[k])
                d["rms_over_crlb"] = rms / float(crlb[k])
            out["params"][k] = d
        return out

    def failure_counts(self) -> dict[str, int]:
        """Failed trials per error name.

        Returns
        -------
        dict of str to int
        """
        names, counts = np.unique(self.error[~self.ok], return_counts=True)
        return {str(a): int(b) for a, b in zip(names, counts)}

    def histogram(self, key: str = "n_steps") -> dict[int, int]:
        """Counts of each integer value of ``key`` (e.g. iterations) over the successful trials.

        Parameters
        ----------
        key : str
            A key of :attr:`values` holding integers, e.g. ``"n_steps"``.

        Returns
        -------
        dict of int to int
        """
        v = self.values[key][self.ok]
        v = v[np.isfinite(v)].astype(int)
        vals, counts = np.unique(v, return_counts=True)
        return {int(a): int(b) for a, b in zip(vals, counts)}


__all__ = ["MonteCarloOptions", "MonteCarloResult"]
