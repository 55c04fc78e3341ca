r"""Scale-out with Dask (``dask.distributed``): Monte-Carlo chunks and frame archives as tasks.

A study of the Monte-Carlo engine (:mod:`jaxlimb.analysis.montecarlo`) is cut into chunks;
each missing chunk is one task, :func:`~jaxlimb.analysis.montecarlo.run_chunk_to_file`, which
runs the chunk's trials on a worker and writes ``chunk_NNNNNN.npz`` atomically into the study's
``out_dir`` (a temporary file renamed into place).  So:

* a killed worker loses only the chunk it was running (Dask reschedules the task elsewhere);
* a killed client, or a rerun, finds the finished chunks on disk and submits only the others
  (:func:`~jaxlimb.analysis.montecarlo.prepare_study`); the seeds of trial ``i`` do not depend on
  who ran it, so the result is the same as an uninterrupted run's, file for file;
* the result is assembled from the chunk files by the engine itself.

JAX inside a worker.  Each worker process imports JAX once, enables float64 and the persistent
compilation cache (:mod:`jaxlimb._jaxcache`), and keeps its compiled programs and the trial's
constant inputs (e.g. the noise-free rendered frame of :class:`~jaxlimb.analysis.pipeline_study.LocateTrial`) between tasks; a
worker on a machine with several devices can still spread a batched fit over them with
:func:`jaxlimb.analysis.sharding.sharded_fit_batch`.

Clusters.  :func:`make_client` starts a ``LocalCluster`` (``workers`` processes, one thread each)
or connects to a running scheduler (``scheduler="tcp://host:8786"``).  On a SLURM machine, with
``dask-jobqueue`` installed (not a dependency of jaxlimb)::

    from dask_jobqueue import SLURMCluster
    from dask.distributed import Client
    cluster = SLURMCluster(cores=2, processes=2, memory="8GB", walltime="02:00:00",
                           job_extra_directives=["--partition=compute"])
    cluster.scale(jobs=10)                       # 10 SLURM jobs x 2 workers
    client = Client(cluster)
    run_monte_carlo_distributed(FamilyTrial(...), MonteCarloOptions(..., out_dir="/shared/mc"), client)

or start ``dask scheduler`` on one node and ``dask worker tcp://node:8786 --preload
jaxlimb.analysis.dask_worker`` on the others (:mod:`jaxlimb.analysis.dask_worker`: JAX started while the
worker registers, a quick exit; the ``LocalCluster`` workers load it themselves) and
pass ``--scheduler tcp://node:8786`` to ``jaxlimb montecarlo --pipeline`` /
``jaxlimb locate ... --scheduler``.  ``out_dir`` must then be on a file system every worker sees.
"""

from __future__ import annotations

import contextlib
import math
import uuid
from collections.abc import Callable, Iterator, Sequence
from dataclasses import replace
from typing import Any


from ..errors import ConfigError, LimbInputError
from .montecarlo import MonteCarloOptions, MonteCarloResult, prepare_study, run_chunk_to_file, run_monte_carlo


WORKER_PRELOAD = "jaxlimb.analysis.dask_worker"
"""The worker preload of the ``LocalCluster`` workers (:mod:`jaxlimb.analysis.dask_worker`; ``dask worker
--preload`` it on a cluster started by hand)."""


def make_client(scheduler: str | None = None, workers: int = 2, processes: bool = True) -> Any:
    """A ``dask.distributed.Client``: to ``scheduler`` if given, else on a new ``LocalCluster``.

    Parameters
    ----------
    scheduler : str, optional
        Address of a running scheduler, e.g. ``"tcp://host:8786"``.
    workers : int
        Worker processes of the ``LocalCluster`` (one thread each); ignored with ``scheduler``.
    processes : bool
        Workers as processes (with :func:`worker_environment` and the :data:`WORKER_PRELOAD`), else threads.

    Returns
    -------
    dask.distributed.Client
        Close it with :func:`close_client`.

    Raises
    ------
    ConfigError
        ``dask.distributed`` is not installed, or the scheduler cannot be reached.
    LimbInputError
        ``workers`` is not an integer >= 1.
    """
    try:
        from dask.distributed import Client, LocalCluster
    except ImportError:  # pragma: no cover - a dependency of jaxlimb
        raise ConfigError("Dask is not installed: pip install 'dask[distributed]'") from None
    if scheduler is not None:
        try:
            return Client(scheduler, timeout="10s")
        except (OSError, TimeoutError) as e:
            raise ConfigError(f"cannot reach the Dask scheduler {scheduler!r}: {e}") from None
    if isinstance(workers, bool) or not isinstance(workers, int) or workers < 1:
        raise LimbInputError(f"`workers` must be an integer >= 1, got {workers!r}")
    # dashboard_address ":0": the scheduler's HTTP server (always started) on a free port, never a clash on 8787
    # worker processes: their threads share the cores; JAX starts while they register, and they exit quickly
    extra = {"env": worker_environment(workers), "preload": [WORKER_PRELOAD]} if processes else {}
    with _workers_start_quietly():
        cluster = LocalCluster(n_workers=workers, threads_per_worker=1, processes=processes,
                               dashboard_address=":0", silence_logs=50, **extra)
    try:
        return Client(cluster)
    except BaseException:
        cluster.close()
        raise


