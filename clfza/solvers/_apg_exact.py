"""Accelerated proximal gradient with adaptive restart on the exact model (issue 33's candidate
"accelerated proximal gradient with adaptive restart", :mod:`bench.bench_exact_convergence`'s
``fista_restart`` made a solver).

Problem (the same as the crop-split ADMM's, :mod:`clfza.solvers._admm_crop`, on the normalised
operator ``K~ = P C H~`` of the exact backends, with the high-pass where the case has it)::

    min_x 1/2 ||y~ - K~ x||^2 + w TV(x) + i_C(x),   C = {x >= 0 [, x = 0 off the object region]}

Iteration (FISTA, Beck & Teboulle 2009, step ``1 / L`` with ``L = 1`` as ``||K~|| <= 1``;
function-value adaptive restart, O'Donoghue & Candes 2015: the momentum is reset whenever
``F`` rises)::

    y_k  = x_k + beta_k (x_k - x_{k-1}),   H y_k = H x_k + beta_k (H x_k - H x_{k-1})
    z    = prox_{w TV + i_C}(y_k + K~^T (y~ - K~ y_k))        FGP, dual warm-started
    F(z) from H z;  beta_{k+1} = 0 if F(z) > F(x_k) else (t_k - 1) / t_{k+1}
    x_{k+1} = z

``H x`` is kept with ``x``, so ``H y_k`` is a linear combination and the iteration costs two
real FFT pairs on the model grid (``K~^T r`` and ``H z``), as the ADMM's. The prox is the
backend's FGP (:meth:`clfza.backends.Backend.fgp_prox`, non-negativity inside) applied to a
point whose values off the object region are ``-(8 w + 1)``: there ``b - w D^T p`` stays
negative for any dual ``|p| <= 1``, so the projection inside the FGP is exactly ``P_C`` with
the support, and no new prox kernel is needed. The point is made by :class:`ApgExactOps`
(``apg_point`` of ``kernels/exact.cl`` on OpenCL, a float64 numpy reference).

Selected with ``algorithm="apg"`` on the exact model's ADMM options (``clfza.reconstruct(y,
cam, "admm", model="exact", algorithm="apg")``); whether it is the default is a measurement
(docs/measurements.md, clfza.solvers._apg_exact).
"""

from __future__ import annotations

import math
from abc import abstractmethod

import numpy as np

from ..backends import Backend, Ops, ProxState, Ready, Scalars, read_all
from ..errors import ClfzaError
from ._common import Stopper
from ._driver import Solver, Step

STOP_WINDOW = 20  # the objective rule's window (restarts make single steps non-monotone)
APG_TV_ITERS = 3  # inner FGP iterations per prox (dual warm-started across iterations)


def off_value(weight: float) -> float:
    """The point's value off the object region: ``b - w D^T p <= -(8 w + 1) + 4 w < 0`` for
    any FGP dual with ``|p| <= 1``, so the FGP's non-negative projection zeroes it."""
    return -(8.0 * weight + 1.0)


class ApgExactOps(Ops):
    """The APG's operations on one exact-model backend (:class:`~clfza.backends._base.Ops`)."""

    def __init__(self, B: Backend):
        if B.exact is None:
            raise ClfzaError("the exact model's APG runs on the exact model's backends "
                             "(model='exact')")
        super().__init__(B)

    @abstractmethod
    def forward(self, x, hx) -> Scalars:
        """``hx = H~ x`` (one FFT pair); returns ``||y~ - P C hx||^2``."""

    @abstractmethod
    def grad_point(self, b, x, hx, off: float, support: bool) -> None:
        """``b = x + K~^T (y~ - P C hx)`` (one FFT pair), set to ``off`` outside the object
        region when ``support``."""

    @abstractmethod
    def project(self, x, support: bool) -> None:
        """``x = max(x, 0)`` (and zero off the object region with ``support``), in place."""


@ApgExactOps.implements("numpy")
class NumpyApgExactOps(ApgExactOps):
    """float64 reference."""

    def forward(self, x, hx):
        B = self.B
        hx[...] = B.conv(x)
        B.ffts += B.nc
        return Ready(float(np.sum(B.residual(hx) ** 2)))

    def grad_point(self, b, x, hx, off, support):
        B = self.B
        g = B.conv(B.geom.embed(B.residual(hx)), conj=True)
        B.ffts += B.nc
        b[...] = x + g
        if support:
            b[...] = np.where(B.region > 0, b, off)

    def project(self, x, support):
        np.maximum(x, 0.0, out=x)
        if support:
            x *= self.B.region


