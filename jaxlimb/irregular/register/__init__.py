r"""Render-and-register: the body-centre image by registering the rendered shape model (beyond Wu et al.).

Operational optical navigation of irregular bodies renders the *predicted* lit image of the shape model
for the attitude ``R_body_to_camera`` and Sun direction, and registers it to the frame.  The body centre
is placed at ``t = D u(P)`` on the line of sight of its image ``P`` (Eq. 4 of Wu et al.), so ``P`` is the
estimate itself and no template approximation remains.

1. **Start** (:mod:`.start`): the pose from the lit figure's extents, then the peak of the normalised
   cross-correlation of the rendered model.
2. **Photometric Gauss-Newton** (:mod:`.gauss_newton`, :mod:`.design`): the linearised model

   .. math::  I(x) \approx a\,M(x; P, s) + b\,(1 - C), \qquad
              M(x; P + \delta, s + \delta_s) \approx M - \delta\cdot\nabla M - \delta_s\,(x - P)\cdot\nabla M

   is linear in ``(a, b, a delta, a delta_s)`` (and the attitude, albedo, surge, pedestal and photometric
   mix columns); each iteration re-renders ``M`` at the new pose, coarse to fine on a pyramid
   (:mod:`.pyramid`).
3. **Covariance and checks** (:mod:`.checks`): the solve's covariance with a model-error term; the residual
   excess over the noise, the overlap of the figures and the centre's sigma give typed failures
   (:class:`~jaxlimb.errors.MatchError`, exit 3).
4. **The lit limb** (attitude known, high phase; :mod:`.registration`): the centre is combined with the edge
   positions of the lit limb alone (:mod:`jaxlimb.irregular.limb_edges`).

Rendering: :func:`jaxlimb.render.mesh.rasterise` in a window camera around the body
(:func:`jaxlimb.irregular.model_render.render_window`).
"""

from .options import RegisterOptions as RegisterOptions
from .options import RegisterResult as RegisterResult
from .pyramid import render_model as render_model
from .registration import Registration as Registration
from .registration import complete_search_registration as complete_search_registration
from .registration import register_known_attitude as register_known_attitude
from .registration import start_search_registration as start_search_registration
from .start import initial_center as initial_center
from .start import lit_figure as lit_figure
from .start import ncc_shift as ncc_shift
from .start import phase_angle_deg as phase_angle_deg

__all__ = [
    "RegisterOptions", "RegisterResult", "Registration", "complete_search_registration", "initial_center", "lit_figure",
    "ncc_shift", "phase_angle_deg", "register_known_attitude", "render_model", "start_search_registration",
]  # fmt: skip
