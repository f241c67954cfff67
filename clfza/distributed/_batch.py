"""Batches of frames on Dask: ``clfza.reconstruct_many(frames, camera, ...)``.

A batch runs in this process (``client=None, workers=None``: no Dask needed) or on a Dask
cluster: an embedded ``LocalCluster`` of worker *processes* (``workers=N``), an existing
scheduler (``scheduler="tcp://host:8786"``) or a ``distributed.Client`` the caller owns.

What travels and what stays
    Tasks carry :class:`~clfza.io._stream.FrameRef` (a path and an index), not pixels: workers
    read their frames from the shared file system, reconstruct with
    :func:`clfza.reconstruct`, write the results themselves (atomically, never over an
    existing file unless ``force``) and send back a small record. Only arrays given in memory
    travel with their tasks.
Per worker
    Each worker process keeps one OpenCL context for its life (``clfza.cl.get_runtime`` caches
    it; programs are built once per context), so kernels compile on a worker's first frame
    only; dark/flat frames are read once per worker, and the solver's set-up (operator,
    FFT plans, device buffers, kernel objects) is kept between frames of one camera and
    method in a :class:`clfza.backends.BackendCache` (``cache_backends=True``; the single
    process batch keeps one too). With several devices on a host pass
    ``device=("0:0", "0:1")``: worker ``k`` is pinned to ``device[k % len(device)]``. Tasks in
    one process never run concurrently (a lock), since kernel objects are shared.
Chunks
    A task reconstructs a chunk of consecutive frames (``chunk``): ``"auto"`` starts with one
    frame per task and then sizes chunks from the measured time per frame so that a task
    lasts about ``CHUNK_TARGET_S`` (the scheduling round trip, a few ms, is then paid once per
    chunk), never more than the unsubmitted frames / (4 x workers) (guided self-scheduling:
    chunks shrink towards the end, so the workers finish together); results come back per
    chunk as small records (no images unless asked for).
Faults
    A frame that fails with a :class:`~clfza.errors.ClfzaError` (a bad file, a bad option) is
    reported in its :class:`FrameResult` and the others go on; any other exception (a device
    error) is retried up to ``retries`` times, as is a frame whose worker died (Dask replaces
    the worker; ``distributed.scheduler.allowed-failures`` bounds it on an embedded cluster).
    A chunk stops at a frame that raised (the frames before it are returned) and the rest is
    resubmitted, starting with that frame; a retried chunk skips the frames this batch
    already completed (their JSON record carries the batch id), and a chunk that still fails
    is split into single frames, so a failure never takes other frames down with it.
    ``resume=True`` skips frames whose complete outputs exist (the JSON record is written last
    and names the other outputs) and redoes partial ones.

Order is kept: ``BatchResult.results[i]`` belongs to the i-th frame whatever order workers
finish in.
"""

from __future__ import annotations

import json
import os
import threading
import time
import uuid
from collections.abc import Callable, Iterable, Iterator
from contextlib import contextmanager, nullcontext
from pathlib import Path

import numpy as np

from .. import __version__
from ..backends import BackendCache, reuse_backends
from ..camera import Camera
from ..errors import ClfzaError, positive_int, report_exception
from ..io import (
    FrameInfo,
    FrameRef,
    check_frame,
    prepare_frame,
    read_frame,
    read_ref,
    write_image,
    write_json,
)
from ..reconstruction import reconstruct
from ._cluster import open_client, require_dask  # noqa: F401 (public here too)
from ._jobs import (  # noqa: F401  (re-exported: the records and frame_state)
    IMAGE_SUFFIX,
    KINDS,
    BatchResult,
    FramePrep,
    FrameResult,
    Job,
    OutputSpec,
    check_batch,
    frame_sources,
    frame_state,
    pending_frames,
)

CHUNK_TARGET_S = 0.5  # chunk="auto": seconds of work per task once the frame time is known
MAX_CHUNK = 64


# ----------------------------------------------------------------------------------------
# worker side
# ----------------------------------------------------------------------------------------
_WORKER: dict = {"frames": 0, "cal": {}, "warm": set(), "backends": None}
_TASK_LOCK = threading.Lock()
WORKER_CACHE_SIZE = 2  # backends a worker process keeps (device memory: ~200 MB at 2048^2)


