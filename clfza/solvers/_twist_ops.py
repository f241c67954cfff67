"""TwIST's fused operations (:mod:`clfza.solvers._twist`): the two-step combination with the
regulariser values its monotone test needs, and the ``sparse`` masking of the past iterates.

A float64 numpy reference and an OpenCL implementation (``kernels/elementwise.cl``:
``twist_combine``, summing ``RROWS`` rows per contribution into the backend's row-blocked
reduction, and ``mask_past``); ``TwistOps.for_backend(B)`` returns the one for ``B``.

On CPU devices (float32, one channel) the combination runs as ``twist_combine16``, 16 columns
of a row per work-item as float16 vectors (as ADMM's ``admm_update16``; measured:
docs/measurements.md, clfza.solvers._twist_ops).

On a batch of frames (:mod:`clfza.solvers._batch`) both kernels take the frames as their
launch's third dimension (the masking: over every frame's elements) and leave the frames
whose running flag is off (``OpenCLBackend.set_frame_params``) as they were: TwIST's batch
turns on, for each kernel, the frames whose candidate it forms.
"""

from __future__ import annotations

from abc import abstractmethod

import numpy as np

from .. import regularizers as R
from ..backends import Ops, Ready, Scalars


class TwistOps(Ops):
    """TwIST's operations on one backend (:class:`~clfza.backends._base.Ops`)."""

    @abstractmethod
    def combine(self, out, xm2, xm1, xist, alpha: float, beta: float, sparse: bool,
                want_tv: bool = True) -> Scalars:
        """``out = m ((1 - alpha) xm2 + (alpha - beta) xm1) + beta xist`` with
        ``m = (xist != 0)`` when ``sparse`` (else 1).

        Returns
        -------
        Scalars
            Three sums: ``Phi(out)`` if ``want_tv`` else ``||out||_1``; the number of zeros
            of ``xist`` (the caller applies :meth:`mask_past` when it is non-zero); and
            ``Phi(xist)`` if ``want_tv`` else ``||xist||_1``, which serves a monotone fallback
            to the IST estimate without another regulariser pass.
        """

    @abstractmethod
    def mask_past(self, xm1, xm2, xist) -> None:
        """Zero ``xm1`` and ``xm2`` in place where ``xist == 0`` (TwIST's ``sparse``)."""


@TwistOps.implements("numpy")
class NumpyTwistOps(TwistOps):
    """float64 reference."""

    def combine(self, out, xm2, xm1, xist, alpha, beta, sparse, want_tv=True):
        m = (xist != 0) if sparse else np.ones(xist.shape, bool)
        out[...] = m * ((1 - alpha) * xm2 + (alpha - beta) * xm1) + beta * xist
        reg = R.tv_value(out) if want_tv else R.l1_value(out)
        reg_ist = R.tv_value(xist) if want_tv else R.l1_value(xist)
        return Ready(reg, float(np.sum(~m)), reg_ist)

    def mask_past(self, xm1, xm2, xist):
        m = xist != 0
        xm1 *= m
        xm2 *= m


@TwistOps.implements("opencl")
class OpenCLTwistOps(TwistOps):
    """One fused kernel for the combination and its three sums (row-blocked: ``RROWS`` rows
    per contribution, tuned per device; on CPU devices in float32 with one channel 16 columns
    per work-item, ``twist_combine16``), one for the masking."""

    KERNELS = (("elementwise", ("twist_combine", "mask_past")),)
    # (the fpar argument: the running flags of a batch's frames; ones for one frame)

    def __init__(self, B):
        super().__init__(B)
        if B.rows16:
            B.use_kernels(("elementwise", ("twist_combine16",)))

    def combine(self, out, xm2, xm1, xist, alpha, beta, sparse, want_tv=True):
        B = self.B
        r = B.r
        args = (out.buf, xm2.buf, xm1.buf, xist.buf, r(1 - alpha), r(alpha - beta), r(beta),
                B.i32(sparse), B.i32(want_tv), B.fpar.buf)
        if B.rows16:
            return B.launch_rows16_reduce("twist_combine16", *args, planes=3)
        return B.launch_rows_reduce("twist_combine", *args, planes=3)

    def mask_past(self, xm1, xm2, xist):
        B = self.B
        B.launch1d("mask_past", xm1.buf, xm2.buf, xist.buf, B.fpar.buf, B.i32(B.n // B.frames))
