"""Test configuration: float64 everywhere (estimation runs in float64)."""

import atexit
import os
import shutil
import tempfile

import jax
import numpy as np
import pytest

from jaxlimb._jaxcache import enable_compile_cache

jax.config.update("jax_enable_x64", True)


@pytest.fixture
def rng() -> np.random.Generator:
    """A seeded NumPy generator (tests never use unseeded randomness)."""
    return np.random.default_rng(20261121)


# One persistent compilation cache (jaxlimb._jaxcache) for the whole run, as the CLI uses one: both xdist workers
# and every jaxlimb process a test starts compile each program once.  A fresh directory per run (the workers and
# the processes inherit it through the environment), removed at the end; JAXLIMB_CACHE_DIR set by the caller wins
# (``off`` runs the suite without it).  Tests of the cache itself set their own directories.
if "JAXLIMB_CACHE_DIR" not in os.environ:
    os.environ["JAXLIMB_CACHE_DIR"] = tempfile.mkdtemp(prefix="jaxlimb-tests-jax-")
    atexit.register(shutil.rmtree, os.environ["JAXLIMB_CACHE_DIR"], True)
enable_compile_cache()
