"""Dask worker preload for jaxlimb tasks: JAX started while the worker registers, and a quick exit.

The workers of :func:`jaxlimb.analysis.distributed.make_client`'s ``LocalCluster`` load it; on a
cluster started by hand pass it to each worker::

    dask worker tcp://node:8786 --preload jaxlimb.analysis.dask_worker

* ``dask_setup``: a background thread imports JAX and the locate pipeline, switches on float64 and
  the persistent compilation cache (:mod:`jaxlimb._jaxcache`) while the worker connects to the
  scheduler and waits for its first task, so that the imports are off the first task's path.
  A task must call :func:`wait_started` before it imports the package: Python's import lock is per
  module, so two threads importing interdependent modules at once can see a partially initialised
  module (``ImportError: cannot import name ... from partially initialized module``).
* ``dask_teardown``: ``gc.freeze()`` before the worker process ends, so the interpreter's shutdown
  does not walk JAX's ~10^6 objects, a time the client's ``close`` pays as it waits for its workers
  (see :func:`jaxlimb.cli.entry`).
"""

from __future__ import annotations

import gc
import threading
from typing import Any

_STARTED: list[threading.Thread] = []


def start_jax() -> None:
    """JAX in float64 with the persistent compilation cache, and the locate pipeline imported; idempotent."""
    from .._jaxcache import start_jax as start

    start()
    import jaxlimb.pipeline  # noqa: F401  (the modules every LocateTrial imports)

    gc.freeze()  # long-lived from here on: later collections skip them


def _start_quietly() -> None:
    try:
        start_jax()
    except Exception:  # noqa: BLE001 - an optimisation: a task that needs JAX starts it (and reports) itself
        pass


def dask_setup(worker: Any) -> None:
    """Start :func:`start_jax` in a daemon thread (the worker's event loop is not held up).

    Parameters
    ----------
    worker : distributed.Worker
        The registering worker (Dask's preload hook; unused).
    """
    del worker
    if not _STARTED:
        t = threading.Thread(target=_start_quietly, name="jaxlimb-start-jax", daemon=True)
        t.start()
        _STARTED.append(t)


def wait_started(timeout: float | None = None) -> None:
    """Wait until :func:`dask_setup`'s start thread has finished its imports (at once where none was started,
    e.g. outside a worker, or from that thread itself).

    Parameters
    ----------
    timeout : float, optional
        Longest wait in seconds; ``None`` waits until the imports are done.
    """
    for t in _STARTED:
        if t is not threading.current_thread():
            t.join(timeout)


def dask_teardown(worker: Any) -> None:
    """Freeze the collector's objects: the worker process then exits without walking them.

    Parameters
    ----------
    worker : distributed.Worker
        The closing worker (Dask's preload hook; unused).
    """
    del worker
    gc.freeze()


__all__ = ["dask_setup", "dask_teardown", "start_jax", "wait_started"]
