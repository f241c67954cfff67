"""OpenCL runtime: device choice, program cache and host-backed device arrays."""

from ._arrays import DeviceArray
from ._runtime import Runtime, get_runtime, list_devices

__all__ = ["DeviceArray", "Runtime", "get_runtime", "list_devices"]
