"""OpenCL runtime: device choice, program cache and host-backed device arrays."""

from __future__ import annotations

from ._arrays import DeviceArray, complex_of
from ._kernels import typed_kernel
from ._runtime import (
    MEASURE_ITERS,
    MEASURE_SIZE,
    SCORES_FILE,
    Runtime,
    cache_dir,
    choice_report,
    device_key,
    device_problems,
    get_runtime,
    kernel_source,
    list_devices,
    read_cache,
    set_device_measurer,
    set_status_writer,
    status,
    stderr_status,
    warning_lines,
    write_cache,
)

__all__ = [
    "DeviceArray",
    "MEASURE_ITERS",
    "MEASURE_SIZE",
    "Runtime",
    "SCORES_FILE",
    "cache_dir",
    "choice_report",
    "complex_of",
    "device_key",
    "device_problems",
    "get_runtime",
    "kernel_source",
    "list_devices",
    "read_cache",
    "set_device_measurer",
    "set_status_writer",
    "status",
    "stderr_status",
    "warning_lines",
    "typed_kernel",
    "write_cache",
]
