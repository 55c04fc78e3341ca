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

from typing import TYPE_CHECKING, Any

from . import errors as errors

if TYPE_CHECKING:  # pragma: no cover
    from .geometry.camera import Camera as Camera
    from .models import (
        CIRCLE as CIRCLE,
        ELLIPSE as ELLIPSE,
        LINEAR as LINEAR,
        CircleParams as CircleParams,
        EllipseParams as EllipseParams,
        LinearParams as LinearParams,
    )

# Imported on first use, so that ``import jaxlimb`` (and ``jaxlimb --help``) does not pay for JAX.
_LAZY = {"Camera": "geometry.camera", "CIRCLE": "models", "ELLIPSE": "models", "LINEAR": "models",
         "CircleParams": "models", "EllipseParams": "models", "LinearParams": "models"}


def __getattr__(name: str) -> Any:
    if name in _LAZY:
        import importlib

        return getattr(importlib.import_module(f"{__name__}.{_LAZY[name]}"), name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


__version__ = "0.1.0"
