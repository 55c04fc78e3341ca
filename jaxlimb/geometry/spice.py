r"""SPICE geometry of a frame: camera model, predicted body image, Sun direction, hints.

Kernels are given by the user (a meta-kernel ``.tm`` or a list of kernel files) and never
downloaded.  :func:`spice_geometry` loads them, computes everything for one image time and
unloads them again (the kernel pool is global: nothing is left behind).

What is computed (CSPICE through ``spiceypy``; Acton 1996, *Planet. Space Sci.* 44:65):

* the **camera** from the instrument kernel (IK): ``INS<id>_FOCAL_LENGTH`` (mm),
  ``INS<id>_PIXEL_SIZE`` (µm), ``INS<id>_PIXEL_SAMPLES/LINES`` and
  ``INS<id>_FOV_CENTER_PIXEL`` (sample, line; 0-based pixel centres, i.e. jaxlimb's
  convention of docs/design.md, (0, 0) = centre of the top-left pixel);
* the body centre in the camera frame, ``spkpos(target, et, frame, "CN+S", observer)``
  (converged Newtonian light time and stellar aberration: where the body *appears*);
* the body orientation ``R_body_to_camera = F pxfrm2(body_frame, frame, et - lt, et)``
  (the body seen as it was when the light left it);
* the Sun direction from the body, ``spkpos("SUN", et - lt, "J2000", "CN+S", target)``
  rotated to the camera frame;
* the predicted limb ellipse (:func:`jaxlimb.geometry.ellipsoid.image_conic`) and the
  image of the body centre, with the body's radii of the shipped IAU 2015 table
  (:data:`jaxlimb.geometry.bodies.BODY_TABLE`) for a body it knows, else the kernel pool's (``bodvrd``).
  A mission's PCK may carry radii decades older than the IAU's: the Cassini PCKs of 2002
  (``pck00007.tpc``, ``cpck01Oct2002.tpc``) give Enceladus 256.3 x 247.3 x 244.6 km (Voyager), the IAU
  2015 report 256.6 x 251.4 x 248.3 km from Cassini's own limbs (Thomas et al. 2007, *Icarus* 190:573); the
  limb those older radii predict is 1.5 % small across the pole, a range 0.3 % short and a centre
  3 px off along the held shape (``benchmarks/cassini_enceladus.py``, ``with_kernel_pck_radii``).

Camera-frame convention (verify per instrument).  jaxlimb's camera frame has ``+x`` toward
``+col`` and ``+y`` toward ``+row`` (docs/design.md).  The instrument frame of SPICE need not:
the Cassini ISS IK (``cas_iss_v08.ti``) says "the CCD samples and lines increase with
decreasing X and Y", so ``x_jaxlimb = -X_ISS``, ``y_jaxlimb = -Y_ISS``, ``z = Z``:
``F = diag(-1, -1, 1)`` for both ISS cameras (:data:`INSTRUMENTS`).  Checked on the
Enceladus frames N1511803932 and N1511803965: with ``F`` the predicted disc lies on the
measured one to a few pixels; with the identity it would be mirrored through the
frame centre (hundreds of pixels off).

Errors are typed (:class:`~jaxlimb.errors.SpiceError`, CLI exit 2) and name what is missing:
a kernel file that does not exist, an unknown instrument, a label without an image time,
an image time outside the kernels' coverage (SPK, CK, or no frame connection).
"""

from __future__ import annotations

import contextlib
import math
import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Iterator, Sequence

import numpy as np

from ..errors import SpiceError
from .bodies import BODY_TABLE, body_radii_km
from .camera import Camera
from .ellipsoid import image_conic
from .hints import Hints

#: Camera-frame flip F (instrument frame -> jaxlimb camera frame), per SPICE instrument.
_FLIP_ISS = ((-1.0, 0.0, 0.0), (0.0, -1.0, 0.0), (0.0, 0.0, 1.0))


@dataclass(frozen=True)
class Instrument:
    """A camera SPICE knows: its frame/instrument name, observer, and the flip F to jaxlimb's frame."""

    spice_name: str
    observer: str
    flip: tuple[tuple[float, float, float], ...] = ((1.0, 0.0, 0.0), (0.0, 1.0, 0.0), (0.0, 0.0, 1.0))


