"""Monotone FISTA (MFISTA, Beck & Teboulle 2009) for Eq. 19 with a fast-gradient-projection TV
prox.

Problem: ``min 1/2 ||y - K x||^2 + w R(x) [+ x >= 0]`` with ``R = Phi`` (circular TV, the
paper's objective regulariser) or l1; ``L = 1`` because ``|H_T| <= 1``. Default weight
``w = tau / 2``: the paper's Psi is ``tvdenoise(x, 2/th, .)``, i.e. ROF with weight ``th/2``,
so paper-mode TwIST's fixed points solve Eq. 19 with ``tau/2``; FISTA and ADMM target the
same image (and report the objective with their own ``w``).

Iteration (one FFT pair: ``K^T(y - K .)`` is affine, so the gradient at the extrapolated point
is the same combination of the gradients at ``x_{k-1}`` and ``z_k``)::

    z_k = prox_w(y_k + K^T (y - K y_k))         FGP, dual warm-started across iterations
    x_k = z_k if F(z_k) <= F(x_{k-1}) else x_{k-1}
    t_{k+1} = (1 + sqrt(1 + 4 t_k^2)) / 2
    y_{k+1} = x_k + t_k/t_{k+1} (z_k - x_k) + (t_k - 1)/t_{k+1} (x_k - x_{k-1})
"""

from __future__ import annotations

import math

from ..backends.base import Backend, ProxState
from .common import Monitor, SolveResult, SolverOptions, Stopper


def fista(B: Backend, opts: SolverOptions, mon: Monitor, x0) -> SolveResult:
    w, reg = opts.weight, opts.reg
    stopper = Stopper(opts.stop, opts.tol, opts.min_iters, opts.iters)

    last = {}

    def objective(data, regv) -> float:
        d, r = data.get(), regv.get()
        last["data"] = 0.5 * d[0]
        return 0.5 * d[0] + w * (r[0] if reg == "tv" else r[1])

    x, gx = B.empty(), B.empty()
    z, gz = B.empty(), B.empty()
    bb = B.empty()
    B.copy(x, x0)
    mon.start()
    fx = objective(B.resid_grad(x, gx), B.reg_value(x))
    dx = last["data"]
    B.fista_extrap(bb, 1.0, x, gx, 0.0, x, gx)
    state = ProxState(warm=True)
    t = 1.0
    hist = [fx]
    evals = 1
    rejected = 0
    mon.maybe(0, x, fx, data=dx)
    it = 0
    reason = None
    while reason is None:
        it += 1
        rv = B.fgp_prox(reg, z, bb, w, opts.tv_iters, state, opts.nonneg)
        fz = objective(B.resid_grad(z, gz), rv)
        evals += 1
        t_new = 0.5 * (1 + math.sqrt(1 + 4 * t * t))
        step = None
        f_prev = fx
        accept = fz <= fx or not opts.monotone
        if stopper.needs_step:
            d = B.diffnorm(z, x).get() if accept else (0.0, 1.0)
            step = math.sqrt(d[0] / d[1]) if d[1] > 0 else 0.0
        if accept:
            c = (t - 1) / t_new
            B.fista_extrap(bb, 1 + c, z, gz, -c, x, gx)
            x, z = z, x
            gx, gz = gz, gx
            fx = fz
            dx = last["data"]
        else:
            a = t / t_new
            B.fista_extrap(bb, a, z, gz, 1 - a, x, gx)
            rejected += 1
        t = t_new
        hist.append(fx)
        stop = mon.maybe(it, x, fx, data=dx)
        # a rejected step leaves F unchanged: that is no sign of convergence
        reason = "callback" if stop else stopper.check(it, fx, f_prev if accept else None,
                                                       step)
    solve_s = mon.elapsed()
    mon.final(it, x, fx, data=dx)
    return SolveResult(x=x, iterations=it, stop_reason=reason, objective=hist, solve_s=solve_s,
                       evaluations=evals, stats={"rejected": rejected, "weight": w})
