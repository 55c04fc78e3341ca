"""Fig. 20 of the Aerospace 2015 Moon paper: image-processing Monte Carlo, fully illuminated Moon.

1000 frames = one rendered full Moon (phase 0) + N(0, 10^2) grey levels, each through
:func:`jaxlimb.pipeline.locate`; histograms of the radius/centre errors, centre scatter,
iterations (shared code: ``_moon_mc.py``).
"""

from __future__ import annotations

from pathlib import Path

import _common
import _moon_mc

STEM = "fig20_full_moon_mc"
PAPER = ("real fully illuminated Moon (25 February 2013, f = 105 mm), 1000 runs with sigma = 10 grey levels: "
         "radius and centre unbiased, maximum error of the order of 0.01 px (an order of magnitude better than the "
         "partial case, the limb being used all around), about three iterations on average, round centre scatter.")


def main(out_dir: Path | str = _common.DEFAULT_OUT, quick: bool = False) -> list[Path]:
    """Run the full-Moon Monte Carlo (Fig. 20) and write the figure and caption."""
    return _moon_mc.run(STEM, "Fig. 20 (2015): full illumination, sigma = 10 DN", 0.0, PAPER, Path(out_dir), quick)


if __name__ == "__main__":
    _common.cli(main, STEM)
