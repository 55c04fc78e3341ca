"""The 2-D figure feature database (Sec. 3 of Wu et al.): build, save, load, cache.

For every viewpoint of the view sphere (Eq. 5-7) the mesh is projected
(Eq. 9) into a template image whose principal point is the image of the body
centre ``P_B`` (the optical axis points at the mesh origin, Sec. 3.3), its
figure is traced (:mod:`.silhouette`) and the features of Sec. 3.3 are stored:
area ``S_B`` (Eq. 14), centre ``C_B``, attitude vector ``C_B F_B``, Hu moments
(Eq. 10-13), plus the second-moment orientation and the resampled outer
contour used by the matching guards (:mod:`.matching`).

Decisions
---------
* Viewing distance: the paper puts the viewpoints at about 3x the long axis.
  At that distance the template is far more perspective than an image taken
  from navigation ranges, and the perspective mismatch moves ``P_B - C_B`` by
  about ``|R/D_template - R/D_image|`` of the figure size (measured: 0.5 px on a
  220-px figure with templates at 20 radii and the image at 66 radii).  The
  default here is ``distance_factor = 50`` bounding radii, the middle (in 1/D)
  of the 30-100 radii at which a body spans 500-150 px in the default camera;
  ``distance_factor=6`` (about 3 long axes) reproduces the paper's choice.
* Template resolution: ``template_size_px`` square images with the body's
  bounding sphere spanning ``fill_fraction`` of the width.  Features are
  computed from the traced contour polygon (sub-pixel exact moments), so a
  modest size suffices.
* The validated mesh itself is stored in the file (a few MB at most), so the
  database alone supports the refinement of :mod:`.refine`.

File format (``.npz``, ``FORMAT_VERSION``): arrays ``format_version``, ``settings_json``, ``mesh_hash``,
``mesh_vertices``, ``mesh_faces``, the per-template arrays, and ``checksum`` -- a SHA-256 over every other
array. The file is written atomically (:func:`jaxlimb._io.atomic_open`); reading it verifies the zip CRCs, the
checksum, the version, the shapes, the stored mesh against its hash and, if given, the expected mesh hash and
settings. Any failure raises :class:`jaxlimb.errors.DatabaseError` and nothing is returned. The file also
records ``built_by`` (:func:`built_by`: the NumPy and OpenCV versions and the format that made the templates),
inside the checksum; the cache of :func:`cached_database` rebuilds an entry built by other versions, or one that
fails any check, and says so once (a :class:`~jaxlimb.errors.CacheRepairWarning`).
"""

from __future__ import annotations

import contextlib
import dataclasses
import hashlib
import json
import math
import os
import zipfile
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from .._io import atomic_open
from ..errors import ConfigError, DatabaseError
from .features import features_from_contours
from .mesh import Mesh, MeshOptions, mesh_hash, validate_mesh
from .silhouette import mesh_topology, render_silhouette
from .views import ViewSphereOptions, template_rotations, view_count

FORMAT_VERSION = 2
#: Readable older versions and the array names they spelled differently (version 1: ``centre_rc``).
_OLD_NAMES = {1: {"centre_rc": "center_rc"}}
_MAGIC = "jaxlimb-template-db"

_PER_TEMPLATE = ("alpha", "beta", "R_body_to_camera", "area", "center_rc", "hu", "orientation", "elongation", "attitude_xy",
                 "contour_xy")  # fmt: skip


