"""Host FFTs through scipy.fft's pocketfft, writing into caller-owned arrays.

scipy.fft's public functions have no ``out=``; the pocketfft binding underneath does, which
saves an allocation and a memory pass per transform (docs/design.md s.6). When that private
binding is unavailable the public API is used and the result copied.
"""

from __future__ import annotations

import os

import numpy as np
import scipy.fft

try:  # private but long-stable binding; fall back to the public API if it moves
    from scipy.fft._pocketfft import pypocketfft as _pp
except ImportError:  # pragma: no cover
    _pp = None

WORKERS = max(1, os.cpu_count() or 1)


def host_rfft2(x: np.ndarray, out: np.ndarray | None = None, workers: int = WORKERS
               ) -> np.ndarray:
    """Unnormalised real-to-complex 2-D FFT over the last two axes (numpy convention)."""
    if _pp is not None and out is not None:
        return _pp.r2c(x, axes=(-2, -1), forward=True, inorm=0, out=out, nthreads=workers)
    res = scipy.fft.rfft2(x, workers=workers)
    if out is None:
        return res
    out[...] = res
    return out


def host_irfft2(X: np.ndarray, nx: int, out: np.ndarray | None = None, workers: int = WORKERS,
                overwrite_x: bool = False) -> np.ndarray:
    """Complex-to-real inverse 2-D FFT with 1/N normalisation; ``nx`` is the output width.

    With ``overwrite_x`` the column transform runs in place in ``X`` (destroyed) and the rows'
    complex-to-real transform reads it from there. pocketfft's own multi-axis ``c2r`` writes
    the column pass to a temporary spectrum first; skipping that stream makes the inverse
    faster with the same arithmetic in the same order (measured: docs/measurements.md,
    clfza.fft._host).
    """
    if _pp is not None and out is not None and overwrite_x:
        _pp.c2c(X, axes=(-2,), forward=False, inorm=2, out=X, nthreads=workers)
        return _pp.c2r(X, axes=(-1,), lastsize=nx, forward=False, inorm=2, out=out,
                       nthreads=workers)
    if _pp is not None and out is not None:
        return _pp.c2r(X, axes=(-2, -1), lastsize=nx, forward=False, inorm=2, out=out,
                       nthreads=workers)
    res = scipy.fft.irfft2(X, s=(X.shape[-2], nx), workers=workers)
    if out is None:
        return res
    out[...] = res
    return out


class HostFFT:
    """rfft2/irfft2 on :class:`~clfza.cl.DeviceArray` through scipy.fft on the host.

    On zero-copy (CPU) devices the transform reads and writes the buffers' own host memory; on
    other devices it copies through the host (correct everywhere, fast only on CPUs).
    """

    name = "host-scipy"
    batched = True  # scipy.fft transforms the last two axes of (C, H, W)

    def __init__(self, rt, shape: tuple[int, int], dtype=np.float32, workers: int = WORKERS):
        self.rt = rt
        self.shape = tuple(shape)
        self.dtype = np.dtype(dtype)
        self.cdtype = np.result_type(self.dtype, np.complex64)
        self.workers = workers

    @property
    def spectrum_shape(self) -> tuple[int, int]:
        return self.shape[0], self.shape[1] // 2 + 1

    def rfft2(self, x, X) -> None:
        if self.rt.zero_copy:
            host_rfft2(x.host_view(), X.host, self.workers)
        else:
            X.set(host_rfft2(x.get(), None, self.workers).astype(self.cdtype, copy=False))

    def irfft2(self, X, x, overwrite_x: bool = False) -> None:
        if self.rt.zero_copy:
            host_irfft2(X.host_view(), self.shape[1], x.host, self.workers, overwrite_x)
        else:
            out = np.empty(x.shape, x.dtype)  # X.get() is a copy: always ours to overwrite
            x.set(host_irfft2(X.get(), self.shape[1], out, self.workers, True))
