"""The exact (finite-aperture, cropped-sensor) model on an OpenCL device.

Same operations and units as the float64 reference :mod:`clfza.backends.numpy_exact` (the
normalised operator ``K / s``), with the kernels of ``kernels/exact.cl`` between the FFTs of the
model grid. Sums over the sensor window (the frame's mean for ``P``, the residual norm) are
per-row partial sums added on the host in float64: one small read per data-term evaluation.
On CPU devices the host FFT drains the queue anyway, so it costs nothing extra there; on GPUs
it is one synchronisation per evaluation.
"""

from __future__ import annotations

import numpy as np

from ..cl.arrays import DeviceArray
from ..cl.operator import make_fft_engine
from ..exact import NORM_SAFETY, ExactModel
from .base import Ready, Scalars
from .numpy_backend import diff_symbol
from .opencl_backend import OpenCLBackend, build_program


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
        self.n_sensor = model.n_sensor
        prg = build_program(self.rt, "exact", self.dtype, self.nc)
        self.kx = {nm: self.rt.cl.Kernel(prg, nm) for nm in
                   ("spec_mul_complex", "window_row_sums", "crop_residual", "crop_v_update",
                    "crop_w_update", "crop_x_spec")}
        (oy, ox), (sy, sx) = self.geom.offset, self.sensor
        self._win = tuple(np.int32(v) for v in (ox, oy, sx, sy))
        m = self.geom.margin
        self._region = tuple(np.int32(v) for v in (ox - m, oy - m, sx + 2 * m, sy + 2 * m))
        self.E = DeviceArray.empty(self.rt, self.sshape, self.op.cdtype)
        self._rows = DeviceArray.empty(self.rt, (self.nc, sy, 3), self.dtype)
        self._per_c = DeviceArray.empty(self.rt, (self.nc,), self.dtype)
        self._shift_host = np.zeros(self.nc)
        self._shift = DeviceArray.from_host(self.rt, np.zeros(self.nc, self.dtype))
        self._zero = self.zeros()
        self._tmp_a = self.empty()
        self._tmp_b = self.empty()
        self.Cy = self.zeros()
        self.inv = None

    def _make_operator(self, camera, fft: str):
        return OpenCLExactOperator(self._model, self.rt, self.dtype, fft)

    # -- launch helpers -----------------------------------------------------------------
    def _grid2(self, name: str, *args, window=None) -> None:
        ny, nx = self.shape
        self.kx[name](self.rt.queue, (nx, ny), self._lw, *args, *(window or self._win),
                      self.i32(nx), self.i32(ny))

    def _spec(self, name: str, *args) -> None:
        n = self.i32(self.shape[0] * self.ws)
        self.kx[name](self.rt.queue, (int(n),), None, *args, n)

    def _conv(self, x, out, X, conj: bool = False) -> None:
        """``out = H~ x`` (or ``H~^T x``) through spectrum ``X``."""
        self.fft.rfft2(x, X)
        self._spec("spec_mul_complex", X.buf, self.op.Hs.buf, self.i32(conj))
        self.fft.irfft2(X, out)

    def _row_sums(self, hx, a=None) -> np.ndarray:
        """float64 (C, 3): sums over the sensor of hx, a (when given), (Cy - hx - mean)^2."""
        use = a is not None
        a = a if use else hx
        sy = int(self._win[3])
        ny, nx = self.shape
        self.kx["window_row_sums"](self.rt.queue, (sy,), None, hx.buf, a.buf, self.Cy.buf,
                                   self._shift.buf,
                                   self._rows.buf, self.i32(use), *self._win, self.i32(nx),
                                   self.i32(ny))
        sums = self._rows.get().astype(np.float64).sum(axis=1)
        m0 = self._shift_host
        m = sums[:, 0] / self.n_sensor
        # ||y~ - P C hx||^2 = sum (Cy - hx + m0)^2 - n (m - m0)^2 (y~ has zero mean): exact
        # for any shift m0, and free of cancellation when m0 is near the window mean m of hx
        # (the aperture's DC, large: with m0 = 0 the float32 data term carried 1e-5..1e-3
        # relative noise and TwIST/FISTA's monotone tests rejected good steps). The next call
        # shifts by this call's m.
        sums[:, 2] -= self.n_sensor * (m - m0) ** 2
        self._shift_host = m.astype(self.dtype).astype(np.float64)
        self._shift.set(self._shift_host.astype(self.dtype))
        return sums

    def _data_term(self, sums: np.ndarray) -> float:
        """``||y~ - P C hx||^2`` from :meth:`_row_sums` (the shift already taken out)."""
        return float(np.sum(sums[:, 2]))

    # -- the data term ------------------------------------------------------------------
    def set_measurement(self, y):
        y = np.asarray(y, dtype=np.float64).reshape((self.nc,) + self.sensor)
        yn = ExactModel.remove_mean(y) / self.data_scale
        self.Cy.set(self.geom.embed(yn).astype(self.dtype))
        self.ynorm2 = float(np.sum(yn**2))
        self._conv(self.Cy, self._b, self.X, conj=True)
        self.ffts += self.nc

    def data_term(self, x) -> float:
        """``||y~ - K x||^2`` alone (one FFT pair: no gradient)."""
        self._conv(x, self._tmp_a, self.X)
        self.ffts += self.nc
        return self._data_term(self._row_sums(self._tmp_a))

    def resid_grad(self, x, g) -> Scalars:
        hx = self._tmp_a
        self._conv(x, hx, self.X)
        sums = self._row_sums(hx)
        self._per_c.set((sums[:, 0] / self.n_sensor).astype(self.dtype))
        self._grid2("crop_residual", self._tmp_b.buf, hx.buf, self.Cy.buf, self._per_c.buf)
        self._conv(self._tmp_b, g, self.X, conj=True)
        self.ffts += 2 * self.nc
        return Ready(self._data_term(sums))

    # -- crop-split ADMM ----------------------------------------------------------------
    def crop_admm_mu1(self, rho: float) -> float:
        return rho / float(np.median(np.abs(self.op.Hn) ** 2))

    def crop_admm_setup(self, mu1: float, rho: float, mu3: float) -> None:
        den = mu1 * np.abs(self.op.Hn) ** 2 + rho * diff_symbol(self.shape) + mu3
        inv = (1.0 / den).astype(self.dtype)
        if self.inv is None:
            self.inv = DeviceArray.from_host(self.rt, inv)
        else:
            self.inv.set(inv)

    def crop_admm_init(self, x, hx, v, a, e) -> None:
        self._conv(x, hx, self.X)
        self.copy(v, hx)
        self.copy(e, hx)
        self.rt.cl.enqueue_fill_buffer(self.rt.queue, a.buf, self.r(0), 0, a.nbytes)
        self.ffts += self.nc

    def crop_admm_v(self, hx, v, a, e, mu1: float) -> Scalars:
        sums = self._row_sums(hx, a)
        # Sherman-Morrison term mean_S(Cy + mu1 t) / (mu1 (1 + mu1)) = mean_S(t) / (1 + mu1)
        # with t = hx + a (Cy has zero mean on the sensor)
        corr = (sums[:, 0] + sums[:, 1]) / self.n_sensor / (1.0 + mu1)
        self._per_c.set(corr.astype(self.dtype))
        self._grid2("crop_v_update", hx.buf, v.buf, a.buf, e.buf, self.Cy.buf,
                    self._per_c.buf, self.r(mu1))
        return Ready(self._data_term(sums))

    def crop_admm_x(self, x, hx, e, q1, q2, w, s, rho: float, mu3: float, mu1: float
                    ) -> None:
        r = self.r
        ny, nx = self.shape
        self.k["admm_rhs"](self.rt.queue, (nx, ny), self._lw, self._tmp_a.buf, self._zero.buf,
                           q1.buf, q2.buf, w.buf, s.buf, r(rho), r(mu3), self.i32(nx),
                           self.i32(ny))
        self.fft.rfft2(self._tmp_a, self.X)
        self.fft.rfft2(e, self.E)
        self._spec("crop_x_spec", self.X.buf, self.E.buf, self.op.Hs.buf, self.inv.buf,
                   r(mu1))
        self.fft.irfft2(self.X, x)
        self.fft.irfft2(self.E, hx)
        self.ffts += 2 * self.nc

    def crop_w_update(self, x, w, s, nonneg: bool, support: bool) -> None:
        self._grid2("crop_w_update", x.buf, w.buf, s.buf, self.i32(nonneg), self.i32(support),
                    window=self._region)

    def crop_admm_residuals(self, hx, v, v_old, mu1: float) -> tuple[float, float]:
        self.lincomb(self._tmp_a, 1.0, v, -1.0, v_old)
        self._conv(self._tmp_a, self._tmp_b, self.X, conj=True)
        self.lincomb(self._tmp_a, 1.0, hx, -1.0, v)
        self.ffts += self.nc
        primal = float(np.linalg.norm(self._tmp_a.get()))
        return primal, mu1 * float(np.linalg.norm(self._tmp_b.get()))

    def admm_setup(self, rho, mu):
        raise NotImplementedError("the exact model uses the crop-split ADMM (admm_crop)")
