"""FISTA's fused operation (:mod:`clfza.solvers._fista`): the extrapolated point's gradient
step as one combination of the kept iterates' gradient steps.

A float64 numpy reference and an OpenCL implementation (``kernels/elementwise.cl``:
``fista_extrap``); ``FistaOps.for_backend(B)`` returns the one for ``B``.
"""

from __future__ import annotations

from abc import abstractmethod

import numpy as np

from ..backends import Ops
from ..cl import DeviceArray


class FistaOps(Ops):
    """FISTA's operations on one backend (:class:`~clfza.backends._base.Ops`)."""

    @abstractmethod
    def extrap(self, out, a1, W1, a2, W2) -> None:
        """``out = a1 W1 + a2 W2`` (``a1 + a2 = 1``, ``W = X + K^T (y - K X)``: the gradient
        step at ``a1 X1 + a2 X2`` without applying ``K`` to it). On a batch of frames ``a1``
        and ``a2`` may be sequences, one value per frame (each frame's monotone step)."""


@FistaOps.implements("numpy")
class NumpyFistaOps(FistaOps):
    """float64 reference (one frame, or frames stacked along the first axis with ``a1``,
    ``a2`` of one value per frame)."""

    def extrap(self, out, a1, W1, a2, W2):
        if np.ndim(a1) == 0:
            out[...] = a1 * W1 + a2 * W2
            return
        f = np.size(a1)
        c1 = np.asarray(a1, np.float64).reshape(f, 1)
        c2 = np.asarray(a2, np.float64).reshape(f, 1)
        out[...] = (c1 * W1.reshape(f, -1) + c2 * W2.reshape(f, -1)).reshape(out.shape)


@FistaOps.implements("opencl")
class OpenCLFistaOps(FistaOps):
    """One element-wise kernel; per-frame coefficients come from a small buffer (``coef``,
    ones for scalar coefficients, so one frame and a batch run the same arithmetic)."""

    KERNELS = (("elementwise", ("fista_extrap",)),)

    def __init__(self, B):
        super().__init__(B)
        F = B.frames
        self.ones = DeviceArray.from_host(B.rt, np.ones((F, 2), B.dtype), B.dtype)
        self.coef = DeviceArray.from_host(B.rt, np.ones((F, 2), B.dtype), B.dtype)

    def extrap(self, out, a1, W1, a2, W2):
        B = self.B
        r = B.r
        per = B.n // B.frames
        if np.ndim(a1) == 0 and np.ndim(a2) == 0:
            B.launch1d("fista_extrap", out.buf, r(a1), W1.buf, r(a2), W2.buf, self.ones.buf,
                       B.i32(per))
            return
        c = np.empty((B.frames, 2), B.dtype)
        c[:, 0] = np.broadcast_to(np.asarray(a1, np.float64), (B.frames,))
        c[:, 1] = np.broadcast_to(np.asarray(a2, np.float64), (B.frames,))
        B.write_async(self.coef, c)  # through the queue: earlier launches keep their values
        B.launch1d("fista_extrap", out.buf, r(1.0), W1.buf, r(1.0), W2.buf, self.coef.buf,
                   B.i32(per))
