"""ADMM for TV-regularised Eq. 19 with an exact Fourier-diagonal x-update.

Problem: ``min 1/2 ||y - K x||^2 + w Phi(x) [+ x >= 0]`` with ``Phi`` the circular TV. Splits
``z = D x`` (D: circular differences) and, with non-negativity, ``v = x``. Scaled ADMM::

    x = F^-1 [ F(K^T y + rho D^T (z - u) + mu (v - s)) / (H_T^2 + rho |D|^2 + mu) ]
    z = shrink(D x + u, w / rho)          isotropic (vectorial across channels)
    u = u + D x - z
    v = max(x + s, 0);  s = s + x - v     (non-negativity only)

With non-negativity the returned image (and every checkpoint's image) is ``max(x, 0)``, the
projection of the x-iterate onto the constraint set: ADMM's x only satisfies ``x = v`` in the
limit, and its negative excursions are what the split variable removes. The reported objective
and ``data`` are those of ``x`` itself (the Fourier-space update gives ``||y - K x||^2`` for
free); at convergence the two coincide.

Both ``K^T K`` and ``D^T D`` are diagonal in Fourier space, so the x-update is exact and one
iteration costs one real FFT pair plus two fused kernels (``admm_rhs``, ``admm_update``); the
data term of the new ``x`` comes out of the Fourier-space division by Parseval, so the
objective is nearly free.

Default penalties (derived from the regularisation weight ``w``, itself ``tau/2`` by default,
see :mod:`clfza.solvers.fista`): ``rho = RHO_PER_WEIGHT * w`` and ``mu = MU_PER_WEIGHT * w``
(nonneg only). The shrink threshold ``w/rho = 1/RHO_PER_WEIGHT`` is then fixed in units of the
image gradient, and ``rho`` stays small next to ``H_T^2 <= 1`` so the data term dominates the
x-update where the camera passes frequencies. Chosen on the paper's Fig. 7 simulation (512^2,
z1 = 200 mm) for the fastest rise of PSNR; see ``bench/bench_solvers.py``.
"""

from __future__ import annotations

import math

from ..backends.base import Backend
from .common import Monitor, SolveResult, SolverOptions, Stopper

RHO_PER_WEIGHT = 10.0
MU_PER_WEIGHT = 10.0


def admm(B: Backend, opts: SolverOptions, mon: Monitor, x0) -> SolveResult:
    w = opts.weight
    rho = opts.rho if opts.rho is not None else RHO_PER_WEIGHT * w
    mu = (opts.mu if opts.mu is not None else MU_PER_WEIGHT * w) if opts.nonneg else 0.0
    stopper = Stopper(opts.stop, opts.tol, opts.min_iters, opts.iters)
    B.admm_setup(rho, mu)
    x = B.empty()
    B.copy(x, x0)
    u1, u2, q1, q2, v, s = (B.zeros() for _ in range(6))
    rhs = B.empty()
    xp = B.empty() if opts.nonneg else None

    def xout():
        """The iterate a checkpoint sees: max(x, 0) with non-negativity (cheap: only at
        checkpoints, never in the loop otherwise)."""
        if xp is None or not mon.due(it):
            return x
        B.project_nonneg(xp, x)
        return xp

    mon.start()
    # z = D x0, u = 0, v = max(x0, 0), s = x0 - v  (a shrink with threshold 0)
    B.admm_update(x, u1, u2, q1, q2, v, s, 0.0, opts.nonneg)
    xprev = B.empty() if stopper.needs_step else None
    hist: list[float] = []
    it = 0
    reason = None
    f_prev = None
    d_prev = None
    need_obj = opts.stop == "objective" or mon.truth is not None or mon.callback is not None
    while reason is None:
        it += 1
        if xprev is not None:
            B.copy(xprev, x)
        B.admm_rhs(rhs, q1, q2, v, s, rho, mu)
        data = B.admm_solve(rhs, x, need_obj)
        rv = B.admm_update(x, u1, u2, q1, q2, v, s, w / rho, opts.nonneg)
        f = dh = None
        if need_obj:
            dh = 0.5 * data.get()[0]
            f = dh + w * rv.get()[0]
            hist.append(f)
        step = None
        if xprev is not None:
            d = B.diffnorm(x, xprev).get()
            step = math.sqrt(d[0] / d[1]) if d[1] > 0 else 0.0
        stop = mon.maybe(it, xout(), f, data=dh)
        reason = "callback" if stop else stopper.check(it, f, f_prev, step)
        f_prev, d_prev = f, dh
    if opts.nonneg:
        B.project_nonneg(x, x)  # the returned image: the projection of x onto x >= 0
    solve_s = mon.elapsed()
    mon.final(it, x, f_prev, data=d_prev)
    return SolveResult(x=x, iterations=it, stop_reason=reason, objective=hist, solve_s=solve_s,
                       evaluations=it, stats={"rho": rho, "mu": mu, "weight": w})
