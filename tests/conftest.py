"""Test configuration: float64 everywhere (estimation runs in float64)."""

import os

# The suite is compile-bound (XLA's compilation is most of a pipeline test's time), so its programs are compiled
# without XLA's backend optimisation: the answers agree with an optimised build to rounding.  A test of what a user's
# process does exactly runs it in a subprocess without this flag; speed is measured by the benchmarks, with the
# user's defaults.
os.environ["XLA_FLAGS"] = f"{os.environ.get('XLA_FLAGS', '')} --xla_backend_optimization_level=0".strip()

import shutil  # noqa: E402
import tempfile  # noqa: E402

import jax  # noqa: E402 - after XLA_FLAGS
import numpy as np  # noqa: E402
import pytest  # noqa: E402

from jaxlimb._jaxcache import enable_compile_cache  # noqa: E402

_RUN_CACHE = "JAXLIMB_TEST_RUN_CACHE"

jax.config.update("jax_enable_x64", True)


@pytest.fixture
def rng() -> np.random.Generator:
    """A seeded NumPy generator (tests never use unseeded randomness)."""
    return np.random.default_rng(20261121)


# One compilation cache for the run (jaxlimb._jaxcache), new and empty: the two workers and the commands the tests
# start load what another compiled instead of compiling it again (most of the suite's time is compilation).  A test of
# the cache itself gives its own directory (tests/cli/test_speed_cli.py, tests/test_programs.py); a
# JAXLIMB_CACHE_DIR set by the caller is used as it is (``off`` runs the suite without a cache).
if "JAXLIMB_CACHE_DIR" not in os.environ:  # the controller (or a run without workers): the workers inherit it
    os.environ["JAXLIMB_CACHE_DIR"] = os.environ[_RUN_CACHE] = tempfile.mkdtemp(prefix="jaxlimb-test-cache-")
    os.environ[_RUN_CACHE + "_OWNER"] = str(os.getpid())
enable_compile_cache()


def pytest_unconfigure(config):
    """The run's cache goes with the run: removed by the process that made it (the controller, after its workers have
    stopped; never a worker or a process a test started, which inherit the variables)."""
    if os.environ.get(_RUN_CACHE + "_OWNER") == str(os.getpid()):
        shutil.rmtree(os.environ[_RUN_CACHE], ignore_errors=True)


@pytest.fixture(autouse=True)
def _bounded_compiled_programs():
    """After every test, the worker's compiled programs are dropped once they hold half the kernel's limit of memory
    maps (jaxlimb._programs.bound_compiled_programs): a long-lived worker would otherwise abort in XLA's compiler."""
    yield
    from jaxlimb._programs import bound_compiled_programs

    bound_compiled_programs()
