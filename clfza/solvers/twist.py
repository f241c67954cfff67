"""TwIST (Bioucas-Dias & Figueiredo 2007) for Eq. 19, as the paper runs it (DESIGN s.2).

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

Efficient mode (labelled as such in the info record): the same iteration with the Chambolle
dual warm-started across calls, which makes the 2 inner iterations converge across outer
iterations instead of restarting from zero (a better prox for the same work).
"""

from __future__ import annotations

import math

from ..backends.base import Backend, ProxState
from .common import Monitor, SolveResult, SolverOptions, Stopper, relative_change

MAX_SVD_DOUBLINGS = 60  # the reference loops for ever; 2^60 makes the step ~1e-18


def twist_parameters(lambda1: float = 1e-4, lambdaN: float = 1.0) -> tuple[float, float]:
    """``(alpha, beta)`` of TwIST for the spectrum bounds ``lambda1, lambdaN`` of ``K^T K``.

    With ``lambda1 = 1e-4``: alpha = 1.9607881580, beta = 3.9211841976 (DESIGN s.2).
    """
    rho0 = (1 - lambda1 / lambdaN) / (1 + lambda1 / lambdaN)
    alpha = 2.0 / (1 + math.sqrt(1 - rho0**2))
    beta = alpha * 2.0 / (lambda1 + lambdaN)
    return alpha, beta


def twist(B: Backend, opts: SolverOptions, mon: Monitor, x0) -> SolveResult:
    """Run TwIST on backend ``B`` (measurement already set) from ``x0`` (backend array)."""
    alpha, beta = twist_parameters(opts.lambda1)
    tau, reg = opts.tau, opts.reg
    paper = opts.mode == "paper"
    stopper = Stopper(opts.stop, opts.tol, opts.min_iters, opts.iters, reference_count=paper)

    def objective(data, regv) -> float:
        d, r = data.get(), regv.get()
        return 0.5 * d[0] + tau * (r[0] if reg == "tv" else r[1])

    xm1 = B.empty()
    B.copy(xm1, x0)
    g, gn = B.empty(), B.empty()
    xist, xnew = B.empty(), B.empty()
    mon.start()
    prev_f = objective(B.resid_grad(xm1, g), B.reg_value(xm1))
    xm2 = B.empty()
    B.copy(xm2, xm1)
    state = ProxState(warm=not paper)
    max_svd = 1.0
    twist_iters = 0
    hist = [prev_f]
    evals = 1
    fallbacks = doublings = 0
    notes: list[str] = []
    mon.maybe(0, xm1, prev_f)
    it = 1
    reason = None
    while True:
        tries = 0
        while True:  # the reference's inner "for_ever" loop
            B.prox_step(reg, xm1, g, 1.0 / max_svd, tau / max_svd, xist, opts.tv_iters, state)
            if twist_iters != 0:
                rv = B.twist_combine(xnew, xm2, xm1, xist, alpha, beta, opts.sparse,
                                     reg == "tv")
                data = B.resid_grad(xnew, gn)
                rvals = rv.get()
                f = 0.5 * data.get()[0] + tau * rvals[0]
                if rvals[1] > 0:  # the reference zeroes the past where x_ist == 0, for good
                    B.mask_past(xm1, xm2, xist)
                evals += 1
                if f > prev_f and opts.monotone:
                    twist_iters = 0  # fall back to an IST step
                    fallbacks += 1
                else:
                    twist_iters += 1
                    if twist_iters % 10000 == 0:
                        max_svd *= 0.9
                    x = xnew
                    break
            else:
                rv = B.reg_value(xist)
                f = objective(B.resid_grad(xist, gn), rv)
                evals += 1
                if f > prev_f:
                    max_svd *= 2.0  # max eig(K^T K) > max_svd: increase the guess
                    twist_iters = 0
                    doublings += 1
                    tries += 1
                    if tries > MAX_SVD_DOUBLINGS:
                        x = xist
                        reason = "stalled"
                        notes.append("the objective rose for every step size (rounding "
                                     "level); stopped")
                        break
                else:
                    twist_iters += 1
                    x = xist
                    break
        step = None
        if stopper.needs_step:
            d = B.diffnorm(x, xm1).get()
            step = math.sqrt(d[0] / d[1]) if d[1] > 0 else 0.0
        free = xm2
        xm2, xm1 = xm1, x
        if x is xnew:
            xnew = free
        else:
            xist = free
        g, gn = gn, g
        hist.append(f)
        mon.maybe(it, xm1, f, max_svd=max_svd)
        if reason is None:
            reason = stopper.check(it, f, prev_f, step)
        prev_f = f
        if reason is not None:
            break
        it += 1
    solve_s = mon.elapsed()
    mon.final(it, xm1, prev_f)
    return SolveResult(x=xm1, iterations=it, stop_reason=reason, objective=hist,
                       solve_s=solve_s, evaluations=evals, notes=notes,
                       stats={"fallbacks": fallbacks, "max_svd_doublings": doublings,
                              "max_svd": max_svd, "alpha": alpha, "beta": beta,
                              "final_relative_change": relative_change(hist[-1], hist[-2])
                              if len(hist) > 1 else None})
