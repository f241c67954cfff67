"""Dask clusters for clfza: an embedded ``LocalCluster`` of worker processes, an existing
scheduler, or the caller's client (:func:`open_client`), and the optional-dependency check."""

from __future__ import annotations

import ctypes
import logging
import os
from contextlib import contextmanager

from ..errors import ClfzaError, positive_int

DASK_EXTRA = ("this needs dask.distributed, an optional dependency of clfza: install it with "
              "pip install 'clfza[dask]' (or pip install 'dask[distributed]')")


def require_dask():
    """Import ``distributed`` or raise one ClfzaError naming the ``dask`` extra."""
    try:
        import distributed  # lazy: Dask is optional (pip install "clfza[dask]")
    except ImportError:
        raise ClfzaError(DASK_EXTRA) from None
    return distributed


def pin_cores(worker_name, n: int) -> set[int]:
    """Give this worker process its share of the cores: worker ``k`` of ``n`` gets its own
    slice (CPU affinity for all its threads) and ``POCL_MAX_PTHREAD_COUNT`` of that size, so
    that ``n`` PoCL workers do not all spread over every core. Returns the cores."""
    cpus = sorted(os.sched_getaffinity(0))
    per = max(1, len(cpus) // n)
    k = int(worker_name) if str(worker_name).isdigit() else 0
    mine = set(cpus[(k * per) % len(cpus):][:per]) or set(cpus)
    os.environ["POCL_MAX_PTHREAD_COUNT"] = str(len(mine))
    for tid in os.listdir("/proc/self/task"):
        try:
            os.sched_setaffinity(int(tid), mine)
        except OSError:
            pass
    return mine


def pin_plugin(n: int):
    """A ``distributed.WorkerPlugin`` that runs :func:`pin_cores` as each worker starts
    (made here so that importing clfza does not import Dask)."""
    from distributed import WorkerPlugin  # lazy: Dask is optional (pip install "clfza[dask]")

    class PinWorkers(WorkerPlugin):
        name = "clfza-pin"

        def setup(self, worker) -> None:
            pin_cores(worker.name, n)

    return PinWorkers()


MMAP_THRESHOLD = 32 << 20   # glibc's largest; its adaptive threshold ends there too
TRIM_THRESHOLD = 64 << 20
M_TRIM_THRESHOLD, M_MMAP_THRESHOLD = -1, -3  # mallopt parameters (<malloc.h>)


def adaptive_malloc() -> bool:
    """Undo Dask's ``MALLOC_TRIM_THRESHOLD_=65536`` in this process (a worker's): with it set,
    glibc stops raising its mmap threshold, so every array above 128 KiB is a fresh mmap whose
    pages fault in again, and the same solves run markedly slower in a worker than in the
    single-process batch (measured: docs/measurements.md, clfza.distributed._cluster).
    Sets glibc's mmap threshold to 32 MiB and its trim threshold to 64 MiB (``mallopt``), the
    state its adaptive rule reaches on such a workload. The nanny puts the variable into its
    own process's environment, so every later worker inherits it: removing it from Dask's
    configuration is not enough. Returns False where there is no glibc."""

    try:
        libc = ctypes.CDLL("libc.so.6")
        return bool(libc.mallopt(M_MMAP_THRESHOLD, MMAP_THRESHOLD)
                    and libc.mallopt(M_TRIM_THRESHOLD, TRIM_THRESHOLD))
    except (OSError, AttributeError):
        return False


def malloc_plugin():
    """A ``distributed.WorkerPlugin`` that runs :func:`adaptive_malloc` as each worker of the
    embedded cluster starts (recorded as ``worker.clfza_malloc``)."""
    from distributed import WorkerPlugin  # lazy: Dask is optional (pip install "clfza[dask]")

    class AdaptiveMalloc(WorkerPlugin):
        name = "clfza-malloc"

        def setup(self, worker) -> None:
            worker.clfza_malloc = adaptive_malloc()

    return AdaptiveMalloc()


@contextmanager
def open_client(client=None, workers: int | None = None, scheduler: str | None = None,
                retries: int = 2, pin_cpus: bool = False):
    """Yield ``(client, where, n_workers)``: the caller's client, a client of ``scheduler``,
    or an embedded ``LocalCluster`` of ``workers`` processes (one thread each); closes only
    what it opened."""
    if client is not None:
        yield client, f"client {client.scheduler.address}", len(client.scheduler_info()
                                                                  ["workers"])
        return
    require_dask()
    import dask  # lazy: Dask is optional (pip install "clfza[dask]")
    from distributed import (  # lazy: Dask is optional (pip install "clfza[dask]")
        Client,
        LocalCluster,
    )

    if scheduler is not None:
        with Client(scheduler, timeout="20s") as c:
            yield c, f"scheduler {scheduler}", len(c.scheduler_info()["workers"])
        return
    n = positive_int("workers", workers)
    with _quiet_dask(), dask.config.set({"distributed.scheduler.allowed-failures": retries}):
        cluster = LocalCluster(n_workers=n, threads_per_worker=1, processes=True,
                               dashboard_address=None, silence_logs=logging.ERROR)
        interrupted = False
        try:
            with Client(cluster) as c:
                c.register_plugin(malloc_plugin())
                if pin_cpus:
                    c.register_plugin(pin_plugin(n))
                yield c, f"LocalCluster({n} processes)", n
        except KeyboardInterrupt:
            interrupted = True
            raise
        finally:
            # Ctrl-C: stop the workers at once (a frame is written whole or not at all, so
            # a killed task leaves no output behind) instead of a graceful close of seconds
            cluster.close(timeout=INTERRUPT_CLOSE_S if interrupted else None)


INTERRUPT_CLOSE_S = 1.0  # seconds an interrupted batch waits for its embedded cluster


@contextmanager
def _quiet_dask():
    """Keep the embedded cluster's INFO chatter off stderr unless clfza logs at INFO."""
    lg = logging.getLogger("distributed")
    old = lg.level
    if logging.getLogger("clfza").getEffectiveLevel() > logging.INFO:
        lg.setLevel(logging.ERROR)
    try:
        yield
    finally:
        lg.setLevel(old)
