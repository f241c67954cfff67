"""Dask clusters for clfza: an embedded ``LocalCluster`` of worker processes, an existing
scheduler, or the caller's client (:func:`open_client`), and the optional-dependency check."""

from __future__ import annotations

import logging
import os
from contextlib import contextmanager

from .errors import ClfzaError, positive_int

DASK_EXTRA = ("this needs dask.distributed, an optional dependency of clfza: install it with "
              "pip install 'clfza[dask]' (or pip install 'dask[distributed]')")


def require_dask():
    """Import ``distributed`` or raise one ClfzaError naming the ``dask`` extra."""
    try:
        import distributed
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
    from distributed import WorkerPlugin

    class PinWorkers(WorkerPlugin):
        name = "clfza-pin"

        def setup(self, worker) -> None:
            pin_cores(worker.name, n)

    return PinWorkers()


MALLOC_ENV = "MALLOC_TRIM_THRESHOLD_"


def worker_environ() -> dict:
    """The environment the embedded cluster's nannies give their workers: Dask's
    ``distributed.nanny.pre-spawn-environ`` without ``MALLOC_TRIM_THRESHOLD_``. Dask sets it
    to 64 KiB to hand freed memory back to the OS; set explicitly, glibc also stops raising its
    mmap threshold, so every array above 128 KiB is a fresh mmap and its pages fault in again:
    the same 512^2 ADMM solves (50 iterations, PoCL 3.1, 2-core Xeon) ran at 6.1-6.4 frames/s
    with it against 8.4-9.5 without, in one process, and a one-worker LocalCluster at 4.3
    frames/s against 6.4-8.0 for the single-process batch."""
    import dask

    env = dict(dask.config.get("distributed.nanny.pre-spawn-environ", {}) or {})
    env.pop(MALLOC_ENV, None)
    return env


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
    import dask
    from distributed import Client, LocalCluster

    if scheduler is not None:
        with Client(scheduler, timeout="20s") as c:
            yield c, f"scheduler {scheduler}", len(c.scheduler_info()["workers"])
        return
    n = positive_int("workers", workers)
    with _quiet_dask(), dask.config.set({"distributed.scheduler.allowed-failures": retries,
                                         "distributed.nanny.pre-spawn-environ":
                                             worker_environ()}):
        cluster = LocalCluster(n_workers=n, threads_per_worker=1, processes=True,
                               dashboard_address=None, silence_logs=logging.ERROR)
        try:
            with Client(cluster) as c:
                if pin_cpus:
                    c.register_plugin(pin_plugin(n))
                yield c, f"LocalCluster({n} processes)", n
        finally:
            cluster.close()


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
