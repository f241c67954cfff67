"""Many frames: :func:`reconstruct_many` (in this process, or on Dask workers), its jobs and
clusters, and parameter sweeps over ``tau`` and the object distance (:func:`sweep`)."""

from __future__ import annotations

from ._batch import prepare_source, reconstruct_many
from ._cluster import require_dask
from ._jobs import BatchResult, FramePrep, Job
from ._sweep import parse_values, sweep, write_sweep

__all__ = [
    "BatchResult",
    "FramePrep",
    "Job",
    "parse_values",
    "prepare_source",
    "reconstruct_many",
    "require_dask",
    "sweep",
    "write_sweep",
]