#: Instruments by SPICE name; the label's ``INSTRUMENT_ID`` maps here through :data:`LABEL_INSTRUMENTS`.
INSTRUMENTS: dict[str, Instrument] = {
    "CASSINI_ISS_NAC": Instrument("CASSINI_ISS_NAC", "CASSINI", _FLIP_ISS),
    "CASSINI_ISS_WAC": Instrument("CASSINI_ISS_WAC", "CASSINI", _FLIP_ISS),
}

#: Label ``INSTRUMENT_ID`` (PDS3/VICAR) -> SPICE instrument name.
LABEL_INSTRUMENTS: dict[str, str] = {"ISSNA": "CASSINI_ISS_NAC", "ISSWA": "CASSINI_ISS_WAC"}


def instrument_from(name_or_label_id: str) -> Instrument:
    """The :class:`Instrument` for a SPICE name (``CASSINI_ISS_NAC``) or a label id (``ISSNA``).

    Raises
    ------
    SpiceError
        An instrument jaxlimb has no camera-frame convention for.
    """
    key = str(name_or_label_id).strip().upper()
    key = LABEL_INSTRUMENTS.get(key, key)
    if key not in INSTRUMENTS:
        known = sorted(set(INSTRUMENTS) | set(LABEL_INSTRUMENTS))
        raise SpiceError(f"unknown instrument {name_or_label_id!r}: no camera model/frame convention (known: {known})")
    return INSTRUMENTS[key]


# ----------------------------------------------------------------------------- kernels
def _kernel_list(kernels: str | os.PathLike[str] | Sequence[str | os.PathLike[str]]) -> list[Path]:
    if isinstance(kernels, (str, os.PathLike)):
        kernels = [kernels]
    paths = [Path(k) for k in kernels]
    if not paths:
        raise SpiceError("no SPICE kernels given")
    missing = [str(p) for p in paths if not p.is_file()]
    if missing:
        raise SpiceError(f"SPICE kernel file(s) not found: {', '.join(missing)}")
    return paths


@contextlib.contextmanager
def loaded_kernels(kernels) -> Iterator[list[Path]]:
    """Furnish ``kernels`` (meta-kernel or files) for the block, then unload exactly those.

    Raises
    ------
    SpiceError
        A missing file, or a file SPICE cannot load (corrupt, wrong type).
    """
    import spiceypy as sp

    paths = _kernel_list(kernels)
    done: list[str] = []
    try:
        for p in paths:
            _check_kernel(sp, p)
            try:
                sp.furnsh(str(p))
            except sp.utils.exceptions.SpiceyError as e:
                raise SpiceError(f"cannot load SPICE kernel {str(p)!r}: {_short(e)}") from None
            done.append(str(p))
        yield paths
    finally:
        for p in reversed(done):
            with contextlib.suppress(Exception):
                sp.unload(p)


def _check_kernel(sp, p: Path) -> None:  # noqa: ANN001
    """A file SPICE would accept and then ignore is refused: a kernel is a binary DAF/DAS file, or a text
    kernel (meta-kernel included) with a ``\\begindata`` section -- CSPICE ``furnsh`` "loads" any other file
    (a text note, a PNG) as a text kernel with nothing in it."""
    try:
        arch, _ = sp.getfat(str(p))
    except sp.utils.exceptions.SpiceyError as e:
        raise SpiceError(f"cannot read SPICE kernel {str(p)!r}: {_short(e)}") from None
    if arch in ("DAF", "DAS"):
        return
    try:
        text = p.read_bytes()
    except OSError as e:
        raise SpiceError(f"cannot read SPICE kernel {str(p)!r}: {e.strerror or e}") from None
    if b"\0" in text[:4096] or b"\\begindata" not in text:
        raise SpiceError(f"{str(p)!r} is not a SPICE kernel: neither a binary DAF/DAS kernel nor a text kernel "
                         "with a \\begindata section (nothing would be loaded from it)")


def _short(e: Exception) -> str:
    lines = [ln.strip() for ln in str(e).splitlines() if ln.strip() and not ln.strip().startswith("=")]
    return " ".join(lines[:4])[:400]


def spice_body_radii(name: str) -> tuple[float, float, float] | None:
    """``BODY<id>_RADII`` of ``name`` from the loaded kernel pool (``bodvrd``), or ``None``."""
    import spiceypy as sp

    try:
        r = sp.bodvrd(str(name).upper(), "RADII", 3)[1]
    except sp.utils.exceptions.SpiceyError:
        return None
    return (float(r[0]), float(r[1]), float(r[2]))