@ApgExactOps.implements("opencl")
class OpenCLApgExactOps(ApgExactOps):
    """``crop_residual`` (the backend's), the adjoint's FFT pair, then ``apg_point`` of
    ``exact.cl`` (the step and the off-region value in one pass)."""

    KERNELS = (("exact", ("apg_point", "crop_residual", "crop_w_update")),)

    def forward(self, x, hx):
        B = self.B
        B.conv(x, hx, B.X)
        B.ffts += B.nc
        return Ready(B.residual_norm(B.row_sums(hx)))

    def grad_point(self, b, x, hx, off, support):
        B = self.B
        sums = B.row_sums(hx)
        B.per_c.set((sums[:, 0] / B.n_sensor).astype(B.dtype))
        B.launch_window("crop_residual", B.tmp_b.buf, hx.buf, B.Cy.buf, B.per_c.buf)
        B.conv(B.tmp_b, B.tmp_a, B.X, conj=True)
        B.ffts += B.nc
        B.launch_window("apg_point", b.buf, x.buf, B.tmp_a.buf, B.r(off), B.i32(support),
                        window=B.region_window)

    def project(self, x, support):
        B = self.B
        B.rt.cl.enqueue_fill_buffer(B.rt.queue, B.tmp_b.buf, B.r(0), 0, B.tmp_b.nbytes)
        B.copy(B.tmp_a, x)
        B.launch_window("crop_w_update", B.tmp_a.buf, x.buf, B.tmp_b.buf, B.i32(1),
                        B.i32(support), window=B.region_window)


class ApgExactSolver(Solver):
    """APG with function-value restart on the exact model: ``x`` and ``hx = H~ x``, the
    previous pair ``xo``/``hxo``, the extrapolated pair ``yv``/``hy``, the prox point ``z``
    (with ``hz``) and the FGP's dual (``ProxState``). Built by the exact model's ADMM entry
    (:class:`clfza.solvers._admm_crop.AdmmCropSolver`) for ``algorithm="apg"``."""

    method = "admm"
    models = ("exact",)

    def stopper(self) -> Stopper:
        """The objective rule over ``STOP_WINDOW`` iterations, on the spread (a restart makes
        one step's change meaningless)."""
        o = self.opts
        return Stopper(o.stop, o.tol, o.min_iters, o.iters, window=o.stop_window or STOP_WINDOW,
                       spread=True)

    def setup(self, x0) -> None:
        B, o = self.B, self.opts
        if not o.nonneg:
            raise ClfzaError("algorithm='apg' solves with x >= 0 (nonneg=True); use "
                             "algorithm='split' without it")
        self.ops = ApgExactOps.for_backend(B)
        self.w = o.weight
        self.off = off_value(self.w)
        self.tv_iters = o.tv_iters or APG_TV_ITERS
        self.x, self.hx, self.xo, self.hxo = (B.empty() for _ in range(4))
        self.yv, self.hy, self.b = B.empty(), B.empty(), B.empty()
        B.copy(self.x, x0)
        self.state = ProxState(warm=True)
        self.t, self.beta = 1.0, 0.0
        self.restarts = 0
        self.evaluations = 1

    def start(self) -> Step:
        B = self.B
        self.ops.project(self.x, self.opts.support)
        d, r = read_all(self.ops.forward(self.x, self.hx), B.reg_value(self.x))
        self.fx, self.dx = 0.5 * d[0] + self.w * r[0], 0.5 * d[0]
        B.copy(self.xo, self.x)
        B.copy(self.hxo, self.hx)
        return Step(self.fx, self.x, extra={"data": self.dx})

    def step(self, it: int) -> Step:
        B, o, beta = self.B, self.opts, self.beta
        if beta:
            B.lincomb(self.yv, 1.0 + beta, self.x, -beta, self.xo)
            B.lincomb(self.hy, 1.0 + beta, self.hx, -beta, self.hxo)
            y, hy = self.yv, self.hy
        else:
            y, hy = self.x, self.hx
        self.ops.grad_point(self.b, y, hy, self.off, o.support)
        z, hz = self.xo, self.hxo  # the oldest pair's memory takes the new point
        rv = B.fgp_prox("tv", z, self.b, self.w, self.tv_iters, self.state, True)
        d, r = read_all(self.ops.forward(z, hz), rv)
        fz, dz = 0.5 * d[0] + self.w * r[0], 0.5 * d[0]
        self.evaluations += 1
        if fz > self.fx:  # O'Donoghue & Candes: keep the point, reset the momentum
            self.t, self.beta = 1.0, 0.0
            self.restarts += 1
        else:
            t_new = 0.5 * (1.0 + math.sqrt(1.0 + 4.0 * self.t * self.t))
            self.beta, self.t = (self.t - 1.0) / t_new, t_new
        self.xo, self.hxo, self.x, self.hx = self.x, self.hx, z, hz
        self.fx, self.dx = fz, dz
        return Step(fz, self.x, extra={"data": dz})

    def finish(self):
        return self.x

    def stats(self, history: list[float]) -> dict:
        return {"algorithm": "apg", "restarts": self.restarts, "weight": self.w,
                "tv_iters": self.tv_iters, "support": self.opts.support}
