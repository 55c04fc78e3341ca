r"""Scene families for validating ``locate`` on what its limb model does not assume.

Every family draws its scenes from a seeded generator; ``own`` is what the pipeline's physical
profile assumes (uniform albedo, lunar-Lambert, Gaussian PSF), every other family changes one
thing (``combined`` several).  Moon: 60 000-384 400 km (log-uniform), phase 0-150 deg, centre
anywhere with the limb in the 1944x2592 frame (16 mm, 2.2 um), 8 or 12 bits.  Earth (WGS-84):
gibbous (phase 20-70 deg) at 40 000 km with an 8 mm lens or 380 000 km with the 16 mm lens,
observer latitude 0-60 deg, 8 or 12 bits; ``R_body_to_camera`` is part of the truth.  The full-disc Earth
(:func:`earth_full_disc_case`): the view from L1 (DSCOVR/EPIC), phase 4-12 deg, 1080^2.

========================  ===========================================================
family                    what differs from ``own``
========================  ===========================================================
``own``                   nothing (Gaussian PSF sigma 0.6-1.2 px)
``hapke``                 Hapke IMSA law (w 0.15-0.35, b 0.2-0.4, surge B0 0.5-1.5, h 0.04-0.1)
``minnaert``              Minnaert k 0.55-0.95
``ls_surge``              Lommel-Seeliger with opposition surge (B0 0.5-1.5, h 0.03-0.1)
``lambert``               Lambert (Earth; no limb brightening at all)
``maria``                 Moon: 8 smooth dark maria 15-35 % deep, 9-26 deg across, 3 of them
                          crossing the lit limb
``clouds``                Earth: Lambert x ocean/continents/clouds albedo map
``glow``                  exponential glow above the limb, brightness 0.03-0.4, scale height
                          6-25 km (Earth) / 2-15 km (Moon)
``airy``, ``defocus``,    non-Gaussian PSFs: Airy (first dark ring 1.2-2.0 px), uniform disc
``motion``                (radius 0.8-1.8 px), Gaussian 0.5-0.8 px smeared over 1.5-3.5 px
``jpeg``                  8-bit JPEG quality 75-95
``stars``                 40 stars, 80 hot pixels
``cropped``               Moon: centre beyond a frame edge by up to half a radius
``combined``              Hapke/clouds + maria + any PSF + glow (Earth) + JPEG half the time
``spots``                 albedo varying everywhere: ~80 overlapping Gaussian spots 9-26 deg FWHM, 15-35 %
                          deep, times a +-4 % gradient (:class:`SpotsMap`); Earth: on Lambert
========================  ===========================================================

Ablations (:func:`earth_case`'s ``ablate``): the same scene with one component of the draw replaced, every random
draw made as without it (same geometry, Sun, attitude, albedo seed, PSF draws, noise), to tell which component
moves a measurement (``benchmarks/earth_ablation.py``):

=====================  ===========================================================
ablation               what is replaced
=====================  ===========================================================
``psf_core``           the PSF by its Gaussian core (a motion smear's ``sigma``; Airy and defocus: the
                       ``sigma`` drawn for them, unused otherwise)
``psf_round``          the PSF by an isotropic Gaussian of the same per-axis variance (motion
                       ``sigma^2 + L^2/24``, Airy ``(0.344 r_z)^2``, defocus ``r_d^2/4``)
``no_glow``            no glow above the limb
``no_jpeg``            no JPEG compression (the sensor's bit depth kept)
``reseed_clouds``      the Earth's albedo map drawn with the next seed (other clouds, same statistics)
``no_clouds``          no albedo map: the family's reflectance law on a uniform albedo (its seed still drawn)
=====================  ===========================================================
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np

from ...geometry.camera import Camera
from .geometry import Body, LimbTruth, Pinhole, limb_truth
from .optics import Glow, Psf, PsfKind
from .raster import Surface, render_radiance
from .sensor import SensorSpec, digitise
from .surface import EarthMap, MariaMap, Photometry, Reflectance, SpotsMap

MOON_RADIUS_KM = 1737.4
WGS84_KM = (6378.137, 6378.137, 6356.752)
MOON_FAMILIES = ("own", "hapke", "minnaert", "ls_surge", "maria", "glow", "airy", "defocus", "motion", "jpeg",
                 "stars", "cropped", "combined", "spots")
EARTH_FAMILIES = ("own", "lambert", "clouds", "glow", "hapke", "airy", "defocus", "motion", "jpeg", "combined",
                  "spots")
ABLATIONS = ("psf_core", "psf_round", "no_glow", "no_jpeg", "reseed_clouds", "no_clouds")
_READ_E = 157.0  # read noise (e-): 2 DN at 8 bits


@dataclass
class Case:
    """One rendered frame: the image, its exact truth, what a filter would know, and the draw."""

    image: np.ndarray
    truth: LimbTruth
    camera: Any  # jaxlimb Camera (for the pipeline)
    hints: dict
    meta: dict = field(default_factory=dict)


# ----------------------------------------------------------------------------- geometry
def image_direction(pin: Pinhole, u: np.ndarray, angle_deg: float) -> np.ndarray:
    """Unit vector perpendicular to ``u`` whose image points at position angle ``angle_deg``
    (from ``+col`` toward ``-row``)."""
    a = math.radians(angle_deg)
    v = np.array([math.cos(a), -math.sin(a), 0.0])
    e = v - (v @ u) * u
    return e / np.linalg.norm(e)


def sun_for_phase(u: np.ndarray, e: np.ndarray, phase_deg: float) -> np.ndarray:
    g = math.radians(phase_deg)
    return math.cos(g) * (-u) + math.sin(g) * e


def random_rotation(rng: np.random.Generator) -> np.ndarray:
    Q, Rm = np.linalg.qr(rng.normal(size=(3, 3)))
    Q = Q * np.sign(np.diag(Rm))
    return Q if np.linalg.det(Q) > 0 else -Q


def earth_attitude(u: np.ndarray, north: np.ndarray, lat_deg: float, lon_deg: float) -> np.ndarray:
    """``R_body_to_camera`` with the observer at geocentric ``lat, lon`` and the pole imaged along ``north``."""
    la, lo = math.radians(lat_deg), math.radians(lon_deg)
    p = np.array([math.cos(la) * math.cos(lo), math.cos(la) * math.sin(lo), math.sin(la)])
    zp = np.array([0.0, 0.0, 1.0]) - math.sin(la) * p
    zp /= np.linalg.norm(zp)
    Bb = np.column_stack([p, zp, np.cross(p, zp)])
    Bc = np.column_stack([-u, north, np.cross(-u, north)])
    return Bc @ Bb.T


def _camera(focal_mm: float):

    return Camera(focal_length_mm=focal_mm, pixel_pitch_mm=0.0022, rows=1944, cols=2592)


def _sensor(rng: np.random.Generator, family: str) -> SensorSpec:
    bits = 8 if family == "jpeg" or rng.uniform() < 0.5 else 12
    jq = int(rng.integers(75, 96)) if family == "jpeg" or (family == "combined" and rng.uniform() < 0.5) else None
    if jq is not None:
        bits = 8
    gain = 20000.0 / (2**bits - 1)
    n_st, n_hot = (40, 80) if family in ("stars", "combined") else (0, 0)
    return SensorSpec(bits=bits, read_noise_dn=_READ_E / gain, background_dn=40.0 / gain, n_stars=n_st,
                      star_flux_dn=(20.0 * (2**bits - 1) / 255, 600.0 * (2**bits - 1) / 255), n_hot=n_hot,
                      jpeg_quality=jq)


def _psf(rng: np.random.Generator, family: str) -> Psf:
    kind = family if family in ("airy", "defocus", "motion") else (
        str(rng.choice(["gaussian", "airy", "defocus", "motion"])) if family == "combined" else "gaussian")
    return Psf(kind=PsfKind(kind), sigma=float(rng.uniform(0.6, 1.2)) if kind == "gaussian" else float(rng.uniform(0.5, 0.8)),
               r_zero=float(rng.uniform(1.2, 2.0)), r_disc=float(rng.uniform(0.8, 1.8)),
               length=float(rng.uniform(1.5, 3.5)), angle_deg=float(rng.uniform(0, 180)))


def _photometry(rng: np.random.Generator, family: str, body: str) -> Photometry:
    law = {"hapke": Reflectance.HAPKE, "minnaert": Reflectance.MINNAERT, "ls_surge": Reflectance.LOMMEL_SEELIGER_SURGE,
           "lambert": Reflectance.LAMBERT, "clouds": Reflectance.LAMBERT}.get(family, Reflectance.LUNAR_LAMBERT)
    if family == "spots" and body == "earth":
        law = Reflectance.LAMBERT
    if family == "combined":
        law = Reflectance.HAPKE if body == "moon" else Reflectance.LAMBERT
    return Photometry(law=law, minnaert_k=float(rng.uniform(0.55, 0.95)), w=float(rng.uniform(0.15, 0.35)),
                      b=float(rng.uniform(0.2, 0.4)), B0=float(rng.uniform(0.5, 1.5)), h=float(rng.uniform(0.03, 0.1)))


def _center(rng: np.random.Generator, pin: Pinhole, R_px: float, cropped: bool) -> tuple[float, float]:
    m = 1.1 * R_px + 12.0
    if not cropped:
        return float(rng.uniform(m, pin.rows - m)), float(rng.uniform(m, pin.cols - m))
    out = float(rng.uniform(0.05, 0.5)) * R_px
    side = int(rng.integers(4))
    along_r, along_c = float(rng.uniform(m, pin.rows - m)), float(rng.uniform(m, pin.cols - m))
    return [(-out, along_c), (pin.rows - 1 + out, along_c), (along_r, -out), (along_r, pin.cols - 1 + out)][side]


def _maria(rng: np.random.Generator, pin: Pinhole, u: np.ndarray, R: np.ndarray, sun_angle: float,
           range_km: float) -> MariaMap:
    beta0 = math.degrees(math.acos(MOON_RADIUS_KM / range_km))  # the limb, seen from the centre
    cams = []
    for _ in range(3):  # crossing the lit limb
        e = image_direction(pin, u, sun_angle + float(rng.uniform(-60, 60)))
        b = math.radians(beta0 + float(rng.uniform(-6, 6)))
        cams.append(math.cos(b) * (-u) + math.sin(b) * e)
    cen = [R.T @ c for c in cams] + [v / np.linalg.norm(v) for v in rng.normal(size=(5, 3))]
    return MariaMap(np.array(cen), rng.uniform(4.5, 13.0, 8), rng.uniform(0.15, 0.35, 8))


# ----------------------------------------------------------------------------- cases
def moon_case(family: str, rng: np.random.Generator) -> Case:
    """A Moon frame of ``family`` (module docstring)."""
    if family not in MOON_FAMILIES:
        raise ValueError(f"unknown Moon family {family!r}; one of {MOON_FAMILIES}")
    cam = _camera(16.0)
    pin = Pinhole.from_camera(cam)
    rng_km = float(math.exp(rng.uniform(math.log(60000.0), math.log(384400.0))))
    phase = float(rng.uniform(0.0, 150.0))
    R_px = pin.focal_px * math.tan(math.asin(MOON_RADIUS_KM / rng_km))
    rc = _center(rng, pin, R_px, family == "cropped")
    u = pin.los(rc)
    sun_angle = float(rng.uniform(0, 360))
    s = sun_for_phase(u, image_direction(pin, u, sun_angle), phase)
    Rm = random_rotation(rng)
    body = Body((MOON_RADIUS_KM,) * 3, rng_km * u, Rm, s)
    albedo = _maria(rng, pin, u, Rm, sun_angle, rng_km) if family in ("maria", "combined") else None
    albedo = SpotsMap.draw(rng) if family == "spots" else albedo
    glow = Glow(float(rng.uniform(2.0, 15.0)), float(rng.uniform(0.03, 0.4))) if family == "glow" else None
    surf = Surface(_photometry(rng, family, "moon"), albedo if albedo is not None else Surface().albedo, glow)
    psf = _psf(rng, family)
    spec = _sensor(rng, family)
    meta = {"family": family, "body": "moon", "range_km": rng_km, "phase_deg": phase, "sun_angle_deg": sun_angle,
            "psf": psf.kind.value, "bits": spec.bits, "jpeg": spec.jpeg_quality, "law": surf.photometry.law.value,
            "glow": None if glow is None else [glow.scale_height_km, glow.brightness]}
    hints = {"body": "moon", "sun_dir_camera": [float(v) for v in s],
             "range_prior_km": rng_km * (1.0 + 0.05 * float(rng.standard_normal()))}
    return _finish(body, surf, pin, psf, spec, rng, cam, hints, meta)


def earth_case(family: str, rng: np.random.Generator, far: bool | None = None, ablate: tuple[str, ...] = (),
               sun_declination_max_deg: float | None = None) -> Case:
    """An Earth frame of ``family`` (module docstring); ``far``: 380 000 km (else 40 000 km; random if None);
    ``ablate``: names of :data:`ABLATIONS` (module docstring) replaced after the same draws;
    ``sun_declination_max_deg``: the phase and the Sun's image direction are drawn again until the Sun lies within
    that angle of the equator (the real Earth: 23.44), else the Sun is placed freely."""
    if family not in EARTH_FAMILIES:
        raise ValueError(f"unknown Earth family {family!r}; one of {EARTH_FAMILIES}")
    bad = set(ablate) - set(ABLATIONS)
    if bad:
        raise ValueError(f"unknown ablations {sorted(bad)}; any of {ABLATIONS}")
    far = bool(rng.uniform() < 0.5) if far is None else far
    rng_km, focal = (380000.0, 16.0) if far else (40000.0, 8.0)
    rng_km *= float(rng.uniform(0.97, 1.03))
    cam = _camera(focal)
    pin = Pinhole.from_camera(cam)
    R_px = pin.focal_px * math.tan(math.asin(WGS84_KM[0] / rng_km))
    rc = _center(rng, pin, R_px, False)
    u = pin.los(rc)
    lat = float(rng.uniform(0.0, 60.0)) * (1 if rng.uniform() < 0.5 else -1)
    R = earth_attitude(u, image_direction(pin, u, float(rng.uniform(0, 360))), lat, float(rng.uniform(-180, 180)))
    phase, s = _earth_sun(rng, pin, u, R, sun_declination_max_deg)
    return _earth_frame(family, rng, cam, pin, (u, R, s, rng_km), {"range_km": rng_km, "focal_mm": focal},
                        lat, phase, tuple(ablate))


def _earth_sun(rng: np.random.Generator, pin, u: np.ndarray, R: np.ndarray,  # type: ignore[no-untyped-def]
               declination_max_deg: float | None) -> tuple[float, np.ndarray]:
    """The phase (20-70 deg) and the Sun direction of :func:`earth_case` (module docstring), drawn again (up to 500
    times) until ``|s . pole| <= sin(declination_max_deg)`` when that is given."""
    for _ in range(500):
        phase, sun_angle = float(rng.uniform(20.0, 70.0)), float(rng.uniform(0, 360))
        s = sun_for_phase(u, image_direction(pin, u, sun_angle), phase)
        if declination_max_deg is None or abs(float(np.dot(s, R[:, 2]))) <= math.sin(math.radians(declination_max_deg)):
            return phase, s
    raise ValueError(f"no gibbous Sun within {declination_max_deg} deg of this observer's equator")


#: Families of :func:`earth_full_disc_case` (the deep-space view: no crop, no stars at these exposures).
EARTH_FULL_DISC_FAMILIES = ("own", "lambert", "clouds", "glow", "jpeg", "combined")


def earth_full_disc_case(family: str, rng: np.random.Generator) -> Case:
    """The sunlit Earth nearly full from deep space, as DSCOVR/EPIC sees it from L1 (~1.5 million km, phase
    4-12 deg, the disc ~80 % of a 1080^2 frame: radius 380-450 px, observer latitude 0-25 deg), with the
    photometry, albedo, glow, PSF and sensor of ``family`` (:func:`earth_case`).  At this phase a Lambert Earth
    darkens to zero at its limb and the strongest edges are the clouds' (``benchmarks/earth_full_disc.py``)."""
    if family not in EARTH_FULL_DISC_FAMILIES:
        raise ValueError(f"unknown full-disc Earth family {family!r}; one of {EARTH_FULL_DISC_FAMILIES}")

    rng_km = 1.5e6 * float(rng.uniform(0.97, 1.03))
    R_px = float(rng.uniform(380.0, 450.0))
    f_px = R_px / math.tan(math.asin(WGS84_KM[0] / rng_km))
    cam = Camera(focal_length_mm=f_px * 0.0022, pixel_pitch_mm=0.0022, rows=1080, cols=1080)
    pin = Pinhole.from_camera(cam)
    u = pin.los((539.5 + float(rng.uniform(-20.0, 20.0)), 539.5 + float(rng.uniform(-20.0, 20.0))))
    lat = float(rng.uniform(0.0, 25.0)) * (1 if rng.uniform() < 0.5 else -1)
    R = earth_attitude(u, image_direction(pin, u, float(rng.uniform(0, 360))), lat, float(rng.uniform(-180, 180)))
    phase = float(rng.uniform(4.0, 12.0))
    s = sun_for_phase(u, image_direction(pin, u, float(rng.uniform(0, 360))), phase)
    return _earth_frame(family, rng, cam, pin, (u, R, s, rng_km),
                        {"geometry": "full-disc", "range_km": rng_km, "focal_px": f_px}, lat, phase)


