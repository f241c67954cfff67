"""Array backends for the solvers: numpy float64 reference and OpenCL (one core interface,
:class:`~clfza.backends._base.Backend`; the solvers' own operations are
:class:`~clfza.backends._base.Ops` families beside the solvers)."""

from __future__ import annotations

import contextvars
import hashlib
import threading
import time
from collections import OrderedDict
from contextlib import contextmanager

import numpy as np

from ..camera import Camera
from ..errors import ClfzaError
from ..models import ExactModel, camera_model
from ._base import Backend, Ops, ProxState, Ready, Scalars
from ._numpy import NumpyBackend
from ._numpy_exact import NumpyExactBackend
from ._opencl import OpenCLBackend
from ._opencl_exact import OpenCLExactBackend

BACKENDS = ("opencl", "numpy")

__all__ = ["Backend", "Ops", "ProxState", "Ready", "Scalars", "get_backend", "BACKENDS",
           "BackendCache", "reuse_backends"]


def exact_model(camera: Camera | None, psf=None, margin: int = 0):
    """The exact model (:class:`clfza.models._exact.ExactModel`) of a camera's mask, or of a
    measured PSF (an array on the sensor's pitch, or a :class:`clfza.models._psf.PSF`) for a sensor
    of the camera's shape."""

    if psf is None:
        return camera_model(camera, int(margin))
    if isinstance(psf, ExactModel):  # a model built elsewhere (e.g. the planner's binned one)
        if psf.sensor != tuple(camera.shape):
            raise ClfzaError(f"the given model's sensor {psf.sensor} is not the camera's "
                             f"{tuple(camera.shape)}")
        return psf
    arr = np.asarray(getattr(psf, "array", psf), dtype=np.float64)
    if arr.ndim == 3:
        raise ClfzaError("a colour PSF (H, W, 3) reconstructs per channel: pass one channel's "
                         "PSF per call (clfza.reconstruct does this for you)")
    return ExactModel(arr, tuple(camera.shape), int(margin))


def get_backend(name: str, camera: Camera, *, nc: int = 1, device: str | None = None,
                dtype=np.float32, fft: str = "auto", model: str = "tf", psf=None,
                margin: int = 0, frames: int = 1) -> Backend:
    """A backend for ``camera`` with ``nc`` coupled channels (and a batch of ``frames``
    independent frames: the OpenCL backend on the transfer-function model).

    ``"numpy"``: float64 reference; ``"opencl"``: kernels on the device chosen by ``device``
    (see :func:`clfza.cl.get_runtime`) in ``dtype``, FFTs by policy ``fft``. ``model``:
    ``"tf"`` (Eq. 17), ``"exact"`` (:mod:`clfza.models._exact`, on the model grid; ``psf`` as its
    kernel when given) or ``"padded"`` (numpy only).

    Inside ``with reuse_backends(cache):`` a backend of the same set-up is taken from
    ``cache`` instead of being built (see :class:`BackendCache`).
    """
    if frames > 1 and (name != "opencl" or model != "tf"):
        raise ClfzaError(f"a batch of frames runs on the OpenCL backend's transfer-function "
                         f"model, not backend={name!r}, model={model!r}")
    cache = _ACTIVE_CACHE.get()
    if cache is not None:
        return cache.get(name, camera, nc=nc, device=device, dtype=dtype, fft=fft, model=model,
                         psf=psf, margin=margin, frames=frames)
    if model == "exact":
        em = exact_model(camera, psf, margin)
        if name == "numpy":

            return NumpyExactBackend(em, nc)
        if name == "opencl":

            return OpenCLExactBackend(em, nc, dtype=dtype, fft=fft, device=device)
    elif name == "numpy":

        return NumpyBackend(camera, nc, model)
    elif name == "opencl":
        if model != "tf":
            raise ClfzaError(f"model={model!r} runs on backend='numpy' only; use "
                             "model='exact' on OpenCL")

        return OpenCLBackend(camera, nc, dtype=dtype, fft=fft, device=device, frames=frames)
    raise ClfzaError(f"backend must be one of {BACKENDS}, got {name!r}")


# ----------------------------------------------------------------------------------------
# reuse between solves (streams of frames with one set-up)
# ----------------------------------------------------------------------------------------
_ACTIVE_CACHE: contextvars.ContextVar = contextvars.ContextVar("clfza_backend_cache",
                                                               default=None)


