"""The crop-split ADMM's operations on the exact model (:mod:`clfza.solvers._admm_crop`; the
x-update and the support projection also serve :mod:`clfza.solvers._wiener`'s exact-model PCG).

:class:`CropAdmmOps`: the default ``mu1``, the initial split, the pixel-wise v-update (with
the Sherman-Morrison term of the mean removal ``P``), the w-update (non-negativity and the
object region) and the residuals of the ``mu1`` balancing. :class:`CropFourierSolve`: the
Fourier-diagonal x-update ``(mu1 |H~|^2 + rho |D|^2 + mu3) x = ...`` as its own object, with
``H x`` from the same spectrum.

Each is a float64 numpy reference (on :class:`clfza.backends._numpy_exact.NumpyExactBackend`)
and an OpenCL implementation (on :class:`clfza.backends._opencl_exact.OpenCLExactBackend`;
``kernels/exact.cl``: ``crop_v_update``, ``crop_w_update``, ``crop_x_spec``;
``kernels/elementwise.cl``: ``admm_rhs``); ``CropAdmmOps.for_backend(B)`` and
``CropFourierSolve.for_backend(B)`` return the ones for ``B``.
"""

from __future__ import annotations

import math
from abc import abstractmethod

import numpy as np
import scipy.fft

from .. import regularizers as R
from ..backends import Backend, Ops, Ready, Scalars, diff_symbol, read_all
from ..cl import DeviceArray
from ..errors import ClfzaError


def _need_exact(B: Backend, what: str) -> None:
    if B.exact is None:
        raise ClfzaError(f"{what} runs on the exact model's backends (model='exact')")


class CropAdmmOps(Ops):
    """The crop split's pixel-wise operations on one exact-model backend
    (:class:`~clfza.backends._base.Ops`). ``H~`` is the backend's normalised kernel, ``Cy``
    its embedded measurement, ``S`` the sensor window."""

    def __init__(self, B: Backend):
        _need_exact(B, "the crop-split ADMM")
        super().__init__(B)

    @abstractmethod
    def default_mu1(self, rho: float) -> float:
        """Default v-split penalty: ``rho / median |H~|^2`` (balances the zone frequencies,
        where the information is, against the TV penalty; the aperture's low frequencies
        have gains up to 1 and need no help)."""

    @abstractmethod
    def init(self, x, hx, v, a, e) -> None:
        """``hx = H~ x``, ``v = hx``, ``a = 0``, ``e = v - a``."""

    @abstractmethod
    def v_update(self, hx, v, a, e, mu1: float) -> Scalars:
        """The v-update at ``t = hx + a`` (pixel-wise, Sherman-Morrison for the mean removal
        ``P``), the dual step ``a = t - v`` and ``e = v - a`` (the next x-update's input).
        Returns ``||y~ - P C hx||^2``."""

    @abstractmethod
    def w_update(self, x, w, s, nonneg: bool, support: bool) -> None:
        """``w = proj(x + s)`` (non-negativity and/or the object region), ``s += x - w``."""

    @abstractmethod
    def residuals(self, hx, v, v_old, mu1: float) -> tuple[float, float]:
        """Primal ``||hx - v||`` and dual ``mu1 ||H~^T (v - v_old)||`` residual norms (one FFT
        pair)."""


@CropAdmmOps.implements("numpy")
class NumpyCropAdmmOps(CropAdmmOps):
    """float64 reference."""

    def default_mu1(self, rho):
        return rho / float(np.median(np.abs(self.B.Hn) ** 2))

    def init(self, x, hx, v, a, e):
        B = self.B
        hx[...] = B.conv(x)
        v[...] = hx
        a[...] = 0.0
        e[...] = hx
        B.ffts += B.nc

    def v_update(self, hx, v, a, e, mu1):
        B = self.B
        t = hx + a
        r = B.Cy + mu1 * t
        m = (r * B.mask).sum(axis=(-2, -1), keepdims=True) / B.n_sensor
        v[...] = r / (B.mask + mu1) + B.mask * m / (mu1 * (1 + mu1))
        a[...] = t - v
        e[...] = v - a
        return Ready(float(np.sum(B.residual(hx) ** 2)))

    def w_update(self, x, w, s, nonneg, support):
        t = x + s
        w[...] = np.maximum(t, 0.0) if nonneg else t
        if support:
            w *= self.B.region
        s[...] = t - w

    def residuals(self, hx, v, v_old, mu1):
        B = self.B
        B.ffts += B.nc
        return (float(np.linalg.norm(hx - v)),
                mu1 * float(np.linalg.norm(B.conv(v - v_old, conj=True))))


