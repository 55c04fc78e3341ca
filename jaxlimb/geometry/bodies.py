"""Radii of named bodies: the PCK kernels through SPICE when given, else a shipped table.

Source of the table (:data:`BODY_TABLE`): the triaxial radii of the IAU Working Group on
Cartographic Coordinates and Rotational Elements, 2015 report -- B. A. Archinal et al.,
*Celest. Mech. Dyn. Astron.* 130:22 (2018), Tables 4-6 -- as distributed by NAIF in the
generic PCK ``pck00011.tpc`` (keywords ``BODYnnn_RADII``), with the NAIF ID code of each
body.  Two entries follow docs/design.md instead: the Moon's mean radius 1737.4 km (also the
IAU value) and the Earth's WGS-84 ellipsoid (6378.137 / 6356.752 km; IAU 6378.1366 /
6356.7519).  The Sun's radius is the IAU 2015 Resolution B3 nominal value 695 700 km.

Lookup order (:func:`body_radii_km`): explicit radii (hints ``body_radii_km``) win; then the table.
With SPICE kernels loaded, :mod:`jaxlimb.geometry.spice` asks the kernel pool's ``BODYnnn_RADII``
(``bodvrd``) first.  An unknown name raises
:class:`~jaxlimb.errors.UnknownBodyError` (CLI exit 2) naming the known bodies.
"""

from __future__ import annotations

from dataclasses import dataclass

from ..errors import UnknownBodyError


@dataclass(frozen=True)
class Body:
    """A named body: NAIF ID and triaxial radii ``(a, b, c)`` in km (a, b equatorial; c polar)."""

    name: str
    naif_id: int
    radii_km: tuple[float, float, float]

    @property
    def mean_radius_km(self) -> float:
        """Arithmetic mean of the three radii (km)."""
        return sum(self.radii_km) / 3.0


def _b(name: str, naif_id: int, a: float, b: float | None = None, c: float | None = None) -> Body:
    return Body(name, naif_id, (float(a), float(b if b is not None else a), float(c if c is not None else a)))


#: IAU WGCCRE 2015 / pck00011 radii (km), keyed by lower-case name (module docstring).
BODY_TABLE: dict[str, Body] = {b.name: b for b in (
    _b("sun", 10, 695700.0),
    _b("mercury", 199, 2440.53, 2440.53, 2438.26),
    _b("venus", 299, 6051.8),
    _b("earth", 399, 6378.137, 6378.137, 6356.752),
    _b("moon", 301, 1737.4),
    _b("mars", 499, 3396.19, 3396.19, 3376.20),
    _b("phobos", 401, 13.0, 11.4, 9.1),
    _b("deimos", 402, 7.8, 6.0, 5.1),
    _b("jupiter", 599, 71492.0, 71492.0, 66854.0),
    _b("io", 501, 1829.4, 1819.4, 1815.7),
    _b("europa", 502, 1562.6, 1560.3, 1559.5),
    _b("ganymede", 503, 2631.2, 2631.2, 2631.2),
    _b("callisto", 504, 2410.3, 2410.3, 2410.3),
    _b("amalthea", 505, 125.0, 73.0, 64.0),
    _b("thebe", 514, 58.0, 49.0, 42.0),
    _b("saturn", 699, 60268.0, 60268.0, 54364.0),
    _b("mimas", 601, 207.8, 196.7, 190.6),
    _b("enceladus", 602, 256.6, 251.4, 248.3),
    _b("tethys", 603, 538.4, 528.3, 526.3),
    _b("dione", 604, 563.4, 561.3, 559.6),
    _b("rhea", 605, 765.0, 763.1, 762.4),
    _b("titan", 606, 2575.15, 2574.78, 2574.47),
    _b("hyperion", 607, 180.1, 133.0, 102.7),
    _b("iapetus", 608, 745.7, 745.7, 712.1),
    _b("phoebe", 609, 109.4, 108.5, 101.8),
    _b("uranus", 799, 25559.0, 25559.0, 24973.0),
    _b("miranda", 705, 240.4, 234.2, 232.9),
    _b("ariel", 701, 581.1, 577.9, 577.7),
    _b("umbriel", 702, 584.7),
    _b("titania", 703, 788.9),
    _b("oberon", 704, 761.4),
    _b("neptune", 899, 24764.0, 24764.0, 24341.0),
    _b("triton", 801, 1352.6),
    _b("pluto", 999, 1188.3),
    _b("charon", 901, 606.0),
)}


def body_from_table(name: str) -> Body:
    """The table entry of ``name`` (case-insensitive).

    Raises
    ------
    UnknownBodyError
        The name is not in :data:`BODY_TABLE`.
    """
    key = str(name).strip().lower()
    if key not in BODY_TABLE:
        raise UnknownBodyError(
            f"unknown body {name!r}: no radii in the shipped IAU 2015 table (known: {', '.join(sorted(BODY_TABLE))}); "
            "give hints `body_radii_km` or SPICE kernels with a PCK that has it"
        )
    return BODY_TABLE[key]


def body_radii_km(name: str, *, radii_km=None) -> tuple[float, float, float]:
    """Radii ``(a, b, c)`` (km) of ``name``: ``radii_km`` if given, else the table.

    Parameters
    ----------
    name
        Body name (case-insensitive), e.g. ``"Enceladus"``.
    radii_km
        Explicit radii (hints ``body_radii_km``): returned as given.

    Raises
    ------
    UnknownBodyError
        The table does not know the body.
    """
    if radii_km is not None:
        a, b, c = (float(x) for x in radii_km)
        return (a, b, c)
    return body_from_table(name).radii_km


def known_body(name: str) -> bool:
    """True when ``name`` is in the shipped table."""
    return str(name).strip().lower() in BODY_TABLE


__all__ = ["BODY_TABLE", "Body", "body_from_table", "body_radii_km", "known_body"]
