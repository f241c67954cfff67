"""The float64 reference of the exact (finite-aperture, cropped-sensor) model for the solvers.

Arrays live on the model grid ``G`` of :class:`clfza.exact.ExactModel`; the measurement on the
sensor. The operator is normalised, ``K~ = K / s`` and ``y~ = y / s`` with
``s = NORM_SAFETY ||K||``, so ``||K~|| <= 1`` and every step rule written for the paper's
``||K|| <= 1`` (TwIST's ``lambdaN = 1``, FISTA's ``L = 1``) holds unchanged; the problem
``1/2 ||y - K x||^2 + tau Phi(x)`` is the same problem with ``tau~ = tau / s^2``
(:attr:`data_scale`), which :func:`clfza.solvers.run_solver` applies.

ADMM on this model is the crop split of DiffuserCam (Antipa et al., Optica 5, 1, 2018), see
:mod:`clfza.solvers.admm_crop`: the operations ``crop_admm_*`` keep every update diagonal in
Fourier space (the x-update) or in pixels (the v- and w-updates).
"""

from __future__ import annotations

import numpy as np
import scipy.fft

from .. import regularizers as R
from ..exact import NORM_SAFETY, ExactModel
from .base import Ready, Scalars
from .numpy_backend import NumpyBackend, diff_symbol


class NumpyExactBackend(NumpyBackend):
    """float64 on the host, exact model (see the module docstring)."""

    def __init__(self, model: ExactModel, nc: int = 1):
        self.camera = None
        self.exact = model
        self.geom = model.geom
        self.shape = tuple(model.shape)
        self.sensor = tuple(model.sensor)
        self.nc = int(nc)
        self.dtype = np.dtype(np.float64)
        self.model = "exact"
        self.ffts = 0
        self._b = None
        self.data_scale = NORM_SAFETY * model.norm
        self.Hn = model.Hs / self.data_scale  # spectrum of K~'s kernel
        self.mask = self.geom.sensor_mask()
        self.region = self.mask if self.geom.margin == 0 else self._region()
        self.n_sensor = model.n_sensor

    # -- the data term ------------------------------------------------------------------
    def _conv(self, x: np.ndarray, conj: bool = False) -> np.ndarray:
        H = np.conj(self.Hn) if conj else self.Hn
        return scipy.fft.irfft2(scipy.fft.rfft2(x) * H, s=self.shape)

    def set_measurement(self, y):
        y = np.asarray(y, dtype=np.float64).reshape((self.nc,) + self.sensor)
        self.y = ExactModel.remove_mean(y) / self.data_scale
        self.Cy = self.geom.embed(self.y)
        self.ynorm2 = float(np.sum(self.y**2))
        self._b = self._conv(self.Cy, conj=True)
        self.ffts += self.nc

    def residual(self, hx: np.ndarray) -> np.ndarray:
        """``y~ - P C hx`` on the sensor."""
        return self.y - ExactModel.remove_mean(self.geom.crop(hx))

    def data_term(self, x) -> float:
        """``||y~ - K x||^2`` alone (one FFT pair: no gradient)."""
        self.ffts += self.nc
        return float(np.sum(self.residual(self._conv(x)) ** 2))

    def resid_grad(self, x, g) -> Scalars:
        self.ffts += 2 * self.nc
        r = self.residual(self._conv(x))
        g[...] = self._conv(self.geom.embed(r), conj=True)
        return Ready(float(np.sum(r**2)))

    # -- crop-split ADMM ---------------------------------------------------------------
    def crop_admm_mu1(self, rho: float) -> float:
        """Default v-split penalty: ``rho / median |H~|^2`` (balances the zone frequencies,
        where the information is, against the TV penalty; the aperture's low frequencies
        have gains up to 1 and need no help)."""
        return rho / float(np.median(np.abs(self.Hn) ** 2))

    def crop_admm_setup(self, mu1: float, rho: float, mu3: float) -> None:
        """``inv = 1 / (mu1 |H~|^2 + rho |D|^2 + mu3)`` on the half spectrum."""
        den = mu1 * np.abs(self.Hn) ** 2 + rho * diff_symbol(self.shape) + mu3
        self.inv = 1.0 / den

    def crop_admm_init(self, x, hx, v, a, e) -> None:
        """``hx = H~ x``, ``v = hx``, ``a = 0``, ``e = v - a``."""
        hx[...] = self._conv(x)
        v[...] = hx
        a[...] = 0.0
        e[...] = hx
        self.ffts += self.nc

    def crop_admm_v(self, hx, v, a, e, mu1: float) -> Scalars:
        """The v-update at ``t = hx + a`` (pixel-wise, Sherman-Morrison for the mean removal
        ``P``), the dual step ``a = t - v`` and ``e = v - a`` (the next x-update's input).
        Returns ``||y~ - P C hx||^2``."""
        t = hx + a
        r = self.Cy + mu1 * t
        m = (r * self.mask).sum(axis=(-2, -1), keepdims=True) / self.n_sensor
        v[...] = r / (self.mask + mu1) + self.mask * m / (mu1 * (1 + mu1))
        a[...] = t - v
        e[...] = v - a
        return Ready(float(np.sum(self.residual(hx) ** 2)))

    def crop_admm_x(self, x, hx, e, q1, q2, w, s, rho: float, mu3: float, mu1: float
                    ) -> None:
        """``x = F^-1[(F(rho D^T q + mu3 (w - s)) + mu1 conj(H~) F(e)) inv]``, ``hx = H~ x``."""
        r2 = rho * R.grad_circ_T(q1, q2) + mu3 * (w - s)
        X = (scipy.fft.rfft2(r2) + mu1 * np.conj(self.Hn) * scipy.fft.rfft2(e)) * self.inv
        x[...] = scipy.fft.irfft2(X, s=self.shape)
        hx[...] = scipy.fft.irfft2(X * self.Hn, s=self.shape)
        self.ffts += 2 * self.nc

    def crop_w_update(self, x, w, s, nonneg: bool, support: bool) -> None:
        """``w = proj(x + s)`` (non-negativity and/or the object region), ``s += x - w``."""
        t = x + s
        w[...] = np.maximum(t, 0.0) if nonneg else t
        if support:
            w *= self.region
        s[...] = t - w

    def _region(self) -> np.ndarray:
        m = self.geom.margin
        (oy, ox), (sy, sx) = self.geom.offset, self.sensor
        out = np.zeros(self.shape)
        out[oy - m:oy + sy + m, ox - m:ox + sx + m] = 1.0
        return out

    def crop_admm_residuals(self, hx, v, v_old, mu1: float) -> tuple[float, float]:
        """Primal ``||hx - v||`` and dual ``mu1 ||H~^T (v - v_old)||`` residual norms."""
        self.ffts += self.nc
        return (float(np.linalg.norm(hx - v)),
                mu1 * float(np.linalg.norm(self._conv(v - v_old, conj=True))))

    # -- the plain ADMM needs the transfer-function model --------------------------------
    def admm_setup(self, rho, mu):
        raise NotImplementedError("the exact model uses the crop-split ADMM (admm_crop)")
