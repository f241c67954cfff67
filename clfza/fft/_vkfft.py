"""Optional FFT engine on pyvkfft's OpenCL backend (VkFFT), for GPUs where it is installed.

pyvkfft is not a dependency: this module imports it lazily and raises :class:`ClfzaError` with
an install hint when it is missing. VkFFT works on PoCL too, but is slower than scipy.fft
there (docs/design.md s.6; measured: docs/measurements.md, clfza.fft._vkfft); on GPUs it is
the transform to beat.
"""

from __future__ import annotations

import numpy as np

from ..cl import DeviceArray
from ..errors import ClfzaError

INSTALL_HINT = ("pyvkfft is not installed; `pip install pyvkfft` (it builds against the OpenCL "
                "headers: apt-get install opencl-headers ocl-icd-opencl-dev) or use the "
                "'device' or 'host' FFT policy")


def vkfft_available() -> bool:
    """True when ``pyvkfft.opencl`` can be imported."""
    try:
        import pyvkfft.opencl  # noqa: F401  # lazy: pyvkfft is an optional FFT engine
    except Exception:
        return False
    return True


class VkFFTEngine:
    """``rfft2``/``irfft2`` on :class:`~clfza.cl.DeviceArray` through pyvkfft's OpenCL backend.

    Parameters
    ----------
    rt : Runtime
        The device.
    shape : (int, int)
        Real grid ``(Ny, Nx)``; spectra are ``(Ny, Nx // 2 + 1)``.
    dtype : numpy dtype
        float32 or float64.

    Notes
    -----
    Out-of-place R2C/C2R with numpy normalisation (``norm=1``: the inverse divides by N). The
    device buffers are wrapped as ``pyopencl.array.Array`` views without copies. ``irfft2``
    copies ``X`` into a scratch spectrum first, because VkFFT's C2R may overwrite its input.
    """

    name = "vkfft"
    batched = False  # one plane per call

    def __init__(self, rt, shape, dtype=np.float32):
        try:
            import pyopencl.array as cla  # lazy: pyopencl loads only when an OpenCL device is used
            from pyvkfft.opencl import VkFFTApp  # lazy: pyvkfft is an optional FFT engine
        except Exception as exc:
            raise ClfzaError(f"{INSTALL_HINT} ({exc})") from None

        self.rt = rt
        self.shape = tuple(int(s) for s in shape)
        if len(self.shape) != 2 or min(self.shape) < 2:
            raise ClfzaError(f"VkFFT shape must be (rows >= 2, cols >= 2), got {shape!r}")
        self.dtype = np.dtype(dtype)
        if self.dtype not in (np.float32, np.float64):
            raise ClfzaError(f"FFT dtype must be float32 or float64, got {self.dtype}")
        self.cdtype = np.dtype(np.complex128 if self.dtype == np.float64 else np.complex64)
        self._cla = cla
        try:
            self.app = VkFFTApp(self.shape, self.dtype, queue=rt.queue, ndim=2, r2c=True,
                                inplace=False, norm=1)
        except Exception as exc:
            raise ClfzaError(f"VkFFT could not plan a {self.shape} {self.dtype} transform on "
                             f"{rt.info.name}: {exc}") from None
        self._spec = DeviceArray.empty(rt, self.spectrum_shape, self.cdtype)

    @property
    def spectrum_shape(self) -> tuple[int, int]:
        return self.shape[0], self.shape[1] // 2 + 1

    def _view(self, a, shape, dtype):
        return self._cla.Array(self.rt.queue, shape, dtype, data=a.buf)

    def _check(self, a, shape, dtype, what: str) -> None:
        if a.shape != tuple(shape) or a.dtype != dtype:
            raise ClfzaError(f"{what} must be a {tuple(shape)} {dtype} device array, got "
                             f"{a.shape} {a.dtype}")

    def rfft2(self, x, X) -> None:
        """``X = rfft2(x)`` (unnormalised)."""
        self._check(x, self.shape, self.dtype, "rfft2 input")
        self._check(X, self.spectrum_shape, self.cdtype, "rfft2 output")
        self.app.fft(self._view(x, self.shape, self.dtype),
                     self._view(X, self.spectrum_shape, self.cdtype))

    def irfft2(self, X, x, overwrite_x: bool = False) -> None:
        """``x = irfft2(X)`` (divides by ``Ny * Nx``); ``X`` is left unchanged unless
        ``overwrite_x`` (VkFFT's inverse real transform works in its input: without the flag
        it works in a copy)."""
        self._check(X, self.spectrum_shape, self.cdtype, "irfft2 input")
        self._check(x, self.shape, self.dtype, "irfft2 output")
        src = X
        if not overwrite_x:
            self.rt.cl.enqueue_copy(self.rt.queue, self._spec.buf, X.buf, byte_count=X.nbytes)
            src = self._spec
        self.app.ifft(self._view(src, self.spectrum_shape, self.cdtype),
                      self._view(x, self.shape, self.dtype))
