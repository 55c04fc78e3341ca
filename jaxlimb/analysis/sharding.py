r"""Scale-out of batched limb fits over JAX devices (sharding).

:func:`sharded_fit_batch` is :func:`jaxlimb.fitting.fit_batch` with the batch split over
all local devices: the padded problem arrays are placed with a
``NamedSharding(Mesh(devices, ("batch",)), PartitionSpec("batch"))`` and the fit core runs
under ``jax.shard_map`` (:func:`per_device`: any solver, optimistix's too), so each device fits its own members one after another
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
from collections.abc import Callable, Sequence
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np
from jax.sharding import Mesh, NamedSharding, PartitionSpec

from ..errors import LimbInputError
from ..fitting import AbstractLimbSolver, LimbFit, LimbProblem, NormalLM, batch_core, batch_problem
from ..models import LimbModel, LimbParams

_CACHE: dict[Any, Any] = {}


def per_device(run: Callable[..., Any], example_args: Sequence[Any], batched: Sequence[bool],
               devices: Sequence[jax.Device] | None = None) -> Callable[..., Any]:
    """``run`` over a batch split across devices: each device runs it on its own share, without communication.

    ``run(*args)`` maps a batch (the leading axis of the ``batched`` arguments) to results with the same
    leading axis; ``example_args`` (arrays or ``jax.ShapeDtypeStruct``) fix the shapes of the *whole* batch,
    whose length must be a multiple of the device count.  Returns a jitted function of the whole batch (one
    compiled program for all devices; ``jax.jit(run)`` on one device).

    How.  ``run`` is traced on one device's share *outside* any mesh (``jax.make_jaxpr``) and its program
    replayed inside ``jax.shard_map`` (``jax.core.eval_jaxpr``).  Traced inside the shard map, every shape
    a library computes with ``jax.eval_shape`` carries the mesh's sharding while the ones it builds by hand
    do not, and lineax's operator checks compare the two: optimistix's solvers then fail with "Incompatible
    linear operator structures" (a lineax limitation, github.com/patrick-kidger/lineax/issues/185); the replayed program is the same computation.

    Parameters
    ----------
    run : callable
        ``run(*args)``: a batch (leading axis of the ``batched`` arguments) to results with that leading axis.
    example_args : sequence of array or jax.ShapeDtypeStruct
        Shapes and dtypes of the whole batch's arguments.
    batched : sequence of bool
        Per argument: split along its leading axis (True) or replicated on every device (False).
    devices : sequence of jax.Device, optional
        Default ``jax.local_devices()``.

    Returns
    -------
    callable
        A jitted function of the whole batch.

    Raises
    ------
    LimbInputError
        A batched argument whose length is not a multiple of the device count.
    """
    mesh = local_mesh(devices)
    n_dev = mesh.devices.size
    if n_dev == 1:
        return jax.jit(run)
    share = []
    for a, b in zip(example_args, batched):
        shape = tuple(np.shape(a))
        if b and shape[0] % n_dev:
            raise LimbInputError(f"a batch of {shape[0]} cannot be split evenly over {n_dev} devices")
        share.append(jax.ShapeDtypeStruct((shape[0] // n_dev, *shape[1:]) if b else shape, a.dtype))
    closed, out_shape = jax.make_jaxpr(run, return_shape=True)(*share)
    treedef = jax.tree_util.tree_structure(out_shape)

    def replay(*args: Any) -> Any:
        return jax.tree_util.tree_unflatten(treedef, jax.core.eval_jaxpr(closed.jaxpr, closed.consts, *args))

    specs = tuple(PartitionSpec("batch") if b else PartitionSpec() for b in batched)
    return jax.jit(jax.shard_map(replay, mesh=mesh, in_specs=specs, out_specs=PartitionSpec("batch"),
                                 check_vma=False))  # solver loops start from replicated constants


def _sharded_core(solver: AbstractLimbSolver, model: LimbModel, free_idx: tuple[int, ...], analytic: bool,
                  max_steps: int, mesh: Mesh, args: Sequence[Any]):  # noqa: ANN202
    key = (solver, model.name, free_idx, analytic, max_steps, tuple(d.id for d in mesh.devices.flat),
           tuple(np.shape(a) for a in args))
    if key not in _CACHE:
        def per_member(theta: jax.Array, coords: jax.Array, z: jax.Array, w: jax.Array) -> LimbFit:
            return batch_core(solver, LimbProblem(model, free_idx, analytic, theta, coords, z, w), max_steps)

        _CACHE[key] = per_device(per_member, args, (True,) * 4, list(mesh.devices.flat))
    return _CACHE[key]


def local_mesh(devices: Sequence[jax.Device] | None = None) -> Mesh:
    """A 1-D ``("batch",)`` mesh over ``devices`` (default: ``jax.local_devices()``).

    Parameters
    ----------
    devices : sequence of jax.Device, optional
        The devices, in mesh order.

    Returns
    -------
    jax.sharding.Mesh
        One axis named ``"batch"``.

    Raises
    ------
    LimbInputError
        ``devices`` is empty.
    """
    devs = list(devices) if devices is not None else jax.local_devices()
    if not devs:
        raise LimbInputError("`devices` is empty")
    return Mesh(np.array(devs), ("batch",))


def sharded_fit_batch(
    model: LimbModel, coords: Any, z: Any, init: LimbParams, solver: AbstractLimbSolver | None = None, *,
    fixed: Sequence[str] = (), weights: Any = None, analytic: bool = True, max_steps: int = 256,
    devices: Sequence[jax.Device] | None = None,
) -> LimbFit:
    """:func:`jaxlimb.fitting.fit_batch` with the batch sharded over devices (module docstring).

    Same arguments and result as :func:`~jaxlimb.fitting.fit_batch` (``coords`` ``(B, N, 2)``,
    ``z`` ``(B, N)``, ``init`` with ``(B,)`` fields), plus ``devices`` (default: all local
    devices).  The returned arrays are sharded over the devices along the batch axis
    (``np.asarray`` gathers them).  Never raises on non-convergence.

    Parameters
    ----------
    model : LimbModel
        The limb model of every member.
    coords : array (B, N, 2)
        Pixels as (row, col) per member (``(B, N)`` for the linear model).
    z : array (B, N)
        Intensities per member.
    init : LimbParams
        Start of every member, ``(B,)`` arrays in each field.
    solver : AbstractLimbSolver, optional
        A jittable solver; default :class:`~jaxlimb.fitting.NormalLM`.
    fixed : sequence of str
        Parameters held at their ``init`` values.
    weights : array (B, N), optional
        Per-pixel weights (zero marks padding); default all 1.
    analytic : bool
        Use the model's analytic Jacobian (else automatic differentiation).
    max_steps : int
        Iteration limit per member.
    devices : sequence of jax.Device, optional
        Default all local devices.

    Returns
    -------
    LimbFit
        Batched fit, ``(B,)`` leading axis on every field; check ``converged`` per member.

    Raises
    ------
    LimbInputError
        As :func:`~jaxlimb.fitting.fit_batch`; a non-jittable solver.
    """
    solver = NormalLM() if solver is None else solver
    if not solver.jittable:
        raise LimbInputError(f"`solver` {solver.name} cannot be batched (not jittable)")
    problem = batch_problem(model, coords, z, init, fixed=fixed, weights=weights, analytic=analytic)
    mesh = local_mesh(devices)
    args, b, pad = _sharded_args(problem, mesh)
    res = _sharded_core(solver, model, problem.free_idx, analytic, max_steps, mesh, args)(*args)
    if pad:
        res = jax.tree_util.tree_map(lambda a: a[:b], res)
    return res


def _sharded_args(problem: LimbProblem, mesh: Mesh) -> tuple[list[jax.Array], int, int]:
    """The problem's ``(theta, coords, z, w)`` sharded over ``mesh`` along the batch axis, the batch size ``b`` and
    the members appended (copies of the first) to fill the last device."""
    theta, coords_, z_, w_ = (np.asarray(a) for a in problem.args)
    n_dev = mesh.devices.size
    b = z_.shape[0]
    pad = (-b) % n_dev
    if pad:
        rep = lambda a: np.concatenate([a, np.repeat(a[:1], pad, axis=0)], axis=0)  # noqa: E731
        coords_, z_, w_, theta = rep(coords_), rep(z_), rep(w_), rep(theta)
    sharding = NamedSharding(mesh, PartitionSpec("batch"))
    return [jax.device_put(jnp.asarray(a), sharding) for a in (theta, coords_, z_, w_)], b, pad


def sharding_speedup(model: LimbModel, coords: Any, z: Any, init: LimbParams, solver: AbstractLimbSolver | None = None,
                     *, fixed: Sequence[str] = (), repeats: int = 3) -> dict[str, float]:
    """Time :func:`sharded_fit_batch` on all local devices against one device (best of ``repeats``).

    Both are compiled before timing.

    Parameters
    ----------
    model, coords, z, init, solver, fixed
        As :func:`sharded_fit_batch`.
    repeats : int
        Timed runs per configuration; the best counts.

    Returns
    -------
    dict of str to float
        ``n_devices``, ``batch``, ``one_device_s``, ``all_devices_s`` (seconds) and ``speedup`` (their ratio).
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


__all__ = ["local_mesh", "per_device", "sharded_fit_batch", "sharding_speedup"]