@dataclass(frozen=True)
class DatabaseOptions:
    """Settings of a template database (all stored in the file and checked on load).

    Parameters
    ----------
    step_deg, pole_axis, rings
        View-sphere sampling, see :class:`~jaxlimb.irregular.views.ViewSphereOptions`.
    template_size_px
        Side of the square template image (px).
    fill_fraction
        Fraction of the template width spanned by the body's bounding sphere.
    distance_factor
        Viewpoint distance in units of the body's bounding radius (paper: ~3x the
        long axis; default 50, see the module docstring).
    n_contour
        Number of stored contour points per template.
    """

    step_deg: float = 3.0
    pole_axis: str = "z"
    rings: str = "paper"
    template_size_px: int = 512
    fill_fraction: float = 0.8
    distance_factor: float = 50.0
    n_contour: int = 128

    def __post_init__(self) -> None:
        ViewSphereOptions(self.step_deg, self.pole_axis, self.rings)  # validates those three
        from .._validate import Range, number

        number(self.template_size_px, "`template_size_px`", Range(32, 8192), integer=True)
        number(self.fill_fraction, "`fill_fraction`", Range(0.1, 0.95))
        number(self.distance_factor, "`distance_factor`", Range(1.5, 1e6))
        number(self.n_contour, "`n_contour`", Range(16, 4096), integer=True)

    @property
    def view_sphere(self) -> ViewSphereOptions:
        return ViewSphereOptions(self.step_deg, self.pole_axis, self.rings)

    def to_json(self) -> str:
        """The settings as canonical JSON (sorted keys), as stored in the file and hashed into the cache name.

        Returns
        -------
        str
        """
        return json.dumps(dataclasses.asdict(self), sort_keys=True)

    @classmethod
    def from_json(cls, text: str) -> DatabaseOptions:
        """Settings from :meth:`to_json`'s text (validated like any :class:`DatabaseOptions`).

        Parameters
        ----------
        text : str
            A JSON object of the fields.

        Returns
        -------
        DatabaseOptions
        """
        d = json.loads(text)
        if not isinstance(d, dict):
            raise ValueError("settings are not a JSON object")
        return cls(**d)


@dataclass(frozen=True)
class TemplateDatabase:
    """Template features for every viewpoint, with the mesh and settings they came from.

    Per-template arrays (``N`` templates): ``alpha``, ``beta`` (rad, Eq. 5);
    ``R_body_to_camera`` ``(N,3,3)``; ``area`` ``S_B`` (px^2); ``center_rc``
    ``C_B``; ``hu`` ``(N,7)``; ``orientation`` (rad); ``elongation``;
    ``attitude_xy`` ``C_B F_B`` (x=col, y=row); ``contour_xy`` ``(N,n,2)``
    relative to ``C_B``.  Template camera: ``focal_px``, ``principal_rc``
    (= ``P_B`` for every template), body centre at distance ``distance_km``.
    """

    options: DatabaseOptions
    mesh: Mesh
    mesh_hash: str
    focal_px: float
    principal_rc: tuple[float, float]
    distance_km: float
    alpha: np.ndarray
    beta: np.ndarray
    R_body_to_camera: np.ndarray
    area: np.ndarray
    center_rc: np.ndarray
    hu: np.ndarray
    orientation: np.ndarray
    elongation: np.ndarray
    attitude_xy: np.ndarray
    contour_xy: np.ndarray

    def __len__(self) -> int:
        return int(self.alpha.shape[0])

    @property
    def center_image_rc(self) -> np.ndarray:
        """``P_B``: the image of the body centre in every template (the principal point)."""
        return np.asarray(self.principal_rc, dtype=float)


def _template_camera(mesh: Mesh, options: DatabaseOptions) -> tuple[float, tuple[float, float], float]:
    S = options.template_size_px
    distance = options.distance_factor * mesh.max_radius
    half_angle = math.asin(1.0 / options.distance_factor)
    focal = options.fill_fraction * (S / 2.0) / math.tan(half_angle)
    pp = ((S - 1) / 2.0, (S - 1) / 2.0)
    return focal, pp, distance


def estimated_nbytes(options: DatabaseOptions) -> float:
    """Memory (bytes) a build with ``options`` needs: the per-template arrays, held about
    three times (the arrays, their copy for the file, the checksum pass), and the template image.

    Parameters
    ----------
    options : DatabaseOptions
        View-sphere step, rings, contour points and template size.

    Returns
    -------
    float
    """
    per_template = 8 * (2 + 9 + 1 + 2 + 7 + 1 + 1 + 2) + 4 * 2 * options.n_contour
    n = view_count(options.step_deg, options.rings)
    return 3.0 * n * per_template + 32.0 * options.template_size_px**2


