"""Test configuration: float64 everywhere (estimation runs in float64)."""

import jax
import numpy as np
import pytest

jax.config.update("jax_enable_x64", True)


@pytest.fixture
def rng() -> np.random.Generator:
    """A seeded NumPy generator (tests never use unseeded randomness)."""
    return np.random.default_rng(20261121)
