"""Many frames: :func:`reconstruct_many` (in this process, or on Dask workers; one frame is a
batch of one, and ``clfza reconstruct`` runs every input through it), its jobs, results and
clusters, and parameter sweeps over ``tau`` and the object distance (:func:`sweep`)."""

from __future__ import annotations

from ._batch import prepare_source, reconstruct_many
from ._cluster import require_dask
from ._jobs import KINDS, BatchResult, FramePrep, FrameResult, Job, check_roi
from ._sweep import edge_warning, parse_values, sweep, write_sweep

__all__ = [
    "KINDS",
    "BatchResult",
    "FramePrep",
    "FrameResult",
    "Job",
    "check_roi",
    "edge_warning",
    "parse_values",
    "prepare_source",
    "reconstruct_many",
    "require_dask",
    "sweep",
    "write_sweep",
]
