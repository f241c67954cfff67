"""The forward model ``y = K o`` (Eqs. 14-18) and its operators, numpy and OpenCL.

After the DC term is removed, the measurement is ``K o`` with
``K = F^-1 diag(H_T) F`` and ``H_T(u, v) = sin(pi r1'^2 (u^2 + v^2))`` on the FFT frequencies
of the sensor grid (Eq. 17). ``K`` is real and symmetric, so the adjoint (back-propagation,
Eqs. 11-12) is ``K`` itself and the normal operator is ``F^-1 diag(H_T^2) F``; ``||K|| <= 1``.

``H_T`` on the FFT grid is exact only at critical sampling ``r1'^2 = N p^2``. The ``"padded"``
model is the accurate alternative for objects on the sensor: the exact model of
:mod:`clfza.models._exact` (linear convolution with the sampled mask on a padded grid, cropped to
the sensor and mean-subtracted: exactly what the simulator does) restricted to the sensor window.
"""

from __future__ import annotations

from typing import Literal

import numpy as np
import scipy.fft

from ..camera import (  # noqa: F401  (re-exported)
    FAR_FROM_CRITICAL,  # noqa: F401  (the threshold lives with the regimes)
    Camera,
    SamplingWarning,
    check_regime,
)
from ..errors import ClfzaError, finite_image
from ._exact import camera_model

ModelKind = Literal["tf", "padded"]


def frequency_phase(n: int, pitch: float, r1p: float, half: bool = False) -> np.ndarray:
    """Per-axis ``r1'^2 f^2`` modulo 2 for the FFT frequencies ``f`` (float64).

    ``H_T = sin(pi (pu + pv))``. With ``half`` the rfft frequencies ``0 .. n//2`` are returned.
    """
    f = scipy.fft.rfftfreq(n, pitch) if half else scipy.fft.fftfreq(n, pitch)
    return np.mod(r1p**2 * f**2, 2.0)


def transfer_function(shape: tuple[int, int], pitch: float, r1p: float, *, half: bool = True
                      ) -> np.ndarray:
    """``H_T(u, v) = sin(pi r1'^2 (u^2 + v^2))`` on the FFT grid (Eq. 17), float64 reference.

    Parameters
    ----------
    shape : (int, int)
        Sensor grid (rows, cols).
    pitch, r1p : float
        Pixel pitch and shadow FZA constant ``r1'``, in mm.
    half : bool
        Return the rfft half spectrum ``(rows, cols // 2 + 1)`` instead of the full one.

    Examples
    --------
    >>> from clfza.models import transfer_function
    >>> transfer_function((4, 4), 0.01, 0.3).shape
    (4, 3)
    """
    ny, nx = shape
    pv = frequency_phase(ny, pitch, r1p)[:, None]
    pu = frequency_phase(nx, pitch, r1p, half=half)[None, :]
    return np.sin(np.pi * (pu + pv))


def apply_spectrum(X: np.ndarray, H: np.ndarray, shape: tuple[int, int], *,
                   workers: int | None = None) -> np.ndarray:
    """``F^-1 diag(H) X``: a transfer function applied to a half spectrum ``X = rfft2(x)``.

    The one host definition of the TF model's ``K`` and ``K^T`` (equal: ``H_T`` is real and
    even), and of ``K^T K`` with ``H_T^2``: :class:`NumpyOperator` applies it to ``rfft2(x)``
    in float64 (the specification); :class:`clfza.focus.FastBP` to one precomputed float32
    spectrum with ``H_T`` at each trial depth.

    Parameters
    ----------
    X : complex array (H, W // 2 + 1)
        Half spectrum of the input.
    H : real array (H, W // 2 + 1)
        Transfer function on the same grid (:func:`transfer_function`).
    shape : (int, int)
        The image grid (rows, cols).
    workers : int, optional
        Threads of ``scipy.fft``.
    """
    return scipy.fft.irfft2(X * H, s=shape, workers=workers)


