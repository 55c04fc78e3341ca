"""Registration on surfaces the model does not assume: the smooth-shading column of the fitted mix,
the opposition-surge columns, the IoU band, the second round of template hypotheses."""

from __future__ import annotations

import math
from types import SimpleNamespace

import numpy as np
import pytest

from jaxlimb.errors import ConfigError, MatchError
from jaxlimb.geometry.camera import Camera
from jaxlimb.irregular import locate as locate_mod
from jaxlimb.irregular.model_render import MIX_LAWS, MixedLaw, _basis, render_window
from jaxlimb.irregular.register.checks import overlap
from jaxlimb.irregular.register.design import surge_fields
from jaxlimb.render.mesh import shade

CAM = Camera(focal_length_mm=30.0, pixel_pitch_mm=0.02, rows=400, cols=400)


def _pose(mesh, size_px=150.0, phase_deg=60.0):
    from scipy.spatial.transform import Rotation

    D = 2.0 * mesh.max_radius * CAM.focal_px / size_px
    t = np.array([0.03 * D, -0.02 * D, D])
    u = -t / np.linalg.norm(t)
    a = np.cross(u, [0.0, 1.0, 0.0])
    a /= np.linalg.norm(a)
    sun = u * math.cos(math.radians(phase_deg)) + a * math.sin(math.radians(phase_deg))
    P = np.array(CAM.principal_point_rc) + CAM.focal_px * t[[1, 0]] / t[2]
    rad = CAM.focal_px * mesh.max_radius / (t[2] - mesh.max_radius)
    lo, hi = np.floor(P - rad - 8).astype(int), np.ceil(P + rad + 8).astype(int)
    return Rotation.from_rotvec([0.4, -0.7, 0.2]).as_matrix(), t, sun, lo, hi


def test_mixed_law_is_the_linear_mix_of_the_laws():
    rng = np.random.default_rng(0)
    mu0, mu = rng.uniform(-0.2, 1.0, 500), rng.uniform(0.01, 1.0, 500)
    w = (0.3, -0.2)
    want = shade(mu0, mu, "lommel-seeliger") * (1.0 - sum(w)) + sum(wi * _basis(mu0, mu, law) for wi, law in zip(w, MIX_LAWS))
    assert np.allclose(MixedLaw("lommel-seeliger", w)(mu0, mu), want)
    assert np.allclose(MixedLaw("lommel-seeliger")(mu0, mu), shade(mu0, mu, "lommel-seeliger"))


def test_smooth_column_is_that_of_the_fitted_mix(lumpy):
    """With the mix at pure Lambert the smooth-minus-flat column is the Lambert model's own (it used to be the
    Lommel-Seeliger one whatever the mix: a Lambert Thebe 0.51 px off, ray-traced, 60 deg)."""
    R, t, sun, lo, hi = _pose(lumpy)
    n = len(MIX_LAWS) + 1
    lam = np.zeros(n)
    lam[MIX_LAWS.index("lambert")] = 1.0
    via_mix = render_window(lumpy, CAM, R, t, sun, lo, hi, 4, "lommel-seeliger", mix=lam).dM_dmix[-1]
    own = render_window(lumpy, CAM, R, t, sun, lo, hi, 4, "lambert", mix=np.zeros(n)).dM_dmix[-1]
    ls = render_window(lumpy, CAM, R, t, sun, lo, hi, 4, "lommel-seeliger", mix=np.zeros(n)).dM_dmix[-1]
    assert np.abs(own).max() > 0.01
    assert np.abs(via_mix - own).max() < 1e-6 * max(1.0, np.abs(own).max())
    assert np.abs(ls - own).max() > 0.05 * np.abs(own).max()  # the two laws' columns differ