@CropAdmmOps.implements("opencl")
class OpenCLCropAdmmOps(CropAdmmOps):
    """Window kernels of ``exact.cl``; the v-update's sensor sums come from the backend's
    :meth:`~clfza.backends._opencl_exact.OpenCLExactBackend.row_sums` (one small read)."""

    KERNELS = (("exact", ("crop_v_update", "crop_w_update")),)

    def default_mu1(self, rho):
        return rho / float(np.median(np.abs(self.B.op.Hn) ** 2))

    def init(self, x, hx, v, a, e):
        B = self.B
        B.conv(x, hx, B.X)
        B.copy(v, hx)
        B.copy(e, hx)
        B.rt.cl.enqueue_fill_buffer(B.rt.queue, a.buf, B.r(0), 0, a.nbytes)
        B.ffts += B.nc

    def v_update(self, hx, v, a, e, mu1):
        B = self.B
        sums = B.row_sums(hx, a)
        # Sherman-Morrison term mean_S(Cy + mu1 t) / (mu1 (1 + mu1)) = mean_S(t) / (1 + mu1)
        # with t = hx + a (Cy has zero mean on the sensor)
        corr = (sums[:, 0] + sums[:, 1]) / B.n_sensor / (1.0 + mu1)
        B.per_c.set(corr.astype(B.dtype))
        B.launch_window("crop_v_update", hx.buf, v.buf, a.buf, e.buf, B.Cy.buf, B.per_c.buf,
                        B.r(mu1))
        return Ready(B.residual_norm(sums))

    def w_update(self, x, w, s, nonneg, support):
        B = self.B
        B.launch_window("crop_w_update", x.buf, w.buf, s.buf, B.i32(nonneg), B.i32(support),
                        window=B.region_window)

    def residuals(self, hx, v, v_old, mu1):
        B = self.B  # both norms as device reductions: two sums read, not two images
        B.lincomb(B.tmp_a, 1.0, v, -1.0, v_old)
        B.conv(B.tmp_a, B.tmp_b, B.X, conj=True)
        B.ffts += B.nc
        primal, dual = read_all(B.diffnorm(hx, v), B.dot(B.tmp_b, B.tmp_b))
        primal2, dual2 = float(primal[0]), float(dual[0])
        return math.sqrt(max(primal2, 0.0)), mu1 * math.sqrt(max(dual2, 0.0))


# ----------------------------------------------------------------------------------------
# the Fourier-diagonal x-update (exact model)
# ----------------------------------------------------------------------------------------
class CropFourierSolve(Ops):
    """The crop split's x-update on one exact-model backend
    (:class:`~clfza.backends._base.Ops`): ``x = F^-1[(F(rho D^T q + mu3 (w - s)) +
    mu1 conj(H~) F(e)) inv]`` and ``hx = H~ x``, with ``inv`` from :meth:`setup` (two real
    FFT pairs). The right-hand side's coefficients are the caller's: the PCG preconditioner
    of :mod:`clfza.solvers._wiener` applies ``inv`` alone (``rho = mu1 = 0``, ``mu3 = 1``)."""

    def __init__(self, B: Backend):
        _need_exact(B, "the crop split's x-update")
        super().__init__(B)

    @abstractmethod
    def setup(self, mu1: float, rho: float, mu3: float) -> None:
        """``inv = 1 / (mu1 |H~|^2 + rho |D|^2 + mu3)`` on the half spectrum."""

    @abstractmethod
    def solve(self, x, hx, e, q1, q2, w, s, rho: float, mu3: float, mu1: float) -> None:
        """``x = F^-1[(F(rho D^T q + mu3 (w - s)) + mu1 conj(H~) F(e)) inv]``,
        ``hx = H~ x``."""

    @abstractmethod
    def solve_rhs(self, x, hx, e, rhs, mu1: float) -> None:
        """:meth:`solve` with its image part ``rhs = rho D^T q + mu3 (w - s)`` given (the
        crop-split ADMM's, from :meth:`clfza.solvers._admm_ops.AdmmOps.update_rhs`):
        ``x = F^-1[(F(rhs) + mu1 conj(H~) F(e)) inv]``, ``hx = H~ x``."""


