"""The fast back-propagation of :mod:`clfza.focus` (:class:`FastBP`: ``FFT(y)`` once, one
spectrum multiply and one inverse FFT per depth; see the "fast path" in :mod:`clfza.focus`'s
docstring) and the depth geometry it uses: ``r1'(z1)`` and the depth of focus.
:mod:`clfza.focus` re-exports every public name here.
"""

from __future__ import annotations

import math
import os
import time

import numpy as np
import scipy.fft
from scipy.ndimage import gaussian_filter

from ..camera import Camera
from ..cl import DeviceArray, complex_of, get_runtime
from ..errors import ClfzaError, finite_image, nonnegative, positive
from ..io import LIMIT_ENV, check_memory, grid_bytes
from ..models import apply_spectrum, device_transfer_function, make_fft_engine, transfer_function
from ..solvers import DEFAULT_BACKEND

WORKERS = max(1, os.cpu_count() or 1)
#: Standard deviation in pixels of the Gaussian blur whose result (the shadows' smooth
#: envelope) the focus search subtracts from ``y`` (:func:`remove_envelope_and_taper`).
ENVELOPE_SIGMA = 8.0
#: Tukey window fraction applied to ``y`` before the focus search's transforms.
TAPER = 0.25


def r1p_at(camera: Camera, z1: float) -> float:
    """Shadow constant ``r1' = (1 + z2/z1) r1`` for an object at ``z1`` (docs/design.md s.1)."""
    return camera.at_depth(z1).r1p


def depth_resolution(camera: Camera, z1: float) -> float:
    """Depth of focus ``dz`` (mm) at ``z1``: the depth change that puts a quarter-wave
    defocus phase at the band limit, ``dz = 1 / (2 rho_c^2 |d(r1'^2)/dz1|)`` with
    ``d(r1'^2)/dz1 = -2 r1^2 (1 + z2/z1) z2 / z1^2`` (:mod:`clfza.focus`'s docstring)."""
    z1 = positive("z1", z1)
    cam = camera.at_depth(z1)
    rho_c = min(cam.band_limit, 0.5 / cam.pitch * math.sqrt(2.0))
    d = 2.0 * cam.r1**2 * (1.0 + cam.z2 / z1) * cam.z2 / z1**2
    return float(1.0 / (2.0 * rho_c**2 * d))


def _mean_channels(y: np.ndarray) -> np.ndarray:
    a = finite_image("measurement", y)
    if a.ndim == 3:
        a = a.mean(axis=2)
    return a


def remove_envelope_and_taper(a: np.ndarray, envelope_sigma: float, taper: float
                              ) -> np.ndarray:
    """``a`` less its Gaussian blur of standard deviation ``envelope_sigma`` pixels (the
    shadows' smooth envelope; 0: none), times a separable Tukey window of taper fraction
    ``taper`` (0: none), so that a correlation sees the zone structure and no edge.

    Not the exact model's box high-pass (ADMM's ``highpass``, a half-width in pixels,
    :mod:`clfza.models`): this one only prepares ``y`` for sharpness scores."""
    sigma = nonnegative("envelope_sigma", envelope_sigma)
    if sigma > 0:
        a = a - gaussian_filter(a, sigma, mode="nearest")
    if taper > 0:
        # lazy: scipy.signal (and the scipy.stats it loads) would double the CLI's start-up
        from scipy.signal.windows import tukey

        a = a * np.outer(tukey(a.shape[0], taper), tukey(a.shape[1], taper))
    return a


