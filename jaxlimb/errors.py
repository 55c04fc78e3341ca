"""Exception hierarchy of jaxlimb.

Two families, matching the command-line contract of docs/design.md:

* :class:`LimbInputError` (a ``ValueError``): the input is unusable -- a missing,
  corrupt, empty, wrong-shaped or non-finite image, a bad argument, a bad camera
  or hints file, an impossible geometry.  The CLI exits with code **2**.
* :class:`CheckFailed`: the input was read, but a check of the method failed --
  no body, body too small or too big, too thin, too many outliers, radius
  inconsistent with the prior, no convergence (the checks 1-5 of the Aerospace
  2015 paper, section 3).  The CLI exits with code **3**.

Every class carries a short machine name in ``check`` that the CLI puts in its
JSON error object (``{"status": "error", "check": NAME, "message": TEXT}``).
Messages name the argument, the valid range and the value received.
"""

from __future__ import annotations


class JaxlimbError(Exception):
    """Base class of every error raised on purpose by jaxlimb."""

    check: str = "error"
    exit_code: int = 1


# --------------------------------------------------------------------------- input
class LimbInputError(JaxlimbError, ValueError):
    """Unusable input: bad argument, shape, dtype, range or file (CLI exit 2)."""

    check = "bad_input"
    exit_code = 2


class ImageReadError(LimbInputError):
    """The image file is missing, unreadable, truncated or of an unsupported type."""

    check = "bad_image"


class ImageContentError(LimbInputError):
    """The image array is empty, 1x1, non-finite, constant or of the wrong shape."""

    check = "bad_image"


class ConfigError(LimbInputError):
    """A camera, hints or options file/object is malformed or out of range."""

    check = "bad_config"


class UsageError(ConfigError):
    """Command-line arguments that do not go together (a flag missing for the chosen mode, a value outside
    the mode's choices): the same check as argparse's usage errors."""

    check = "bad_arguments"


class GeometryError(LimbInputError):
    """Impossible geometry: observer inside the ellipsoid, degenerate radii, ..."""

    check = "bad_geometry"


class AttitudeError(GeometryError):
    """An attitude matrix/quaternion that is not a proper rotation."""

    check = "bad_attitude"


class EphemerisError(LimbInputError):
    """Epoch outside the ephemeris span, or the ephemeris file is missing."""

    check = "ephemeris"


class MeshError(LimbInputError):
    """A shape model that cannot be read, or is open, inconsistently wound or degenerate."""

    check = "bad_mesh"


class DatabaseError(LimbInputError):
    """A template database that is corrupt, of another version or for another mesh."""

    check = "bad_database"


# --------------------------------------------------------------------------- checks
class UnknownBodyError(ConfigError):
    """A body name with no known radii (neither the SPICE kernels nor the shipped table)."""

    check = "unknown_body"


class SpiceError(LimbInputError):
    """SPICE geometry cannot be computed: kernels missing or unreadable, an unknown instrument,
    an image time outside the kernels' coverage, a label without an image time."""

    check = "spice"


class LabelError(ImageReadError):
    """A planetary-format label (VICAR, PDS3, PDS4) is corrupt or lacks a needed keyword."""

    check = "bad_label"


class CheckFailed(JaxlimbError):
    """A check of the method failed on a readable input (CLI exit 3)."""

    check = "check_failed"
    exit_code = 3


class NoBodyError(CheckFailed):
    """No body found in the image (all-black, all-white, pure noise)."""

    check = "no_body"


class TooSmallError(CheckFailed):
    """Check 1: the body is too small for a limb fit."""

    check = "too_small"


class TooBigError(CheckFailed):
    """Check 1: the body is too big (fills or exceeds the frame)."""

    check = "too_big"


class TooThinError(CheckFailed):
    """Check 2: new moon or a crescent too thin to fit."""

    check = "too_thin"


class TooManyOutliersError(CheckFailed):
    """Check 3: too many outliers among the candidate limb points."""

    check = "too_many_outliers"


class RadiusInconsistentError(CheckFailed):
    """Check 4: the estimated radius is inconsistent with the prior."""

    check = "radius_inconsistent"


class CenterTooUncertainError(CheckFailed):
    """The fit's own 1-sigma of the centre exceeds the stated tolerance (``LocateOptions.max_center_sigma_px``)."""

    check = "center_too_uncertain"


class DarkLimbInconsistentError(CheckFailed):
    """The dark limb visible against a brighter sky lies off the circle fitted to the lit limb."""

    check = "dark_limb_inconsistent"


class ArcTooShortError(CheckFailed):
    """Check 3/4: the lit limb visible in the frame is too short an arc to fix a circle (cropped body)."""

    check = "arc_too_short"


class ConvergenceError(CheckFailed):
    """Check 5: the least-squares fit did not converge or diverged."""

    check = "no_convergence"


class PosteriorImproperError(ConvergenceError):
    """The posterior cannot be sampled or is improper: the walkers run away (k, means -> 1e62),
    or its spread is out of all proportion to the fit's Laplace covariance."""

    check = "posterior_improper"


class JumpError(ConvergenceError):
    """Check 5: the fit converged far away from its (Taubin) initial estimate."""

    check = "jump_from_initial"


class GradientMismatchError(CheckFailed):
    """``jaxlimb gradcheck``: an analytic Jacobian disagrees with autodiff beyond the tolerance."""

    check = "gradient_mismatch"


class OutputBusyError(LimbInputError):
    """Another process holds the lock of the output file being written (concurrent writers)."""

    check = "output_busy"


class OutputWriteError(LimbInputError):
    """An output could not be written whole (disk full, I/O error, quota): the run stops; what was written
    stays whole and a many-frame ``--out`` file stays resumable (CLI exit 2)."""

    check = "write_failed"


class MatchError(CheckFailed):
    """The shape model does not explain the frame: poor residual or overlap (model-based line of sight)."""

    check = "poor_match"


class AmbiguousMatchError(MatchError):
    """Two poses of the shape model that put the body centre apart explain the frame about equally well."""

    check = "ambiguous_match"


class SaturationWarning(UserWarning):
    """Pixels of the limb annulus are clipped (saturated): the measured radius, hence the range,
    can be biased outward (measured: 0.3-1 px on Moons over-exposed 1.5-6x; the centre stays
    within ~0.05 px); ``extras["saturation"]`` of the measurement says how many."""


class CacheRepairWarning(UserWarning):
    """A cache entry (compiled program, exported fit core, template database) failed its check -- damaged,
    truncated, or written by other versions -- and was deleted and rebuilt; or the cache was bypassed.
    The answer is the one an undamaged cache gives."""


__all__ = [
    "AmbiguousMatchError",
    "ArcTooShortError",
    "CenterTooUncertainError",
    "DarkLimbInconsistentError",
    "UsageError",
    "AttitudeError",
    "CacheRepairWarning",
    "CheckFailed",
    "ConfigError",
    "ConvergenceError",
    "DatabaseError",
    "EphemerisError",
    "GeometryError",
    "GradientMismatchError",
    "ImageContentError",
    "ImageReadError",
    "JaxlimbError",
    "JumpError",
    "LabelError",
    "LimbInputError",
    "MatchError",
    "MeshError",
    "NoBodyError",
    "OutputBusyError",
    "OutputWriteError",
    "PosteriorImproperError",
    "RadiusInconsistentError",
    "SaturationWarning",
    "SpiceError",
    "TooBigError",
    "TooManyOutliersError",
    "TooSmallError",
    "TooThinError",
    "UnknownBodyError",
]