def _ik(sp, inst_id: int, key: str, n: int) -> np.ndarray:
    name = f"INS{inst_id}_{key}"
    try:
        return np.asarray(sp.gdpool(name, 0, n), dtype=float)
    except sp.utils.exceptions.SpiceyError:
        raise SpiceError(f"the instrument kernel (IK) lacks {name}: load the IK of the instrument") from None


def camera_from_ik(instrument: Instrument) -> Camera:
    """The pinhole :class:`~jaxlimb.geometry.camera.Camera` of ``instrument`` from its loaded IK."""
    import spiceypy as sp

    try:
        inst_id = int(sp.bods2c(instrument.spice_name))
    except sp.utils.exceptions.SpiceyError:
        raise SpiceError(f"SPICE does not know the instrument {instrument.spice_name!r}: load its IK/FK") from None
    f_mm = float(_ik(sp, inst_id, "FOCAL_LENGTH", 1)[0])
    pitch_mm = float(_ik(sp, inst_id, "PIXEL_SIZE", 1)[0]) / 1000.0  # IK: microns
    cols = int(_ik(sp, inst_id, "PIXEL_SAMPLES", 1)[0])
    rows = int(_ik(sp, inst_id, "PIXEL_LINES", 1)[0])
    s0, l0 = _ik(sp, inst_id, "FOV_CENTER_PIXEL", 2)
    return Camera(f_mm, pitch_mm, rows, cols, (float(l0), float(s0)))


def focal_length_sigma_from_ik(instrument: Instrument) -> float | None:
    """``INS<id>_FL_UNCERTAINTY`` (mm) of ``instrument``'s loaded IK, or ``None`` when the IK does not state it."""
    import spiceypy as sp

    try:
        v = float(_ik(sp, int(sp.bods2c(instrument.spice_name)), "FL_UNCERTAINTY", 1)[0])
    except (SpiceError, sp.utils.exceptions.SpiceyError):
        return None
    return v if math.isfinite(v) and v >= 0 else None


# ----------------------------------------------------------------------------- geometry
@dataclass(frozen=True)
class SpiceGeometry:
    """The SPICE prediction for one frame (camera frame = jaxlimb's, docs/design.md).

    Attributes
    ----------
    camera
        Pinhole camera from the IK.
    target, observer, instrument
        Names as SPICE knows them.
    utc, et
        The image time (label) and its ephemeris time (s past J2000 TDB).
    body_center_cam
        Body centre in the camera frame (km; light time + aberration corrected).
    range_km
        ``|body_center_cam|``.
    radii_km
        Body radii from the kernel pool (km).
    sun_dir_camera
        Unit vector from the body toward the Sun, camera frame.
    R_body_to_camera
        Body-fixed -> camera frame rotation.
    C_camera_from_j2000
        J2000 -> camera frame rotation at ``et`` (the reconstructed pointing).
    observer_j2000_km
        Observer position relative to the body centre, J2000 (km): minus the apparent body
        vector (light time + aberration), so that it compares with the measured line of sight.
    center_rc
        Image of the body centre (px).
    limb
        The predicted limb ellipse (:class:`~jaxlimb.geometry.ellipsoid.ImageConic`).
    radii_source
        ``"iau2015"`` (the shipped table) or ``"kernel"`` (the kernel pool's ``BODY<id>_RADII``).
    focal_length_sigma_mm
        The IK's stated focal-length uncertainty (mm), ``None`` when it states none.
    """

    camera: Camera
    target: str
    observer: str
    instrument: str
    utc: str
    et: float
    body_center_cam: tuple[float, float, float]
    range_km: float
    radii_km: tuple[float, float, float]
    sun_dir_camera: tuple[float, float, float]
    R_body_to_camera: tuple[tuple[float, float, float], ...]
    C_camera_from_j2000: tuple[tuple[float, float, float], ...]
    observer_j2000_km: tuple[float, float, float]
    center_rc: tuple[float, float]
    limb: Any = field(repr=False)
    radii_source: str = "kernel"
    focal_length_sigma_mm: float | None = None

    def hints(self, *, radius_uncertainty_frac: float = 0.05):
        """:class:`~jaxlimb.geometry.hints.Hints` from the prediction: body, radii, range, Sun, orientation."""
        return Hints(
            body=self.target.lower(),
            body_radii_km=self.radii_km,
            range_prior_km=self.range_km,
            expected_radius_uncertainty_frac=radius_uncertainty_frac,
            sun_dir_camera=self.sun_dir_camera,
            R_body_to_camera=self.R_body_to_camera,
            expected_center_rc=self.center_rc,
        )

    def to_json(self) -> dict[str, Any]:
        """The prediction as plain JSON types."""
        return {
            "instrument": self.instrument, "target": self.target, "observer": self.observer, "utc": self.utc,
            "et": self.et, "center_rc": list(self.center_rc), "range_km": self.range_km,
            "radii_km": list(self.radii_km), "radii_source": self.radii_source,
            "focal_length_sigma_mm": self.focal_length_sigma_mm, "sun_dir_camera": list(self.sun_dir_camera),
            "ellipse": {"center_rc": list(self.limb.center_rc), "semi_axes_px": list(self.limb.semi_axes_px),
                        "angle_rad": self.limb.angle_rad},
            "camera": self.camera.to_dict(),
        }


