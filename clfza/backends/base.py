"""The array-operations interface the solvers are written against.

A backend owns the working precision, the operator ``K`` (Eqs. 17-18) for one camera and one
measurement ``y``, and a handful of fused operations. Arrays are opaque handles of shape
``(C, H, W)`` (C = 1, or 3 for joint colour); the solver never looks inside them except through
:meth:`Backend.to_host` at checkpoints. Operations that produce scalars (objective pieces,
norms) return a :class:`Scalars` handle; reading it (``.get()``) is the only point where the
host waits for the device, so solvers read them once per iteration (the monotone tests need
the objective) or only at checkpoints.

The numpy backend (:mod:`.numpy_backend`) is the float64 reference; the OpenCL backend
(:mod:`.opencl_backend`) implements every operation with the kernels in ``kernels/*.cl``.
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from dataclasses import dataclass, field

import numpy as np


class Scalars(ABC):
    """A deferred pair of sums; ``get()`` returns them as float64 (synchronises)."""

    @abstractmethod
    def get(self) -> np.ndarray: ...


class Ready(Scalars):
    """Scalars already on the host."""

    def __init__(self, *values: float):
        self.values = np.array(values + (0.0,) * (2 - len(values)), dtype=np.float64)
        # (at least two values; twist_combine returns three)

    def get(self) -> np.ndarray:
        return self.values


@dataclass
class ProxState:
    """Dual state of an iterative TV prox (Chambolle or FGP), kept across calls when warm."""

    warm: bool = False
    arrays: dict = field(default_factory=dict)
    valid: bool = False  # the stored dual may be used (warm start)


class Backend(ABC):
    """Operations the solvers need. Subclasses set ``name``, ``dtype``, ``shape``, ``nc``,
    ``device`` and ``ffts`` (count of real FFT pairs done)."""

    name: str
    device: str
    dtype: np.dtype
    shape: tuple[int, int]
    nc: int
    ffts: int = 0  # real FFT pairs done so far (one rfft2 + one irfft2 = 1)

    # ---- arrays ----------------------------------------------------------------------
    @abstractmethod
    def empty(self): ...

    @abstractmethod
    def from_host(self, a: np.ndarray): ...

    @abstractmethod
    def to_host(self, a) -> np.ndarray:
        """A float64 (C, H, W) host copy (synchronises)."""

    @abstractmethod
    def copy(self, dst, src) -> None: ...

    def zeros(self):
        return self.from_host(np.zeros((self.nc,) + tuple(self.shape)))

    @abstractmethod
    def finish(self) -> None:
        """Wait for queued work."""

    # ---- the measurement and the data term ------------------------------------------
    @abstractmethod
    def set_measurement(self, y: np.ndarray) -> None:
        """Store ``y`` (C, H, W) and precompute ``K^T y`` (:attr:`b`) and ``||y||^2``."""

    @property
    @abstractmethod
    def b(self):
        """``K^T y`` (back-propagation, Eqs. 11-12; TwIST's initialisation 2).

        The same ``K^T y`` as :func:`clfza.model.back_propagate` (the float64 specification;
        the numpy backends compute it with that operator's adjoint), made once per
        measurement in :meth:`set_measurement`. The OpenCL backend evaluates it as the data
        term's gradient at ``x = 0`` (:meth:`resid_grad`, with the operator's ``H_T``) from the
        spectrum of ``y`` it keeps for every later gradient, so it needs no FFT of its own;
        the agreement tests hold it to the numpy value.
        """

    @abstractmethod
    def resid_grad(self, x, g) -> Scalars:
        """``g = K^T (y - K x)`` and ``(||y - K x||^2, 0)``: the data term of Eq. 19 and its
        negative gradient, with one real FFT pair (the residual norm by Parseval)."""

    # ---- regularisers ----------------------------------------------------------------
    @abstractmethod
    def reg_value(self, x) -> Scalars:
        """``(Phi(x), ||x||_1)``: circular TV (Eq. 20) and l1."""

    @abstractmethod
    def prox_step(self, reg: str, x, g, s: float, th: float, out, iters: int,
                  state: ProxState, tol: float = 0.0, check_every: int = 2) -> int:
        """TwIST's Psi at ``v = x + s g``: ``out = Psi(v, th)``; returns the number of inner
        iterations done.

        ``reg="tv"``: Chambolle's algorithm with ``lam = 2 / th`` (the paper's
        ``tvdenoise(v, 2/th, iters)``), dual reset unless ``state.warm``; ``reg="l1"``: soft
        thresholding at ``th``. With ``tol > 0`` (adaptive inner iterations, issue 6), ``iters``
        is a maximum: after every ``check_every``-th inner step that started from a non-zero
        dual (and is not the last) the relative change ``||p_new - p|| / ||p_new||`` is read
        back (one small reduction and one synchronisation) and the loop stops when it is
        ``<= tol``. ``tol = 0`` runs exactly ``iters`` steps (the reference).
        """

    @abstractmethod
    def twist_combine(self, out, xm2, xm1, xist, alpha: float, beta: float, sparse: bool,
                      want_tv: bool = True) -> Scalars:
        """``out = m ((1 - alpha) xm2 + (alpha - beta) xm1) + beta xist`` with ``m = (xist != 0)``
        when ``sparse`` (else 1); returns ``(Phi(out) if want_tv else ||out||_1, #zeros of
        xist, Phi(xist) if want_tv else ||xist||_1)``. The caller applies :meth:`mask_past`
        when the count is non-zero; the third value serves a monotone fallback to the IST
        estimate without another regulariser pass."""

    @abstractmethod
    def project_nonneg(self, out, v) -> None:
        """``out = max(v, 0)``."""

    @abstractmethod
    def mask_past(self, xm1, xm2, xist) -> None:
        """Zero ``xm1`` and ``xm2`` in place where ``xist == 0`` (TwIST's ``sparse``)."""

    @abstractmethod
    def fgp_prox(self, reg: str, out, b, weight: float, iters: int, state: ProxState,
                 nonneg: bool) -> Scalars:
        """``out = argmin 1/2 ||u - b||^2 + weight R(u) [+ u >= 0]``: FGP with periodic
        differences for TV (warm-started from ``state``), soft thresholding for l1. Returns
        ``(Phi(out), ||out||_1)``."""

    # ---- small fused element-wise operations ----------------------------------------
    @abstractmethod
    def lincomb(self, out, a: float, X, b: float = 0.0, Y=None, c: float = 0.0, Z=None
                ) -> None:
        """``out = a X + b Y + c Z``."""

    @abstractmethod
    def fista_extrap(self, out, a1: float, X1, G1, a2: float, X2, G2) -> None:
        """``out = a1 (X1 + G1) + a2 (X2 + G2)``."""

    @abstractmethod
    def diffnorm(self, a, b) -> Scalars:
        """``(||a - b||^2, ||a||^2)`` (relative step change)."""

    # ---- ADMM ------------------------------------------------------------------------
    @abstractmethod
    def admm_setup(self, rho: float, mu: float) -> None:
        """Precompute ``1 / (H_T^2 + rho |D|^2 + mu)`` on the half spectrum."""

    @abstractmethod
    def admm_rhs(self, out, q1, q2, v, s, rho: float, mu: float) -> None:
        """``out = K^T y + rho D^T q + mu (v - s)``."""

    @abstractmethod
    def admm_solve(self, rhs, x, want: bool) -> Scalars:
        """``x = F^-1 [F(rhs) / (H_T^2 + rho |D|^2 + mu)]``; with ``want`` also
        ``(||y - K x||^2, 0)``."""

    @abstractmethod
    def admm_update(self, x, u1, u2, q1, q2, v, s, thr: float, nonneg: bool) -> Scalars:
        """``t = D x + u; z = shrink(t, thr); u = t - z; q = z - u``; with ``nonneg``
        ``v = max(x + s, 0), s += x - v``. Returns ``(Phi(x), ||D x - z||^2)``."""