def build_database(mesh: Mesh, options: DatabaseOptions = DatabaseOptions(), progress: bool = True) -> TemplateDatabase:
    """Render every template and extract its features (Sec. 3 of Wu et al.).

    Parameters
    ----------
    mesh
        A validated mesh (:func:`~jaxlimb.irregular.mesh.load_mesh`).
    options
        Database settings.
    progress
        Show a tqdm progress bar (on stderr).

    Returns
    -------
    TemplateDatabase
        The features of one template per viewpoint (Eq. 5-14) with the mesh and settings.
    """
    from tqdm import tqdm

    from .._validate import check_memory

    check_memory(estimated_nbytes(options), f"a template database of {view_count(options.step_deg, options.rings)} "
                 f"views (step {options.step_deg:g} deg)")
    topo = mesh_topology(mesh)
    focal, pp, distance = _template_camera(mesh, options)
    S = options.template_size_px
    alpha, beta, R = template_rotations(options.view_sphere)
    f = [_template_features(topo, R[i], np.array([0.0, 0.0, distance]), focal, pp, S, options.n_contour,
                            (alpha[i], beta[i], i))
         for i in tqdm(range(alpha.shape[0]), desc="templates", unit="view", disable=not progress, mininterval=0.5)]
    return TemplateDatabase(
        options=options, mesh=mesh, mesh_hash=mesh_hash(mesh), focal_px=float(focal),
        principal_rc=(float(pp[0]), float(pp[1])), distance_km=float(distance), alpha=alpha, beta=beta,
        R_body_to_camera=R, area=np.array([x.area for x in f], float), center_rc=np.array([x.center_rc for x in f], float),
        hu=np.array([x.hu for x in f], float), orientation=np.array([x.orientation for x in f], float),
        elongation=np.array([x.elongation for x in f], float), attitude_xy=np.array([x.attitude_xy for x in f], float),
        contour_xy=np.array([x.contour_xy for x in f], dtype=np.float32),
    )


def _template_features(topo, R, t, focal, pp, S: int, n_contour: int, where: tuple):  # type: ignore[no-untyped-def]
    """The features of one template's silhouette (an empty figure is a DatabaseError naming the view)."""
    _, contours = render_silhouette(topo, R, t, focal, pp, (S, S))
    if not contours:
        a, b, i = where
        raise DatabaseError(f"template {i} (alpha={a:.4f}, beta={b:.4f}) has an empty figure")
    return features_from_contours(contours, n_contour)


# --------------------------------------------------------------------------- file I/O
def _arrays(db: TemplateDatabase) -> dict[str, np.ndarray]:
    d: dict[str, np.ndarray] = {
        "magic": np.array(_MAGIC),
        "format_version": np.array(FORMAT_VERSION, dtype=np.int64),
        "settings_json": np.array(db.options.to_json()),
        "mesh_hash": np.array(db.mesh_hash),
        "mesh_vertices": np.asarray(db.mesh.vertices, dtype=np.float64),
        "mesh_faces": np.asarray(db.mesh.faces, dtype=np.int64),
        "camera": np.array([db.focal_px, db.principal_rc[0], db.principal_rc[1], db.distance_km]),
        "built_by": np.array(built_by()),
    }
    for k in _PER_TEMPLATE:
        d[k] = np.asarray(getattr(db, k))
    return d


def built_by() -> str:
    """The versions a database's templates depend on: NumPy, OpenCV (the silhouettes) and the file format.

    Returns
    -------
    str
        ``"numpy=...;opencv=...;format=N"``.
    """
    import cv2

    return f"numpy={np.__version__};opencv={cv2.__version__};format={FORMAT_VERSION}"


def _checksum(arrays: dict[str, np.ndarray]) -> str:
    h = hashlib.sha256()
    for k in sorted(arrays):
        if k == "checksum":
            continue
        a = np.ascontiguousarray(arrays[k])
        h.update(k.encode())
        h.update(str(a.dtype).encode())
        h.update(str(a.shape).encode())
        h.update(a.tobytes())
    return h.hexdigest()


def save_database(db: TemplateDatabase, path: str | os.PathLike[str]) -> Path:
    """Write ``db`` to ``path`` (``.npz``, format of the module docstring) atomically.

    Parameters
    ----------
    db : TemplateDatabase
        The database.
    path : str or os.PathLike
        Output file.

    Returns
    -------
    Path
        ``path``.
    """
    p = Path(path)
    arrays = _arrays(db)
    arrays["checksum"] = np.array(_checksum(arrays))
    with atomic_open(p, "wb") as fh:
        np.savez_compressed(fh, **arrays)  # type: ignore[arg-type]
    return p


