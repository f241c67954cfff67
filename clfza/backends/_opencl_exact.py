"""The exact (finite-aperture, cropped-sensor) model on an OpenCL device.

Same operations and units as the float64 reference :mod:`clfza.backends._numpy_exact` (the
normalised operator ``K / s``), with the kernels of ``kernels/exact.cl`` between the FFTs of the
model grid. Sums over the sensor window (the frame's mean for ``P``, the residual norm) are
per-row partial sums added on the host in float64: one small read per data-term evaluation.
On CPU devices the host FFT drains the queue anyway, so it costs nothing extra there; on GPUs
it is one synchronisation per evaluation.

The crop-split ADMM's operations (:mod:`clfza.solvers._admm_crop_ops`) use this backend's
:meth:`~OpenCLExactBackend.conv`, :meth:`~OpenCLExactBackend.row_sums`, the window launches
and the scratch images ``tmp_a``, ``tmp_b`` (free between calls).
"""

from __future__ import annotations

import numpy as np

from ..cl import DeviceArray
from ..models import NORM_SAFETY, ExactModel, make_fft_engine
from ._base import Ready, Scalars
from ._opencl import OpenCLBackend


class OpenCLExactOperator:
    """The model grid's FFT engine and the normalised kernel spectrum on the device."""

    def __init__(self, model: ExactModel, rt, dtype, fft: str):
        self.model = model
        self.rt = rt
        self.shape = tuple(model.shape)
        self.dtype = np.dtype(dtype)
        self.cdtype = np.dtype(np.complex128 if self.dtype == np.float64 else np.complex64)
        self.scale = NORM_SAFETY * model.norm
        self.Hn = model.Hs / self.scale
        ny, nx = self.shape
        nbytes = (12 * ny * nx) * self.dtype.itemsize + 3 * ny * (nx // 2 + 1) * \
            self.cdtype.itemsize
        rt.check_total(nbytes, f"a {ny}x{nx} {self.dtype} exact-model solve")
        self.Hs = DeviceArray.from_host(rt, self.Hn.astype(self.cdtype))
        self.fft = make_fft_engine(rt, self.shape, self.dtype, fft)


class OpenCLExactBackend(OpenCLBackend):
    """OpenCL backend on the exact model's grid (see the module docstring)."""

    def __init__(self, model: ExactModel, nc: int = 1, dtype=np.float32, fft: str = "auto",
                 device: str | None = None, runtime=None):
        self._model = model
        self._fft_policy = fft
        super().__init__(None, nc, runtime=runtime, dtype=dtype, fft=fft, device=device)
        self.exact = model
        self.geom = model.geom
        self.sensor = tuple(model.sensor)
        self.data_scale = self.op.scale
        self.Hn = self.op.Hn  # spectrum of K~'s kernel (host, complex128)
        self.n_sensor = model.n_sensor
        self.use_kernels(("exact", ("spec_mul_complex", "window_row_sums", "crop_residual")))
        (oy, ox), (sy, sx) = self.geom.offset, self.sensor
        self._win = tuple(np.int32(v) for v in (ox, oy, sx, sy))
        m = self.geom.margin
        # the object region (the sensor plus the margin) as a window
        self.region_window = tuple(np.int32(v) for v in (ox - m, oy - m, sx + 2 * m,
                                                         sy + 2 * m))
        self._rows = DeviceArray.empty(self.rt, (self.nc, sy, 3), self.dtype)
        self.per_c = DeviceArray.empty(self.rt, (self.nc,), self.dtype)  # one value a channel
        self._shift_host = np.zeros(self.nc)
        self._shift = DeviceArray.from_host(self.rt, np.zeros(self.nc, self.dtype))
        self.tmp_a = self.empty()  # scratch images (no state kept between calls)
        self.tmp_b = self.empty()
        self.Cy = self.zeros()

    def _make_operator(self, camera, fft: str):
        return OpenCLExactOperator(self._model, self.rt, self.dtype, fft)

    # -- launch helpers (this backend's and the crop-split ADMM's) ----------------------
    def launch_window(self, name: str, *args, window=None) -> None:
        """Kernel ``name`` of ``exact.cl`` over the model grid, with a window (default the
        sensor's; ``region_window`` the object region): ``(*args, x0, y0, w, h, W, H)``."""
        ny, nx = self.shape
        self.k[name](self.rt.queue, (nx, ny), self._lw, *args, *(window or self._win),
                     self.i32(nx), self.i32(ny))

    def launch_spec_flat(self, name: str, *args, lanes: int = 1) -> None:
        """Kernel ``name`` over the half spectrum as one range of ``n = H (W // 2 + 1)``
        frequencies, ``lanes`` per work-item (the last one takes what is left): ``(*args,
        n)``."""
        n = self.i32(self.shape[0] * self.ws)
        self.k[name](self.rt.queue, (-(-int(n) // lanes),), None, *args, n)

    def conv(self, x, out, X, conj: bool = False) -> None:
        """``out = H~ x`` (or ``H~^T x``) through spectrum ``X``."""
        self.fft.rfft2(x, X)
        self.launch_spec_flat("spec_mul_complex", X.buf, self.op.Hs.buf, self.i32(conj))
        self.fft.irfft2(X, out, overwrite_x=True)

    def row_sums(self, hx, a=None) -> np.ndarray:
        """float64 (C, 3): sums over the sensor of hx, a (when given), (Cy - hx - mean)^2."""
        use = a is not None
        a = a if use else hx
        sy = int(self._win[3])
        ny, nx = self.shape
        self.k["window_row_sums"](self.rt.queue, (sy,), None, hx.buf, a.buf, self.Cy.buf,
                                  self._shift.buf,
                                  self._rows.buf, self.i32(use), *self._win, self.i32(nx),
                                  self.i32(ny))
        sums = self._rows.get().astype(np.float64).sum(axis=1)
        m0 = self._shift_host
        m = sums[:, 0] / self.n_sensor
        # ||y~ - P C hx||^2 = sum (Cy - hx + m0)^2 - n (m - m0)^2 (y~ has zero mean): exact
        # for any shift m0, and free of cancellation when m0 is near the window mean m of hx
        # (the aperture's DC, large: with m0 = 0 the float32 data term is too noisy for
        # TwIST/FISTA's monotone tests; measured: docs/measurements.md,
        # clfza.backends._opencl_exact). The next call shifts by this call's m.
        sums[:, 2] -= self.n_sensor * (m - m0) ** 2
        self._shift_host = m.astype(self.dtype).astype(np.float64)
        self._shift.set(self._shift_host.astype(self.dtype))
        return sums

    @staticmethod
    def residual_norm(sums: np.ndarray) -> float:
        """``||y~ - P C hx||^2`` from :meth:`row_sums` (the shift already taken out)."""
        return float(np.sum(sums[:, 2]))

    # -- the data term ------------------------------------------------------------------
    def set_measurement(self, y):
        y = np.asarray(y, dtype=np.float64).reshape((self.nc,) + self.sensor)
        yn = ExactModel.remove_mean(y) / self.data_scale
        self.Cy.set(self.geom.embed(yn).astype(self.dtype))
        self.ynorm2 = float(np.sum(yn**2))
        self.conv(self.Cy, self._b, self.X, conj=True)
        self.ffts += self.nc

    def data_term(self, x) -> float:
        """``||y~ - K x||^2`` alone (one FFT pair: no gradient)."""
        self.conv(x, self.tmp_a, self.X)
        self.ffts += self.nc
        return self.residual_norm(self.row_sums(self.tmp_a))

    def resid_grad(self, x, g, step: bool = False) -> Scalars:
        hx = self.tmp_a
        self.conv(x, hx, self.X)
        sums = self.row_sums(hx)
        self.per_c.set((sums[:, 0] / self.n_sensor).astype(self.dtype))
        self.launch_window("crop_residual", self.tmp_b.buf, hx.buf, self.Cy.buf, self.per_c.buf)
        self.conv(self.tmp_b, g, self.X, conj=True)
        if step:  # the exact model's adjoint ends in an FFT of its own: add x in the image
            self.lincomb(g, 1.0, g, 1.0, x)
        self.ffts += 2 * self.nc
        return Ready(self.residual_norm(sums))