@contextlib.contextmanager
def _workers_start_quietly() -> Iterator[None]:
    """The worker processes started in the block get ``/dev/null`` as their stderr: a Ctrl-C that reaches them
    while Python starts (before Dask's handlers exist) would print a traceback each; their errors reach the
    client as task errors, and ``silence_logs`` keeps their logs quiet anyway.  This process's stderr is the
    same again after the block."""
    import os

    try:
        saved = os.dup(2)
    except OSError:  # no stderr at all
        yield
        return
    null = os.open(os.devnull, os.O_WRONLY)
    try:
        os.dup2(null, 2)
        yield
    finally:
        os.dup2(saved, 2)
        os.close(saved)
        os.close(null)


def worker_environment(workers: int, cores: int | None = None) -> dict[str, str]:
    """Environment of the worker processes of a ``LocalCluster``: their threads share the cores, and
    ``malloc`` keeps the frames' buffers.

    XLA's CPU backend, OpenCV and BLAS each start one thread per core in every process, so
    ``workers`` processes on ``cores`` cores would run ``workers x cores`` busy threads and
    spend the difference switching.  With one core or less per worker each worker runs
    single-threaded (XLA ``--xla_cpu_multi_thread_eigen=false``, ``OPENCV_FOR_THREADS_NUM``,
    ``OMP``/``OPENBLAS``/``MKL_NUM_THREADS`` = 1); with more cores per worker the libraries keep
    their defaults.

    Dask's nanny sets ``MALLOC_TRIM_THRESHOLD_=65536`` for its workers (its memory accounting); setting
    it also fixes glibc's mmap threshold at its 128 KiB default (the threshold no longer adapts,
    ``mallopt(3)``), so every array of a full frame is mapped, zero-filled and unmapped again on every
    trial.  The workers get ``MALLOC_MMAP_THRESHOLD_`` = 64 MiB and ``MALLOC_TRIM_THRESHOLD_`` = 128 MiB
    instead: a full frame's buffers are reused, at the cost of a worker keeping up to ~200 MB more.
    A variable the user set is kept (the ``MALLOC_`` ones passed on explicitly).

    Parameters
    ----------
    workers : int
        Worker processes sharing the machine.
    cores : int, optional
        Usable cores; default the process's CPU affinity (``jaxlimb._jaxcache.usable_cores``).

    Returns
    -------
    dict of str to str
        Environment variables to set in each worker.
    """
    import os

    if cores is None:
        from .._jaxcache import usable_cores

        cores = usable_cores()
    # passed explicitly (the nanny would override an inherited value with its own)
    env = {k: os.environ.get(k, v) for k, v in (("MALLOC_MMAP_THRESHOLD_", str(64 << 20)),
                                                 ("MALLOC_TRIM_THRESHOLD_", str(128 << 20)))}
    if cores // max(workers, 1) > 1:
        return env
    env.update({k: "1" for k in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "OPENCV_FOR_THREADS_NUM")
                if k not in os.environ})
    flags = os.environ.get("XLA_FLAGS", "")
    if "xla_cpu_multi_thread_eigen" not in flags:
        env["XLA_FLAGS"] = f"{flags} --xla_cpu_multi_thread_eigen=false".strip()
    return env


def close_client(client: Any) -> None:
    """Close ``client`` and the ``LocalCluster`` it started (a remote scheduler is left running).

    Parameters
    ----------
    client : dask.distributed.Client
        A client of :func:`make_client`.
    """
    cluster = getattr(client, "cluster", None)
    client.close()
    if cluster is not None:
        cluster.close()


