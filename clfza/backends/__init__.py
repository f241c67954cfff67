"""Array backends for the solvers: numpy float64 reference and OpenCL (one interface,
:class:`~clfza.backends.base.Backend`)."""

from __future__ import annotations

import numpy as np

from ..camera import Camera
from ..errors import ClfzaError
from .base import Backend, ProxState, Ready, Scalars

BACKENDS = ("opencl", "numpy")

__all__ = ["Backend", "ProxState", "Ready", "Scalars", "get_backend", "BACKENDS"]


def exact_model(camera: Camera | None, psf=None, margin: int = 0):
    """The exact model (:class:`clfza.exact.ExactModel`) of a camera's mask, or of a measured
    PSF (an array on the sensor's pitch, or a :class:`clfza.psf.PSF`) for a sensor of the
    camera's shape."""
    from ..exact import ExactModel, camera_model

    if psf is None:
        return camera_model(camera, int(margin))
    arr = np.asarray(getattr(psf, "array", psf), dtype=np.float64)
    if arr.ndim == 3:
        raise ClfzaError("a colour PSF (H, W, 3) reconstructs per channel: pass one channel's "
                         "PSF per call (clfza.reconstruct does this for you)")
    return ExactModel(arr, tuple(camera.shape), int(margin))


def get_backend(name: str, camera: Camera, *, nc: int = 1, device: str | None = None,
                dtype=np.float32, fft: str = "auto", model: str = "tf", psf=None,
                margin: int = 0) -> Backend:
    """A backend for ``camera`` with ``nc`` coupled channels.

    ``"numpy"``: float64 reference; ``"opencl"``: kernels on the device chosen by ``device``
    (see :func:`clfza.cl.get_runtime`) in ``dtype``, FFTs by policy ``fft``. ``model``:
    ``"tf"`` (Eq. 17), ``"exact"`` (:mod:`clfza.exact`, on the model grid; ``psf`` as its
    kernel when given) or ``"padded"`` (numpy only).
    """
    if model == "exact":
        em = exact_model(camera, psf, margin)
        if name == "numpy":
            from .numpy_exact import NumpyExactBackend

            return NumpyExactBackend(em, nc)
        if name == "opencl":
            from .opencl_exact import OpenCLExactBackend

            return OpenCLExactBackend(em, nc, dtype=dtype, fft=fft, device=device)
    elif name == "numpy":
        from .numpy_backend import NumpyBackend

        return NumpyBackend(camera, nc, model)
    elif name == "opencl":
        if model != "tf":
            raise ClfzaError(f"model={model!r} runs on backend='numpy' only; use "
                             "model='exact' on OpenCL")
        from .opencl_backend import OpenCLBackend

        return OpenCLBackend(camera, nc, dtype=dtype, fft=fft, device=device)
    raise ClfzaError(f"backend must be one of {BACKENDS}, got {name!r}")