class FastBP:
    """Back-propagation at many depths with one forward FFT (:mod:`clfza.focus`'s docstring).

    ``K^T y`` is :func:`clfza.models._transfer.back_propagate` (the float64 specification), computed
    here for speed across many depths: the spectrum of the (pre-processed, float32) ``y`` is
    taken once and kept, and each depth costs ``H_T(r1'(z1))`` (:func:`clfza.models._transfer.
    transfer_function`, or the same table made on the device by
    :func:`clfza.models._device_operator. device_transfer_function`), one spectrum multiply and one
    inverse real FFT (:func:`clfza.models._transfer.apply_spectrum` on the host). Nothing is built
    per depth.

    Parameters
    ----------
    y : array (H, W) or (H, W, 3)
        DC-free observation (channels are averaged).
    camera : Camera
        Camera; its ``z1`` is ignored (each call names the depth).
    envelope_sigma : float
        Standard deviation in pixels of the Gaussian whose blur (the shadows' envelope) is
        subtracted before the transform; 0 disables it.
    taper : float
        Tukey window fraction (0 = none) applied to ``y`` to suppress the wrap-around edge.
    backend : {"opencl", "numpy"}
        An OpenCL device (default, :data:`clfza.solvers.DEFAULT_BACKEND`: its FFT engine and
        the spectrum multiply kernel of the device operator) or the host's float32
        ``scipy.fft``.
    device : str, optional
        OpenCL device spec (see :func:`clfza.cl.get_runtime`).

    Examples
    --------
    >>> eng = FastBP(y, camera, backend="numpy")  # doctest: +SKIP
    >>> images = [eng.image(z1) for z1 in (100.0, 200.0, 300.0)]  # doctest: +SKIP
    """

    def __init__(self, y: np.ndarray, camera: Camera, *,
                 envelope_sigma: float = ENVELOPE_SIGMA, taper: float = TAPER,
                 backend: str = DEFAULT_BACKEND, device: str | None = None):
        a = _mean_channels(y)
        if a.shape != tuple(camera.shape):
            raise ClfzaError(f"measurement has shape {a.shape}, but the camera grid is "
                             f"{tuple(camera.shape)}")
        if not np.any(a):
            raise ClfzaError("the measurement is all zeros: no light reached the sensor, so no "
                             "depth can be found from it")

        check_memory(f"focusing a {a.shape[0]}x{a.shape[1]} measurement",
                            grid_bytes(a.shape, 1, 8, 8.0),
                            "the measurement, its spectrum, the frequency grid and one image "
                            "per depth", f"crop or bin the frame, or raise the limit with "
                            f"{LIMIT_ENV}")
        if backend not in ("numpy", "opencl"):
            raise ClfzaError(f"backend must be 'numpy' or 'opencl', got {backend!r}")
        self.camera = camera
        self.shape = a.shape
        self.backend = backend
        t0 = time.perf_counter()
        a = remove_envelope_and_taper(a, envelope_sigma, taper)
        if not np.any(a):
            raise ClfzaError("the measurement has no structure (all zeros, or constant once "
                             "the shadows' envelope is removed): no depth can be found from it")
        self.y = a.astype(np.float32)
        if backend == "numpy":
            self.Y = scipy.fft.rfft2(self.y, workers=WORKERS)
        else:
            self._device_setup(device)
        self.setup_s = time.perf_counter() - t0

    def _device_setup(self, device: str | None) -> None:
        """The OpenCL path's one-time work: FFT plan, ``rfft2(y)`` kept on the device, the
        spectrum buffer and output image every depth reuses."""

        ny, nx = self.shape
        spec = (ny, nx // 2 + 1)
        self.rt = rt = get_runtime(device)
        self.fft = make_fft_engine(rt, self.shape, np.float32)
        yd = DeviceArray.from_host(rt, self.y, np.float32)
        self.Yd = DeviceArray.empty(rt, spec, complex_of(np.float32))
        self.fft.rfft2(yd, self.Yd)
        self.Xd = DeviceArray.empty(rt, spec, complex_of(np.float32))
        self.out = DeviceArray.empty(rt, self.shape, np.float32)
        self._mul = rt.kernel("spectrum", "multiply_real", np.float32)
        self._n_spec = np.int32(spec[0] * spec[1])
        rt.finish()

    def image(self, z1: float) -> np.ndarray:
        """``K^T y`` with ``r1' = r1'(z1)`` (Eqs. 11-12) as a float32 host array."""
        return self.image_r1p(r1p_at(self.camera, z1))

    def image_r1p(self, r1p: float) -> np.ndarray:
        """``K^T y`` for a given shadow constant ``r1'`` (mm)."""
        pitch = self.camera.pitch
        if self.backend == "numpy":
            H = transfer_function(self.shape, pitch, r1p).astype(np.float32)
            return apply_spectrum(self.Y, H, self.shape, workers=WORKERS)

        rt = self.rt
        H = device_transfer_function(rt, self.shape, pitch, r1p, 1, np.float32)
        rt.cl.enqueue_copy(rt.queue, self.Xd.buf, self.Yd.buf)  # the kept spectrum, per depth
        self._mul(rt.queue, (int(self._n_spec),), None, self.Xd.buf, H.buf, self._n_spec)
        self.fft.irfft2(self.Xd, self.out, overwrite_x=True)
        return self.out.get()