def run_monte_carlo_distributed(trial: Callable[..., Any], options: MonteCarloOptions, client: Any,
                                progress: bool = True) -> MonteCarloResult:
    """:func:`~jaxlimb.analysis.montecarlo.run_monte_carlo` with one Dask task per missing chunk.

    Parameters
    ----------
    trial : callable
        As for :func:`~jaxlimb.analysis.montecarlo.run_monte_carlo`, and picklable (a module-level function or a
        dataclass like :class:`~jaxlimb.analysis.pipeline_study.LocateTrial`).
    options : MonteCarloOptions
        The study; ``out_dir`` is required (the chunk files are the results) and must be visible to every worker.
    client : dask.distributed.Client
        Where the chunk tasks run.
    progress : bool
        Show a progress bar over the chunks.

    Returns
    -------
    MonteCarloResult
        The same as an in-process run's, with ``chunks_run`` the tasks submitted now.

    Raises
    ------
    LimbInputError
        ``options.out_dir`` is ``None``.
    ConfigError
        ``out_dir`` holds another study.
    """
    from dask.distributed import as_completed
    from tqdm.auto import tqdm

    todo = prepare_study(options)
    opt = replace(options, progress=False)
    bar = tqdm(total=len(todo), desc=options.name, unit="chunk", disable=not progress)
    # one key per call: a rerun on the same client must not reuse the keys whose futures the
    # previous call cancels in its ``finally`` (the scheduler would cancel the new tasks too)
    run_id = uuid.uuid4().hex[:8]
    futures = [client.submit(run_chunk_to_file, trial, opt, c,
                             key=f"{options.name}-chunk-{c}-{options.seed}-{run_id}", pure=False) for c in todo]
    try:
        for fut in as_completed(futures):
            fut.result()  # re-raises a task's error here
            bar.update(1)
    finally:
        bar.close()
        for f in futures:
            f.cancel()
    res = run_monte_carlo(trial, opt)  # every chunk is on disk now: assembled, nothing recomputed
    return replace(res, chunks_run=len(todo), chunks_skipped=options.n_chunks - len(todo))


def chunked(items: Sequence[Any], size: int) -> Iterator[list[Any]]:
    """``items`` in consecutive lists of at most ``size``.

    Parameters
    ----------
    items : sequence
        What to cut.
    size : int
        Largest list length.

    Yields
    ------
    list
        The next consecutive slice of ``items``.
    """
    for i in range(0, len(items), size):
        yield list(items[i : i + size])


def map_chunks(fn: Callable[[list[Any]], Any], items: Sequence[Any], client: Any, chunk_size: int) -> Iterator[Any]:
    """``fn(chunk)`` for consecutive chunks of ``items`` as Dask tasks, yielded in order.

    The frame-archive path of ``jaxlimb locate ... --workers N``: the caller writes each
    chunk's records as soon as it arrives (in order, so an interrupted run resumes cleanly).

    Parameters
    ----------
    fn : callable
        ``fn(list) -> result``, picklable.
    items : sequence
        The work items (e.g. frame paths).
    client : dask.distributed.Client
        Where the tasks run.
    chunk_size : int
        Items per task.

    Yields
    ------
    object
        ``fn(chunk)`` of each chunk, in order; a task's error is raised here, and the remaining tasks are
        cancelled when the generator is closed.
    """
    futures = [client.submit(fn, ch, pure=False) for ch in chunked(items, chunk_size)]
    try:
        for fut in futures:
            yield fut.result()
    finally:
        for f in futures:
            f.cancel()


TASKS_PER_WORKER = 16
"""Tasks per worker of :func:`default_chunk`: the workers finish within about one chunk of each other (the
last chunks are handed out as workers free up), so smaller chunks leave less idle time at the end, while a
task's own cost (scheduling, the chunk file) is small against a full-frame trial's
(``docs/validation/constants.md#tasks_per_worker``)."""


def default_chunk(n: int, workers: int) -> int:
    """A chunk size giving each worker about :data:`TASKS_PER_WORKER` tasks (at least 1, at most 50 trials).

    Parameters
    ----------
    n : int
        Trials of the study.
    workers : int
        Dask workers.

    Returns
    -------
    int
        Trials per chunk.
    """
    return max(1, min(50, math.ceil(n / (TASKS_PER_WORKER * max(workers, 1)))))


__all__ = ["chunked", "close_client", "default_chunk", "make_client", "map_chunks",
           "run_monte_carlo_distributed"]
