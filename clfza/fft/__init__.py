"""FFT engines for the operator K.

An engine has ``rfft2(x, X)`` and ``irfft2(X, x)`` on :class:`~clfza.cl.DeviceArray`; the
operator sees nothing else. Policy (``select_engine``): host scipy.fft on CPU devices (fastest
there, zero-copy), OpenCL kernels on GPUs.
"""

from __future__ import annotations

import numpy as np

from ..errors import ClfzaError
from .host import HostFFT, host_irfft2, host_rfft2

POLICIES = ("auto", "host", "device", "vkfft")

__all__ = ["HostFFT", "host_rfft2", "host_irfft2", "select_engine", "POLICIES"]


def select_engine(rt, shape, dtype=np.float32, policy: str = "auto"):
    """Pick the FFT engine for a runtime, grid and dtype.

    ``"auto"``: host scipy.fft on CPU devices; the OpenCL device FFT on other devices when it
    is available, else host scipy.fft with copies. ``"host"``, ``"device"`` and ``"vkfft"``
    force a path.
    """
    if policy not in POLICIES:
        raise ClfzaError(f"fft policy must be one of {POLICIES}, got {policy!r}")
    if policy == "host" or (policy == "auto" and rt.is_cpu):
        return HostFFT(rt, shape, dtype)
    try:
        from .opencl import DeviceFFT  # noqa: F401  (added by the device-FFT work)
    except ImportError:
        if policy == "auto":
            return HostFFT(rt, shape, dtype)
        raise ClfzaError("the OpenCL device FFT is not available in this build") from None
    if policy == "vkfft":
        from .vkfft import VkFFTEngine

        return VkFFTEngine(rt, shape, dtype)
    return DeviceFFT(rt, shape, dtype)
