"""The array backends the solvers run on: one core interface (:class:`Backend`, with the
operation families :class:`Ops`), the numpy float64 reference and OpenCL, on the transfer-function
model (Eq. 17) and on the exact finite-aperture model; :func:`get_backend` makes one, and the
OpenCL kernels' variants are tuned per device (:func:`retune`)."""

from __future__ import annotations

from ._base import Backend, Ops, ProxState, Ready, Scalars, read_all
from ._numpy import diff_symbol, half_weights
from ._opencl import OpenCLBackend
from ._select import BACKENDS, BackendCache, exact_model, get_backend, reuse_backends
from ._tuning import cache_path as tuning_cache_path
from ._tuning import load_cache as tuning_cache
from ._tuning import report as tuning_report
from ._tuning import retune, tuning_key
from ._tuning import table_lines as tuning_table

__all__ = [
    "BACKENDS",
    "Backend",
    "BackendCache",
    "OpenCLBackend",
    "Ops",
    "ProxState",
    "Ready",
    "Scalars",
    "diff_symbol",
    "exact_model",
    "get_backend",
    "half_weights",
    "read_all",
    "retune",
    "reuse_backends",
    "tuning_cache",
    "tuning_cache_path",
    "tuning_key",
    "tuning_report",
    "tuning_table",
]
