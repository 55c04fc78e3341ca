"""Fig. 19 of the Aerospace 2015 Moon paper: image-processing Monte Carlo, partially illuminated Moon.

1000 frames = one rendered gibbous Moon (phase 60 deg) + N(0, 10^2) grey levels, each through
:func:`jaxlimb.pipeline.locate`; histograms of the radius/centre errors, centre scatter,
iterations (shared code: ``_moon_mc.py``).
"""

from __future__ import annotations

from pathlib import Path

import _common
import _moon_mc

STEM = "fig19_partial_moon_mc"
PAPER = ("real partially illuminated Moon (6 March 2013, f = 100 mm), 1000 runs with sigma = 10 grey levels: "
         "radius and centre unbiased, maximum error of the order of 0.2 px, about eight least-squares iterations on "
         "average, elongated (elliptical) centre-error distribution because only one side of the limb is used.")


def main(out_dir: Path | str = _common.DEFAULT_OUT, quick: bool = False) -> list[Path]:
    """Run the partial-Moon Monte Carlo (Fig. 19) and write the figure and caption."""
    return _moon_mc.run(STEM, "Fig. 19 (2015): partial illumination, sigma = 10 DN", 60.0, PAPER, Path(out_dir), quick)


if __name__ == "__main__":
    _common.cli(main, STEM)