class NumpyOperator:
    """Reference float64 implementation of ``K``, ``K^T`` and ``K^T K`` on the host.

    Parameters
    ----------
    camera : Camera
        The camera; its ``shape`` is the grid.
    model : {"tf", "padded"}
        ``"tf"``: the paper's periodic transfer-function model (one FFT pair per apply).
        ``"padded"``: the exact model (:mod:`clfza.models._exact`) for objects on the sensor
        (accurate in every sampling regime; two FFT pairs on a padded grid per apply).
    warn : bool
        Warn (SamplingWarning) when ``"tf"`` is used far from critical sampling.
    """

    def __init__(self, camera: Camera, model: ModelKind = "tf", *, warn: bool = True):
        if model not in ("tf", "padded"):
            raise ClfzaError(f"model must be 'tf' or 'padded', got {model!r}")
        self.camera = camera
        self.model = model
        self.shape = camera.shape
        self.dtype = np.dtype(np.float64)
        if warn:
            check_regime(camera, model)
        if model == "tf":
            self.H = transfer_function(self.shape, camera.pitch, camera.r1p)
            self.H2 = self.H**2
        else:  # the exact model (clfza.models._exact) for objects on the sensor

            self.exact = camera_model(camera)

    def _check(self, x: np.ndarray, name: str) -> np.ndarray:
        if x.shape != tuple(self.shape):
            raise ClfzaError(f"{name} has shape {x.shape}, but the camera grid is "
                             f"{tuple(self.shape)}")
        return x

    def _tf_apply(self, x: np.ndarray, H: np.ndarray) -> np.ndarray:
        return apply_spectrum(scipy.fft.rfft2(x), H, x.shape)

    def forward(self, x: np.ndarray) -> np.ndarray:
        """``K x``: the DC-free measurement of a sensor-plane object (Eq. 17)."""
        x = self._check(np.asarray(x, dtype=np.float64), "object")
        if self.model == "tf":
            return self._tf_apply(x, self.H)
        return self.exact.forward(self.exact.geom.embed(x))

    def adjoint(self, y: np.ndarray) -> np.ndarray:
        """``K^T y``: back-propagation (Eqs. 11-12); equal to ``K y`` for the TF model."""
        y = self._check(np.asarray(y, dtype=np.float64), "measurement")
        if self.model == "tf":
            return self._tf_apply(y, self.H)
        return self.exact.crop(self.exact.adjoint(y))

    def normal(self, x: np.ndarray) -> np.ndarray:
        """``K^T K x`` (one FFT pair with ``H_T^2`` for the TF model)."""
        x = self._check(np.asarray(x, dtype=np.float64), "object")
        if self.model == "tf":
            return self._tf_apply(x, self.H2)
        return self.adjoint(self.forward(x))

    def norm_estimate(self, iters: int = 30, seed: int = 0) -> float:
        """Power-iteration estimate of ``||K||`` (<= 1 for the TF model)."""
        rng = np.random.default_rng(seed)
        x = rng.standard_normal(self.shape)
        x /= np.linalg.norm(x)
        lam = 0.0
        for _ in range(iters):
            z = self.normal(x)
            lam = float(np.linalg.norm(z))
            if lam == 0:
                return 0.0
            x = z / lam
        return float(np.sqrt(lam))


def back_propagate(y: np.ndarray, camera: Camera, model: ModelKind = "tf") -> np.ndarray:
    """Back-propagation reconstruction ``Re{F^-1 conj(H) F y} = K^T y`` (Eqs. 11-12), float64.

    The result holds the in-focus image plus the twin image (Eq. 12, third term). This is the
    specification every other back-propagation is tested against: ``clfza.reconstruct(...,
    "bp")`` (:class:`NumpyOperator` on the host,
    :class:`clfza.models._device_operator.OpenCLOperator` on a device), the solvers' ``Backend.b``
    and :class:`clfza.focus.FastBP`.
    """
    y = finite_image("measurement", y, ndim=(2,))
    return NumpyOperator(camera, model).adjoint(y)
