"""Offline Moon / Sun / Earth ephemerides from JPL DE421 (skyfield + skyfield-data).

Nothing is downloaded, ever:

* the kernel is the ``de421.bsp`` shipped by the ``skyfield-data`` package
  (``skyfield_data.get_skyfield_data_path()``), or a ``.bsp`` in a directory you pass;
  the file's existence is checked *before* skyfield's :class:`~skyfield.iokit.Loader`
  (created with ``expire=False``) is asked to open it, because a Loader asked for a missing
  file would try to download it;
* time scales use skyfield's built-in leap-second and Delta-T tables
  (``Loader.timescale(builtin=True)``), not the IERS files.

Positions are **geometric** (no light-time, no aberration) unless ``light_time=True``:
then the *astrometric* BCRS position (target at the emission time, skyfield ``observe``).
Beware: for the Moon seen from the Earth that differs from the geometric position by
~38 km, the Moon's *barycentric* motion (~30 km/s) during the 1.28 s light time; the stellar
aberration of a camera moving with the Earth almost cancels it in the apparent direction.
For navigation with an attitude from a star tracker (apparent star directions) the
geometric relative position is the consistent choice to ~1 km at the Moon.
Frame: ICRF (the J2000 axes to ~20 mas).
Units: km.  DE421 covers JD(TDB) 2414864.5 - 2471184.5 (1899-07-29 to 2053-10-09); an epoch
outside raises :class:`~jaxlimb.errors.EphemerisError` (skyfield itself silently
extrapolates the Chebyshev polynomials there).

Reference: Folkner, Williams & Boggs (2009), "The Planetary and Lunar Ephemeris DE 421",
IPN Progress Report 42-178.
"""

from __future__ import annotations

import atexit
import datetime as _dt
import os
import warnings
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..errors import EphemerisError

BODIES = ("moon", "sun", "earth", "earth barycenter")
DEFAULT_KERNEL = "de421.bsp"

Epoch = str | _dt.datetime | float | int


def default_data_dir() -> Path:
    """Directory of the ephemeris shipped with ``skyfield-data``."""
    try:
        with warnings.catch_warnings():
            # skyfield-data warns that its IERS file expired; we never use that file
            warnings.simplefilter("ignore", RuntimeWarning)
            from skyfield_data import get_skyfield_data_path

            return Path(get_skyfield_data_path())
    except ImportError as e:  # pragma: no cover - dependency missing
        raise EphemerisError(f"package skyfield-data is not installed ({e}); it ships the DE421 kernel") from None


@dataclass(frozen=True)
class Ephemeris:
    """A loaded planetary kernel with its time scale and valid span.

    Use :func:`load_ephemeris` (cached) rather than constructing it.
    """

    path: Path
    kernel: object
    timescale: object
    start_jd_tdb: float
    end_jd_tdb: float

    # ---------------------------------------------------------------- time
    def span_iso(self) -> tuple[str, str]:
        """Span as ISO TDB dates."""
        a = self.timescale.tdb_jd(self.start_jd_tdb).tdb_strftime("%Y-%m-%d")
        b = self.timescale.tdb_jd(self.end_jd_tdb).tdb_strftime("%Y-%m-%d")
        return a, b

    def time(self, epoch: Epoch):
        """skyfield ``Time`` of an epoch, checked against the kernel span.

        Parameters
        ----------
        epoch
            ISO 8601 string (UTC; a trailing ``Z`` or ``+00:00`` offset accepted, e.g.
            ``"2013-03-06T11:08:10Z"``), a :class:`datetime.datetime` (naive = UTC, aware is
            converted), or a float/int Julian date in **TDB**.
        """
        ts = self.timescale
        if isinstance(epoch, bool):
            raise EphemerisError(f"`epoch` must be an ISO string, datetime or TDB Julian date, got {epoch!r}")
        if isinstance(epoch, (int, float, np.integer, np.floating)):
            jd = float(epoch)
            if not np.isfinite(jd):
                raise EphemerisError(f"`epoch` Julian date must be finite, got {epoch!r}")
            self._check_span(jd, repr(epoch))
            return ts.tdb_jd(jd)
        if isinstance(epoch, str):
            s = epoch.strip()
            if s.endswith("Z"):
                s = s[:-1] + "+00:00"
            try:
                dt = _dt.datetime.fromisoformat(s)
            except ValueError:
                raise EphemerisError(
                    f"`epoch` {epoch!r} is not an ISO 8601 date/time (e.g. '2013-03-06T11:08:10Z')"
                ) from None
            return self.time(dt)
        if isinstance(epoch, _dt.datetime):
            dt = epoch if epoch.tzinfo is not None else epoch.replace(tzinfo=_dt.timezone.utc)
            dt = dt.astimezone(_dt.timezone.utc)
            sec = dt.second + dt.microsecond * 1e-6
            # the span check needs TDB: convert via a first Time object (valid for any year)
            t = ts.utc(dt.year, dt.month, dt.day, dt.hour, dt.minute, sec)
            self._check_span(float(t.tdb), repr(epoch))
            return t
        raise EphemerisError(f"`epoch` must be an ISO string, datetime or TDB Julian date, got {type(epoch).__name__}")

    def _check_span(self, jd_tdb: float, label: str) -> None:
        if not (self.start_jd_tdb <= jd_tdb <= self.end_jd_tdb):
            a, b = self.span_iso()
            raise EphemerisError(
                f"epoch {label} (JD TDB {jd_tdb:.6f}) is outside the span of {self.path.name}: "
                f"{a} to {b} (JD TDB {self.start_jd_tdb} - {self.end_jd_tdb})"
            )

    # ---------------------------------------------------------------- positions
    def _body(self, name: str):
        key = name.lower().strip()
        if key not in BODIES:
            raise EphemerisError(f"unknown body {name!r}; available: {list(BODIES)}")
        return self.kernel[key]

    def position(self, target: str, epoch: Epoch, center: str = "earth", light_time: bool = False) -> np.ndarray:
        """Position (km, ICRF) of ``target`` relative to ``center`` at ``epoch``.

        ``target`` and ``center`` are any of :data:`BODIES`.  With ``light_time=True`` the
        astrometric position (target at the emission time) is returned.
        """
        t = self.time(epoch)
        tgt, ctr = self._body(target), self._body(center)
        if light_time:
            return np.asarray(ctr.at(t).observe(tgt).position.km, dtype=float)
        return np.asarray((tgt - ctr).at(t).position.km, dtype=float)

    def positions(self, epoch: Epoch, center: str = "earth") -> dict[str, np.ndarray]:
        """Geometric positions of Moon, Sun and Earth relative to ``center`` (km, ICRF)."""
        return {b: self.position(b, epoch, center) for b in ("moon", "sun", "earth")}


