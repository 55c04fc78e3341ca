"""jaxlimb: limb-based optical navigation with differentiable JAX models.

Estimation runs in float64.  JAX defaults to float32; enable 64-bit before any
computation::

    import jax
    jax.config.update("jax_enable_x64", True)

In float32 a fit can still report convergence while its tolerances sit below
the arithmetic precision (centre errors of ~1e-3 px appear from rounding
alone); :func:`jaxlimb.fitting.fit` warns when it sees float32 data.  The
``jaxlimb`` command, the tests and the benchmarks enable x64 themselves.
"""

from . import errors as errors
from .geometry.camera import Camera as Camera
from .models import (
    CIRCLE as CIRCLE,
    ELLIPSE as ELLIPSE,
    LINEAR as LINEAR,
    CircleParams as CircleParams,
    EllipseParams as EllipseParams,
    LinearParams as LinearParams,
)

__version__ = "0.1.0"
