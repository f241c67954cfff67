"""Batches of frames on Dask: ``clfza.reconstruct_many(frames, camera, ...)``.

A batch runs in this process (``client=None, workers=None``: no Dask needed) or on a Dask
cluster: an embedded ``LocalCluster`` of worker *processes* (``workers=N``), an existing
scheduler (``scheduler="tcp://host:8786"``) or a ``distributed.Client`` the caller owns.

One frame is a batch of one: ``clfza reconstruct`` sends every input through here, so the
whole of a frame's work is the task's (:func:`run_frame`): prepare (dark, flat, Bayer, crop,
bin), plan (``plan``/``explain``: :func:`clfza.reconstruction.reconstruct_planned`),
reconstruct (:func:`clfza.reconstruct` with ``model``, ``margin`` and a measured ``psf``),
cut ``roi`` and orient, write.

What travels and what stays
    Tasks carry :class:`clfza.io.FrameRef` (a path and an index), not pixels, and the
    :class:`Job` (the options; a measured PSF's array inside it, sent once per task): workers
    read their frames from the shared file system, reconstruct, write the results themselves
    (image, NPY and JSON record together or none of them, never over an existing file
    unless ``force``) and send back a small record. Only arrays given in memory travel with
    their tasks.
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
    lasts about ``CHUNK_TARGET_S`` (the scheduling round trip is then paid once per chunk;
    its cost: docs/measurements.md, clfza.distributed._batch), never more than the
    unsubmitted frames / (4 x workers) (guided self-scheduling: chunks shrink towards the end,
    so the workers finish together); results come back per chunk as small records (no images
    unless asked for).
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
import math
import os
import platform
import sys
import threading
import time
import uuid
from collections.abc import Callable, Iterable, Iterator
from contextlib import contextmanager, nullcontext
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np
from tqdm import tqdm

from .. import __version__
from ..backends import BackendCache, reuse_backends
from ..camera import Camera
from ..errors import ClfzaError, positive_int, report_exception
from ..io import (
    FrameInfo,
    FrameRef,
    atomic_write_many,
    check_frame,
    encode_image,
    encode_json,
    load_calibration_frame,
    prepare_frame,
    read_frame,
    read_ref,
)
from ..reconstruction import make_plan, reconstruct, reconstruct_planned
from ..solvers import (
    BATCH_METHODS,
    DEFAULT_BACKEND,
    DEFAULT_METHOD,
    Reconstruction,
    default_iters,
    frames_per_solve_for,
    method_model,
    resolve_method,
)
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
    check_roi,
    explain_ran,
    finish_image,
    frame_sources,
    frame_state,
    pending_frames,
    what_ran,
)

CHUNK_TARGET_S = 0.5  # chunk="auto": seconds of work per task once the frame time is known
MAX_CHUNK = 64


# ----------------------------------------------------------------------------------------
# worker side
# ----------------------------------------------------------------------------------------
_WORKER: dict = {"frames": 0, "cal": {}, "warm": set(), "backends": None}
_TASK_LOCK = threading.Lock()
WORKER_CACHE_SIZE = 2  # backends a worker process keeps (their device memory:
# docs/measurements.md, clfza.distributed._batch)


def worker_backend_cache():
    """This process's :class:`clfza.backends.BackendCache` for batch tasks (made on first
    use; kept for the life of the worker process)."""
    if _WORKER["backends"] is None:

        _WORKER["backends"] = BackendCache(WORKER_CACHE_SIZE)
    return _WORKER["backends"]


@contextmanager
def batch_backend_cache():
    """A batch in the caller's own process: its own backend cache, dropped at its end (the
    caller's process is not a worker, it should not keep device memory after the batch), and
    its own dark and flat frames (read again by the next batch: the files may have changed)."""
    saved, cal = _WORKER["backends"], _WORKER["cal"]
    _WORKER["backends"], _WORKER["cal"] = None, {}
    try:
        yield
    finally:
        _WORKER["backends"], _WORKER["cal"] = saved, cal


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
    """Read (timed as I/O) and prepare one frame; returns y, its camera and a record part.

    ``src`` is a :class:`clfza.io.FrameRef` or an array; ``job.kind`` says whether it is a
    raw frame (prepared by ``job.prep``, see :func:`clfza.io.prepare_frame`) or a DC-free
    observation y (used as it is). ``t`` receives the ``read`` and ``prepare`` times (s).
    """

    t0 = time.perf_counter()
    if isinstance(src, np.ndarray):
        if job.kind == "frame":
            _not_an_observation(src)
        frame, bits = (check_frame(src, "frame") if job.kind == "frame"
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


def _not_an_observation(a: np.ndarray) -> None:
    """A one-line error for an in-memory array given as a raw frame (``kind="frame"``, the
    default) that looks like a DC-free observation: a raw frame is an intensity, well above
    zero on average; an observation y has mean ~0 and negative values."""
    a = np.asarray(a)
    if a.dtype.kind != "f" or not a.size or not np.isfinite(a).all():
        return
    mean, std = float(a.mean()), float(a.std())
    if a.min() < 0 and abs(mean) < 0.1 * std:
        raise ClfzaError("the array has mean ~0 and negative values: a DC-free observation "
                         "y, not a raw frame (an intensity); pass kind='y'")


def _refuse_existing(paths: dict[str, Path]) -> None:
    """Before any work: a frame's outputs must not exist (unless ``force`` or ``resume``)."""
    for p in paths.values():
        if p.exists():
            raise ClfzaError(f"{str(p)!r} exists; pass --force to overwrite it or "
                             "--resume to skip complete frames")