def _et(sp, utc: str) -> float:
    try:
        return float(sp.str2et(str(utc)))
    except sp.utils.exceptions.SpiceyError as e:
        raise SpiceError(f"cannot convert the image time {utc!r} to ephemeris time (is the LSK loaded?): {_short(e)}") from None


def _coverage(call, what: str, utc: str):
    import spiceypy as sp

    try:
        return call()
    except sp.utils.exceptions.SpiceyError as e:
        raise SpiceError(f"{what} at the image time {utc} is not available from the kernels "
                         f"(outside their coverage, or a kernel is missing): {_short(e)}") from None


def _body_frame(sp, target: str, utc: str) -> str:
    try:
        code = int(sp.bods2c(target))
    except sp.utils.exceptions.SpiceyError:
        raise SpiceError(f"SPICE does not know the body {target!r}") from None
    name = sp.cidfrm(code)[1]
    if not name:
        raise SpiceError(f"no body-fixed frame for {target!r} in the loaded kernels (load a PCK)")
    return name


def predict_loaded(utc: str, instrument: Instrument, target: str) -> SpiceGeometry:
    """:class:`SpiceGeometry` with the kernels already loaded (see :func:`spice_geometry`)."""
    import spiceypy as sp

    et = _et(sp, utc)
    cam = camera_from_ik(instrument)
    frame, obs, tgt = instrument.spice_name, instrument.observer, str(target).upper()
    F = np.asarray(instrument.flip, dtype=float)
    pos, lt = _coverage(lambda: sp.spkpos(tgt, et, frame, "CN+S", obs), f"the position of {tgt} seen from {obs}", utc)
    c_cam = F @ np.asarray(pos, float)
    C = F @ np.asarray(_coverage(lambda: sp.pxform("J2000", frame, et), f"the pointing of {frame}", utc))
    bframe = _body_frame(sp, tgt, utc)
    Rb = F @ np.asarray(_coverage(lambda: sp.pxfrm2(bframe, frame, et - lt, et), f"the orientation of {bframe}", utc))
    sun_j, _ = _coverage(lambda: sp.spkpos("SUN", et - lt, "J2000", "CN+S", tgt), f"the Sun seen from {tgt}", utc)
    s = C @ np.asarray(sun_j, float)
    obs_j = -(C.T @ c_cam)  # the observer seen from the body along the apparent line of sight
    radii, source = body_radii(tgt)
    limb = image_conic(cam, radii, c_cam, Rb)
    rc = cam.project(c_cam)
    t3 = lambda v: tuple(float(x) for x in v)  # noqa: E731
    return SpiceGeometry(
        camera=cam, target=tgt, observer=obs, instrument=frame, utc=str(utc), et=et,
        body_center_cam=t3(c_cam), range_km=float(np.linalg.norm(c_cam)), radii_km=t3(radii),
        sun_dir_camera=t3(s / np.linalg.norm(s)), R_body_to_camera=tuple(t3(r) for r in Rb),
        C_camera_from_j2000=tuple(t3(r) for r in C), observer_j2000_km=t3(obs_j),
        center_rc=(float(rc[0]), float(rc[1])), limb=limb, radii_source=source,
        focal_length_sigma_mm=focal_length_sigma_from_ik(instrument),
    )


