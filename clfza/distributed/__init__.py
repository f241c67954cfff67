"""Many frames: :func:`reconstruct_many` on Dask, its jobs and clusters, and parameter sweeps."""

from __future__ import annotations

from ._batch import reconstruct_many

__all__ = ["reconstruct_many"]
