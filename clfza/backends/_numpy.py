"""The float64 numpy reference backend: every core operation written plainly, for reading and
for testing the OpenCL kernels against (the solvers' own operations have their references
beside them, :mod:`clfza.solvers._twist_ops` and the others)."""

from __future__ import annotations

import numpy as np
import scipy.fft

from .. import regularizers as R
from ..camera import Camera
from ..models import NumpyOperator
from ._base import Backend, ProxState, Ready, Scalars


def half_weights(shape: tuple[int, int]) -> np.ndarray:
    """Parseval weights of the rfft half spectrum: 1 on column 0 (and the Nyquist column for
    even widths), 2 elsewhere, so ``sum |x|^2 = sum w |X|^2 / (H W)``."""
    ny, nx = shape
    w = np.full(nx // 2 + 1, 2.0)
    w[0] = 1.0
    if nx % 2 == 0:
        w[-1] = 1.0
    return np.broadcast_to(w, (ny, nx // 2 + 1))


def diff_symbol(shape: tuple[int, int]) -> np.ndarray:
    """``|D|^2`` of the circular backward differences on the half spectrum:
    ``4 sin^2(pi kx / W) + 4 sin^2(pi ky / H)``."""
    ny, nx = shape
    kx = np.arange(nx // 2 + 1)
    ky = np.arange(ny)
    return (4 * np.sin(np.pi * kx / nx) ** 2)[None, :] + (4 * np.sin(np.pi * ky / ny) ** 2)[:, None]


class NumpyBackend(Backend):
    """float64 on the host; ``model="padded"`` uses the linear-convolution operator."""

    name = "numpy"
    device = "host (numpy float64)"

    def __init__(self, camera: Camera, nc: int = 1, model: str = "tf"):
        self.camera = camera
        self.shape = tuple(camera.shape)
        self.nc = int(nc)
        self.dtype = np.dtype(np.float64)
        self.model = model
        self.op = NumpyOperator(camera, model, warn=False)
        self.ffts = 0
        self._b = None

    @property
    def fourier_diagonal(self) -> bool:
        return self.exact is None and self.model == "tf"

    # arrays ---------------------------------------------------------------------------
    def empty(self):
        return np.empty((self.nc,) + self.shape)

    def from_host(self, a):
        return np.array(np.broadcast_to(np.asarray(a, np.float64),
                                        (self.nc,) + self.shape), dtype=np.float64)

    def to_host(self, a):
        return np.array(a, dtype=np.float64)

    def copy(self, dst, src):
        dst[...] = src

    def finish(self):
        pass

    # data term ------------------------------------------------------------------------
    def set_measurement(self, y):
        self.y = self.from_host(y)
        self.ynorm2 = float(np.sum(self.y**2))
        if self.model == "tf":
            self.Y = scipy.fft.rfft2(self.y)
            self.w = half_weights(self.shape)
        self._b = np.stack([self.op.adjoint(c) for c in self.y])  # back_propagate's K^T y
        self.ffts += self.nc

    @property
    def b(self):
        return self._b

    def resid_grad(self, x, g, step: bool = False) -> Scalars:
        self.ffts += self.nc
        if self.model == "tf":  # residual spectrum R = Y - H X; Parseval for its norm
            Rs = self.Y - self.op.H * scipy.fft.rfft2(x)
            g[...] = scipy.fft.irfft2(self.op.H * Rs, s=self.shape) + (x if step else 0.0)
            return Ready(float(np.sum(self.w * np.abs(Rs) ** 2)) / (self.shape[0] *
                                                                      self.shape[1]))
        self.ffts += self.nc  # literal: r = y - K x, g = K^T r (two operator applications)
        r = np.stack([self.y[c] - self.op.forward(x[c]) for c in range(self.nc)])
        g[...] = np.stack([self.op.adjoint(rc) for rc in r]) + (x if step else 0.0)
        return Ready(float(np.sum(r**2)))

    # regularisers ---------------------------------------------------------------------
    def reg_value(self, x) -> Scalars:
        return Ready(R.tv_value(x), R.l1_value(x))

    def prox_step(self, reg, x, g, s, th, out, iters, state: ProxState, tol: float = 0.0,
                  check_every: int = 2) -> int:
        v = x + s * g
        if reg == "l1":
            out[...] = R.soft(v, th)
            return 0
        p = state.arrays.get("p") if (state.warm and state.valid) else None
        done = int(iters)
        if tol > 0:  # same schedule as the OpenCL backend: checks after warm steps only
            done = 0
            for k in range(1, int(iters) + 1):
                _, pn = R.chambolle(v, 2.0 / th, 1, p)
                done = k
                if p is not None and k % check_every == 0 and k < iters:
                    d = sum(float(np.sum((a - b) ** 2)) for a, b in zip(pn, p, strict=True))
                    n = sum(float(np.sum(a**2)) for a in pn)
                    p = pn
                    if d <= tol * tol * n:
                        break
                p = pn
            out[...], p = R.chambolle(v, 2.0 / th, 0, p)
        else:
            out[...], p = R.chambolle(v, 2.0 / th, iters, p)
        state.arrays["p"] = p
        state.valid = True
        return done

    def project_nonneg(self, out, v):
        out[...] = np.maximum(v, 0.0)

    def fgp_prox(self, reg, out, b, weight, iters, state, nonneg):
        if reg == "l1":
            u = R.soft(b, weight)
            out[...] = np.maximum(u, 0) if nonneg else u
        else:
            p = state.arrays.get("p") if (state.warm and state.valid) else None
            out[...], p = R.fgp(b, weight, iters, p, nonneg=nonneg)
            state.arrays["p"] = p
            state.valid = True
        return self.reg_value(out)

    # element-wise ---------------------------------------------------------------------
    def lincomb(self, out, a, X, b=0.0, Y=None, c=0.0, Z=None):
        r = a * X
        if Y is not None:
            r = r + b * Y
        if Z is not None:
            r = r + c * Z
        out[...] = r

    def diffnorm(self, a, b) -> Scalars:
        return Ready(float(np.sum((a - b) ** 2)), float(np.sum(a**2)))

    def dot(self, a, b) -> Scalars:
        return Ready(float(np.sum(a * b)))