@CropFourierSolve.implements("numpy")
class NumpyCropFourierSolve(CropFourierSolve):
    """float64 reference."""

    def setup(self, mu1, rho, mu3):
        B = self.B
        den = mu1 * np.abs(B.Hn) ** 2 + rho * diff_symbol(B.shape) + mu3
        self.inv = 1.0 / den

    def solve(self, x, hx, e, q1, q2, w, s, rho, mu3, mu1):
        self.solve_rhs(x, hx, e, rho * R.grad_circ_T(q1, q2) + mu3 * (w - s), mu1)

    def solve_rhs(self, x, hx, e, rhs, mu1):
        B = self.B
        X = (scipy.fft.rfft2(rhs) + mu1 * np.conj(B.Hn) * scipy.fft.rfft2(e)) * self.inv
        x[...] = scipy.fft.irfft2(X, s=B.shape)
        hx[...] = scipy.fft.irfft2(X * B.Hn, s=B.shape)
        B.ffts += 2 * B.nc


@CropFourierSolve.implements("opencl")
class OpenCLCropFourierSolve(CropFourierSolve):
    """``admm_rhs`` (with a zero ``K^T y``) into the backend's scratch image, the FFTs of it
    and of ``e``, one spectral kernel, the two inverse FFTs."""

    KERNELS = (("elementwise", ("admm_rhs",)), ("exact", ("crop_x_spec",)))

    def __init__(self, B: Backend):
        super().__init__(B)
        # CPU devices in float32: 8 frequencies per work-item (crop_x_spec8; measured:
        # docs/measurements.md, clfza.solvers._admm_crop_ops)
        self.lanes = 8 if B.spec8 else 1
        if self.lanes > 1:
            B.use_kernels(("exact", ("crop_x_spec8",)))
        self.inv = None
        self.E = DeviceArray.empty(B.rt, B.sshape, B.op.cdtype)  # the spectrum of e, then H x
        self.zero = B.zeros()

    def setup(self, mu1, rho, mu3):
        B = self.B
        den = mu1 * np.abs(B.op.Hn) ** 2 + rho * diff_symbol(B.shape) + mu3
        inv = (1.0 / den).astype(B.dtype)
        if self.inv is None:
            self.inv = DeviceArray.from_host(B.rt, inv)
        else:
            self.inv.set(inv)

    def solve(self, x, hx, e, q1, q2, w, s, rho, mu3, mu1):
        B = self.B
        r = B.r
        B.launch2d("admm_rhs", B.tmp_a.buf, self.zero.buf, q1.buf, q2.buf, w.buf, s.buf,
                   r(rho), r(mu3), B.fpar.buf)
        self.solve_rhs(x, hx, e, B.tmp_a, mu1)

    def solve_rhs(self, x, hx, e, rhs, mu1):
        B = self.B
        r = B.r
        B.fft.rfft2(rhs, B.X)
        B.fft.rfft2(e, self.E)
        B.launch_spec_flat("crop_x_spec8" if self.lanes > 1 else "crop_x_spec", B.X.buf,
                           self.E.buf, B.op.Hs.buf, self.inv.buf, r(mu1), lanes=self.lanes)
        B.fft.irfft2(B.X, x, overwrite_x=True)
        B.fft.irfft2(self.E, hx, overwrite_x=True)
        B.ffts += 2 * B.nc
