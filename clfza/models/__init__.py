"""The forward models ``y = K o``: the transfer function (Eq. 17), the exact finite-aperture
model, its high-pass view, the operator on an OpenCL device, and measured PSFs."""

from __future__ import annotations

from ._transfer import NumpyOperator, back_propagate, transfer_function

__all__ = ["NumpyOperator", "back_propagate", "transfer_function"]
