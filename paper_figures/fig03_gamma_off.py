"""Fig. 3 of Mortari, D'Souza & Zanetti (2016): the Earth centre-offset angle gamma_off surface.

gamma_off (arcsec) over latitude 0-90 deg x distance GEO -> lunar, from
:func:`jaxlimb.geometry.earth.gamma_off_surface` (WGS-84, no atmosphere), drawn as filled
contours; the observed axis ratio rho (Eq. 9) on the same grid is written to the JSON.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

import _common

STEM = "fig03_gamma_off"


def main(out_dir: Path | str = _common.DEFAULT_OUT, quick: bool = False) -> list[Path]:
    """Compute and plot the gamma_off surface (Fig. 3) and write its caption."""
    plt = _common.setup()
    from jaxlimb.geometry.earth import GEO_RADIUS_KM, MOON_DISTANCE_KM, gamma_off_surface

    out_dir = Path(out_dir)
    lat = np.linspace(0.0, 90.0, 10 if quick else 46)
    dist = np.linspace(GEO_RADIUS_KM, MOON_DISTANCE_KM, 8 if quick else 40)
    s = gamma_off_surface(lat, dist)
    g = s.gamma_off_arcsec
    fig = plt.figure(figsize=(5.4, 3.6))
    ax = fig.add_subplot(projection="3d")
    L, D = np.meshgrid(s.latitudes_deg, s.distances_km / 1e3, indexing="ij")
    ax.plot_surface(D, L, g, cmap="viridis", linewidth=0, antialiased=True)
    ax.set(xlabel="distance (10$^3$ km)", ylabel="latitude (deg)", zlabel=r"$\gamma_{off}$ (arcsec)",
           title=r"Earth centre offset $\gamma_{off}$ (WGS-84)")
    paths = [_common.save(fig, out_dir, STEM)]
    i, j = np.unravel_index(np.argmax(g), g.shape)
    body = (
        f"gamma_off (arcsec), the angle between the direction of the observed limb-ellipse centre and the "
        "Earth centre, over geocentric latitude 0-90 deg and distance GEO ({GEO_RADIUS_KM:.0f} km) to the Moon ({MOON_DISTANCE_KM:.0f} km), "
        f"on a {lat.size} x {dist.size} grid (WGS-84, no atmosphere). Maximum {g[i, j]:.2f} arcsec at latitude "
        f"{s.latitudes_deg[i]:.1f} deg, {s.distances_km[j]:.0f} km; zero at the equator ({np.abs(g[0]).max():.2e}) "
        f"and at the pole ({np.abs(g[-1]).max():.2e}); it falls with distance (at latitude {s.latitudes_deg[i]:.0f} deg: "
        f"{g[i, 0]:.2f} arcsec at GEO, {g[i, -1]:.3f} arcsec at lunar distance). The paper's Fig. 3 shows the same "
        "surface without printing values; its text says the offset is negative for southern latitudes (odd symmetry)."
    )
    paths.append(_common.write_caption(out_dir, STEM, "Fig. 3 (2016): gamma_off surface", body, quick, {
        "latitudes_deg": s.latitudes_deg.tolist(), "distances_km": s.distances_km.tolist(),
        "gamma_off_arcsec": g.tolist(), "rho": s.rho.tolist(), "max_arcsec": float(g[i, j]),
    }))
    return paths


if __name__ == "__main__":
    _common.cli(main, STEM)
