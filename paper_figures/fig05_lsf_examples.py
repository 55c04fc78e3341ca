"""Fig. 5 of Mortari, D'Souza & Zanetti (2016): linear sigmoid functions for k = 0.1 ... 0.9.

Eq. (12): ``f = ymax + (ymin - ymax) / (1 + exp(k (xt - x)))`` with ymin = 20, ymax = 150,
xt = 50, evaluated by :func:`jaxlimb.models.linear_intensity` (the library's model, not a copy).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

import _common

STEM = "fig05_lsf_examples"


def main(out_dir: Path | str = _common.DEFAULT_OUT, quick: bool = False) -> list[Path]:
    """Plot Fig. 5 (LSF examples) and write its caption."""
    plt = _common.setup()
    import jax.numpy as jnp

    from jaxlimb.models import LinearParams, linear_intensity

    out_dir = Path(out_dir)
    ks = np.round(np.arange(0.1, 0.95, 0.1), 2)
    x = np.linspace(0.0, 100.0, 201 if quick else 1001)
    fig, ax = plt.subplots()
    slopes = {}
    for k in ks:
        p = LinearParams(50.0, float(k), 150.0, 20.0)
        f = np.asarray(linear_intensity(p, jnp.asarray(x)))
        ax.plot(x, f, label=f"k = {k:.1f}", color=plt.cm.viridis((k - 0.1) / 0.8))
        slopes[f"{k:.1f}"] = float((20.0 - 150.0) * k / 4.0)  # df/dx at xt: (ymin - ymax) k / 4
    ax.axvline(50.0, color="0.5", lw=0.6, ls=":")
    ax.set(xlabel="x (px)", ylabel="f (grey level)", title="Linear sigmoid functions, Eq. (12)", ylim=(10, 160))
    ax.legend(ncol=3, loc="upper right")
    paths = [_common.save(fig, out_dir, STEM)]
    body = (
        "Linear sigmoid function (LSF), Eq. (12) of Mortari, D'Souza & Zanetti (2016), for "
        f"k = {', '.join(f'{k:.1f}' for k in ks)} with ymin = 20, ymax = 150, xt = 50 -- the parameters of the "
        "paper's Fig. 5 (which prints no numbers beyond these). Every curve passes through (xt, (ymax + ymin)/2) = "
        "(50, 85); its slope there is (ymin - ymax) k / 4, from "
        f"{slopes['0.1']:.2f} (k = 0.1) to {slopes['0.9']:.2f} grey levels/px (k = 0.9). "
        "In jaxlimb's sign convention f -> ymax for x << xt (inside the body) and f -> ymin for x >> xt."
    )
    paths.append(_common.write_caption(out_dir, STEM, "Fig. 5 (2016): LSF examples", body, quick,
                                       {"k": ks.tolist(), "slope_at_xt": slopes}))
    return paths


if __name__ == "__main__":
    _common.cli(main, STEM)
