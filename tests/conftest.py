"""Test configuration: float64 everywhere (estimation runs in float64)."""

import os

# The suite is compile-bound (XLA's compilation is most of a pipeline test's time), so its programs are compiled
# without XLA's backend optimisation: the answers agree with an optimised build to rounding.  A test of what a user's
# process does exactly runs it in a subprocess without this flag; speed is measured by the benchmarks, with the
# user's defaults.
os.environ["XLA_FLAGS"] = f"{os.environ.get('XLA_FLAGS', '')} --xla_backend_optimization_level=0".strip()

import jax  # noqa: E402 - after XLA_FLAGS
import numpy as np
import pytest

jax.config.update("jax_enable_x64", True)


@pytest.fixture
def rng() -> np.random.Generator:
    """A seeded NumPy generator (tests never use unseeded randomness)."""
    return np.random.default_rng(20261121)


# The CLI switches JAX's persistent compilation cache on (jaxlimb._jaxcache); the suite runs
# without it unless a test asks for it (tests/cli/test_speed_cli.py does, in subprocesses).
os.environ.setdefault("JAXLIMB_CACHE_DIR", "off")


@pytest.fixture(autouse=True)
def _bounded_compiled_programs():
    """After every test, the worker's compiled programs are dropped once they hold half the kernel's limit of memory
    maps (jaxlimb._programs.bound_compiled_programs): a long-lived worker would otherwise abort in XLA's compiler."""
    yield
    from jaxlimb._programs import bound_compiled_programs

    bound_compiled_programs()