def _check_psf_pitch(psf, cam: Camera) -> None:
    """A measured PSF must be sampled on the prepared frame's pitch."""
    pitch = getattr(psf, "pitch", None)
    if pitch is not None and not math.isclose(pitch, cam.pitch, rel_tol=1e-6):
        raise ClfzaError(f"the PSF is sampled at {pitch:g} mm but the prepared frame at "
                         f"{cam.pitch:g} mm (crop, Bayer and binning change the frame's "
                         "pitch: load the PSF with frame_pitch set to it)")


def _encode(name: str, image: np.ndarray, out: OutputSpec, t: dict
            ) -> tuple[list[tuple[Path, bytes]], dict]:
    """The image and NPY files of one frame as bytes (written with its JSON, see
    :func:`run_frame`) and their part of the record."""

    t0 = time.perf_counter()
    paths = out.paths(name)
    npy, _ = encode_image(paths["npy"], image)
    img, scaling = encode_image(paths["image"], image, scaling=out.scaling,
                                percentiles=tuple(out.percentiles),
                                tiff_float=out.format == "tiff-float")
    t["write"] = time.perf_counter() - t0
    return ([(paths["npy"], npy), (paths["image"], img)],
            {"outputs": {k: str(v) for k, v in paths.items()}, "scaling": scaling})