def worker_backend_cache():
    """This process's :class:`clfza.backends.BackendCache` for batch tasks (made on first
    use; kept for the life of the worker process)."""
    if _WORKER["backends"] is None:

        _WORKER["backends"] = BackendCache(WORKER_CACHE_SIZE)
    return _WORKER["backends"]


@contextmanager
def batch_backend_cache():
    """A batch in the caller's own process: its own backend cache, dropped at its end (the
    caller's process is not a worker, it should not keep device memory after the batch)."""
    saved = _WORKER["backends"]
    _WORKER["backends"] = None
    try:
        yield
    finally:
        _WORKER["backends"] = saved


def _worker_name() -> str:
    try:
        from distributed import get_worker  # lazy: Dask is optional (pip install "clfza[dask]")

        return str(get_worker().name)
    except (ImportError, ValueError):
        return "local"


def _device_for(job: Job, name: str) -> str | None:
    """The device spec of this worker: ``job.device``, or one of a tuple by worker index."""
    if not isinstance(job.device, (list, tuple)):
        return job.device
    k = int(name) if name.isdigit() else sum(map(ord, name))
    return job.device[k % len(job.device)]


def _calibration(prep: FramePrep) -> dict:
    """Dark and flat frames, read once per worker process."""

    out = {}
    for what, path in (("dark", prep.dark), ("flat", prep.flat)):
        if path is None:
            out[what] = None
            continue
        if path not in _WORKER["cal"]:
            label = "dark frame" if what == "dark" else "flat field"
            _WORKER["cal"][path] = read_frame(path, name=f"{label} {str(path)!r}")[0]
        out[what] = _WORKER["cal"][path]
    return out


def prepare_source(src, job: Job, t: dict) -> tuple[np.ndarray, Camera, dict]:
    """Read (timed as I/O) and prepare one frame; returns y, its camera and a record part."""

    t0 = time.perf_counter()
    if isinstance(src, np.ndarray):

        frame, bits = (check_frame(src, "frame") if job.kind == "raw"
                       else (np.asarray(src, np.float64), None))
        loaded = (frame, FrameInfo("<array>", "array", str(src.dtype), src.shape, bits))
    elif job.kind == "y":
        arr = np.load(src.path, mmap_mode="r", allow_pickle=False) if src.index is not None \
            else None
        loaded = ((np.asarray(arr[src.index], np.float64), None) if arr is not None
                  else (np.load(src.path, allow_pickle=False).astype(np.float64), None))
    else:
        loaded = read_ref(src)
    t["read"] = time.perf_counter() - t0
    if job.kind == "y":
        t["prepare"] = 0.0
        return loaded[0], job.camera, {"kind": "y"}
    t1 = time.perf_counter()
    prep = prepare_frame(getattr(src, "path", "<array>"), job.camera, job.prep,
                         _calibration(job.prep), loaded=loaded)
    t["prepare"] = time.perf_counter() - t1
    return prep.y, prep.camera, prep.record


def _write(name: str, image: np.ndarray, out: OutputSpec, force: bool, t: dict) -> dict:

    t0 = time.perf_counter()
    paths = out.paths(name)
    if not force:
        for p in paths.values():
            if p.exists():
                raise ClfzaError(f"{str(p)!r} exists; pass --force to overwrite it or "
                                 "--resume to skip complete frames")
    write_image(paths["npy"], image, force=force)
    _, scaling = write_image(paths["image"], image, force=force, scaling=out.scaling,
                             percentiles=tuple(out.percentiles),
                             tiff_float=out.format == "tiff-float")
    t["write"] = time.perf_counter() - t0
    return {"outputs": {k: str(v) for k, v in paths.items()}, "scaling": scaling}


def _solve(y: np.ndarray, cam: Camera, job: Job, device, t: dict, cache=None):


    t0 = time.perf_counter()
    with reuse_backends(cache) if cache is not None else nullcontext():
        rec = reconstruct(y, cam, job.method, backend=job.backend, device=device,
                          **job.options)
    t["reconstruct"] = time.perf_counter() - t0
    for k in ("compile", "plan", "solve"):
        t[k] = float(rec.info.timings.get(k, 0.0))
    return rec