def body_radii(target: str) -> tuple[tuple[float, float, float], str]:
    """The radii of ``target`` for the prediction and their source (module docstring): the shipped IAU 2015 table
    (``"iau2015"``) for a body it knows, else the loaded kernel pool's (``"kernel"``).

    Raises
    ------
    UnknownBodyError
        Neither the table nor the kernel pool has the body's radii.
    """
    if str(target).lower() in BODY_TABLE:
        return body_radii_km(str(target).lower()), "iau2015"
    r = spice_body_radii(target)
    return (r, "kernel") if r is not None else (body_radii_km(target), "iau2015")


def spice_geometry(kernels, utc: str | None, instrument: str, target: str | None) -> SpiceGeometry:
    """Load ``kernels``, predict the frame's geometry at ``utc`` and unload them.

    Parameters
    ----------
    kernels
        A meta-kernel, a kernel file, or a list of them (never downloaded).
    utc
        The image time (mid-exposure), e.g. the label's ``IMAGE_MID_TIME``.
    instrument
        SPICE instrument name or label ``INSTRUMENT_ID`` (:func:`instrument_from`).
    target
        The body's name (label ``TARGET_NAME``).

    Raises
    ------
    SpiceError
        Missing kernels, unknown instrument or body, no image time, time outside coverage.
    """
    if not utc:
        raise SpiceError("the frame has no image time (label IMAGE_MID_TIME/IMAGE_TIME/START_TIME): cannot use SPICE")
    if not target:
        raise SpiceError("the frame names no target (label TARGET_NAME) and no --body was given")
    inst = instrument_from(instrument) if instrument else None
    if inst is None:
        raise SpiceError("the frame names no instrument (label INSTRUMENT_ID) and no --instrument was given")
    with loaded_kernels(kernels):
        return predict_loaded(utc, inst, target)


# ----------------------------------------------------------------------------- comparison
def pointing_residual(geom: SpiceGeometry, center_rc, cov_rc=None) -> dict[str, Any]:
    """Measured - predicted image of the body centre, in pixels and as an angle.

    Parameters
    ----------
    geom
        The SPICE prediction.
    center_rc
        The measured image of the body centre (px).
    cov_rc
        Its 2x2 covariance (px^2), optional.

    Returns
    -------
    dict
        ``delta_rc_px``, ``delta_px`` (norm), ``angle_urad`` (angle between the two lines of
        sight), ``sigma_rc_px`` (when ``cov_rc`` is given).
    """
    cam = geom.camera
    d = np.asarray(center_rc, float) - np.asarray(geom.center_rc, float)
    u_m, u_p = cam.los(np.asarray(center_rc, float)), cam.los(np.asarray(geom.center_rc, float))
    ang = math.atan2(float(np.linalg.norm(np.cross(u_m, u_p))), float(u_m @ u_p))
    out: dict[str, Any] = {"delta_rc_px": [float(d[0]), float(d[1])], "delta_px": float(np.hypot(*d)),
                           "angle_urad": 1e6 * ang}
    if cov_rc is not None:
        out["sigma_rc_px"] = [float(math.sqrt(cov_rc[0][0])), float(math.sqrt(cov_rc[1][1]))]
    return out


def observer_from_measurement(geom: SpiceGeometry, los_camera, range_km: float) -> dict[str, Any]:
    """Observer position relative to the body (J2000, km) from the measured LOS and range.

    The SPICE attitude ``C_camera_from_j2000`` rotates the measured body vector
    ``range * los`` to J2000; the observer is at minus that.  Returned beside the SPICE
    position and their difference.
    """
    b_cam = float(range_km) * np.asarray(los_camera, float)
    C = np.asarray(geom.C_camera_from_j2000, float)
    obs = -(C.T @ b_cam)
    ref = np.asarray(geom.observer_j2000_km, float)
    return {"observer_j2000_km": [float(x) for x in obs], "spice_observer_j2000_km": [float(x) for x in ref],
            "difference_km": [float(x) for x in obs - ref], "difference_norm_km": float(np.linalg.norm(obs - ref))}


__all__ = [
    "INSTRUMENTS",
    "LABEL_INSTRUMENTS",
    "Instrument",
    "SpiceGeometry",
    "body_radii",
    "camera_from_ik",
    "focal_length_sigma_from_ik",
    "instrument_from",
    "loaded_kernels",
    "observer_from_measurement",
    "pointing_residual",
    "predict_loaded",
    "spice_body_radii",
    "spice_geometry",
]
