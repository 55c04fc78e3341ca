"""The albedo field's Cramér--Rao bound: how well can *any* estimator place the limb of a Moon whose albedo varies?

For each Moon scene of ``benchmarks/albedo_invariance.py`` (the same renders, uniform albedo, noise draw 0),
``locate``'s answer gives the profile (centre, radius, PSF, levels, phase) and its pixels; the bound is
:func:`jaxlimb.analysis.crlb.albedo_field_crlb` there, with the noise variance that makes its ``tau = 0`` value
equal to ``locate``'s own Cramér--Rao bound, and the albedo prior of the ``spots`` family: ``--maps`` draws of
:class:`jaxlimb.render.independent.surface.SpotsMap`, whose relative albedo's covariance over great-circle angle
gives ``tau`` (at 0) and ``ell`` (a squared exponential fitted within 20 deg).  Reported per scene: the white bound,
the albedo-field bound, and the scatter the albedo alone must add at best (``sqrt(field^2 - white^2)``) against the
noise-only bound: the albedo-invariance target (albedo spread <= 1.2 x noise spread) needs that ratio <= 0.66.

Run::

    python benchmarks/albedo_bound.py --cache build/albedo_renders       # -> results/albedo_bound.json
"""

from __future__ import annotations

import argparse
import math
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

from _common import environment, save  # noqa: E402
from albedo_invariance import SCENES, scene_case  # noqa: E402


def family_prior(n_maps: int, seed: int = 1) -> tuple[float, float]:
    """``(tau, ell_rad)`` of the spots family: its relative albedo's covariance over great-circle angle, sampled on
    ``n_maps`` randomly rotated draws, a squared exponential fitted within 20 deg."""
    from jaxlimb.render.independent.surface import SpotsMap

    rng = np.random.default_rng(seed)
    g = np.radians(np.arange(0.0, 21.0, 1.0))
    pts = np.stack([np.cos(g), np.sin(g), np.zeros_like(g)], 1)
    vals = np.array([SpotsMap.draw(rng)(pts @ np.linalg.qr(rng.normal(size=(3, 3)))[0].T) for _ in range(n_maps)])
    a = vals / vals.mean() - 1.0
    cov = (a[:, :1] * a).mean(0) - a[:, :1].mean() * a.mean(0)
    rho = np.clip(cov / cov[0], 1e-6, 1.0)
    ell = math.sqrt(float(np.sum(g[1:] ** 4) / np.sum(-2.0 * np.log(rho[1:]) * g[1:] ** 2)))  # LS of -2 ln rho = g^2/ell^2
    return math.sqrt(float(cov[0])), ell


def scene_bound(case, tau: float, ell: float) -> dict:  # type: ignore[no-untyped-def]
    """The white and albedo-field bounds of the centre at ``locate``'s answer on ``case``."""
    from jaxlimb.analysis.crlb import albedo_field_crlb
    from jaxlimb.geometry.hints import Hints
    from jaxlimb.geometry.sphere_image import sphere_from_ellipse_center
    from jaxlimb.imaging.prior import sun_direction_image
    from jaxlimb.models import LimbProfileParams
    from jaxlimb.pipeline import locate

    m = locate(case.image, case.camera, Hints.from_dict(case.hints))
    prof, cam = m.extras["profile"], case.camera
    rc = np.asarray(m.selected_pixels_rc, float)
    sph = sphere_from_ellipse_center(cam.focal_px, cam.principal_point_rc, tuple(m.center_rc), float(m.radius_px))
    sun = sun_direction_image(case.hints["sun_dir_camera"], cam, tuple(m.center_rc), min_norm=0.0)
    p = LimbProfileParams(r0=float(m.center_rc[0]), c0=float(m.center_rc[1]), a=float(sph.a), theta=float(sph.angle_rad),
                          rho=float(sph.rho), sigma=float(prof["psf_sigma_px"]), amp=float(prof["amp"]),
                          ymin=float(m.ymin), sun_r=sun[0], sun_c=sun[1], phase=math.radians(prof["phase_deg"]),
                          inv_f=1.0 / cam.focal_px, L=float(prof["L"]),
                          L_slope=float(prof["L_slope"]), L_ref=float(prof["L_ref"]))
    unit = albedo_field_crlb(rc, p, np.ones(len(rc)), 0.0, ell)
    var = (float(m.crlb["center_r"]) / unit.std["r0"]) ** 2  # the noise locate's own bound assumes
    white, field = albedo_field_crlb(rc, p, np.full(len(rc), var), 0.0, ell), albedo_field_crlb(rc, p, np.full(len(rc), var), tau, ell)
    w = math.hypot(white.std["r0"], white.std["c0"]) / math.sqrt(2.0)
    f = math.hypot(field.std["r0"], field.std["c0"]) / math.sqrt(2.0)
    return {"white_px": w, "field_px": f, "field_rc_px": [field.std["r0"], field.std["c0"]],
            "albedo_part_px": math.sqrt(max(f * f - w * w, 0.0)), "ratio": math.sqrt(max(f * f - w * w, 0.0)) / w,
            "pixels": int(len(rc)), "radius_px": float(m.radius_px)}


def main(argv: list[str] | None = None) -> dict:
    import jax

    jax.config.update("jax_enable_x64", True)
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--maps", type=int, default=400, help="SpotsMap draws for the family's prior (default 400)")
    ap.add_argument("--cache", type=Path, default=None, help="directory keeping the renders (albedo_invariance's)")
    args = ap.parse_args(argv)
    tau, ell = family_prior(args.maps)
    out = {"environment": environment(), "tau": tau, "ell_deg": math.degrees(ell), "scenes": []}
    for body, range_km, phase_deg in SCENES:
        if body != "moon":
            continue
        case = scene_case(args.cache, body, range_km, phase_deg, "uniform", 0, 0)
        row = {"body": body, "range_km": range_km, "phase_deg": phase_deg, **scene_bound(case, tau, ell)}
        out["scenes"].append(row)
        print(f"moon {range_km:>9.0f} km {phase_deg:>4.0f} deg (radius {row['radius_px']:.1f} px): white {row['white_px']:.4f} px,"
              f" albedo field {row['field_px']:.4f} px, albedo part / white {row['ratio']:.2f}")
    print(f"spots family prior: tau {tau:.3f}, ell {math.degrees(ell):.1f} deg")
    save("albedo_bound", out)
    return out


if __name__ == "__main__":
    main()
