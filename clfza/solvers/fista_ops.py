"""FISTA's fused operation (:mod:`clfza.solvers.fista`): the extrapolated point's gradient
step as one combination of the kept iterates and their gradients.

A float64 numpy reference and an OpenCL implementation (``kernels/elementwise.cl``:
``fista_extrap``); ``FistaOps.for_backend(B)`` returns the one for ``B``.
"""

from __future__ import annotations

from abc import abstractmethod

from ..backends.base import Ops


class FistaOps(Ops):
    """FISTA's operations on one backend (:class:`~clfza.backends.base.Ops`)."""

    @abstractmethod
    def extrap(self, out, a1: float, X1, G1, a2: float, X2, G2) -> None:
        """``out = a1 (X1 + G1) + a2 (X2 + G2)``."""


@FistaOps.implements("numpy")
class NumpyFistaOps(FistaOps):
    """float64 reference."""

    def extrap(self, out, a1, X1, G1, a2, X2, G2):
        out[...] = a1 * (X1 + G1) + a2 * (X2 + G2)


@FistaOps.implements("opencl")
class OpenCLFistaOps(FistaOps):
    """One element-wise kernel."""

    KERNELS = (("elementwise", ("fista_extrap",)),)

    def extrap(self, out, a1, X1, G1, a2, X2, G2):
        r = self.B.r
        self.B.launch1d("fista_extrap", out.buf, r(a1), X1.buf, G1.buf, r(a2), X2.buf, G2.buf)
