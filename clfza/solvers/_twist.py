"""TwIST (Bioucas-Dias & Figueiredo 2007) for Eq. 19, as the paper runs it (docs/design.md s.2).

Paper mode reproduces the authors' call ``TwIST(y, A, tau, 'AT', AT, 'Psi', @(x,th)
tvdenoise(x, 2/th, tv_iters), 'Phi', @TVnorm, 'Initialization', 2, 'Monotone', 1,
'StopCriterion', 1, 'MaxIterA', K, 'MinIterA', K, 'ToleranceA', 1e-6)``:

* ``lambda1 = 1e-4, lambdaN = 1``: ``rho0 = (1 - l1/lN)/(1 + l1/lN)``,
  ``alpha = 2/(1 + sqrt(1 - rho0^2))``, ``beta = 2 alpha/(l1 + lN)``;
* ``x0 = K^T y``, ``max_svd = 1``; every outer iteration computes ``g = K^T (y - K x_t)`` and
  the IST estimate ``x_ist = Psi(x_t + g/max_svd, tau/max_svd)``;
* the first step is a plain IST step, accepted if the objective
  ``1/2 ||y - K x||^2 + tau Phi(x)`` did not rise, otherwise ``max_svd`` doubles and it is
  retried; later steps form ``x = (1 - alpha) x_{t-1} + (alpha - beta) x_t + beta x_ist`` and
  fall back to an IST step when the objective rose (monotone variant); where ``x_ist == 0``
  the past iterates are zeroed first (the reference's ``sparse`` default);
* stop when ``|f - f_prev|/f_prev <= tolA``, never before ``min_iters`` and never after
  ``max_iters`` (min = max = K runs K + 1 iterations);
* ``Psi = tvdenoise(x, 2/th, tv_iters)`` (Chambolle, dual reset on every call, zero-flux
  boundaries) and ``Phi`` = TV with circular differences; the l1 variant uses soft
  thresholding and ``||x||_1``.

Cost: one real FFT pair per objective evaluation. The reference applies ``A`` and ``A^T``
separately (two pairs); here the residual's spectrum ``Y - H X`` gives both the residual norm
(Parseval) and the next gradient ``F^-1 H (Y - H X)`` from one ``rfft2``/``irfft2``. That is
the same arithmetic in a different order, not an approximation.

Paper mode spends, per iteration: the prox (on CPU devices one explicitly vectorised pass for
the paper's 2 Chambolle steps, kernels/tv_fused.cl; elsewhere three kernels), one fused
kernel for the two-step combination and both regulariser values (of the combination and of the
IST estimate), one FFT pair with one spectral kernel between, and one read of a few thousand
partial sums (the monotone test needs the objective). A monotone fallback reuses the IST
estimate already computed (the reference recomputes ``Psi(x_{t-1} + g/max_svd)`` with the same
inputs, so the result is the same unless the sparse mask changed ``x_{t-1}``, in which case it
is recomputed) and its regulariser value from the combination kernel, so a fallback costs one
FFT pair.

The fallback's data term is evaluated directly, not taken by linearity from kept spectra
(``x_ist = (x_new - c2 x_{t-1} - c1 x_t) / cb``): the monotone test needs every evaluation of
a point to give the same value, and in float32 the combined residual norm does not (measured
and dropped: docs/measurements.md, clfza.solvers._twist).

Efficient mode (labelled as such in the info record) differs on purpose. On CPU devices it
costs more per iteration than paper mode: it falls back to IST steps more often, and its
warm-started dual runs the three tv.cl kernels (a one-pass warm-start variant of tv_fused.cl
gained nothing; measured: docs/measurements.md, clfza.solvers._twist).

* the Chambolle dual is warm-started across calls (2 inner steps then continue converging
  across outer iterations instead of restarting from zero), optionally with adaptive inner
  iterations (``tv_tol``: stop the inner loop when the dual's relative change is below it,
  ``tv_iters`` is then a maximum);
* ``monotone`` stays on (the reference's safeguard): the warm, stateful prox and the
  two-step recursion with alpha = 1.96 are not a contraction together (turning it off was
  measured, not made the default: docs/measurements.md, clfza.solvers._twist);
* stopping: the relative objective change is averaged over the last
  ``EFFICIENT_STOP_WINDOW`` iterations (a single small step, typically a monotone fallback to
  an IST step, is no sign of convergence), and the rule never fires in the first half of the
  iteration budget (``min_iters = iters // 2`` by default).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..backends import ProxState, read_all
from ..errors import ClfzaError
from ._common import Stopper, relative_change
from ._driver import Solver, Step, register
from ._options import MethodOptions, boolean, choice, integer, nonneg_number, open_unit, option
from ._twist_ops import TwistOps

EFFICIENT_STOP_WINDOW = 10  # efficient mode: mean relative objective change over 10 iterations
# Past this the IST step g/max_svd is below the rounding of the iterate. The reference keeps
# doubling until its IST estimate equals x_t and then accepts that no-op step; here a rejected
# IST step at this bound is that no-op step at once. Without the bound, rounding-level "rises"
# (pixels at exactly 0 move by 1e-30 in float32) doubled max_svd about once per iteration on
# the Fig. 7 noisy setup until lam = 2 max_svd / tau overflowed float32 (~2^120): NaN.
MAX_SVD_LIMIT = 2.0**50
PAPER_TV_ITERS = 2  # the paper's tvdenoise(x, 2/th, 2)
# Efficient mode: adaptive inner TV iterations, at most EFFICIENT_TV_ITERS, stopping when the
# warm dual's relative change is <= DEFAULT_TV_TOL (checked after every 2nd step); chosen by
# measurement (docs/measurements.md, clfza.solvers._twist).
DEFAULT_TV_TOL = 0.02
EFFICIENT_TV_ITERS = 4


@dataclass(kw_only=True)
class TwistOptions(MethodOptions):
    """TwIST's options (:class:`~clfza.solvers._options.MethodOptions` and these)."""

    mode: str = option("paper", choice("paper", "efficient"),
                       "paper: the authors' run; efficient: warm-started TV dual")
    monotone: bool = option(True, boolean, "fall back to an IST step when the objective rose")
    sparse: bool = option(True, boolean, "zero the past iterates where x_ist == 0")
    lambda1: float = option(1e-4, open_unit, "lower spectrum bound of K^T K (alpha, beta)")
    tv_tol: float | None = option(None, nonneg_number,
                                  "efficient mode: adaptive inner TV stop (tv_iters a maximum)")
    tv_iters: int | None = option(None, integer(1), "inner Chambolle iterations "
                                  f"(paper {PAPER_TV_ITERS}, efficient <= {EFFICIENT_TV_ITERS})")

    def resolve(self, exact: bool) -> None:

        paper = self.mode == "paper"
        if self.nonneg:
            raise ClfzaError("TwIST has no non-negativity option (the paper's algorithm); use "
                             "fista or admm with nonneg=True")
        if self.tv_tol and paper:
            raise ClfzaError("tv_tol (adaptive inner TV iterations) needs mode='efficient': "
                             "paper mode restarts the TV dual from zero on every call, as the "
                             "reference")
        if self.min_iters is None:  # efficient mode: never in the first half
            self.min_iters = self.iters if paper else max(1, self.iters // 2)
        if self.tv_iters is None:
            self.tv_iters = PAPER_TV_ITERS if paper else EFFICIENT_TV_ITERS
        if self.tv_tol is None:
            self.tv_tol = 0.0 if paper else DEFAULT_TV_TOL
        super().resolve(exact)


def twist_parameters(lambda1: float = 1e-4, lambdaN: float = 1.0) -> tuple[float, float]:
    """``(alpha, beta)`` of TwIST for the spectrum bounds ``lambda1, lambdaN`` of ``K^T K``:
    ``rho0 = (1 - l1/lN)/(1 + l1/lN)``, ``alpha = 2/(1 + sqrt(1 - rho0^2))``,
    ``beta = 2 alpha/(l1 + lN)``.

    Examples
    --------
    >>> alpha, beta = twist_parameters(1e-4)
    >>> round(alpha, 10), round(beta, 10)
    (1.960788158, 3.9211841976)
    """
    rho0 = (1 - lambda1 / lambdaN) / (1 + lambda1 / lambdaN)
    alpha = 2.0 / (1 + math.sqrt(1 - rho0**2))
    beta = alpha * 2.0 / (lambda1 + lambdaN)
    return alpha, beta


@register
class TwistSolver(Solver):
    """TwIST: IST estimates, two-step combinations, the monotone fallback (module docstring).

    State: ``xm1`` = x_t, ``xm2`` = x_{t-1}, ``g`` = K^T (y - K x_t), ``xist`` the IST
    estimate, ``xnew`` the two-step combination (:class:`~clfza.solvers._twist_ops.TwistOps`),
    ``gn`` the gradient of the candidate;
    ``prev_f``/``prev_d`` the objective and residual norm of x_t. ``twist_iters`` is the
    reference's counter: 0 means the next candidate is an IST step.
    """

    method = "twist"
    order = 0
    Options = TwistOptions

    def stopper(self) -> Stopper:
        o = self.opts
        paper = o.mode == "paper"
        window = o.stop_window or (1 if paper else EFFICIENT_STOP_WINDOW)
        return Stopper(o.stop, o.tol, o.min_iters, o.iters, reference_count=paper,
                       window=window)

    def setup(self, x0) -> None:
        B, o = self.B, self.opts
        self.alpha, self.beta = twist_parameters(o.lambda1)
        self.ops = TwistOps.for_backend(B)
        self.xm1 = B.empty()
        B.copy(self.xm1, x0)
        self.g, self.gn = B.empty(), B.empty()
        self.xist, self.xnew = B.empty(), B.empty()
        self.state = ProxState(warm=o.mode != "paper")
        self.max_svd = 1.0
        self.twist_iters = 0
        self.evaluations = 1
        self.fallbacks = self.doublings = self.inner_total = self.noops = 0

    def _read(self, data, regv) -> tuple[float, np.ndarray]:
        """One synchronisation: the residual norm and the regulariser sums."""
        d, r = read_all(data, regv)
        return d[0], r

    def _reg_of(self, r) -> float:
        return r[0] if self.opts.reg == "tv" else r[1]

    def start(self) -> Step:
        B = self.B
        d, r = self._read(B.resid_grad(self.xm1, self.g), B.reg_value(self.xm1))
        self.prev_f = 0.5 * d + self.opts.tau * self._reg_of(r)
        self.prev_d = d
        self.xm2 = B.empty()
        B.copy(self.xm2, self.xm1)
        return Step(self.prev_f, self.xm1, extra={"data": 0.5 * d})

    def step(self, it: int) -> Step:
        """The reference's inner "for_ever" loop: candidates until one is accepted."""
        reuse = None  # regulariser value of an IST estimate still valid in `xist`
        while True:
            if reuse is None:
                self._prox()
            if self.twist_iters != 0:
                accepted, reuse = self._two_step()
                if accepted:
                    x = self.xnew
                    break
            else:
                x = self._ist_step(reuse)
                reuse = None
                if x is not None:
                    break
        return self._advance(x)

    def _prox(self) -> None:
        """``xist = Psi(x_t + g / max_svd, tau / max_svd)``."""
        o = self.opts
        self.inner_total += self.B.prox_step(o.reg, self.xm1, self.g, 1.0 / self.max_svd,
                                             o.tau / self.max_svd, self.xist, o.tv_iters,
                                             self.state, o.tv_tol or 0.0)

    def _two_step(self) -> tuple[bool, float | None]:
        """The two-step candidate ``xnew``; returns (accepted, reusable regulariser value of
        the IST estimate on a monotone fallback)."""
        B, o = self.B, self.opts
        rv = self.ops.combine(self.xnew, self.xm2, self.xm1, self.xist, self.alpha, self.beta,
                              o.sparse, o.reg == "tv")
        d, rvals = self._read(B.resid_grad(self.xnew, self.gn), rv)
        f = 0.5 * d + o.tau * rvals[0]
        masked = rvals[1] > 0
        if masked:  # the reference zeroes the past where x_ist == 0, for good
            self.ops.mask_past(self.xm1, self.xm2, self.xist)
        self.evaluations += 1
        if f > self.prev_f and o.monotone:
            self.twist_iters = 0  # fall back to an IST step
            self.fallbacks += 1
            # Psi(x_{t-1} + g/max_svd) again gives the same x_ist unless the mask changed
            # x_{t-1}: keep it and its regulariser value
            return False, (None if masked else rvals[2])
        self.twist_iters += 1
        if self.twist_iters % 10000 == 0:
            self.max_svd *= 0.9
        self.f, self.d = f, d
        return True, None

    def _ist_step(self, reuse: float | None):
        """The IST candidate ``xist``: accepted (returned), a no-op step at the
        ``MAX_SVD_LIMIT`` (returned), or rejected with ``max_svd`` doubled (None)."""
        B, o = self.B, self.opts
        if reuse is None:
            d, r = self._read(B.resid_grad(self.xist, self.gn), B.reg_value(self.xist))
            regv = self._reg_of(r)
        else:
            d = B.resid_grad(self.xist, self.gn).get()[0]
            regv = reuse
        f = 0.5 * d + o.tau * regv
        self.evaluations += 1
        if f > self.prev_f and self.max_svd * 2.0 > MAX_SVD_LIMIT:
            # the step is below rounding: take the no-op step x_{t+1} = x_t (with x_t's
            # gradient)
            B.copy(self.xist, self.xm1)
            B.copy(self.gn, self.g)
            self.f, self.d = self.prev_f, self.prev_d
            self.noops += 1
            self.twist_iters += 1
            return self.xist
        if f > self.prev_f:
            self.max_svd *= 2.0  # max eig(K^T K) > max_svd: increase the guess
            self.twist_iters = 0
            self.doublings += 1
            return None
        self.twist_iters += 1
        self.f, self.d = f, d
        return self.xist

    def _advance(self, x) -> Step:
        """Accept ``x`` as x_{t+1}: the step change, then rotate the buffers."""
        step = None
        if self.needs_step:
            dn = self.B.diffnorm(x, self.xm1).get()
            step = math.sqrt(dn[0] / dn[1]) if dn[1] > 0 else 0.0
        free = self.xm2
        self.xm2, self.xm1 = self.xm1, x
        if x is self.xnew:
            self.xnew = free
        else:
            self.xist = free
        self.g, self.gn = self.gn, self.g
        self.prev_f, self.prev_d = self.f, self.d
        return Step(self.f, self.xm1, step=step,
                    extra={"data": 0.5 * self.d, "max_svd": self.max_svd})

    def finish(self):
        if self.noops:
            self.notes.append(f"stalled at rounding level: max_svd reached 2^50 and "
                              f"{self.noops} IST steps were no-op steps (the reference doubles "
                              "max_svd for ever instead)")
        return self.xm1

    def stats(self, history: list[float]) -> dict:
        return {"fallbacks": self.fallbacks, "max_svd_doublings": self.doublings,
                "max_svd": self.max_svd, "alpha": self.alpha, "beta": self.beta,
                "inner_tv_iterations": self.inner_total, "noop_ist_steps": self.noops,
                "final_relative_change": relative_change(history[-1], history[-2])
                if len(history) > 1 else None}