def test_surge_fields_zero_at_the_center_and_falling_with_phase():
    cam = Camera(focal_length_mm=16.0, pixel_pitch_mm=0.02, rows=200, cols=200)
    Pk = np.array([90.0, 110.0])
    ray = np.array([(Pk[1] - cam.principal_point_rc[1]) / cam.focal_px, (Pk[0] - cam.principal_point_rc[0]) / cam.focal_px, 1.0])
    sun = -ray / np.linalg.norm(ray)  # zero phase at the centre
    lo, hi = np.array([40, 60]), np.array([140, 160])
    f03, f10 = surge_fields(cam, lo, hi, Pk, sun, (0.03, 0.1))
    i, j = int(Pk[0] - lo[0]), int(Pk[1] - lo[1])
    assert abs(f03[i, j]) < 1e-6 and abs(f10[i, j]) < 1e-6
    assert f03[i, j + 40] < f03[i, j + 10] < 0.0  # further from zero phase: less surge
    # the formula at one pixel: B(g) / B0 = 1 / (1 + tan(g/2) / h), minus its value at the centre
    r = np.array([(lo[1] + j + 40 - cam.principal_point_rc[1]) / cam.focal_px, (lo[0] + i - cam.principal_point_rc[0]) / cam.focal_px, 1.0])
    g = math.acos(-float(sun @ r) / float(np.linalg.norm(r)))
    assert f10[i, j + 40] == pytest.approx(1.0 / (1.0 + math.tan(g / 2) / 0.1) - 1.0, rel=1e-9)
    # at 60 deg phase the narrow surge hardly varies across the window: left out, the wide one kept
    a = np.cross(sun, [0.0, 1.0, 0.0])
    high = surge_fields(cam, lo, hi, Pk, sun * 0.5 + a / np.linalg.norm(a) * 0.866, (0.03, 0.1))
    assert len(surge_fields(cam, lo, hi, Pk, sun * 0.5 + a / np.linalg.norm(a) * 0.866, (0.03, 0.1), 0.04)) == sum(
        float(f.max() - f.min()) >= 0.04 for f in high) < 2


def test_overlap_leaves_out_pixels_within_the_misfit_of_the_threshold():
    """A noiseless (8-bit, MAD 0) background: model pixels just across the threshold flip the IoU unless the
    accepted misfit band leaves them out."""
    yy, xx = np.mgrid[0:60, 0:60]
    r = np.hypot(yy - 30, xx - 30)
    obs = r < 20
    model = np.clip(30.0 - 1.2 * r, 0.0, None)  # threshold 6 at r = 20; a dim, gently sloping edge
    model = model + np.where((r > 14) & (r < 26), 1.5 * np.sin(xx / 2.0), 0.0)  # a misfit of +-1.5 DN near the edge
    tight = overlap(obs, model.ravel(), 6.0, 0.0)
    banded = overlap(obs, model.ravel(), 6.0, 0.0, misfit=2.0)
    assert tight < banded and banded > 0.95


def test_next_hypotheses_are_tried_only_when_none_explains_the_frame(monkeypatch):
    hyps = [SimpleNamespace(i=i) for i in range(30)]
    calls = []
    monkeypatch.setattr(locate_mod, "phase_candidates", lambda *a, **k: hyps)
    monkeypatch.setattr(locate_mod, "lit_figure", lambda img: (np.ones((4, 4), np.uint8), 0.5))
    monkeypatch.setattr(locate_mod, "figure_center", lambda m: np.zeros(2))
    monkeypatch.setattr(locate_mod, "_sun_image_direction", lambda *a: None)

    def register(frame, db, hs, options):
        calls.append([h.i for h in hs])
        return [], [MatchError("no")]

    monkeypatch.setattr(locate_mod, "register_hypotheses", register)
    opts = locate_mod.LosOptions(n_verify=10, n_retry=20)
    with pytest.raises(MatchError, match="none of the 30 template hypotheses"):
        locate_mod.locate_los(np.zeros((4, 4)), SimpleNamespace(mesh=None), CAM, None, options=opts)
    assert calls == [list(range(10)), list(range(10, 30))]
    calls.clear()
    monkeypatch.setattr(locate_mod, "register_hypotheses", lambda *a: (calls.append(1) or ["a fit"], []))
    monkeypatch.setattr(locate_mod, "_choose", lambda fits, errors, n_tried, options: (fits, n_tried))
    assert locate_mod.locate_los(np.zeros((4, 4)), SimpleNamespace(mesh=None), CAM, None, options=opts) == (["a fit"], 10)
    assert calls == [1]  # a fit in the first round: no second round