def _record(res: FrameResult, src, job: Job, rec, part: dict, cam: Camera, worker: dict
            ) -> dict:

    info = rec.info
    r = {"clfza_version": __version__, "date": time.strftime("%Y-%m-%d %H:%M:%S"),
         "command": job.command, "input": res.input, "name": res.name, **part,
         "camera": cam.summary(), "method": info.method,
         "parameters": {**job.options, **info.params}, "backend": info.backend,
         "device": info.device, "dtype": info.dtype, "iterations": info.iterations,
         "stop_reason": info.stop_reason, "notes": list(info.notes), "worker": worker,
         "batch": job.batch}
    if info.objective:
        last = info.objective[-1]
        r["objective_last"] = last[-1] if isinstance(last, list) and last else last
    return r


def _done_by_this_batch(res: FrameResult, job: Job) -> bool:
    """A retried chunk: the frame's complete outputs were written by this very batch."""
    if job.output is None or not job.batch:
        return False
    p = job.output.paths(res.name)["json"]
    if not p.exists() or frame_state(job.output, res.name) != "complete":
        return False
    try:
        rec = json.loads(p.read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return False
    if not isinstance(rec, dict) or rec.get("batch") != job.batch:
        return False
    res.ok, res.record = True, rec
    if job.return_images:
        res.image = np.load(rec["outputs"]["npy"], allow_pickle=False)
    return True


def run_frame(index: int, src, name: str, job: Job, overwrite: bool = False) -> FrameResult:
    """Reconstruct one frame on this process (a Dask task, or a step of a local batch).

    A :class:`ClfzaError` becomes a failed :class:`FrameResult`; anything else propagates, so
    that Dask (or the local loop) retries it.
    """
    label = src.label if isinstance(src, FrameRef) else f"<array {index}>"
    res = FrameResult(index=index, name=name, input=label)
    wall0, t0 = time.time(), time.perf_counter()
    t: dict = {}
    wname = _worker_name()
    with _TASK_LOCK:
        if _done_by_this_batch(res, job):
            return res
        try:
            y, cam, part = prepare_source(src, job, t)
            cache = worker_backend_cache() if job.cache_backends else None
            rec = _solve(y, cam, job, _device_for(job, wname), t, cache)
        except ClfzaError as exc:
            res.error = _one_line(exc, label)
            return res
        key = (cam, job.method, job.backend, str(_device_for(job, wname)))
        first = key not in _WORKER["warm"]
        _WORKER["warm"].add(key)
        _WORKER["frames"] += 1
        worker = {"name": wname, "pid": os.getpid(), "frames_done": _WORKER["frames"],
                  "first_of_kind": first}
        record = _record(res, src, job, rec, part, cam, worker)
        if job.output is not None:
            try:
                record.update(_write(name, rec.image, job.output,
                                     job.output.force or overwrite, t))
            except ClfzaError as exc:
                res.error = _one_line(exc, label)
                return res
    t["task"] = time.perf_counter() - t0
    record["timings_s"] = {**t, "start_unix": wall0, "end_unix": time.time()}
    if job.output is not None:

        write_json(job.output.paths(name)["json"], record, force=True)  # last: marks complete
    res.ok, res.record = True, record
    res.image = rec.image if job.return_images else None
    return res


def _one_line(exc: BaseException, label: str) -> str:

    msg = report_exception(exc)[0].removeprefix("clfza: error: ")
    return msg if label.strip("'") in msg else f"{label}: {msg}"


def run_chunk(items: list, job: Job) -> list[FrameResult]:
    """Reconstruct consecutive frames ``[(index, source, name, overwrite), ...]`` (one Dask
    task). Returns their results in order; an exception other than a ClfzaError on the
    first frame propagates (Dask retries the chunk), on a later frame it ends the chunk
    early: the caller resubmits the frames not returned."""
    out: list[FrameResult] = []
    for i, src, name, overwrite in items:
        try:
            out.append(run_frame(i, src, name, job, overwrite))
        except Exception:
            if not out:
                raise
            break
    return out


# ----------------------------------------------------------------------------------------
# client side
# ----------------------------------------------------------------------------------------


def _run_local(todo, job: Job, retries: int) -> Iterator[FrameResult]:
    for i, src, name, overwrite in todo:
        for attempt in range(retries + 1):
            try:
                yield run_frame(i, src, name, job, overwrite)
                break
            except KeyboardInterrupt:
                raise
            except Exception as exc:
                if attempt == retries:
                    label = src.label if isinstance(src, FrameRef) else f"<array {i}>"
                    yield FrameResult(i, name, label, error=_one_line(exc, label)
                                      + f" (after {retries + 1} attempt(s))")


def _failed_task(item, exc: BaseException, retries: int) -> FrameResult:
    i, src, name, _ = item
    label = src.label if isinstance(src, FrameRef) else f"<array {i}>"
    if isinstance(exc, tuple) and len(exc) == 3:  # as_completed gives (type, value, tb)
        exc = exc[1]
    if type(exc).__name__ == "KilledWorker":
        msg = f"{label}: the workers running it died {retries + 1} time(s); giving up"
    else:
        msg = _one_line(exc, label) + f" (after {retries + 1} attempt(s))"
    return FrameResult(i, name, label, error=msg)


class ChunkSizer:
    """Frames per task for ``chunk="auto"``: 1 until a frame time is measured, then about
    ``target_s`` of work per task, at most ``remaining / (4 workers)`` frames (two tasks per
    worker are in flight: the last ones stay short and the workers finish together) and
    ``MAX_CHUNK``."""

    def __init__(self, workers: int, chunk: int | str = "auto",
                 target_s: float = CHUNK_TARGET_S):
        self.workers, self.fixed, self.target = max(1, workers), chunk, target_s
        self.frame_s: list[float] = []

    def observe(self, r: FrameResult) -> None:
        t = r.timings.get("task") if r.ok and not r.skipped else None
        if t:
            self.frame_s = (self.frame_s + [float(t)])[-16:]

    def size(self, remaining: int) -> int:
        if self.fixed != "auto":
            return max(1, min(int(self.fixed), remaining))
        if not self.frame_s:
            return 1
        want = round(self.target / max(float(np.median(self.frame_s)), 1e-6))
        return int(max(1, min(want, remaining // (4 * self.workers), MAX_CHUNK)))


def _run_dask(todo, job: Job, client, retries: int, workers: int, chunk: int | str = "auto"
              ) -> Iterator[FrameResult]:
    """Submit chunks of frames, two tasks per worker in flight; yield results as they come."""
    from distributed import as_completed  # lazy: Dask is optional (pip install "clfza[dask]")

    token = uuid.uuid4().hex[:8]
    queue = list(reversed(todo))  # pop() takes the next frame in input order
    sizer = ChunkSizer(workers, chunk)
    pending: dict = {}
    # the client's own loop: the default client's (as_completed's default) may be another
    # client's when several live in this process, and tornado streams are not thread-safe
    ac = as_completed(with_results=True, raise_errors=False, loop=client.loop)
    serial = iter(range(1 << 62))

    def submit(items: list, tries: int = retries) -> None:
        fut = client.submit(run_chunk, items, job, key=f"clfza-{token}-{next(serial)}",
                            retries=tries, priority=-items[0][0], pure=False)
        pending[fut.key] = (items, fut)
        ac.add(fut)

    def submit_next() -> None:
        k = sizer.size(len(queue))
        if queue:
            submit([queue.pop() for _ in range(min(k, len(queue)))])

    for _ in range(2 * max(1, workers)):
        submit_next()
    try:
        for fut, value in ac:
            items, _ = pending.pop(fut.key)
            if fut.status == "finished" and isinstance(value, list):
                for r in value:
                    sizer.observe(r)
                    yield r
                if len(value) < len(items):  # stopped at a frame that raised: resubmit
                    submit(items[len(value):])
            elif len(items) > 1:  # a failed chunk: its frames one by one, no further retry
                for it in items:
                    submit([it], 0)
            else:
                yield _failed_task(items[0], value, retries)
            if len(pending) < 2 * max(1, workers):
                submit_next()
    finally:
        if pending:  # interrupted: stop the rest, keep what is written
            client.cancel([f for _, f in pending.values()])


def reconstruct_many(frames, camera: Camera, method: str = "bp", *, client=None,
                     workers: int | None = None, scheduler: str | None = None,
                     out_dir: str | Path | None = None, kind: str = "raw",
                     prep: FramePrep | None = None, backend: str = "opencl",
                     device: str | tuple | None = None, format: str = "png",
                     scaling: str = "percentile", percentiles: tuple = (0.1, 99.9),
                     force: bool = False, resume: bool = False, retries: int = 2,
                     return_images: bool | None = None, pin_cpus: bool = False,
                     progress: Callable[[FrameResult], None] | None = None, command: str = "",
                     chunk: int | str = "auto", cache_backends: bool = True,
                     **options) -> BatchResult:
    """Reconstruct many frames, in this process or on Dask, keeping their order.

    Parameters
    ----------
    frames : paths, FrameRefs or arrays
        Files, folders, globs, multi-page TIFFs, ``.npy``/``.npz`` stacks, videos (see
        :mod:`clfza.io._stream`), a list of arrays or one ``(N, H, W[, 3])`` array.
    camera : Camera
        The camera (the sensor crop for raw frames, see ``prep``).
    method : str
        As :func:`clfza.reconstruct`; ``**options`` are its method options (tau, iters, ...).
    client, workers, scheduler
        Where to run: a ``distributed.Client``; else ``scheduler`` (an address); else an
        embedded LocalCluster of ``workers`` processes; none of them: this process.
    out_dir : path, optional
        Workers write ``NAME.png|.tif``, ``NAME.npy`` and ``NAME.json`` there (atomic; no
        overwrite unless ``force``). Without it the images come back (``return_images``).
    kind : {"raw", "y"}
        Raw sensor frames, prepared by ``prep`` (dark, flat, Bayer, crop, bin) as the CLI
        does; or DC-free observations passed to :func:`clfza.reconstruct` as they are.
    resume : bool
        Skip frames whose complete outputs exist in ``out_dir``; redo partial ones.
    retries : int
        Further attempts for a frame that failed other than by a ClfzaError, or whose worker
        died.
    pin_cpus : bool
        Embedded cluster only: give each worker its own share of the cores.
    progress : callable, optional
        Called with each :class:`FrameResult` as it finishes (skipped frames first).
    chunk : int or "auto"
        Frames per Dask task (see the module notes); 1 submits every frame as its own task.
    cache_backends : bool
        Keep the solver set-up between frames (per worker process; per batch in this
        process): see :class:`clfza.backends.BackendCache`. False rebuilds it per frame.

    Returns
    -------
    BatchResult
        ``results`` in input order; failed frames have ``error`` set.
    """
    out = None if out_dir is None else OutputSpec(str(out_dir), format, scaling,
                                                  tuple(percentiles), force)
    check_batch(camera, method, backend, kind, retries, out)
    if out is None and resume:
        raise ClfzaError("resume=True needs out_dir (it looks for complete outputs there)")
    if chunk != "auto":
        chunk = positive_int("chunk", chunk)
    job = Job(camera, method, dict(options), backend, device, kind, prep or FramePrep(), out,
              bool(return_images if return_images is not None else out is None), command,
              bool(cache_backends), uuid.uuid4().hex)
    sources = frame_sources(frames)
    if not sources:
        raise ClfzaError("no frames to reconstruct")
    todo, results = pending_frames(sources, out, resume)
    if out is not None:
        Path(out.out_dir).mkdir(parents=True, exist_ok=True)
    for r in results.values():
        if progress is not None:
            progress(r)
    t0 = time.perf_counter()
    where, n = _run(todo, job, results, progress, client, workers, scheduler, retries,
                    pin_cpus, chunk)
    ordered = [results[i] for i in range(len(sources))]
    return BatchResult(ordered, time.perf_counter() - t0, where, n)


def _run(todo, job: Job, results: dict, progress, client, workers: int | None,
         scheduler: str | None, retries: int, pin_cpus: bool, chunk: int | str
         ) -> tuple[str, int]:
    """Run the tasks ``todo`` where :func:`reconstruct_many` was told to, collecting their
    results into ``results``; returns where they ran and on how many workers."""
    local = client is None and workers is None and scheduler is None
    if not todo:
        return "nothing to do", 0
    if local:
        with batch_backend_cache():
            _collect(_run_local(todo, job, retries), results, progress)
        return "this process", 1
    with open_client(client, workers, scheduler, retries, pin_cpus) as (c, where, n):
        _collect(_run_dask(todo, job, c, retries, max(n, 1), chunk), results, progress)
    return where, n


def _collect(stream: Iterable[FrameResult], results: dict, progress) -> None:
    for r in stream:
        results[r.index] = r
        if progress is not None:
            progress(r)