def load_database(
    path: str | os.PathLike[str], expected_mesh_hash: str | None = None, expected_options: DatabaseOptions | None = None,
    expected_built_by: str | None = None,
) -> TemplateDatabase:  # fmt: skip
    """Read and verify a database file; see the module docstring.

    Parameters
    ----------
    path : str or os.PathLike
        A file written by :func:`save_database`.
    expected_mesh_hash, expected_options, expected_built_by : optional
        If given, the file must hold this mesh (:func:`~.mesh.mesh_hash`), settings and :func:`built_by`.

    Returns
    -------
    TemplateDatabase

    Raises
    ------
    DatabaseError
        Missing, truncated or corrupt file, other format version, checksum or mesh-hash mismatch, or other
        mesh / settings / builder than expected.
    """
    from .._validate import input_file

    p = input_file(path, "template database", error=DatabaseError)
    arrays = _upgrade(_read_arrays(p), p)
    need = {"magic", "format_version", "settings_json", "mesh_hash", "mesh_vertices", "mesh_faces", "camera", "checksum"}
    missing = sorted((need | set(_PER_TEMPLATE)) - set(arrays))
    if missing:
        raise DatabaseError(f"template database {str(p)!r} lacks arrays {missing}: not a jaxlimb database or corrupt")
    try:
        options = DatabaseOptions.from_json(str(arrays["settings_json"]))
    except (ValueError, TypeError, ConfigError) as e:
        raise DatabaseError(f"template database {str(p)!r} has unreadable settings: {e}") from None
    stored_hash = str(arrays["mesh_hash"])
    try:
        mesh = validate_mesh(arrays["mesh_vertices"], arrays["mesh_faces"], MeshOptions(repair=False), source=p.name)
    except Exception as e:
        raise DatabaseError(f"template database {str(p)!r} holds an invalid mesh: {e}") from None
    if mesh_hash(mesh) != stored_hash:
        raise DatabaseError(f"template database {str(p)!r}: stored mesh does not match its hash")
    _check_expected(p, arrays, options, expected_mesh_hash, expected_options, expected_built_by)
    _check_template_arrays(p, arrays, options)
    cam = arrays["camera"]
    return TemplateDatabase(
        options=options, mesh=mesh, mesh_hash=stored_hash, focal_px=float(cam[0]), principal_rc=(float(cam[1]), float(cam[2])),
        distance_km=float(cam[3]), **{k: arrays[k] for k in _PER_TEMPLATE},
    )  # fmt: skip


def _read_arrays(p: Path) -> dict:
    """Every array of the file (reading each member checks its CRC); a damaged file is a DatabaseError."""
    try:
        with open(p, "rb") as fh, np.load(fh, allow_pickle=False) as z:
            return {k: z[k] for k in z.files}
    except (zipfile.BadZipFile, OSError, ValueError, EOFError, KeyError, zipfile.LargeZipFile) as e:
        raise DatabaseError(f"template database {str(p)!r} is corrupt or truncated: {type(e).__name__}: {e}") from None
    except Exception as e:  # zlib.error and friends
        raise DatabaseError(f"template database {str(p)!r} cannot be read: {type(e).__name__}: {e}") from None


def _check_expected(p: Path, arrays: dict, options: DatabaseOptions, expected_mesh_hash: str | None,
                    expected_options: DatabaseOptions | None, expected_built_by: str | None) -> None:
    """The mesh, builder and settings the caller expects."""
    stored_hash = str(arrays["mesh_hash"])
    if expected_mesh_hash is not None and stored_hash != expected_mesh_hash:
        raise DatabaseError(
            f"template database {str(p)!r} was built for mesh {stored_hash[:12]}..., not for the given mesh"
            f" {expected_mesh_hash[:12]}..."
        )
    if expected_built_by is not None and str(arrays.get("built_by", "")) != expected_built_by:
        raise DatabaseError(f"template database {str(p)!r} was built by {str(arrays.get('built_by', 'an older jaxlimb'))}"
                            f", not {expected_built_by}")
    if expected_options is not None and options != expected_options:
        raise DatabaseError(
            f"template database {str(p)!r} was built with settings {options.to_json()}, expected"
            f" {expected_options.to_json()}"
        )


