"""What a batch of frames is made of (:func:`clfza.distributed.reconstruct_many`).

The records a task carries (:class:`Job`, with :class:`FramePrep` and :class:`OutputSpec`)
and those it returns (:class:`FrameResult`, gathered into a :class:`BatchResult`), and the
client's preparation of a batch before anything runs: its sources, the checks of its
options, and the frames ``resume`` skips (:func:`frame_state`). :mod:`clfza.distributed`
re-exports the public names here.
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..camera import Camera
from ..errors import ClfzaError, positive_int
from ..io import FrameRef, expand_frames, unique_names
from ..solvers import METHODS

IMAGE_SUFFIX = {"png": ".png", "tiff": ".tif", "tiff-float": ".tif"}
KINDS = ("raw", "y")


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
    """Everything a worker needs besides the frame (small; sent with every task)."""

    camera: Camera
    method: str = "bp"
    options: dict = field(default_factory=dict)
    backend: str = "opencl"
    device: str | tuple | None = None
    kind: str = "raw"
    prep: FramePrep = field(default_factory=FramePrep)
    output: OutputSpec | None = None
    return_images: bool = False
    command: str = ""
    cache_backends: bool = True
    batch: str = ""  # this batch's id, recorded in each JSON (a retried chunk skips its own)


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

    @property
    def timings(self) -> dict:
        return (self.record or {}).get("timings_s", {})


@dataclass
class BatchResult:
    """All frames in input order, with the wall time and where they ran."""

    results: list[FrameResult]
    wall_s: float
    where: str
    n_workers: int

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
        return [r.image for r in self.results]

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


def check_batch(camera, method: str, backend: str, kind: str, retries: int, out: OutputSpec | None
           ) -> None:
    if not isinstance(camera, Camera):
        raise ClfzaError(f"camera must be a clfza.Camera, got {type(camera).__name__}")

    if method not in METHODS:
        raise ClfzaError(f"unknown method {method!r}; available: {', '.join(METHODS)}")
    if backend not in ("opencl", "numpy"):
        raise ClfzaError(f"backend must be 'opencl' or 'numpy', got {backend!r}")
    if kind not in KINDS:
        raise ClfzaError(f"kind must be one of {KINDS}, got {kind!r}")
    positive_int("retries", retries, 0)
    if out is not None:
        if out.format not in IMAGE_SUFFIX:
            raise ClfzaError(f"format must be one of {tuple(IMAGE_SUFFIX)}, got {out.format!r}")
        if Path(out.out_dir).exists() and not Path(out.out_dir).is_dir():
            raise ClfzaError(f"out_dir {out.out_dir!r} is a file, not a folder")


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
