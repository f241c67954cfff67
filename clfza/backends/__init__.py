"""Array backends for the solvers: numpy float64 reference and OpenCL (one interface,
:class:`~clfza.backends.base.Backend`)."""

from __future__ import annotations

import numpy as np

from ..camera import Camera
from ..errors import ClfzaError
from .base import Backend, ProxState, Ready, Scalars

BACKENDS = ("opencl", "numpy")

__all__ = ["Backend", "ProxState", "Ready", "Scalars", "get_backend", "BACKENDS"]


def get_backend(name: str, camera: Camera, *, nc: int = 1, device: str | None = None,
                dtype=np.float32, fft: str = "auto", model: str = "tf") -> Backend:
    """A backend for ``camera`` with ``nc`` coupled channels.

    ``"numpy"``: float64 reference (``model`` "tf" or "padded"); ``"opencl"``: kernels on the
    device chosen by ``device`` (see :func:`clfza.cl.get_runtime`) in ``dtype``, FFTs by
    policy ``fft``; transfer-function model only.
    """
    if name == "numpy":
        from .numpy_backend import NumpyBackend

        return NumpyBackend(camera, nc, model)
    if name == "opencl":
        if model != "tf":
            raise ClfzaError("model='padded' runs on backend='numpy' only")
        from .opencl_backend import OpenCLBackend

        return OpenCLBackend(camera, nc, dtype=dtype, fft=fft, device=device)
    raise ClfzaError(f"backend must be one of {BACKENDS}, got {name!r}")