def _check_template_arrays(p: Path, arrays: dict, options: DatabaseOptions) -> None:
    """Every per-template array has the shape of ``n`` templates and finite values; the camera is valid."""
    n = arrays["alpha"].shape[0]
    shapes = {
        "alpha": (n,), "beta": (n,), "R_body_to_camera": (n, 3, 3), "area": (n,), "center_rc": (n, 2), "hu": (n, 7),
        "orientation": (n,), "elongation": (n,), "attitude_xy": (n, 2), "contour_xy": (n, options.n_contour, 2),
    }
    for k, shp in shapes.items():
        if arrays[k].shape != shp or not np.all(np.isfinite(arrays[k])):
            raise DatabaseError(f"template database {str(p)!r}: array {k!r} has shape {arrays[k].shape}, expected {shp}")
    cam = arrays["camera"]
    if n < 2 or cam.shape != (4,) or not np.all(np.isfinite(cam)) or not np.all(arrays["area"] > 0):
        raise DatabaseError(f"template database {str(p)!r} holds invalid template data")


def _upgrade(arrays: dict, p: Path) -> dict:
    """Check magic, version and checksum as stored; rename an older version's arrays to today's names."""
    for k in ("magic", "format_version", "checksum"):
        if k not in arrays:
            raise DatabaseError(f"template database {str(p)!r} lacks arrays [{k!r}]: not a jaxlimb database or corrupt")
    if str(arrays["magic"]) != _MAGIC:
        raise DatabaseError(f"{str(p)!r} is not a jaxlimb template database")
    version = int(arrays["format_version"])
    if version != FORMAT_VERSION and version not in _OLD_NAMES:
        raise DatabaseError(
            f"template database {str(p)!r} has format version {version}; this jaxlimb reads versions"
            f" {sorted({FORMAT_VERSION, *_OLD_NAMES})} (rebuild it with `jaxlimb los build-db`)"
        )
    if str(arrays["checksum"]) != _checksum(arrays):
        raise DatabaseError(f"template database {str(p)!r} fails its checksum: corrupt")
    renames = _OLD_NAMES.get(version, {})
    return {renames.get(k, k): v for k, v in arrays.items()}


def cache_dir() -> Path:
    """Database cache directory: ``$JAXLIMB_CACHE`` or ``~/.cache/jaxlimb``.

    Returns
    -------
    Path
    """
    env = os.environ.get("JAXLIMB_CACHE")
    return Path(env) if env else Path.home() / ".cache" / "jaxlimb"


def cache_path(mesh: Mesh, options: DatabaseOptions) -> Path:
    """Cache file name for a mesh and settings (both hashed into the name).

    Parameters
    ----------
    mesh : Mesh
        The shape model.
    options : DatabaseOptions
        The settings.

    Returns
    -------
    Path
        ``cache_dir() / los-templates-v{FORMAT_VERSION}-{mesh hash}-{settings hash}.npz``.
    """
    sh = hashlib.sha256(options.to_json().encode()).hexdigest()[:12]
    return cache_dir() / f"los-templates-v{FORMAT_VERSION}-{mesh_hash(mesh)[:16]}-{sh}.npz"


def cached_database(mesh: Mesh, options: DatabaseOptions = DatabaseOptions(), progress: bool = True) -> TemplateDatabase:
    """Load the cached database for ``mesh`` and ``options``, building (and caching) it if needed.

    A cached file that fails verification, or was built by other versions (:func:`built_by`), is
    deleted, rebuilt and replaced, and one warning says so; a cache that cannot be written (a full
    disk, ``JAXLIMB_CACHE`` naming a file) is skipped with one warning.

    Parameters
    ----------
    mesh, options, progress
        As :func:`build_database`.

    Returns
    -------
    TemplateDatabase
    """
    from .._jaxcache import warn_once

    p = cache_path(mesh, options)
    if p.is_file():
        try:
            return load_database(p, expected_mesh_hash=mesh_hash(mesh), expected_options=options,
                                 expected_built_by=built_by())
        except DatabaseError as e:
            with contextlib.suppress(OSError):
                p.unlink()
            warn_once("template-database-cache", f"cached template database rebuilt: {e}")
    db = build_database(mesh, options, progress=progress)
    try:
        save_database(db, p)
    except (OSError, ValueError) as e:  # OutputWriteError is a ValueError
        warn_once("template-database-cache-write", f"the template database cache cannot be written ({e}): "
                  "the database is used without being cached")
    return db


__all__ = [
    "FORMAT_VERSION", "DatabaseOptions", "built_by", "TemplateDatabase", "build_database", "cache_dir", "cache_path",
    "cached_database", "load_database", "save_database",
]  # fmt: skip