def _resolve(path: str | os.PathLike[str] | None) -> Path:
    if path is None:
        return default_data_dir() / DEFAULT_KERNEL
    p = Path(path)
    return p / DEFAULT_KERNEL if p.is_dir() or not p.suffix else p


_CACHE: dict[str, Ephemeris] = {}


def clear_cache() -> None:
    """Close and forget every cached kernel (the next call reloads from disk)."""
    while _CACHE:
        _, e = _CACHE.popitem()
        try:
            e.kernel.close()
        except Exception:  # pragma: no cover - already closed
            pass


def _load_cached(resolved: str) -> Ephemeris:
    if resolved in _CACHE:
        return _CACHE[resolved]
    e = _open(resolved)
    if not _CACHE:
        atexit.register(clear_cache)  # close the kernel files at exit (no ResourceWarning)
    _CACHE[resolved] = e
    return e


def _open(resolved: str) -> Ephemeris:
    p = Path(resolved)
    if not p.is_file():
        raise EphemerisError(
            f"ephemeris file {str(p)!r} not found; jaxlimb never downloads it: install skyfield-data "
            "(ships de421.bsp) or pass the directory/file of a JPL .bsp kernel"
        )
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        from skyfield.api import Loader

    loader = Loader(str(p.parent), verbose=False, expire=False)
    try:
        kernel = loader(p.name)
    except Exception as e:  # corrupt / not an SPK file
        raise EphemerisError(f"cannot read ephemeris file {str(p)!r}: {e}") from None
    segs = [s for s in kernel.spk.segments]
    start = max(float(s.start_jd) for s in segs)
    end = min(float(s.end_jd) for s in segs)
    ts = loader.timescale(builtin=True)
    return Ephemeris(path=p, kernel=kernel, timescale=ts, start_jd_tdb=start, end_jd_tdb=end)


def load_ephemeris(path: str | os.PathLike[str] | None = None) -> Ephemeris:
    """Load (once; cached per resolved path) a JPL kernel, by default DE421 from skyfield-data.

    Parameters
    ----------
    path
        ``None`` (skyfield-data's DE421), a directory containing ``de421.bsp``, or a ``.bsp`` file.

    Raises
    ------
    EphemerisError
        The file does not exist (nothing is downloaded) or cannot be read.
    """
    return _load_cached(str(_resolve(path).resolve()))


def body_position(
    target: str,
    epoch: Epoch,
    center: str = "earth",
    *,
    light_time: bool = False,
    path: str | os.PathLike[str] | None = None,
) -> np.ndarray:
    """Position (km, ICRF/J2000) of ``target`` relative to ``center`` (``"moon"``, ``"sun"``, ``"earth"``)."""
    return load_ephemeris(path).position(target, epoch, center, light_time=light_time)


def moon_position(epoch: Epoch, center: str = "earth", **kw) -> np.ndarray:
    """Moon position (km, ICRF) relative to ``center``."""
    return body_position("moon", epoch, center, **kw)


def sun_position(epoch: Epoch, center: str = "earth", **kw) -> np.ndarray:
    """Sun position (km, ICRF) relative to ``center``."""
    return body_position("sun", epoch, center, **kw)


def earth_position(epoch: Epoch, center: str = "moon", **kw) -> np.ndarray:
    """Earth position (km, ICRF) relative to ``center`` (default the Moon)."""
    return body_position("earth", epoch, center, **kw)


def epoch_to_jd_tdb(epoch: Epoch, path: str | os.PathLike[str] | None = None) -> float:
    """TDB Julian date of an epoch (span-checked)."""
    return float(load_ephemeris(path).time(epoch).tdb)


__all__ = [
    "BODIES",
    "Ephemeris",
    "body_position",
    "clear_cache",
    "default_data_dir",
    "earth_position",
    "epoch_to_jd_tdb",
    "load_ephemeris",
    "moon_position",
    "sun_position",
]
