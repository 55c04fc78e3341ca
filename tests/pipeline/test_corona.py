"""The Sun in the extreme ultraviolet: the corona-over-an-opaque-disc limb (:mod:`jaxlimb.models.corona`) against
brute-force quadrature, the choice of it by the disc's own profile, the real SDO/AIA 171 A frame and an independent
render (:mod:`jaxlimb.render.independent.corona`)."""

from __future__ import annotations

import math

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from scipy.integrate import quad
from scipy.special import erfcx

from jaxlimb._data import shared_data_dir
from jaxlimb.errors import ConfigError
from jaxlimb.geometry.hints import Hints
from jaxlimb.imaging.io import load_image
from jaxlimb.imaging.sdo import AIA_171_FITS, sun_truth_from_header
from jaxlimb.models.corona import CoronaParams, corona_intensity
from jaxlimb.pipeline import LocateOptions, locate
from jaxlimb.pipeline.sphere.corona import limb_brightened
from jaxlimb.render.independent.corona import euv_sun
from jaxlimb.pipeline import covariance_block

jax.config.update("jax_enable_x64", True)


def _center_nees(m, truth_rc) -> tuple[np.ndarray, float]:
    cv = m.covariance
    P = covariance_block(cv)
    e = np.subtract(m.center_rc, truth_rc)
    return e, float(e @ np.linalg.solve(P, e))


@pytest.mark.parametrize("sigma, h", [(0.0, 0.4), (0.7, 2.0), (1.8, 6.0)])
def test_profile_is_the_blurred_column(sigma, h):
    """The model at distances across the limb equals the column of the module docstring (a jump by 2 at the limb,
    ``erfcx`` on the disc) convolved with the Gaussian by adaptive quadrature, to 1e-7 of the corona's level."""
    a, amp, disc = 80.0, 1.0, 0.3
    se = math.sqrt(sigma * sigma + 1.0 / 12.0)

    def column(t):
        return math.exp(-t / h) if t >= 0 else 0.5 * erfcx(math.sqrt(-t / h)) + disc / amp

    xs = np.linspace(-10.0, 10.0, 17)
    ref = [quad(lambda t: column(t) * math.exp(-0.5 * ((x - t) / se) ** 2) / (se * math.sqrt(2 * math.pi)),
                x - 9 * se, x + 9 * se, points=[0.0], limit=400)[0] for x in xs]
    p = CoronaParams(0.0, 0.0, a, sigma, math.log(h), amp, disc, 0.0)
    got = np.asarray(corona_intensity(p, jnp.stack([jnp.zeros(xs.size), a + jnp.asarray(xs)], -1)))
    assert np.max(np.abs(got - np.asarray(ref))) < 1e-7


def _aia():
    img, info = load_image(shared_data_dir() / "sun" / AIA_171_FITS)
    return img, sun_truth_from_header(info.header)


def test_aia_171_is_located_by_its_corona():
    """The real EUV Sun (SDO/AIA 171 A, 128 px, radius 50.66 px): answered with the corona's limb, its centre within
    0.2 px of the header's WCS and of its own sigma (3 sigma), the occulting limb 0-1 px above the photosphere."""
    img, truth = _aia()
    assert limb_brightened(img, truth.center_rc, truth.radius_px)
    m = locate(img, None, Hints(body="sun"))
    assert m.extras["profile"]["model"] == "corona"
    e, nees = _center_nees(m, truth.center_rc)
    assert math.hypot(*e) < 0.2 and nees < 3.0**2, (e, nees)
    assert 0.0 < m.radius_px - truth.radius_px < 1.0


def test_independent_euv_render_is_located():
    """A corona the model does not assume (line-of-sight integral of three hydrostatic components, active regions,
    a scattered-light wing): the centre within 0.2 px and within 3 sigma."""
    f = euv_sun(np.random.default_rng(0), 50.0, 130)
    m = locate(f.image, None, Hints(body="sun"))
    assert m.extras["profile"]["model"] == "corona"
    e, nees = _center_nees(m, f.center_rc)
    assert math.hypot(*e) < 0.2 and nees < 3.0**2, (e, nees)


def test_a_limb_darkened_disc_is_not_limb_brightened():
    """An opaque limb-darkened disc peaks at its centre: the disc strategy keeps the limb-darkened profile."""
    rr, cc = np.indices((200, 200))
    q = np.hypot(rr - 99.3, cc - 100.6) / 80.0
    mu = np.sqrt(np.clip(1.0 - q * q, 0.0, None))
    img = np.where(q < 1.0, 1.0 - 0.6 * (1.0 - mu), 0.0) + np.random.default_rng(1).normal(0, 0.01, rr.shape)
    assert not limb_brightened(img, (99.3, 100.6), 80.0)
    assert limb_brightened(np.where(q < 1.0, 0.3 + 0.7 * q**8, 0.0), (99.3, 100.6), 80.0)


def test_corona_profile_is_the_discs():
    """``profile="corona"`` belongs to the disc strategy: asked of another strategy it is a configuration error."""
    img, _ = _aia()
    with pytest.raises(ConfigError, match="disc strategy"):
        locate(img, None, Hints(body="moon"), LocateOptions(profile="corona", shape="sphere"))
    with pytest.raises(ConfigError, match="circle"):
        LocateOptions(profile="corona", model="ellipse")


def test_aia_171_from_the_command_line(capsys):
    """``jaxlimb locate aia_171_level1.fits --body sun --json``: exit 0, the corona's profile in the answer."""
    import json

    from jaxlimb.cli import main

    code = main(["locate", str(shared_data_dir() / "sun" / AIA_171_FITS), "--body", "sun", "--json"])
    out = json.loads(capsys.readouterr().out)
    assert code == 0 and out["status"] == "ok", out
    assert out["extras"]["profile"]["model"] == "corona" and "jump_limit_px" not in out["extras"]  # no limit: None


def test_euv_disc_cut_by_the_frame_border():
    """A disc cut by the frame's border (radius 40 px in 86 px): its annulus is taken all round (a ring has no lit
    step for the sigmoid's bins to find, and a star no lit side: this frame was refused as a crescent 'too thin')."""
    f = euv_sun(np.random.default_rng(1), 40.0, 86)
    assert min(f.center_rc) < 40.0  # the disc leaves the frame
    m = locate(f.image, None, Hints(body="sun"))
    e, nees = _center_nees(m, f.center_rc)
    assert m.extras["profile"]["model"] == "corona" and math.hypot(*e) < 0.2 and nees < 3.0**2, (e, nees)
