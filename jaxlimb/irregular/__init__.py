"""Irregular bodies: model-based line of sight (Wu, Zou, Xu and Mao).

Shape model (:mod:`.mesh`) -> view sphere (Eq. 5-7, :mod:`.views`) -> template silhouettes and
features (Eq. 9-14, :mod:`.silhouette`, :mod:`.features`) -> template database (:mod:`.database`)
-> Hu-moment matching (Eq. 15-17) and the similarity transform to the body-centre image
(Eq. 18-25) on the rectified figure (:mod:`.matching`, :mod:`.rectify`) -> line of sight
(Eq. 1-4); the FC/BC baselines; a local densification and soft-silhouette refinement of the
match (:mod:`.densify`, :mod:`.refine`, beyond the paper).

Beyond the paper, for frames at any phase: :func:`locate_los` (:mod:`.locate`) -- phase-aware
template search (:mod:`.phase`) and render-and-register with the attitude known or fitted
(:mod:`.register`), with typed failures when the model does not explain the frame; generated
test bodies in :mod:`.shapes`.
"""

from .database import DatabaseOptions as DatabaseOptions
from .database import TemplateDatabase as TemplateDatabase
from .database import build_database as build_database
from .database import cache_path as cache_path
from .database import cached_database as cached_database
from .database import load_database as load_database
from .database import save_database as save_database
from .densify import DensifyResult as DensifyResult
from .densify import densify_match as densify_match
from .features import FigureFeatures as FigureFeatures
from .features import features_from_contours as features_from_contours
from .features import features_from_mask as features_from_mask
from .features import hu_from_central as hu_from_central
from .features import log_hu as log_hu
from .locate import LosMode as LosMode
from .locate import LosOptions as LosOptions
from .locate import LosResult as LosResult
from .locate import locate_los as locate_los
from .matching import LocateResult as LocateResult
from .matching import MatchOptions as MatchOptions
from .matching import line_of_sight as line_of_sight
from .matching import locate_center as locate_center
from .matching import match_weights as match_weights
from .matching import rotation_from_attitude as rotation_from_attitude
from .matching import shape_distance as shape_distance
from .matching import similarity_center as similarity_center
from .mesh import Mesh as Mesh
from .mesh import MeshOptions as MeshOptions
from .mesh import load_mesh as load_mesh
from .mesh import mesh_hash as mesh_hash
from .mesh import validate_mesh as validate_mesh
from .silhouette import SegmentOptions as SegmentOptions
from .silhouette import brightness_center as brightness_center
from .silhouette import figure_center as figure_center
from .silhouette import mesh_topology as mesh_topology
from .silhouette import render_silhouette as render_silhouette
from .silhouette import segment_body as segment_body
from .views import ViewSphereOptions as ViewSphereOptions
from .views import camera_transform as camera_transform
from .views import project_points as project_points
from .views import template_rotations as template_rotations
from .views import view_angles as view_angles
from .views import view_count as view_count

# The refinement imports JAX and optimistix (seconds): loaded on first use only, so that
# ``jaxlimb los locate`` (numpy + OpenCV) does not pay for them.
_LAZY = {"RefineOptions", "RefineResult", "refine_center"}


def __getattr__(name: str):  # type: ignore[no-untyped-def]
    if name in _LAZY:
        from . import refine

        return getattr(refine, name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
