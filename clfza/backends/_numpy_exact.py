"""The float64 reference of the exact (finite-aperture, cropped-sensor) model for the solvers.

Arrays live on the model grid ``G`` of :class:`clfza.models._exact.ExactModel`; the measurement on
the sensor. The operator is normalised, ``K~ = K / s`` and ``y~ = y / s`` with
``s = NORM_SAFETY ||K||``, so ``||K~|| <= 1`` and every step rule written for the paper's
``||K|| <= 1`` (TwIST's ``lambdaN = 1``, FISTA's ``L = 1``) holds unchanged; the problem
``1/2 ||y - K x||^2 + tau Phi(x)`` is the same problem with ``tau~ = tau / s^2``
(:attr:`data_scale`), which :func:`clfza.solvers.run_solver` applies.

ADMM on this model is the crop split of DiffuserCam (Antipa et al., Optica 5, 1, 2018), see
:mod:`clfza.solvers._admm_crop`: its operations (:mod:`clfza.solvers._admm_crop_ops`) keep every
update diagonal in Fourier space (the x-update) or in pixels (the v- and w-updates), with this
backend's :meth:`~NumpyExactBackend.conv`, ``Cy``, ``mask`` and ``region``.
"""

from __future__ import annotations

import numpy as np
import scipy.fft

from ..models import NORM_SAFETY, ExactModel
from ._base import Ready, Scalars
from ._numpy import NumpyBackend


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
    def conv(self, x: np.ndarray, conj: bool = False) -> np.ndarray:
        """``H~ x`` (or ``H~^T x``): the periodic convolution on the model grid."""
        H = np.conj(self.Hn) if conj else self.Hn
        return scipy.fft.irfft2(scipy.fft.rfft2(x) * H, s=self.shape)

    def set_measurement(self, y):
        y = np.asarray(y, dtype=np.float64).reshape((self.nc,) + self.sensor)
        self.y = ExactModel.remove_mean(y) / self.data_scale
        self.Cy = self.geom.embed(self.y)
        self.ynorm2 = float(np.sum(self.y**2))
        self._b = self.conv(self.Cy, conj=True)
        self.ffts += self.nc

    def residual(self, hx: np.ndarray) -> np.ndarray:
        """``y~ - P C hx`` on the sensor."""
        return self.y - ExactModel.remove_mean(self.geom.crop(hx))

    def data_term(self, x) -> float:
        """``||y~ - K x||^2`` alone (one FFT pair: no gradient)."""
        self.ffts += self.nc
        return float(np.sum(self.residual(self.conv(x)) ** 2))

    def resid_grad(self, x, g, step: bool = False) -> Scalars:
        self.ffts += 2 * self.nc
        r = self.residual(self.conv(x))
        g[...] = self.conv(self.geom.embed(r), conj=True) + (x if step else 0.0)
        return Ready(float(np.sum(r**2)))

    def _region(self) -> np.ndarray:
        m = self.geom.margin
        (oy, ox), (sy, sx) = self.geom.offset, self.sensor
        out = np.zeros(self.shape)
        out[oy - m:oy + sy + m, ox - m:ox + sx + m] = 1.0
        return out
