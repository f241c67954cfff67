"""What a batch of frames is made of (:func:`clfza.distributed.reconstruct_many`).

The records a task carries (:class:`Job`, with :class:`FramePrep` and :class:`OutputSpec`)
and those it returns (:class:`FrameResult`, gathered into a :class:`BatchResult`), the
client's preparation of a batch before anything runs (its sources, the checks of its
options, the frames ``resume`` skips: :func:`frame_state`), and the pieces of a frame's JSON
record that describe what ran (:func:`what_ran`, :func:`explain_ran`, :func:`finish_image`).
:mod:`clfza.distributed` re-exports the public names here.
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..backends import BACKENDS
from ..camera import Camera
from ..errors import ClfzaError, positive_int
from ..io import FrameRef, expand_frames, unique_names
from ..models import PSF
from ..solvers import DEFAULT_BACKEND, DEFAULT_METHOD, METHOD_NAMES, method_model

IMAGE_SUFFIX = {"png": ".png", "tiff": ".tif", "tiff-float": ".tif"}
#: What a batch's frames are: raw sensor frames, or DC-free observations y (the words of
#: :func:`clfza.reconstruction.make_plan`'s ``kind``, which also guesses with "auto").
KINDS = ("frame", "y")
ORIENTS = ("sensor", "upright")


@dataclass(frozen=True)
class FramePrep:
    """How a raw frame becomes the observation y (the CLI's frame options, see
    :func:`clfza.io.prepare_frame`)."""

    dark: str | None = None
    flat: str | None = None
    bayer: str | None = None
    crop: tuple | None = None
    center: tuple | None = None
    bin: str = "1"
    object_mean: float = 0.5
    # the options already warned about as ignored (clfza.io.warn_ignored: once per batch)
    _warned: set = field(default_factory=set, init=False, compare=False, repr=False)


@dataclass(frozen=True)
class OutputSpec:
    """Where and how workers write: ``DIR/NAME.png|.tif``, ``NAME.npy``, ``NAME.json``."""

    out_dir: str
    format: str = "png"
    scaling: str = "percentile"
    percentiles: tuple = (0.1, 99.9)
    force: bool = False

    def paths(self, name: str) -> dict[str, Path]:
        d = Path(self.out_dir)
        return {"image": d / f"{name}{IMAGE_SUFFIX[self.format]}", "npy": d / f"{name}.npy",
                "json": d / f"{name}.json"}


@dataclass(frozen=True)
class Job:
    """Everything a worker needs besides the frame (sent with every task; picklable: Dask
    pickles it by module path, a measured PSF's array travels inside it).

    ``model``, ``margin`` and ``psf`` choose the forward model (as :func:`clfza.reconstruct`);
    ``plan`` applies the planner (:func:`clfza.reconstruction.reconstruct_planned`),
    ``explain`` describes it (:attr:`FrameResult.explain`); ``roi`` (``(y, x, h, w)``
    pixels) and ``orient`` shape the saved image; ``record`` holds fields added to every
    frame's JSON record; ``raise_errors`` lets a frame's error propagate instead of being
    recorded; ``iteration_bar`` shows a solver progress bar (a single frame in this process,
    on a terminal).
    """

    camera: Camera
    method: str = DEFAULT_METHOD
    options: dict = field(default_factory=dict)
    backend: str = DEFAULT_BACKEND
    device: str | tuple | None = None
    kind: str = "frame"
    prep: FramePrep = field(default_factory=FramePrep)
    output: OutputSpec | None = None
    return_images: bool = False
    command: str = ""
    cache_backends: bool = True
    batch: str = ""  # this batch's id, recorded in each JSON (a retried chunk skips its own)
    model: str = "auto"
    margin: int = 0
    psf: PSF | np.ndarray | None = None  # on the prepared frames' pitch
    plan: bool = False
    explain: bool = False
    roi: tuple | None = None
    orient: str = "sensor"
    record: dict = field(default_factory=dict)
    raise_errors: bool = False
    iteration_bar: bool = False
    frames_per_solve: int = 1  # consecutive frames solved together (run_group)


@dataclass
class FrameResult:
    """The outcome of one frame: its record (timings, outputs, device, worker) or its error."""

    index: int
    name: str
    input: str
    ok: bool = False
    error: str | None = None
    record: dict | None = None
    image: np.ndarray | None = None
    skipped: bool = False  # resume found complete outputs
    explain: str | None = None  # Job.explain: the plan and what ran, as text

    @property
    def timings(self) -> dict:
        return (self.record or {}).get("timings_s", {})


@dataclass
class BatchResult:
    """All frames in input order, with the wall time and where they ran.

    A batch unpacks as ``images, infos`` (as :func:`clfza.reconstruct`'s result unpacks as
    ``image, info``): two lists in input order, one entry per frame. ``images[i]`` is the
    reconstruction (float64 ``(H, W)`` or ``(H, W, 3)``, after ``roi`` and ``orient``), or
    None for a frame that failed, that ``resume`` skipped, or whose image was only written
    to disk (images are kept when there is no ``out_dir``, or with ``return_images=True``).
    ``infos[i]`` is the frame's JSON record (a dict: parameters, camera, device, timings,
    outputs, ...); for a failed frame it is ``{"input", "name", "error"}``.

    Examples
    --------
    >>> images, infos = clfza.reconstruct_many(ys, camera, "admm", kind="y")  # doctest: +SKIP
    >>> res = clfza.reconstruct_many("frames/", camera, out_dir="out")  # doctest: +SKIP
    >>> [r.error for r in res.failed]                                   # doctest: +SKIP
    """

    results: list[FrameResult]
    wall_s: float
    where: str
    n_workers: int

    def __iter__(self):  # allows ``images, infos = clfza.reconstruct_many(...)``
        yield self.images
        yield self.infos

    @property
    def succeeded(self) -> list[FrameResult]:
        return [r for r in self.results if r.ok]

    @property
    def failed(self) -> list[FrameResult]:
        return [r for r in self.results if not r.ok]

    @property
    def skipped(self) -> list[FrameResult]:
        return [r for r in self.results if r.skipped]

    @property
    def images(self) -> list[np.ndarray | None]:
        """Per frame, in input order: the image, or None (see the class docstring)."""
        return [r.image for r in self.results]

    @property
    def infos(self) -> list[dict]:
        """Per frame, in input order: its JSON record, or ``{"input", "name", "error"}``."""
        return [r.record if r.ok and r.record is not None
                else {"input": r.input, "name": r.name, "error": r.error}
                for r in self.results]

    def summary(self) -> dict:
        """A JSON-able summary: counts, wall time, outputs and failures (in input order)."""
        return {"frames": len(self.results), "succeeded": len(self.succeeded),
                "skipped_complete": len(self.skipped), "failed": len(self.failed),
                "wall_s": self.wall_s, "where": self.where, "workers": self.n_workers,
                "outputs": [{"input": r.input, **(r.record or {}).get("outputs", {})}
                            for r in self.results if r.ok],
                "failures": [{"input": r.input, "error": r.error} for r in self.failed]}


def frame_state(out: OutputSpec, name: str) -> str:
    """``"complete"`` (the JSON record exists, parses and its outputs exist), ``"partial"``
    (some outputs exist) or ``"absent"``."""
    paths = out.paths(name)
    if paths["json"].exists():
        try:
            rec = json.loads(paths["json"].read_text(encoding="utf-8"))
            outs = rec.get("outputs", {})
            if all(Path(outs.get(k, "")).is_file() for k in ("image", "npy")):
                return "complete"
        except (OSError, ValueError, AttributeError):
            pass
        return "partial"
    return "partial" if any(p.exists() for p in paths.values()) else "absent"


def frame_sources(frames) -> list[tuple[object, str]]:
    """(source, output name) per frame: FrameRefs from paths/globs/stacks, or arrays."""
    if isinstance(frames, np.ndarray):
        one = frames.ndim == 2 or (frames.ndim == 3 and frames.shape[2] in (1, 3, 4))
        frames = [frames] if one else list(frames)
    if isinstance(frames, (str, Path)):
        frames = [frames]
    items = list(frames)
    if items and all(isinstance(f, np.ndarray) for f in items):
        return [(a, f"frame-{i:05d}") for i, a in enumerate(items)]
    refs: list[FrameRef] = []
    for f in items:
        if isinstance(f, FrameRef):
            refs.append(f)
        elif isinstance(f, (str, Path)):
            got, missing = expand_frames([f])
            if missing:
                raise ClfzaError(f"{missing[0][0]!r}: {missing[0][1]}")
            refs.extend(got)
        else:
            raise ClfzaError(f"frames must be paths, FrameRefs or arrays, got {type(f).__name__}")
    refs = unique_names(refs) if any(not r.name for r in refs) else refs
    return [(r, r.name) for r in refs]


def check_batch(job: Job, retries: int) -> None:
    """Every option of a batch that can be checked before a frame is read, with one line."""
    if not isinstance(job.camera, Camera):
        raise ClfzaError(f"camera must be a clfza.Camera, got {type(job.camera).__name__}")
    if job.method not in METHOD_NAMES:
        raise ClfzaError(f"unknown method {job.method!r}; available: "
                         f"{', '.join(METHOD_NAMES)}")
    if job.backend not in BACKENDS:
        raise ClfzaError(f"backend must be 'opencl' or 'numpy', got {job.backend!r}")
    if job.kind not in KINDS:
        hint = " ('raw' is now called 'frame')" if job.kind == "raw" else ""
        raise ClfzaError(f"kind must be one of {KINDS}, got {job.kind!r}{hint}")
    positive_int("retries", retries, 0)
    positive_int("margin", job.margin, 0)
    if isinstance(job.model, str):  # the model's name, and a PSF with model="tf"
        method_model(job.camera, job.model, "bp", psf=job.psf is not None)
    if job.plan and (job.psf is not None or job.margin):
        raise ClfzaError("--plan bins for the camera's own mask model; give --psf or "
                         "--margin without --plan")
    if job.orient not in ORIENTS:
        raise ClfzaError(f"orient must be one of {ORIENTS}, got {job.orient!r}")
    if job.roi is not None and (len(job.roi) != 4 or min(job.roi) < 0
                                or not job.roi[2] or not job.roi[3]):
        raise ClfzaError(f"roi must be (y, x, h, w) integers (h, w > 0), got {job.roi!r}")
    out = job.output
    if out is not None:
        if out.format not in IMAGE_SUFFIX:
            raise ClfzaError(f"format must be one of {tuple(IMAGE_SUFFIX)}, got {out.format!r}")
        if Path(out.out_dir).exists() and not Path(out.out_dir).is_dir():
            raise ClfzaError(f"out_dir {out.out_dir!r} is a file, not a folder")


def check_roi(roi, shape) -> None:
    """``roi`` (``(y, x, h, w)`` pixels, or None) must lie inside the grid ``shape``."""
    if roi is not None and (roi[0] + roi[2] > shape[0] or roi[1] + roi[3] > shape[1]):
        raise ClfzaError(f"--roi {','.join(map(str, roi))} reaches outside the "
                         f"{shape[0]}x{shape[1]} reconstruction grid")


def finish_image(img: np.ndarray, roi, orient: str) -> tuple[np.ndarray, dict]:
    """The saved image: ``roi`` (rows y..y+h, columns x..x+w of the sensor grid) cut out,
    then rotated by 180 degrees for ``orient="upright"`` (the pinhole geometry inverts the
    scene, Eq. 2); returns it and what was done (the record's ``output_geometry``).

    Examples
    --------
    >>> finish_image(np.arange(16.).reshape(4, 4), (1, 1, 2, 2), "upright")[0]
    array([[10.,  9.],
           [ 6.,  5.]])
    """
    done: dict = {"orient": orient}
    if roi is not None:
        check_roi(roi, img.shape[:2])
        y, x, h, w = roi
        img = img[y:y + h, x:x + w]
        done["roi"] = list(roi)
    if orient == "upright":
        img = img[::-1, ::-1]
    return img, done


def what_ran(prep_record: dict, shape, plan, info) -> dict:
    """The facts of a run for its JSON record, from the run itself: the bin factor and grid
    the solve ran on (frame preparation x the plan), the iterations and the stop rule that
    fired. ``prep_record``: the preparation's record (its ``bin``); ``shape``: the prepared
    frame's grid; ``plan``: the applied plan, or None."""
    b_prep = int(prep_record.get("bin", 1))
    b_plan = int(plan.bin) if plan is not None else 1
    work = plan.work_camera.shape if plan is not None else shape
    if plan is not None and plan.skip_solve:
        b_plan, work = 1, shape
    stop = str(info.stop_reason)
    params = info.params.get("plan") or {}
    rule = params.get("stop_rule_fired") if isinstance(params, dict) else None
    return {"bin": b_prep * b_plan, "bin_prepare": b_prep, "bin_plan": b_plan,
            "solve_shape": [int(v) for v in work], "iterations": int(info.iterations),
            "stop_reason": stop, "stop_rule_fired": rule or stop}


def explain_ran(plan, ran: dict, applied: bool, no_plan: str | None = None) -> str:
    """``--explain``: the plan, then what actually ran (from the run's own record);
    ``no_plan``: what to say where there is no plan."""
    text = plan.explain() if plan is not None else (no_plan or "  (no plan)")
    head = ("" if applied or plan is None
            else "  (advice only: the plan was not applied; add --plan)\n")
    return (head + text + f"\n  ran: {ran['iterations']} iteration(s) on "
            f"{ran['solve_shape'][0]}x{ran['solve_shape'][1]} (bin {ran['bin']}: "
            f"{ran['bin_prepare']} at preparation x {ran['bin_plan']} by the plan), stop: "
            f"{ran['stop_rule_fired']}")


def pending_frames(sources, out: OutputSpec | None, resume: bool
          ) -> tuple[list[tuple[int, object, str, bool]], dict[int, FrameResult]]:
    """Tasks to run ``(index, source, name, overwrite)`` and the frames resume skips."""
    todo, done = [], {}
    for i, (src, name) in enumerate(sources):
        label = src.label if isinstance(src, FrameRef) else f"<array {i}>"
        state = frame_state(out, name) if (out is not None and resume) else "absent"
        if state == "complete":
            rec = json.loads(out.paths(name)["json"].read_text(encoding="utf-8"))
            done[i] = FrameResult(i, name, label, ok=True, record=rec, skipped=True)
        else:
            # resume: this batch's own, unfinished outputs may be replaced (a partial frame,
            # or one an interrupted task still completes meanwhile); others never
            todo.append((i, src, name, resume))
    return todo, done
