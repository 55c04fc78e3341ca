r"""Scale-out of batched limb fits over JAX devices (sharding).

:func:`sharded_fit_batch` is :func:`jaxlimb.fitting.fit_batch` with the batch split over
all local devices: the padded problem arrays are placed with a
``NamedSharding(Mesh(devices, ("batch",)), PartitionSpec("batch"))`` and the fit core runs
under ``jax.shard_map``, so each device fits its own members one after another
(``jax.lax.map``, as ``fit_batch(strategy="map")``) with no communication between
devices.  The batch is padded to a multiple of the device count with copies of its first
member, which are dropped from the result.  Results equal :func:`fit_batch`'s to rounding.

Devices.  On a CPU-only machine, XLA exposes one device per process unless asked:
set ``XLA_FLAGS=--xla_force_host_platform_device_count=N`` *before* ``jax`` is imported
(the tests do this in a subprocess).  Each device then runs on its own thread, so the
speed-up is bounded by the physical cores.  On GPU/TPU hosts the local accelerators are
used as they are.

Multi-host path (documented, not exercised by the tests).  On a cluster, start one
process per host and call ``jax.distributed.initialize()`` (coordinator address, number of
processes and process id from the arguments or the cluster's environment, e.g. SLURM)
before any other JAX call.  Then ``jax.devices()`` lists the devices of *all* hosts and
``jax.local_devices()`` those of this host.  Build the mesh over ``jax.devices()`` and give
each process its own slice of the Monte-Carlo batch: the per-trial seeds of
:func:`jaxlimb.analysis.montecarlo.trial_seed` make the slices independent of the split,
so process ``p`` of ``P`` simply runs
``run_monte_carlo(trial, MonteCarloOptions(..., out_dir=SHARED, shard=(p, P)))`` -- chunks
``p, p + P, ...`` -- into a shared directory (the chunk files are written atomically, so
hosts never see each other's partial files), and any process reads the whole study with
:func:`~jaxlimb.analysis.montecarlo.load_monte_carlo` at the end.  Inside each process,
:func:`sharded_fit_batch` spreads its chunk over the local devices (``devices=jax.local_devices()``,
no cross-host communication).  For one
global batch instead, assemble it with ``jax.make_array_from_process_local_data(sharding,
local_rows)`` and collect the results with
``jax.experimental.multihost_utils.process_allgather``; a global mesh over ``jax.devices()``
is then the ``devices`` argument (:func:`sharded_fit_batch` itself places host-local NumPy
data, so it is the single-host building block).
"""

from __future__ import annotations

import time
from collections.abc import Sequence
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np
from jax.sharding import Mesh, NamedSharding, PartitionSpec

from ..errors import LimbInputError
from ..fitting import AbstractLimbSolver, LimbFit, LimbProblem, NormalLM, batch_core, batch_problem
from ..models import LimbModel, LimbParams

_CACHE: dict[Any, Any] = {}


def _sharded_core(solver: AbstractLimbSolver, model: LimbModel, free_idx: tuple[int, ...], analytic: bool,
                  max_steps: int, mesh: Mesh):  # noqa: ANN202
    key = (solver, model.name, free_idx, analytic, max_steps, tuple(d.id for d in mesh.devices.flat))
    if key in _CACHE:
        return _CACHE[key]
    spec = PartitionSpec("batch")

    def per_device(theta: jax.Array, coords: jax.Array, z: jax.Array, w: jax.Array) -> LimbFit:
        return batch_core(solver, LimbProblem(model, free_idx, analytic, theta, coords, z, w), max_steps)

    fn = jax.jit(jax.shard_map(per_device, mesh=mesh, in_specs=(spec, spec, spec, spec), out_specs=spec,
                                check_vma=False))  # solver loops start from replicated constants
    _CACHE[key] = fn
    return fn


def local_mesh(devices: Sequence[jax.Device] | None = None) -> Mesh:
    """A 1-D ``("batch",)`` mesh over ``devices`` (default: ``jax.local_devices()``)."""
    devs = list(devices) if devices is not None else jax.local_devices()
    if not devs:
        raise LimbInputError("`devices` is empty")
    return Mesh(np.array(devs), ("batch",))


def sharded_fit_batch(
    model: LimbModel,
    coords: Any,
    z: Any,
    init: LimbParams,
    solver: AbstractLimbSolver | None = None,
    *,
    fixed: Sequence[str] = (),
    weights: Any = None,
    analytic: bool = True,
    max_steps: int = 256,
    devices: Sequence[jax.Device] | None = None,
) -> LimbFit:
    """:func:`jaxlimb.fitting.fit_batch` with the batch sharded over devices (module docstring).

    Same arguments and result as :func:`~jaxlimb.fitting.fit_batch` (``coords`` ``(B, N, 2)``,
    ``z`` ``(B, N)``, ``init`` with ``(B,)`` fields), plus ``devices`` (default: all local
    devices).  The returned arrays are sharded over the devices along the batch axis
    (``np.asarray`` gathers them).  Never raises on non-convergence.

    Raises
    ------
    LimbInputError
        As :func:`~jaxlimb.fitting.fit_batch`; a non-jittable solver.
    """
    solver = NormalLM() if solver is None else solver
    if not solver.jittable:
        raise LimbInputError(f"`solver` {solver.name} cannot be batched (not jittable)")
    problem = batch_problem(model, coords, z, init, fixed=fixed, weights=weights, analytic=analytic)
    free_idx = problem.free_idx
    theta, coords_, z_, w_ = (np.asarray(a) for a in problem.args)
    mesh = local_mesh(devices)
    n_dev = mesh.devices.size
    b = z_.shape[0]
    pad = (-b) % n_dev
    if pad:
        rep = lambda a: np.concatenate([a, np.repeat(a[:1], pad, axis=0)], axis=0)  # noqa: E731
        coords_, z_, w_, theta = rep(coords_), rep(z_), rep(w_), rep(theta)
    sharding = NamedSharding(mesh, PartitionSpec("batch"))
    args = [jax.device_put(jnp.asarray(a), sharding) for a in (theta, coords_, z_, w_)]
    res = _sharded_core(solver, model, free_idx, analytic, max_steps, mesh)(*args)
    if pad:
        res = jax.tree_util.tree_map(lambda a: a[:b], res)
    return res


def sharding_speedup(model: LimbModel, coords: Any, z: Any, init: LimbParams, solver: AbstractLimbSolver | None = None,
                     *, fixed: Sequence[str] = (), repeats: int = 3) -> dict[str, float]:
    """Time :func:`sharded_fit_batch` on all local devices against one device (best of ``repeats``).

    Both are compiled before timing.  Returns ``{"n_devices", "one_device_s",
    "all_devices_s", "speedup", "batch"}``.
    """
    devs = jax.local_devices()
    out: dict[str, float] = {"n_devices": float(len(devs)), "batch": float(np.shape(z)[0])}
    for key, d in (("one_device_s", devs[:1]), ("all_devices_s", devs)):
        jax.block_until_ready(sharded_fit_batch(model, coords, z, init, solver, fixed=fixed, devices=d))
        best = np.inf
        for _ in range(repeats):
            t0 = time.perf_counter()
            jax.block_until_ready(sharded_fit_batch(model, coords, z, init, solver, fixed=fixed, devices=d))
            best = min(best, time.perf_counter() - t0)
        out[key] = best
    out["speedup"] = out["one_device_s"] / out["all_devices_s"]
    return out


__all__ = ["local_mesh", "sharded_fit_batch", "sharding_speedup"]
