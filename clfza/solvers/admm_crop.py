"""ADMM with the crop split (DiffuserCam: Antipa et al., Optica 5, 1, 2018) for the exact model.

Problem: ``min 1/2 ||y - P C H x||^2 + w Phi(x) [+ x >= 0] [+ x = 0 off the object region]``
with ``H`` the periodic convolution on the model grid, ``C`` the sensor crop and ``P`` the mean
removal (:mod:`clfza.exact`). ``K^T K`` is not diagonal in any basis, so ADMM splits it where
each piece is::

    v = H x      v-update: (C^T P C + mu1) v = C^T y + mu1 (H x + a)   pixel-wise; P's rank-1
                 part by Sherman-Morrison (one sum over the sensor)
    z = D x      shrink(D x + u, w / rho)                               pixel-wise
    w = x        proj(x + s): max(., 0) and/or zero off the object region   pixel-wise
    x-update     (mu1 |H|^2 + rho |D|^2 + mu3) x = H^T mu1 (v - a) + rho D^T (z - u) + mu3 (w - s)
                 diagonal in Fourier space

One iteration costs two real FFT pairs on the model grid (``F(rhs)``, ``F(v - a)`` and the two
inverses for ``x`` and ``H x``) plus pixel-wise kernels.

Penalties. The kernel of a real FZA has a gain of ``||K||`` (hundreds: the aperture's open
disc) at the lowest frequencies and of about one at the zone frequencies that carry the image,
so no single ``mu1`` suits both; ``mu1`` starts at ``MU1_FACTOR rho / median |H~|^2`` (balanced
for the zone frequencies) and is adapted by residual balancing (Boyd et al. 2011, s. 3.4.1)
every ``ADAPT_EVERY`` iterations: doubled when the primal residual ``||H x - v||`` exceeds
``ADAPT_RATIO`` times the dual residual ``mu1 ||H^T (v - v_prev)||``, halved in the opposite
case (the scaled dual ``a`` rescaled with it). ``rho = RHO_PER_WEIGHT w`` and
``mu3 = rho`` as in :mod:`clfza.solvers.admm`.

Order per iteration: x-update; then v (with its dual ``a``), z (with ``u``) and w (with ``s``),
each from the new ``x``. The data term ``||y - P C H x||^2`` of the new iterate comes out of the
v-update (``H x`` is already there), so the objective costs no FFT.
"""

from __future__ import annotations

from ..backends.base import Backend
from .admm import RHO_PER_WEIGHT
from .common import Monitor, SolveResult, SolverOptions, Stopper

MU1_FACTOR = 0.01
ADAPT_EVERY = 10
ADAPT_RATIO = 10.0


def admm_crop(B: Backend, opts: SolverOptions, mon: Monitor, x0) -> SolveResult:
    """Run the crop-split ADMM on an exact-model backend (measurement already set)."""
    w = opts.weight
    rho = opts.rho if opts.rho is not None else RHO_PER_WEIGHT * w
    support = opts.extra.get("support", True)
    split_w = opts.nonneg or support
    mu3 = (opts.mu if opts.mu is not None else rho) if split_w else 0.0
    mu1 = opts.extra.get("mu1") or MU1_FACTOR * B.crop_admm_mu1(rho)
    adapt = opts.extra.get("adapt", True)
    stopper = Stopper(opts.stop, opts.tol, opts.min_iters, opts.iters)
    x, hx, v, a, e = (B.empty() for _ in range(5))
    B.copy(x, x0)
    u1, u2, q1, q2, ww, s = (B.zeros() for _ in range(6))
    v_old = B.empty() if adapt else None
    B.crop_admm_setup(mu1, rho, mu3)
    mon.start()
    B.crop_admm_init(x, hx, v, a, e)
    B.admm_update(x, u1, u2, q1, q2, ww, s, 0.0, False)  # z = D x0, u = 0
    if split_w:
        B.crop_w_update(x, ww, s, opts.nonneg, support)
    hist: list[float] = []
    it, reason, f_prev, d_prev, adaptations = 0, None, None, None, 0
    while reason is None:
        it += 1
        check = adapt and it % ADAPT_EVERY == 0
        if check:
            B.copy(v_old, v)
        B.crop_admm_x(x, hx, e, q1, q2, ww, s, rho, mu3, mu1)
        data = B.crop_admm_v(hx, v, a, e, mu1)
        rv = B.admm_update(x, u1, u2, q1, q2, ww, s, w / rho, False)
        if split_w:
            B.crop_w_update(x, ww, s, opts.nonneg, support)
        dh = 0.5 * data.get()[0]
        f = dh + w * rv.get()[0]
        hist.append(f)
        if check:
            mu1, changed = _balance(B, hx, v, v_old, a, mu1, rho, mu3)
            adaptations += changed
        stop = mon.maybe(it, x, f, data=dh, mu1=mu1)
        reason = "callback" if stop else stopper.check(it, f, f_prev, None)
        f_prev, d_prev = f, dh
    if opts.nonneg:
        B.project_nonneg(x, x)
    solve_s = mon.elapsed()
    mon.final(it, x, f_prev, data=d_prev)
    return SolveResult(x=x, iterations=it, stop_reason=reason, objective=hist, solve_s=solve_s,
                       evaluations=it, stats={"rho": rho, "mu3": mu3, "mu1_final": mu1,
                                              "mu1_adaptations": adaptations, "weight": w,
                                              "support": support})


def _balance(B: Backend, hx, v, v_old, a, mu1: float, rho: float, mu3: float
             ) -> tuple[float, int]:
    """Residual balancing of ``mu1`` (one extra FFT pair); returns the new ``mu1`` and 1 when
    it changed."""
    primal, dual = B.crop_admm_residuals(hx, v, v_old, mu1)
    if primal > ADAPT_RATIO * dual:
        factor = 2.0
    elif dual > ADAPT_RATIO * primal:
        factor = 0.5
    else:
        return mu1, 0
    B.lincomb(a, 1.0 / factor, a)  # the scaled dual a = lambda / mu1
    mu1 *= factor
    B.crop_admm_setup(mu1, rho, mu3)
    return mu1, 1