def _psf_key(psf):
    """A PSF array by content; any other kernel object (an ExactModel) by identity (the cached
    backend keeps it alive, so the identity is not reused meanwhile)."""
    if psf is None:
        return None
    arr = getattr(psf, "array", psf)
    if not isinstance(arr, (np.ndarray, list, tuple)):
        return ("object", id(psf))
    a = np.ascontiguousarray(np.asarray(arr, dtype=np.float64))
    return (a.shape, hashlib.blake2b(a.tobytes(), digest_size=16).hexdigest())


class BackendCache:
    """Backends kept between solves of one set-up, for streams of frames (each worker of
    :func:`clfza.reconstruct_many` keeps one).

    A backend holds what a solve needs besides its measurement: the operator (the transfer
    function, or the exact model's kernel spectrum), the FFT plans, the device buffers and the
    kernel objects, and the solvers' operation families made on it (:meth:`Backend.ops`);
    building one is part of the ``plan`` timing (its cost: docs/measurements.md,
    clfza.backends._select).
    Inside ``with reuse_backends(cache):``, :func:`get_backend` (so :func:`clfza.reconstruct`)
    returns the backend cached for the same backend name, camera, channel count, device,
    dtype, FFT policy, model, PSF (by content) and margin, and builds and keeps one on a miss.
    Each solve sets its own measurement and method set-up (``set_measurement``, the
    x-update's ``setup``), so results are identical to those of fresh backends; on a hit the
    backend's FFT count restarts and its ``compile_s`` reads 0 and ``plan_s`` the lookup.
    Method options are not part of the key: they live in the solver, not the backend.

    At most ``maxsize`` backends are kept (the least recently used is dropped: device memory).
    A cache serves one solve at a time: do not share it between threads that solve
    concurrently. ``hits`` and ``misses`` count lookups; :meth:`clear` drops everything.

    Example::

        from clfza.backends import BackendCache, reuse_backends

        with reuse_backends(BackendCache()):
            images = [clfza.reconstruct(y, cam, "admm").image for y in ys]
    """

    def __init__(self, maxsize: int = 4):
        if int(maxsize) < 1:
            raise ClfzaError(f"maxsize must be >= 1, got {maxsize!r}")
        self.maxsize = int(maxsize)
        self.hits = 0
        self.misses = 0
        self._items: OrderedDict = OrderedDict()
        self._lock = threading.Lock()

    def __len__(self) -> int:
        return len(self._items)

    def clear(self) -> None:
        with self._lock:
            self._items.clear()

    def get(self, name: str, camera: Camera, *, nc: int = 1, device=None, dtype=np.float32,
            fft: str = "auto", model: str = "tf", psf=None, margin: int = 0,
            frames: int = 1) -> Backend:
        """The cached backend of this set-up, or a new one (then kept)."""
        t0 = time.perf_counter()
        dev = device if isinstance(device, (str, type(None))) else repr(device)
        key = (name, camera, int(nc), dev, np.dtype(dtype).str, fft, model, _psf_key(psf),
               int(margin), int(frames))
        with self._lock:
            B = self._items.get(key)
            if B is not None:
                self._items.move_to_end(key)
                self.hits += 1
        if B is not None:
            B.ffts = 0
            B.compile_s = 0.0
            B.plan_s = time.perf_counter() - t0
            return B
        token = _ACTIVE_CACHE.set(None)
        try:
            B = get_backend(name, camera, nc=nc, device=device, dtype=dtype, fft=fft,
                            model=model, psf=psf, margin=margin, frames=frames)
        finally:
            _ACTIVE_CACHE.reset(token)
        with self._lock:
            self.misses += 1
            self._items[key] = B
            while len(self._items) > self.maxsize:
                self._items.popitem(last=False)
        return B


@contextmanager
def reuse_backends(cache: BackendCache | None = None):
    """Within this block (this thread, or this task's context), :func:`get_backend` reuses
    the backends of ``cache`` (a new :class:`BackendCache` if none); yields the cache."""
    cache = BackendCache() if cache is None else cache
    token = _ACTIVE_CACHE.set(cache)
    try:
        yield cache
    finally:
        _ACTIVE_CACHE.reset(token)
