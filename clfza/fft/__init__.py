"""FFT engines for the operator K.

An engine has ``rfft2(x, X)`` and ``irfft2(X, x)`` on :class:`~clfza.cl.DeviceArray`; the
operator sees nothing else. Policy (:func:`select_engine`): host scipy.fft (float32,
``workers`` = cores, zero-copy buffers) on CPU devices, where it is the fastest transform
(docs/design.md s.6); the OpenCL Stockham kernels (:class:`~clfza.fft._opencl.DeviceFFT`) on GPUs
and other devices; pyvkfft's VkFFT when asked for and installed. The user can override the
policy; :func:`describe_policy` says which path a runtime uses (``clfza info``).
"""

from __future__ import annotations

import os

import numpy as np

from ..errors import ClfzaError
from ._engine import FFTEngine
from ._host import WORKERS, HostFFT, host_irfft2, host_rfft2
from ._opencl import plan
from ._vkfft import VkFFTEngine, vkfft_available

POLICIES = ("auto", "host", "device", "vkfft")
ENV_POLICY = "CLFZA_FFT"

__all__ = [
    "FFTEngine",
    "HostFFT",
    "host_rfft2",
    "host_irfft2",
    "select_engine",
    "describe_policy",
    "resolve_policy",
    "POLICIES",
]


def resolve_policy(rt, policy: str = "auto") -> str:
    """The concrete path (``"host"``, ``"device"`` or ``"vkfft"``) for a policy on a runtime.

    ``"auto"`` honours the ``CLFZA_FFT`` environment variable when it names a policy, then
    picks host scipy.fft on CPU devices and the OpenCL device kernels elsewhere.
    """
    if policy not in POLICIES:
        raise ClfzaError(f"fft policy must be one of {POLICIES}, got {policy!r}")
    if policy == "auto":
        env = os.environ.get(ENV_POLICY, "").strip().lower()
        if env and env != "auto":
            if env not in POLICIES:
                raise ClfzaError(f"{ENV_POLICY} must be one of {POLICIES}, got {env!r}")
            return env
        return "host" if rt.is_cpu else "device"
    return policy


def select_engine(rt, shape, dtype=np.float32, policy: str = "auto", **options):
    """Pick the FFT engine for a runtime, grid and dtype.

    Parameters
    ----------
    rt : Runtime
        The device.
    shape : (int, int)
        Real grid.
    dtype : numpy dtype
        float32 or float64.
    policy : str
        ``"auto"`` (host scipy.fft on CPU devices, OpenCL kernels on GPUs; overridable with the
        ``CLFZA_FFT`` environment variable), or ``"host"``, ``"device"``, ``"vkfft"`` to force
        a path.
    **options
        Passed to :class:`~clfza.fft._opencl.DeviceFFT` (``bluestein``, ``pad_to_fast``, ...)
        on the device path.
    """
    path = resolve_policy(rt, policy)
    if path == "host":
        return HostFFT(rt, shape, dtype)
    if path == "vkfft":
        return VkFFTEngine(rt, shape, dtype)

    return plan(rt, shape, dtype, **options)


def describe_policy(rt, policy: str = "auto") -> str:
    """One line saying which FFT path ``policy`` uses on ``rt`` (for ``clfza info``)."""

    path = resolve_policy(rt, policy)
    vk = "pyvkfft available" if vkfft_available() else "pyvkfft not installed"
    if path == "host":
        how = "zero-copy buffers" if rt.zero_copy else "copies through the host"
        return (
            f"host scipy.fft (pocketfft, workers={WORKERS}, {how}); device kernels "
            f"'opencl-stockham' with fft='device'; {vk}"
        )
    if path == "vkfft":
        return (
            "pyvkfft VkFFT (OpenCL backend)"
            if vkfft_available()
            else "pyvkfft VkFFT requested but not installed"
        )
    return (
        f"OpenCL Stockham kernels 'opencl-stockham' (radix 2/3/4/5/7/8, Bluestein for "
        f"other sizes) on {rt.info.name}; {vk}"
    )