def _ablated_psf(psf: Psf, ablate: tuple[str, ...]) -> Psf:
    """The PSF with ``psf_core`` / ``psf_round`` applied (module docstring, "Ablations")."""
    if "psf_round" in ablate:
        var = {PsfKind.MOTION: psf.sigma**2 + psf.length**2 / 24.0, PsfKind.AIRY: (0.344 * psf.r_zero) ** 2,
               PsfKind.DEFOCUS: psf.r_disc**2 / 4.0}.get(PsfKind(psf.kind), psf.sigma**2)
        return Psf(kind=PsfKind.GAUSSIAN, sigma=math.sqrt(var))
    if "psf_core" in ablate:
        return Psf(kind=PsfKind.GAUSSIAN, sigma=psf.sigma)
    return psf


def _earth_frame(family: str, rng: np.random.Generator, cam, pin, pose, geometry: dict, lat: float, phase: float,  # type: ignore[no-untyped-def]
                 ablate: tuple[str, ...] = ()) -> Case:
    """The Earth seen along ``u`` at ``rng_km`` (``pose = (u, R, s, rng_km)``: line of sight, attitude, Sun) with the
    albedo, glow, photometry, PSF and sensor of ``family`` (drawn from ``rng`` in that order), its hints and meta
    (``geometry``: the meta entries of the view); ``ablate``: components replaced after the same draws (module
    docstring, "Ablations")."""
    u, R, s, rng_km = pose
    body = Body(WGS84_KM, rng_km * u, R, s)
    albedo = EarthMap(seed=int(rng.integers(2**31))) if family in ("clouds", "combined") else None
    if albedo is not None and "reseed_clouds" in ablate:
        albedo = EarthMap(seed=(albedo.seed + 1) % 2**31)
    albedo = None if "no_clouds" in ablate else albedo
    albedo = SpotsMap.draw(rng) if family == "spots" else albedo
    glow = (Glow(float(rng.uniform(6.0, 25.0)), float(rng.uniform(0.03, 0.4)))
            if family in ("glow", "combined") else None)
    glow = None if "no_glow" in ablate else glow
    surf = Surface(_photometry(rng, family, "earth"), albedo if albedo is not None else Surface().albedo, glow)
    psf = _ablated_psf(_psf(rng, family), ablate)
    spec = _sensor(rng, family)
    spec = replace(spec, jpeg_quality=None) if "no_jpeg" in ablate else spec
    meta = {"family": family, "body": "earth", **geometry, "latitude_deg": lat, "phase_deg": phase,
            "psf": psf.kind.value, "bits": spec.bits, "jpeg": spec.jpeg_quality, "law": surf.photometry.law.value,
            "glow": None if glow is None else [glow.scale_height_km, glow.brightness],
            **({"ablated": sorted(ablate)} if ablate else {})}
    hints = {"body": "earth", "sun_dir_camera": [float(v) for v in s], "R_body_to_camera": R.tolist(),
             "range_prior_km": rng_km * (1.0 + 0.05 * float(rng.standard_normal())), "atmosphere_km": 0.0}
    return _finish(body, surf, pin, psf, spec, rng, cam, hints, meta)