def test_exact_coverage_removes_the_painter_bias_at_90_deg(lumpy):
    """A frame rendered with exact facet coverage (8x8 sub-pixels) at 90 deg phase: the model rendered with the
    painter's fill (every nearer facet dilated over its neighbours by half a sub-pixel) is registered off along
    the Sun direction, three times as far as with exact coverage (the default)."""
    import dataclasses

    from jaxlimb.irregular.register import RegisterOptions, register_known_attitude
    from jaxlimb.render.mesh import MeshRenderOptions, render_mesh

    R, t, sun, _, _ = _pose(lumpy, size_px=150.0, phase_deg=90.0)
    frame = render_mesh(lumpy.vertices, lumpy.faces, CAM, R, t, sun, MeshRenderOptions(supersample=8, albedo=200.0, background=10.0))
    err = {}
    for exact in (True, False):
        opts = dataclasses.replace(RegisterOptions(), exact_coverage=exact)
        res = register_known_attitude(frame.image, lumpy, CAM, R, sun, float(np.linalg.norm(t)) * 1.05, opts)
        err[exact] = float(np.linalg.norm(res.center_rc - frame.center_rc))
    assert err[True] < 0.03 and err[False] > 2.0 * err[True], err  # 0.020 and 0.062 px (2026-11-26)


def test_minnaert_body_at_zero_phase_needs_the_third_law():
    """A ray-traced Minnaert body (``k = 0.81``, cratered) at zero phase, attitude known: there ``mu0 = mu``, the
    two-law mix spans only ``1`` and ``mu`` while the surface shows ``mu^0.62``; Minnaert 3/4 in the mix
    (``RegisterOptions.mix_laws = 3``) brings 0.26 px to 0.04 px."""
    pytest.importorskip("embreex")
    from scipy.spatial.transform import Rotation

    from jaxlimb.irregular.mesh import validate_mesh
    from jaxlimb.irregular.register import RegisterOptions, register_known_attitude
    from jaxlimb.render.independent import Photometry, Pinhole, Psf, Reflectance
    from jaxlimb.render.independent.mesh_rays import MeshScene, cratered_body, render_mesh_frame

    body = validate_mesh(*cratered_body(101, subdivisions=4), source="cratered")
    R = Rotation.from_rotvec([0.3, -0.8, 0.4]).as_matrix()
    D = 2.0 * body.max_radius * CAM.focal_px / 250.0
    t = np.array([10.0 * D / CAM.focal_px, -6.0 * D / CAM.focal_px, D])
    sun = -t / np.linalg.norm(t)
    sc = MeshScene(body.vertices, body.faces, R, t, sun, Photometry(law=Reflectance.MINNAERT, minnaert_k=0.81), psf=Psf(sigma=0.75))
    img, truth = render_mesh_frame(sc, Pinhole.from_camera(CAM), np.random.default_rng(0))
    err = {n: float(np.linalg.norm(register_known_attitude(img, body, CAM, R, sun, options=RegisterOptions(mix_laws=n)).center_rc - truth))
           for n in (2, 3)}
    assert RegisterOptions().mix_laws == 3
    assert err[3] < 0.1
    assert err[2] > 0.15  # the two-law mix of before


def test_mix_laws_count_checked():
    from jaxlimb.irregular.model_render import mix_laws
    from jaxlimb.irregular.register import RegisterOptions

    assert mix_laws(2) == ("lambert", "minnaert-half")
    assert len(mix_laws(len(MIX_LAWS))) == 3
    with pytest.raises(ConfigError, match=r"mix_laws must be an integer in \[0, 3\], got 4"):
        mix_laws(len(MIX_LAWS) + 1)
    with pytest.raises(ConfigError, match="mix_laws"):  # refused when the options are made, not mid-registration
        RegisterOptions(mix_laws=-1)
