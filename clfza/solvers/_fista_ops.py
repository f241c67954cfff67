"""FISTA's fused operation (:mod:`clfza.solvers._fista`): the extrapolated point's gradient
step as one combination of the kept iterates' gradient steps.

A float64 numpy reference and an OpenCL implementation (``kernels/elementwise.cl``:
``fista_extrap``); ``FistaOps.for_backend(B)`` returns the one for ``B``.
"""

from __future__ import annotations

from abc import abstractmethod

from ..backends import Ops


class FistaOps(Ops):
    """FISTA's operations on one backend (:class:`~clfza.backends._base.Ops`)."""

    @abstractmethod
    def extrap(self, out, a1: float, W1, a2: float, W2) -> None:
        """``out = a1 W1 + a2 W2`` (``a1 + a2 = 1``, ``W = X + K^T (y - K X)``: the gradient
        step at ``a1 X1 + a2 X2`` without applying ``K`` to it)."""


@FistaOps.implements("numpy")
class NumpyFistaOps(FistaOps):
    """float64 reference."""

    def extrap(self, out, a1, W1, a2, W2):
        out[...] = a1 * W1 + a2 * W2


@FistaOps.implements("opencl")
class OpenCLFistaOps(FistaOps):
    """One element-wise kernel."""

    KERNELS = (("elementwise", ("fista_extrap",)),)

    def extrap(self, out, a1, W1, a2, W2):
        r = self.B.r
        self.B.launch1d("fista_extrap", out.buf, r(a1), W1.buf, r(a2), W2.buf)