def _finish(body, surf, pin, psf, spec, rng, cam, hints, meta) -> Case:
    rad = render_radiance(body, surf, pin, psf)
    nz = np.nonzero(rad.any(axis=1))[0], np.nonzero(rad.any(axis=0))[0]
    window = (int(nz[0][0]), int(nz[0][-1]), int(nz[1][0]), int(nz[1][-1])) if nz[0].size else (0, 0, 0, 0)
    img = digitise(rad, spec, rng, window)
    return Case(img, limb_truth(body, pin), cam, hints, meta)


#: Albedo maps of :func:`albedo_case`: none (uniform), ``spots`` (:class:`SpotsMap`), ``maria`` (flat caps,
#: :class:`MariaMap` drawn as the ``maria`` family draws them), ``earthmap`` (:class:`EarthMap`, no cloud heights).
ALBEDO_KINDS = ("uniform", "spots", "maria", "earthmap")


def albedo_case(body: str, range_km: float, phase_deg: float, albedo: str, albedo_seed: int, noise_seed: int,
                geometry_seed: int = 0) -> Case:
    """One scene with the albedo map swapped and everything else held: the same geometry (``geometry_seed``: the
    body's position in the frame, its rotation, the Sun's image direction), PSF (Gaussian 0.9 px), sensor (12 bits)
    and noise draw (``noise_seed``) for every ``albedo`` of :data:`ALBEDO_KINDS` and ``albedo_seed`` (the map's
    draw).  Moon: lunar-Lambert; Earth: Lambert with its WGS-84 limb, attitude in the hints.  What an
    albedo-invariance benchmark needs (``benchmarks/albedo_invariance.py``)."""
    if albedo not in ALBEDO_KINDS:
        raise ValueError(f"unknown albedo {albedo!r}; one of {ALBEDO_KINDS}")
    g = np.random.default_rng([geometry_seed, 7])
    radii = (MOON_RADIUS_KM,) * 3 if body == "moon" else WGS84_KM
    cam = _camera(16.0 if body == "moon" else (8.0 if range_km < 100000.0 else 16.0))
    pin = Pinhole.from_camera(cam)
    R_px = pin.focal_px * math.tan(math.asin(radii[0] / range_km))
    rc = _center(g, pin, R_px, False)
    u = pin.los(rc)
    sun_angle = float(g.uniform(0, 360))
    s = sun_for_phase(u, image_direction(pin, u, sun_angle), phase_deg)
    if body == "moon":
        R = random_rotation(g)
    else:
        R = earth_attitude(u, image_direction(pin, u, float(g.uniform(0, 360))), float(g.uniform(-60, 60)),
                           float(g.uniform(-180, 180)))
    a = np.random.default_rng([albedo_seed, 11])
    amap = {"uniform": lambda: None, "spots": lambda: SpotsMap.draw(a),
            "maria": lambda: _maria(a, pin, u, R, sun_angle, range_km),
            "earthmap": lambda: EarthMap(seed=int(a.integers(2**31)))}[albedo]()
    law = Reflectance.LUNAR_LAMBERT if body == "moon" else Reflectance.LAMBERT
    surf = Surface(Photometry(law=law), amap if amap is not None else Surface().albedo, None)
    spec = SensorSpec(bits=12, read_noise_dn=_READ_E / (20000.0 / 4095), background_dn=40.0 / (20000.0 / 4095))
    hints: dict = {"body": body, "sun_dir_camera": [float(v) for v in s], "range_prior_km": range_km * 1.03}
    if body == "earth":
        hints.update({"R_body_to_camera": R.tolist(), "atmosphere_km": 0.0})
    meta = {"family": f"albedo-{albedo}", "body": body, "range_km": range_km, "phase_deg": phase_deg,
            "albedo_seed": albedo_seed, "noise_seed": noise_seed, "geometry_seed": geometry_seed}
    return _finish(Body(radii, range_km * u, R, s), surf, pin, Psf(kind=PsfKind.GAUSSIAN, sigma=0.9), spec,
                   np.random.default_rng([noise_seed, 13]), cam, hints, meta)
