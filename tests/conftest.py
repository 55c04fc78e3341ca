"""Test configuration: float64 everywhere (estimation runs in float64)."""

import os

import jax
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