@contextmanager
def _iteration_bar(job: Job, options: dict, y: np.ndarray, cam: Camera):
    """Options with a progress callback for an iterative method (``job.iteration_bar``: a
    single frame in this process, on a terminal); a checkpoint every ~2 % of the
    iterations."""
    if (not job.iteration_bar or job.method == "bp" or "callback" in options
            or "checkpoints" in options):
        yield options
        return
    method, resolved, _ = resolve_method(job.method, options)
    model = method_model(cam, job.model, method, resolved, psf=job.psf is not None, y=y)[0]
    iters = int(options.get("iters") or default_iters(method, model, psf=job.psf is not None) or 1)
    chans = 1 if y.ndim == 2 else y.shape[2]
    bar = tqdm(total=iters * chans, desc=job.method, unit="it", file=sys.stderr,
               dynamic_ncols=True, leave=False)

    def cb(rec: dict) -> None:
        done = int(rec.get("iteration", 0)) + iters * int(rec.get("channel") or 0)
        bar.update(max(0, min(done, bar.total) - bar.n))

    try:
        yield {**options, "checkpoints": max(1, iters // 50), "callback": cb}
    finally:
        bar.close()


def _solve(y: np.ndarray, cam: Camera, job: Job, device, t: dict, cache=None):
    """Plan (``job.plan``/``job.explain``) and reconstruct one prepared frame; returns the
    reconstruction and the plan (None without plan or explain)."""

    t0 = time.perf_counter()
    plan = None
    opts = dict(job.options)
    with reuse_backends(cache) if cache is not None else nullcontext():
        if (job.plan or job.explain) and not measured_psf(job, cam):
            plan = make_plan(y, cam, method=job.method, kind="y", iters=opts.get("iters"))
        if job.plan:
            rec = reconstruct_planned(y, cam, job.method, plan=plan, backend=job.backend,
                                      device=device, model=job.model, **opts)
            plan = rec.info.plan
        else:
            with _iteration_bar(job, opts, y, cam) as run_opts:
                rec = reconstruct(y, cam, job.method, backend=job.backend, device=device,
                                  model=job.model, margin=job.margin, psf=job.psf,
                                  **run_opts)
    t["reconstruct"] = time.perf_counter() - t0
    for k in ("compile", "plan", "solve"):
        t[k] = float(rec.info.timings.get(k, 0.0))
    return rec, plan


PSF_NO_PLAN = ("  measured PSF: no plan. The planner's decisions (binning, skips, the field of "
               "view) rest on the zone plate's geometry (its zone radius, depths and "
               "aperture), which a measured PSF replaces: solved as given")


def measured_psf(job: Job, cam: Camera) -> bool:
    """A measured PSF is the operator (``--psf``, or a camera of kind ``psf``): the planner,
    which models the zone plate, has nothing to say about it."""
    return job.psf is not None or getattr(cam, "kind", "fza") == "psf"


def _psf_record(psf) -> dict | None:
    if psf is None:
        return None
    info = dict(getattr(psf, "info", None) or {})
    return {"file": info.get("source", f"array {np.shape(getattr(psf, 'array', psf))}"),
            **info}


def _record(res: FrameResult, src, job: Job, rec, part: dict, cam: Camera, worker: dict,
            ran: dict, finish: dict) -> dict:
    """The JSON record of one reconstructed frame (outputs, scaling and timings are added
    by :func:`run_frame`)."""
    info = rec.info
    extra = {k: v for k, v in job.record.items() if k != "ignored_options"}
    where = {"input": getattr(src, "path", res.input)}
    if getattr(src, "key", None) is not None:
        where["input_key"] = src.key
    if getattr(src, "index", None) is not None:
        where["input_index"] = src.index
    r = {"clfza_version": __version__, "date": time.strftime("%Y-%m-%d %H:%M:%S"),
         "command": job.command, **where, "name": res.name, **part,
         "camera": cam.summary(), **extra, "method": info.method,
         "parameters": {**job.options, **({"margin": job.margin} if job.margin else {}),
                        **info.params}, "backend": info.backend,
         "device": info.device, "dtype": info.dtype, "iterations": info.iterations,
         "stop_reason": info.stop_reason, "notes": list(info.notes),
         "psf": _psf_record(job.psf), "output_geometry": finish, "worker": worker,
         "batch": job.batch,
         "machine": {"platform": platform.platform(), "python": platform.python_version()}}
    r.update(ran)  # the grid, bin factor, iterations and stop rule that actually ran
    ignored = [*job.record.get("ignored_options", []), *part.get("ignored_options", [])]
    if ignored:
        r["ignored_options"] = ignored
    r["objective_last"] = objective_last(info.objective)
    r["objective_history"] = _history(info.objective)
    if info.stats.get("white_balance"):  # colour: the gains divided out
        r["white_balance"] = info.stats["white_balance"]
    if info.stats.get("tau_auto"):  # tau=auto: the chosen tau and the criterion's values
        r["tau_auto"] = info.stats["tau_auto"]
    if info.stats.get("coarse_pilot"):  # a measured-PSF frame's coarse pilot
        r["coarse_pilot"] = info.stats["coarse_pilot"]
    chans = info.stats.get("channels") or []
    if any(c.get("tau_auto") or c.get("coarse_pilot") for c in chans):
        # a colour frame's channels, solved one by one: each its own choice
        r["channel_choices"] = [{k: c[k] for k in ("tau_auto", "coarse_pilot") if c.get(k)}
                                for c in chans]
    r["returned"] = _returned(info)
    r["frames_per_solve"] = int(info.stats.get("batch", {}).get("frames", 1))
    return r


def _number(v) -> float | None:
    if isinstance(v, (bool, np.bool_)) or not isinstance(v, (int, float, np.number)):
        return None
    return float(v)


def objective_last(history) -> float | None:
    """The final objective of a solve as one number: the last value of its history, summed
    over the colour channels when each has its own (the objective is a sum over channels);
    None for a method without one (back-propagation)."""
    if not history:
        return None
    if all(isinstance(h, (list, tuple)) for h in history):
        lasts = [_number(h[-1]) for h in history if len(h)]
        return None if not lasts or None in lasts else float(sum(lasts))
    return _number(history[-1])


def _history(history) -> list | None:
    """The objective's history for the record: a list of numbers, or one per channel."""
    if not history:
        return None
    if all(isinstance(h, (list, tuple)) for h in history):
        return [[_number(v) for v in h] for h in history]
    return [_number(v) for v in history]


def _returned(info) -> dict:
    """Which image the solve returned: the exact model's ADMM chooses the mean or the last
    iterate by their objectives; every other iterative method returns its last iterate, and
    a direct method (back-propagation, Wiener) its one image."""
    st = info.stats
    if st.get("returned"):
        return {"image": str(st["returned"]), "objective_mean": _number(st["objective_mean"]),
                "objective_last": _number(st["objective_last"])}
    direct = info.method in ("bp", "wiener")
    return {"image": "direct" if direct else "last", "objective_mean": None,
            "objective_last": objective_last(info.objective)}


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


@dataclass
class _Frame:
    """A frame between its preparation and its outputs (:func:`run_frame`,
    :func:`run_group`)."""

    res: FrameResult
    src: object
    label: str
    y: np.ndarray
    cam: Camera
    part: dict
    t: dict
    t0: float
    wall0: float


def _start_frame(index: int, src, name: str, job: Job, overwrite: bool
                 ) -> tuple[FrameResult, _Frame | None]:
    """Prepare one frame (refusing outputs that exist, checking the roi and the PSF's pitch):
    its result and the prepared frame, or the finished result (done by this batch already,
    or failed with a :class:`ClfzaError`) and None."""
    label = src.label if isinstance(src, FrameRef) else f"<array {index}>"
    res = FrameResult(index=index, name=name, input=label)
    wall0, t0 = time.time(), time.perf_counter()
    t: dict = {}
    out = job.output
    if _done_by_this_batch(res, job):
        return res, None
    try:
        if out is not None and not (out.force or overwrite):
            _refuse_existing(out.paths(name))
        y, cam, part = prepare_source(src, job, t)
        check_roi(job.roi, cam.shape)
        _check_psf_pitch(job.psf, cam)
    except ClfzaError as exc:
        if job.raise_errors:
            raise
        res.error = _one_line(exc, label)
        return res, None
    return res, _Frame(res, src, label, y, cam, part, t, t0, wall0)


def _end_frame(fr: _Frame, job: Job, rec, plan, overwrite: bool) -> FrameResult:
    """Cut the roi and orient, write the image, the NPY and the JSON record together (the
    JSON last: it marks the frame complete) or none of them; the frame's result."""
    res, t, cam, name = fr.res, fr.t, fr.cam, fr.res.name
    out = job.output
    force = out is not None and (out.force or overwrite)
    wname = _worker_name()
    try:
        image, finish = finish_image(rec.image, job.roi, job.orient)
        files, written = _encode(name, image, out, t) if out is not None else ([], {})
    except ClfzaError as exc:
        if job.raise_errors:
            raise
        res.error = _one_line(exc, fr.label)
        return res
    key = (cam, job.method, job.backend, str(_device_for(job, wname)))
    first = key not in _WORKER["warm"]
    _WORKER["warm"].add(key)
    _WORKER["frames"] += 1
    worker = {"name": wname, "pid": os.getpid(), "frames_done": _WORKER["frames"],
              "first_of_kind": first}
    ran = what_ran(fr.part, cam.shape, plan if job.plan else None, rec.info)
    record = _record(res, fr.src, job, rec, fr.part, cam, worker, ran, finish)
    record.update(written)
    t["task"] = time.perf_counter() - fr.t0
    record["timings_s"] = {**t, "solver": dict(rec.info.timings), "start_unix": fr.wall0,
                           "end_unix": time.time()}
    if out is not None:
        json_path = out.paths(name)["json"]
        try:  # the whole record or nothing; the JSON last marks the frame complete
            atomic_write_many(files + [(json_path, encode_json(record))], force=force)
        except ClfzaError as exc:
            if job.raise_errors:
                raise
            res.error = _one_line(exc, fr.label)
            return res
    if job.explain:
        res.explain = explain_ran(plan, ran, applied=job.plan,
                                  no_plan=PSF_NO_PLAN if measured_psf(job, cam) else None)
    res.ok, res.record = True, record
    res.image = image if job.return_images else None
    return res


def run_frame(index: int, src, name: str, job: Job, overwrite: bool = False) -> FrameResult:
    """Reconstruct one frame on this process (a Dask task, or a step of a local batch).

    Prepare, plan, solve, cut ``roi`` and orient, then write the image, the NPY and the JSON
    record together (the JSON last: it marks the frame complete) or none of them. A
    :class:`ClfzaError` becomes a failed :class:`FrameResult` (unless ``job.raise_errors``);
    anything else propagates, so that Dask (or the local loop) retries it.
    """
    with _TASK_LOCK:
        res, fr = _start_frame(index, src, name, job, overwrite)
        if fr is None:
            return res
        try:
            cache = worker_backend_cache() if job.cache_backends else None
            rec, plan = _solve(fr.y, fr.cam, job, _device_for(job, _worker_name()), fr.t,
                               cache)
        except ClfzaError as exc:
            if job.raise_errors:
                raise
            res.error = _one_line(exc, fr.label)
            return res
        return _end_frame(fr, job, rec, plan, overwrite)


def groups_frames(job: Job) -> bool:
    """Whether ``job`` solves consecutive frames together (:attr:`Job.frames_per_solve` > 1
    or "auto", a method that batches, no plan, no PSF, no per-frame progress bar)."""
    method = resolve_method(job.method, job.options)[0]
    return (job.frames_per_solve != 1 and not (job.plan or job.explain or job.iteration_bar)
            and job.psf is None and any(method == m for m, _ in BATCH_METHODS))


def resolve_frames_per_solve(job: Job, device) -> Job:
    """``job`` with ``frames_per_solve="auto"`` sized for ``device`` and the camera's frames
    (after the preparation's binning; :func:`clfza.solvers.frames_per_solve_for`)."""
    if job.frames_per_solve != "auto":
        return job
    b = str(job.prep.bin) if job.kind == "frame" else "1"
    b = int(b) if b.isdigit() else 1  # "auto" binning: sized for the unbinned frames
    shape = (job.camera.shape[0] // b, job.camera.shape[1] // b)
    n = frames_per_solve_for(resolve_method(job.method, job.options)[0], job.backend, device,
                             shape)
    return replace(job, frames_per_solve=n)


def run_group(items: list, job: Job) -> list[FrameResult]:
    """Reconstruct consecutive frames ``[(index, source, name, overwrite), ...]`` solved
    together (:func:`clfza.solvers.run_solver_batch` through :func:`clfza.reconstruct` on
    their stack), at most ``job.frames_per_solve`` at a time, frames of one camera and shape
    in one solve; each frame prepared and written as :func:`run_frame` does. A solve that
    fails with a :class:`ClfzaError` is redone frame by frame, so that one frame's error is
    its own."""
    if len(items) == 1 or not groups_frames(job):
        return [run_frame(i, src, name, job, ow) for i, src, name, ow in items]
    out: dict[int, FrameResult] = {}
    with _TASK_LOCK:
        ready: list[tuple[_Frame, bool]] = []
        for index, src, name, overwrite in items:
            res, fr = _start_frame(index, src, name, job, overwrite)
            if fr is None:
                out[index] = res
            else:
                ready.append((fr, overwrite))
        device = _device_for(job, _worker_name())
        cache = worker_backend_cache() if job.cache_backends else None
        for group in _solve_groups(ready, job.frames_per_solve):
            frs = [fr for fr, _ in group]
            try:
                recs = _solve_stack(frs, job, device, cache)
            except ClfzaError:
                if job.raise_errors:
                    raise
                recs = None
            for k, (fr, overwrite) in enumerate(group):
                if recs is None:  # one frame at a time: each frame's own error
                    try:
                        rec, plan = _solve(fr.y, fr.cam, job, device, fr.t, cache)
                    except ClfzaError as exc:
                        fr.res.error = _one_line(exc, fr.label)
                        out[fr.res.index] = fr.res
                        continue
                    out[fr.res.index] = _end_frame(fr, job, rec, plan, overwrite)
                else:
                    out[fr.res.index] = _end_frame(fr, job, recs[k], None, overwrite)
    return [out[it[0]] for it in items]


def _solve_groups(ready: list, size: int) -> Iterator[list]:
    """Consecutive prepared frames in solves of at most ``size`` frames of one camera and
    shape."""
    group: list = []
    for fr, ow in ready:
        if group and (len(group) == size or fr.cam != group[0][0].cam
                      or fr.y.shape != group[0][0].y.shape):
            yield group
            group = []
        group.append((fr, ow))
    if group:
        yield group


def _solve_stack(frs: list, job: Job, device, cache) -> list:
    """The frames' stack through :func:`clfza.reconstruct` (one batch where the method
    allows it); each frame's timings get its share of the call."""
    t0 = time.perf_counter()
    with reuse_backends(cache) if cache is not None else nullcontext():
        images, infos = reconstruct(np.stack([fr.y for fr in frs]), frs[0].cam, job.method,
                                    backend=job.backend, device=device, model=job.model,
                                    margin=job.margin, **job.options)
    share = (time.perf_counter() - t0) / len(frs)
    recs = []
    for fr, image, info in zip(frs, images, infos, strict=True):
        fr.t["reconstruct"] = share
        for k in ("compile", "plan", "solve"):
            fr.t[k] = float(info.timings.get(k, 0.0))
        recs.append(Reconstruction(image, info))
    return recs


def _one_line(exc: BaseException, label: str) -> str:

    msg = report_exception(exc)[0].removeprefix("clfza: error: ")
    return msg if label.strip("'") in msg else f"{label}: {msg}"


def run_chunk(items: list, job: Job) -> list[FrameResult]:
    """Reconstruct consecutive frames ``[(index, source, name, overwrite), ...]`` (one Dask
    task). Returns their results in order; an exception other than a ClfzaError on the
    first frame propagates (Dask retries the chunk), on a later frame it ends the chunk
    early: the caller resubmits the frames not returned."""
    job = resolve_frames_per_solve(job, _device_for(job, _worker_name()))
    if groups_frames(job):  # solved together, frames_per_solve at a time
        return run_group(items, job)
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
    if groups_frames(job):
        yield from _run_local_groups(todo, job, retries)
        return
    for i, src, name, overwrite in todo:
        for attempt in range(retries + 1):
            try:
                yield run_frame(i, src, name, job, overwrite)
                break
            except KeyboardInterrupt:
                raise
            except Exception as exc:
                if job.raise_errors:
                    raise
                if attempt == retries:
                    label = src.label if isinstance(src, FrameRef) else f"<array {i}>"
                    yield FrameResult(i, name, label, error=_one_line(exc, label)
                                      + f" (after {retries + 1} attempt(s))")


def _run_local_groups(todo, job: Job, retries: int) -> Iterator[FrameResult]:
    """Consecutive frames solved together; a group that raises anything but a
    :class:`ClfzaError` is redone frame by frame with the retries."""
    size = job.frames_per_solve
    for k in range(0, len(todo), size):
        items = todo[k:k + size]
        try:
            results = run_group(items, job)
        except KeyboardInterrupt:
            raise
        except Exception:
            if job.raise_errors:
                raise
            single = replace(job, frames_per_solve=1)
            yield from _run_local(items, single, retries)
            continue
        yield from results


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
                 target_s: float = CHUNK_TARGET_S, least: int = 1):
        self.workers, self.fixed, self.target = max(1, workers), chunk, target_s
        self.least = max(1, int(least))
        self.frame_s: list[float] = []

    def observe(self, r: FrameResult) -> None:
        t = r.timings.get("task") if r.ok and not r.skipped else None
        if t:
            self.frame_s = (self.frame_s + [float(t)])[-16:]

    def size(self, remaining: int) -> int:
        if self.fixed != "auto":
            return max(1, min(int(self.fixed), remaining))
        if self.least > 1:  # frames solved together: a task holds at least one solve's
            return max(1, min(remaining, max(self.least, self._timed(remaining))))
        return self._timed(remaining)

    def _timed(self, remaining: int) -> int:
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
    sizer = ChunkSizer(workers, chunk, least=job.frames_per_solve
                       if isinstance(job.frames_per_solve, int) else 1)
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
            elif job.raise_errors:  # the first error, as it was raised on the worker
                raise value[1] if isinstance(value, tuple) else value
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


def reconstruct_many(frames, camera: Camera, method: str = DEFAULT_METHOD, *, client=None,
                     workers: int | None = None, scheduler: str | None = None,
                     out_dir: str | Path | None = None, kind: str = "frame",
                     prep: FramePrep | None = None, backend: str = DEFAULT_BACKEND,
                     device: str | tuple | None = None, model: str = "auto", psf=None,
                     margin: int = 0, plan: bool = False, explain: bool = False,
                     roi: tuple[int, int, int, int] | None = None, orient: str = "sensor",
                     format: str = "png", scaling: str = "percentile",
                     percentiles: tuple = (0.1, 99.9), force: bool = False,
                     resume: bool = False, retries: int = 2, return_images: bool | None = None,
                     pin_cpus: bool = False,
                     progress: Callable[[FrameResult], None] | None = None, command: str = "",
                     record: dict | None = None, chunk: int | str = "auto",
                     cache_backends: bool = True, raise_errors: bool = False,
                     iteration_bar: bool = False, frames_per_solve: int | str = "auto",
                     **options) -> BatchResult:
    """Reconstruct many frames, in this process or on Dask, keeping their order.

    One frame is a batch of one: ``clfza reconstruct`` runs every input through here.

    Parameters
    ----------
    frames : paths, FrameRefs or arrays
        Files, folders, globs, multi-page TIFFs, ``.npy``/``.npz`` stacks, videos (see
        :func:`clfza.io.expand_frames`), a list of arrays or one ``(N, H, W[, 3])`` array.
    camera : Camera
        The camera (the sensor crop for raw frames, see ``prep``).
    method : str
        As :func:`clfza.reconstruct`; ``**options`` are its method options (tau, iters, ...).
    client, workers, scheduler
        Where to run: a ``distributed.Client``; else ``scheduler`` (an address); else an
        embedded LocalCluster of ``workers`` processes; none of them: this process.
    out_dir : path, optional
        Workers write ``NAME.png|.tif``, ``NAME.npy`` and ``NAME.json`` there, all three or
        none (atomic, the JSON last; no overwrite unless ``force``). Without it the images
        come back (``return_images``).
    kind : {"frame", "y"}
        Raw sensor frames, prepared by ``prep`` (dark, flat, Bayer, crop, bin) as the CLI
        does; or DC-free observations passed to :func:`clfza.reconstruct` as they are (the
        words of :func:`clfza.reconstruction.make_plan`'s ``kind``).
    model, psf, margin
        The forward model, as :func:`clfza.reconstruct`: ``psf`` is an array or a
        :class:`clfza.models.PSF` (:func:`clfza.models.load_psf`) on the prepared frames'
        pitch, sent once with the job and used for every frame.
    plan : bool
        Apply the planner (:func:`clfza.reconstruction.reconstruct_planned`: bin, skip flat
        frames, stop by the discrepancy principle); not with ``psf`` or ``margin``.
    explain : bool
        Make the plan and describe it with what ran in :attr:`FrameResult.explain`.
    roi : (y, x, h, w), optional
        Keep only rows ``y..y+h`` and columns ``x..x+w`` (pixels of the reconstruction grid).
    orient : {"sensor", "upright"}
        ``"upright"`` rotates the kept image by 180 degrees (the pinhole inverts the scene).
    format, scaling, percentiles
        The image file: ``"png"``/``"tiff"`` (16 bits, scaled) or ``"tiff-float"``.
    resume : bool
        Skip frames whose complete outputs exist in ``out_dir``; redo partial ones.
    retries : int
        Further attempts for a frame that failed other than by a ClfzaError, or whose worker
        died.
    pin_cpus : bool
        Embedded cluster only: give each worker its own share of the cores.
    progress : callable, optional
        Called with each :class:`FrameResult` as it finishes (skipped frames first).
    command, record
        The command recorded in each JSON record, and further fields added to every record
        (``record["ignored_options"]`` joins the frame's own list).
    chunk : int or "auto"
        Frames per Dask task (see the module notes); 1 submits every frame as its own task.
    cache_backends : bool
        Keep the solver set-up between frames (per worker process; per batch in this
        process): see :class:`clfza.backends.BackendCache`. False rebuilds it per frame.
    raise_errors : bool
        Raise a frame's error at once (with its traceback) instead of recording it in its
        :class:`FrameResult` (``clfza --debug``).
    iteration_bar : bool
        Show the solver's iterations as a progress bar on stderr (frames solved in this
        process).
    frames_per_solve : int or "auto"
        Consecutive frames of one camera and shape solved together, one kernel launch per
        step for all of them (:func:`clfza.solvers.run_solver_batch`: ADMM, FISTA (TV) and
        TwIST (TV) on the transfer-function model, a fixed ``tau`` or ``"auto"``; other
        solves run one frame at a time).
        ``"auto"``: sized per device and frame size
        (:func:`clfza.solvers.frames_per_solve_for`); 1 solves each frame alone. Not with
        ``plan``, ``explain``, a ``psf`` or the iteration bar.

    Returns
    -------
    BatchResult
        ``results`` in input order; failed frames have ``error`` set. It unpacks as
        ``images, infos`` (see :class:`BatchResult`).

    Examples
    --------
    >>> images, infos = clfza.reconstruct_many(np.stack(ys), camera, "admm", kind="y",
    ...                                        iters=50)               # doctest: +SKIP
    >>> res = clfza.reconstruct_many(["a.tif", "frames/"], camera, out_dir="out",
    ...                              workers=4)                       # doctest: +SKIP
    """
    out = None if out_dir is None else OutputSpec(str(out_dir), format, scaling,
                                                  tuple(percentiles), force)
    if out is None and resume:
        raise ClfzaError("resume=True needs out_dir (it looks for complete outputs there)")
    if chunk != "auto":
        chunk = positive_int("chunk", chunk)
    job = Job(camera, method, dict(options), backend, device, kind, prep or FramePrep(), out,
              bool(return_images if return_images is not None else out is None), command,
              bool(cache_backends), uuid.uuid4().hex, model=model, margin=margin, psf=psf,
              plan=bool(plan), explain=bool(explain), roi=None if roi is None else tuple(roi),
              orient=orient, record=dict(record or {}), raise_errors=bool(raise_errors),
              iteration_bar=bool(iteration_bar),
              frames_per_solve=(frames_per_solve if frames_per_solve == "auto" else
                                positive_int("frames_per_solve", frames_per_solve)))
    check_batch(job, retries)
    local = client is None and workers is None and scheduler is None
    if local:  # Dask workers size "auto" for their own device (run_chunk)
        job = resolve_frames_per_solve(job, device[0] if isinstance(device, tuple)
                                       else device)
    with batch_backend_cache() if local else nullcontext():
        _check_calibration(job, local)
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


def _check_calibration(job: Job, local: bool) -> None:
    """Read the dark and flat frames before any frame: a bad one fails the batch with one
    error (in this process they are kept for the batch's frames)."""
    if job.kind != "frame":
        return
    if local:
        _calibration(job.prep)
        return
    load_calibration_frame(job.prep.dark, "dark frame")
    load_calibration_frame(job.prep.flat, "flat field")


def _run(todo, job: Job, results: dict, progress, client, workers: int | None,
         scheduler: str | None, retries: int, pin_cpus: bool, chunk: int | str
         ) -> tuple[str, int]:
    """Run the tasks ``todo`` where :func:`reconstruct_many` was told to, collecting their
    results into ``results``; returns where they ran and on how many workers."""
    if not todo:
        return "nothing to do", 0
    if client is None and workers is None and scheduler is None:
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
