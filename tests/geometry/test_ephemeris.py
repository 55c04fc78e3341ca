"""Offline DE421 ephemerides: values, frames, span and missing-file errors, no network."""

import datetime as dt
import socket

import numpy as np
import pytest

from jaxlimb.errors import EphemerisError
from jaxlimb.geometry import ephemeris as eph

EPOCH = "2013-03-06T11:08:10Z"  # the Moon image of Mortari et al. §VI (06:08:10 CDT)


@pytest.fixture
def no_network(monkeypatch):
    def _refuse(*a, **k):
        raise AssertionError("network access attempted")

    monkeypatch.setattr(socket.socket, "connect", _refuse)
    monkeypatch.setattr(socket, "create_connection", _refuse)
    eph.clear_cache()  # force a fresh load under the guard
    yield


def test_loads_offline_and_caches(no_network):
    e1 = eph.load_ephemeris()
    e2 = eph.load_ephemeris()
    assert e1 is e2  # cached
    r = eph.moon_position(EPOCH)
    assert 356_000 < np.linalg.norm(r) < 407_000
    assert e1.start_jd_tdb == 2414864.5 and e1.end_jd_tdb == 2471184.5
    assert e1.span_iso() == ("1899-07-29", "2053-10-09")


def test_epoch_forms_agree():
    t_iso = eph.moon_position("2013-03-06T11:08:10+00:00")
    t_z = eph.moon_position(EPOCH)
    t_dt = eph.moon_position(dt.datetime(2013, 3, 6, 11, 8, 10))  # naive = UTC
    cdt = dt.timezone(dt.timedelta(hours=-5))
    t_aware = eph.moon_position(dt.datetime(2013, 3, 6, 6, 8, 10, tzinfo=cdt))
    jd = eph.epoch_to_jd_tdb(EPOCH)
    t_jd = eph.moon_position(jd)
    for v in (t_iso, t_dt, t_aware, t_jd):
        np.testing.assert_allclose(v, t_z, atol=1e-6)
    # TDB - UTC in 2013 = 35 leap s + 32.184 s + periodic (< 2 ms)
    jd_utc = 2456357.5 + (11 * 3600 + 8 * 60 + 10) / 86400.0
    assert abs((jd - jd_utc) * 86400.0 - 67.184) < 0.002


def test_relative_positions_are_consistent():
    p = eph.load_ephemeris().positions(EPOCH, center="earth")
    np.testing.assert_allclose(p["earth"], 0.0, atol=1e-6)
    sun_from_moon = eph.sun_position(EPOCH, center="moon")
    np.testing.assert_allclose(sun_from_moon, p["sun"] - p["moon"], rtol=0, atol=1e-4)
    np.testing.assert_allclose(eph.earth_position(EPOCH), -p["moon"], atol=1e-6)
    au = np.linalg.norm(p["sun"]) / 149_597_870.7
    assert 0.98 < au < 1.02
    # astrometric (BCRS light time): the Moon's *barycentric* motion (~30 km/s) over ~1.28 s
    lt = eph.moon_position(EPOCH, light_time=True)
    d = np.linalg.norm(lt - p["moon"])
    assert 30.0 < d < 45.0, d


def test_against_astropy_builtin_ephemeris():
    """Independent check: astropy's analytic builtin ephemeris (ERFA epv00 + Meeus moon98)."""
    from astropy.time import Time
    from astropy.utils import iers

    from astropy.coordinates import get_body_barycentric

    with iers.conf.set_temp("auto_download", False):
        for epoch in ("2013-03-06T11:08:10Z", "1969-07-20T20:17:00Z", "2040-01-01T00:00:00Z"):
            jd = eph.epoch_to_jd_tdb(epoch)
            t = Time(jd, format="jd", scale="tdb")  # TDB directly: no leap-second table needed
            moon = (get_body_barycentric("moon", t, ephemeris="builtin") - get_body_barycentric("earth", t, ephemeris="builtin")).xyz.to_value("km")
            sun = (get_body_barycentric("sun", t, ephemeris="builtin") - get_body_barycentric("earth", t, ephemeris="builtin")).xyz.to_value("km")
            assert np.linalg.norm(eph.moon_position(jd) - moon) < 50.0  # moon98 is good to ~10"
            ang = np.arccos(np.clip(eph.sun_position(jd) @ sun / np.linalg.norm(sun) / np.linalg.norm(eph.sun_position(jd)), -1, 1))
            assert np.degrees(ang) * 3600 < 30.0


@pytest.mark.parametrize("epoch", ["1899-07-28T00:00:00Z", "2053-10-10T00:00:00Z", 2414864.0, 2471185.0, "1700-01-01"])
def test_epoch_outside_span(epoch):
    with pytest.raises(EphemerisError, match="outside the span of de421.bsp: 1899-07-29 to 2053-10-09"):
        eph.moon_position(epoch)


def test_edges_inside_span():
    e = eph.load_ephemeris()
    for jd in (e.start_jd_tdb, e.end_jd_tdb):
        assert np.linalg.norm(eph.moon_position(jd)) > 3e5


@pytest.mark.parametrize("bad", ["not a date", True, float("nan"), [2013, 3, 6]])
def test_bad_epoch(bad):
    with pytest.raises(EphemerisError, match="epoch"):
        eph.moon_position(bad)


def test_unknown_body():
    with pytest.raises(EphemerisError, match="unknown body 'mars'"):
        eph.body_position("mars", EPOCH)


def test_missing_file_in_empty_dir(tmp_path, no_network):
    with pytest.raises(EphemerisError, match="not found; jaxlimb never downloads"):
        eph.load_ephemeris(tmp_path)
    with pytest.raises(EphemerisError, match="not found"):
        eph.moon_position(EPOCH, path=tmp_path)
    assert list(tmp_path.iterdir()) == []  # nothing was written (no download attempt)


def test_corrupt_file(tmp_path):
    f = tmp_path / "de421.bsp"
    f.write_bytes(b"not an spk file" * 10)
    with pytest.raises(EphemerisError, match="cannot read ephemeris file"):
        eph.load_ephemeris(tmp_path)
