"""The operator ``K`` on an OpenCL device: transfer function made by a kernel, spectrum
multiply as a kernel, FFTs through an FFT engine (host scipy.fft on CPU devices)."""

from __future__ import annotations

import numpy as np

from ..camera import Camera, aperture_radius2_pixels, axis_phase
from ..cl import DeviceArray, Runtime, complex_of, get_runtime
from ..errors import ClfzaError
from ..fft import select_engine
from ._transfer import check_regime, frequency_phase


def make_fft_engine(rt: Runtime, shape, dtype, policy: str = "auto"):
    """The FFT engine for a device: see :mod:`clfza.fft`. ``policy``: "auto", "host",
    "device" or "vkfft"."""

    return select_engine(rt, shape, dtype, policy)


def device_zone_plate(rt: Runtime, shape, pitch: float, r1: float, *, kind: str = "gzp",
                      R: float | None = None, phase: float = 0.0, dtype=np.float32,
                      center: tuple[float, float] = (0.0, 0.0)) -> DeviceArray:
    """Synthesise a zone-plate mask on the device (kernel ``zone_plate``, masks.cl).

    Matches :func:`clfza.camera._masks.zone_plate` (the float64 reference) to float32 rounding. The
    kernel draws centred masks only: a non-zero ``center`` (a camera's ``mask_center``) is
    refused.
    """
    if tuple(float(c) for c in center) != (0.0, 0.0):
        raise ClfzaError(f"the OpenCL zone-plate kernel draws centred masks only; got a mask "
                         f"centre offset {tuple(center)} px (use clfza.camera._masks.zone_plate)")
    ny, nx = shape
    dtype = np.dtype(dtype)
    out = DeviceArray.empty(rt, (ny, nx), dtype)
    phx = DeviceArray.from_host(rt, axis_phase(nx, pitch, r1).astype(dtype))
    phy = DeviceArray.from_host(rt, axis_phase(ny, pitch, r1).astype(dtype))
    r2 = aperture_radius2_pixels(R, pitch)
    r2max = np.int64(2**62) if not np.isfinite(r2) else np.int64(np.floor(r2))
    k = rt.kernel("masks", "zone_plate", dtype)
    k(rt.queue, (nx, ny), None, out.buf, phx.buf, phy.buf, np.int32(nx), np.int32(nx // 2),
      np.int32(ny // 2), r2max, dtype.type(phase / np.pi), np.int32(kind == "fza"))
    rt.finish()  # the per-axis tables are temporaries: let the kernel finish with them
    return out


def device_transfer_function(rt: Runtime, shape, pitch: float, r1p: float, power: int = 1,
                             dtype=np.float32) -> DeviceArray:
    """``H_T`` (or ``H_T^2``) on the rfft half-spectrum grid, made on the device (masks.cl)."""
    ny, nx = shape
    nxh = nx // 2 + 1
    dtype = np.dtype(dtype)
    out = DeviceArray.empty(rt, (ny, nxh), dtype)
    pu = DeviceArray.from_host(rt, frequency_phase(nx, pitch, r1p, half=True).astype(dtype))
    pv = DeviceArray.from_host(rt, frequency_phase(ny, pitch, r1p).astype(dtype))
    k = rt.kernel("masks", "transfer_function", dtype)
    k(rt.queue, (nxh, ny), None, out.buf, pu.buf, pv.buf, np.int32(nxh), np.int32(power))
    rt.finish()  # pu, pv are temporaries
    return out


class OpenCLOperator:
    """``K``, ``K^T`` and ``K^T K`` on device arrays (TF model, Eq. 17).

    Parameters
    ----------
    camera : Camera
        The camera (grid, pitch, ``r1'``).
    runtime : Runtime, optional
        The device; default :func:`get_runtime`.
    dtype : numpy dtype
        float32 (default) or float64 where the device supports it.
    fft : str
        FFT policy: "auto" (host scipy.fft on CPU devices, device kernels on GPUs), "host",
        "device" or "vkfft".
    warn : bool
        Warn when far from critical sampling (see :func:`clfza.models._transfer.check_regime`).
    """

    def __init__(self, camera: Camera, runtime: Runtime | None = None, dtype=np.float32,
                 fft: str = "auto", *, warn: bool = True, model: str = "tf"):
        if model != "tf":
            raise ClfzaError("the OpenCL operator implements the transfer-function model "
                             "(model='tf'); use backend='numpy' for model='padded'")
        self.camera = camera
        self.rt = runtime or get_runtime()
        self.dtype = np.dtype(dtype)
        if self.dtype not in (np.float32, np.float64):
            raise ClfzaError(f"dtype must be float32 or float64, got {self.dtype}")
        self.cdtype = complex_of(self.dtype)
        self.shape = tuple(camera.shape)
        ny, nx = self.shape
        self.spec_shape = (ny, nx // 2 + 1)
        if warn:
            check_regime(camera, "tf")
        # working set: H, H^2, one spectrum, and ~8 solver arrays
        nbytes = (2 * ny * (nx // 2 + 1) + 8 * ny * nx) * self.dtype.itemsize \
            + ny * (nx // 2 + 1) * self.cdtype.itemsize
        self.rt.check_total(nbytes, f"a {ny}x{nx} {self.dtype} solve")
        self.H = device_transfer_function(self.rt, self.shape, camera.pitch, camera.r1p, 1,
                                          self.dtype)
        self.H2 = device_transfer_function(self.rt, self.shape, camera.pitch, camera.r1p, 2,
                                           self.dtype)
        self.X = DeviceArray.empty(self.rt, self.spec_shape, self.cdtype)
        self.fft = make_fft_engine(self.rt, self.shape, self.dtype, fft)
        self._mul = self.rt.kernel("spectrum", "multiply_real", self.dtype)
        self._n_spec = np.int32(self.spec_shape[0] * self.spec_shape[1])

    def empty(self) -> DeviceArray:
        """A new device array on the sensor grid."""
        return DeviceArray.empty(self.rt, self.shape, self.dtype)

    def _check(self, a: DeviceArray, name: str) -> None:
        if a.shape != self.shape or a.dtype != self.dtype:
            raise ClfzaError(f"{name} must be a {self.shape} {self.dtype} device array, got "
                             f"{a.shape} {a.dtype}")

    def _apply(self, x: DeviceArray, out: DeviceArray, H: DeviceArray) -> DeviceArray:
        self._check(x, "input")
        self._check(out, "output")
        self.fft.rfft2(x, self.X)
        self._mul(self.rt.queue, (int(self._n_spec),), None, self.X.buf, H.buf, self._n_spec)
        self.fft.irfft2(self.X, out, overwrite_x=True)
        return out

    def forward(self, x: DeviceArray, out: DeviceArray | None = None) -> DeviceArray:
        """``out = K x`` (one real FFT pair and a spectrum multiply)."""
        return self._apply(x, out if out is not None else self.empty(), self.H)

    adjoint = forward  # K is real and symmetric

    def normal(self, x: DeviceArray, out: DeviceArray | None = None) -> DeviceArray:
        """``out = K^T K x`` with ``H_T^2`` (one real FFT pair)."""
        return self._apply(x, out if out is not None else self.empty(), self.H2)

    # host conveniences (tests, demos) ------------------------------------------------
    def forward_host(self, x: np.ndarray) -> np.ndarray:
        xd = DeviceArray.from_host(self.rt, np.asarray(x), self.dtype)
        return self.forward(xd).get()

    adjoint_host = forward_host

    def normal_host(self, x: np.ndarray) -> np.ndarray:
        xd = DeviceArray.from_host(self.rt, np.asarray(x), self.dtype)
        return self.normal(xd).get()
