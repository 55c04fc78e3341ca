"""Is the batch fit of ``jaxlimb track`` efficient?  Its position error against the posterior Cramér--Rao bound on
measurements drawn from the rendered transfer's own covariances (the model holds by construction).

On the frames of ``benchmarks/track_render.py`` (its ``--cache``), each sequence draws, per frame, one of the
measured noise draws' covariances ``R`` (as ``track_transfer.py`` does), Gaussian measurements about the truth from
``R``, a 10 µrad attitude error per axis and a start from the prior (1000 km, 1 m/s per axis); the batch fit
(:func:`jaxlimb.track.fit_arc`, no bias states) runs from that start.  Reported: the RMS position error over every
epoch and sequence against the root-mean posterior CRB (:func:`jaxlimb.track.posterior_crlb`) with its bootstrap
standard error over the sequences; the batch's own position covariance against the CRB; the mean NEES of its
positions (3 expected); and, along each eigendirection of the CRB of the initial state, the mean squared error
over the bound's variance (1 expected).  ``track_transfer.py``'s drawn Monte Carlo is one seed of 50 sequences
of the whole filter; this is the estimator alone over more of them.

    python benchmarks/track_efficiency.py --cache /tmp/track-cache --sequences 100   # -> results/track_efficiency.json
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _common import environment, save  # noqa: E402
from track_render import THETA_TRUE, scenario  # noqa: E402
from track_transfer import _pick, as_frames, kept_frames, load_records  # noqa: E402

ATTITUDE_SIGMA_RAD = 1e-5
P0 = np.diag([1000.0**2] * 3 + [1e-3**2] * 3)


def one_sequence(arc, prop, tr, draws, keep, z_true, rng) -> dict:  # noqa: ANN001
    from jaxlimb.track import fit_arc, nees, posterior_crlb
    from jaxlimb.track.scenario import perturb_attitudes

    fr = as_frames(arc, tr, [_pick(draws, k, rng) for k in keep], perturb_attitudes(tr.C_true[keep], ATTITUDE_SIGMA_RAD, rng),
                   THETA_TRUE, ATTITUDE_SIGMA_RAD)
    fr.z[:] = z_true + np.einsum("kij,kj->ki", np.linalg.cholesky(fr.R), rng.standard_normal(fr.z.shape))
    x0 = tr.x0 + np.linalg.cholesky(P0) @ rng.standard_normal(6)
    fit = fit_arc(fr, prop, float(fr.t[0]), x0, bias=False)
    X, P = fit.states(prop, fr.t)
    truth = tr.states[keep]
    crb = posterior_crlb(fr, prop, tr.x0, 0.0, P0, bias=False)
    return {"err2": np.sum((X[:, :3] - truth[:, :3]) ** 2, -1), "crb": np.trace(crb[:, :3, :3], axis1=1, axis2=2),
            "cov": np.trace(P[:, :3, :3], axis1=1, axis2=2), "nees": float(nees(X[:, :3], P[:, :3, :3], truth[:, :3]).mean()),
            "e0": X[0] - truth[0], "crb0": crb[0]}


def summarise(runs: list[dict], rng: np.random.Generator, n_boot: int = 2000) -> dict:
    err2, crb = np.array([r["err2"] for r in runs]), np.array([r["crb"] for r in runs])
    n = len(runs)
    idx = rng.integers(0, n, (n_boot, n))
    boot = np.sqrt(err2.mean(1)[idx].mean(1) / crb.mean(1)[idx].mean(1))
    C0 = np.mean([r["crb0"] for r in runs], 0)
    w, V = np.linalg.eigh(C0)
    E0 = np.array([r["e0"] for r in runs]) @ V
    return {"sequences": n, "frames": int(err2.shape[1]),
            "batch_rms_pos_km": float(np.sqrt(err2.mean())), "pcrb_rms_pos_km": float(np.sqrt(crb.mean())),
            "batch_over_pcrb": float(np.sqrt(err2.mean() / crb.mean())), "batch_over_pcrb_se": float(boot.std(ddof=1)),
            "batch_cov_over_pcrb": float(np.sqrt(np.mean([r["cov"] for r in runs]) / crb.mean())),
            "batch_nees_position_mean": float(np.mean([r["nees"] for r in runs])),
            "batch_nees_position_se": float(np.std([r["nees"] for r in runs], ddof=1) / np.sqrt(n)),
            "initial_state_eigendirections": [{"sigma": float(np.sqrt(wi)), "mse_over_variance": float(np.mean(E0[:, i] ** 2) / wi)}
                                              for i, wi in enumerate(w)]}


def main(argv: list[str] | None = None) -> int:
    import jax

    jax.config.update("jax_enable_x64", True)
    from tqdm import tqdm

    from jaxlimb.track.scenario import true_measurements

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--cache", type=Path, required=True)
    ap.add_argument("--n-frames", type=int, default=200)
    ap.add_argument("--sequences", type=int, default=100)
    ap.add_argument("--seed", type=int, default=38)
    a = ap.parse_args(argv)
    arc, prop, tr = scenario(a.n_frames, a.seed)
    draws = [v for k, v in load_records(a.cache).items() if k != "nominal"]
    keep = kept_frames(draws, a.n_frames)
    z_true = true_measurements(tr)[keep]
    rng = np.random.default_rng([a.seed, 7])
    runs = [one_sequence(arc, prop, tr, draws, keep, z_true, rng) for _ in tqdm(range(a.sequences), desc="sequences")]
    out = {"seed": a.seed, "environment": environment()} | summarise(runs, np.random.default_rng([a.seed, 8]))
    print({k: v for k, v in out.items() if k != "environment"}, flush=True)
    print(save("track_efficiency", out))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
