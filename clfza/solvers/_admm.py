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
iteration costs one real FFT pair plus two fused kernels (``admm_update``, then ``admm_rhs`` for
the next iteration; on CPU devices one, ``admm_update_rhs16``); the
data term of the new ``x`` comes out of the Fourier-space division by Parseval, so the
objective is nearly free.

Default penalties (derived from the regularisation weight ``w``, itself ``tau/2`` by default,
see :mod:`clfza.solvers._fista`): ``rho = RHO_PER_WEIGHT * w`` and ``mu = MU_PER_WEIGHT * w``
(nonneg only). The shrink threshold ``w/rho = 1/RHO_PER_WEIGHT`` is then fixed in units of the
image gradient, and ``rho`` stays small next to ``H_T^2 <= 1`` so the data term dominates the
x-update where the camera passes frequencies (chosen by measurement: docs/measurements.md,
clfza.solvers._admm).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from ..backends import read_all
from ..denoisers import VARIANTS
from ..errors import ClfzaError
from ._admm_ops import AdmmOps, FourierSolve
from ._common import Stopper
from ._driver import Solver, Step, register
from ._options import MethodOptions, boolean, choice, integer, option, positive, relaxation

RHO_PER_WEIGHT = 10.0
MU_PER_WEIGHT = 10.0
# over-relaxation of the crop split's v = H x: none (see clfza.solvers._admm_crop)
EXACT_RELAX = 1.0


@dataclass(kw_only=True)
class AdmmOptions(MethodOptions):
    """ADMM's options (:class:`~clfza.solvers._options.MethodOptions` and these); ``mu1`` and
    ``support`` belong to the exact model's crop split (:mod:`clfza.solvers._admm_crop`)."""

    tau: float = option(0.005, positive, "Eq. 19 weight, or 'auto': chosen from the frame "
                        "(clfza.solvers._tau), which it is unless tau or weight is given",
                        shown="'auto'")
    weight: float | None = option(None, positive, "TV weight w (default tau / 2)")
    rho: float | None = option(None, positive, f"penalty of z = D x ({RHO_PER_WEIGHT:g} w)")
    mu: float | None = option(None, positive, "penalty of the non-negativity split "
                              f"({MU_PER_WEIGHT:g} w; exact model: rho)")
    mu1: float | None = option(None, positive, "exact model: initial penalty of v = H x")
    adapt: bool = option(True, boolean, "exact model: residual balancing of mu1")
    relax: float | None = option(None, relaxation, "exact model: over-relaxation of v = H "
                                 f"x, in (0, 2) (default {EXACT_RELAX:g}: none)")
    average: bool | None = option(None, boolean, "exact model: return the running mean of "
                                  "the iterates, weights growing with the iteration number "
                                  "(default true)")
    support: bool | None = option(None, boolean, "exact model: zero off the object region "
                                  "(default true)")
    highpass: int | None = option(None, integer(0), "exact model: half-width k of the data "
                                  "term's box high-pass in pixels, 0 for none (default: "
                                  "from the mask's r1' with an aperture and support, "
                                  "clfza.models._highpass)")
    # issue 38: plug-and-play with a learned denoiser as the prior (clfza.solvers._pnp)
    reg: str = option("tv", choice("tv", "l1", "dncnn"), "regulariser: TV (Eq. 20), or dncnn: "
                      "plug-and-play ADMM with a pretrained DnCNN denoiser as the prior")
    denoiser: str | None = option(None, choice(*VARIANTS, "blind"), "reg='dncnn': the DnCNN "
                                  "variant (default: 6N, noise-conditional; 'blind': the "
                                  "blind one for sigma)")

    def resolve(self, exact: bool) -> None:
        if self.reg not in ("tv", "dncnn"):
            raise ClfzaError("ADMM is implemented for reg='tv' and 'dncnn'; use fista or twist "
                             "for l1")
        if self.denoiser is not None and self.reg != "dncnn":
            raise ClfzaError("denoiser is an option of reg='dncnn'")
        if not exact and (self.mu1 is not None or self.support is not None
                          or self.average is not None or self.relax is not None
                          or self.highpass is not None):
            raise ClfzaError("mu1, support, average, relax and highpass are options of the "
                             "exact model's ADMM (model='exact')")
        if self.support is None and exact:
            self.support = True
        if self.average is None and exact:
            self.average = True
        if self.relax is None and exact:
            self.relax = EXACT_RELAX
        if self.weight is None:
            self.weight = self.tau / 2.0
        if self.nonneg is None:
            # the exact model's ADMM splits w = x anyway (support): non-negativity is free
            self.nonneg = exact
        super().resolve(exact)


@dataclass(kw_only=True)
class AdmmExactOptions(AdmmOptions):
    """ADMM's options on the exact model: 400 iterations by default, as the returned
    iterate-weighted mean (``average``) needs them (:mod:`clfza.solvers._admm_crop`)."""

    iters: int = option(400, integer(1), "maximum number of iterations")


@register
class AdmmSolver(Solver):
    """ADMM-TV on the transfer-function model: ``x``, the splits ``u`` (2), ``q`` (2) and,
    with non-negativity, ``v``, ``s``; ``rhs`` of the x-update. ``ops``: the split's fused
    operations (:class:`~clfza.solvers._admm_ops.AdmmOps`); ``xsolve``: the Fourier-diagonal
    x-update (:class:`~clfza.solvers._admm_ops.FourierSolve`)."""

    method = "admm"
    order = 2
    # not "padded": its x-update divides by H_T^2 + rho |D|^2 + mu, which needs a Fourier-
    # diagonal K^T K; the linear-convolution model is the exact model's crop-split ADMM
    models = ("tf",)
    Options = AdmmOptions

    def setup(self, x0) -> None:
        B, o = self.B, self.opts
        if o.reg != "tv":  # reg="dncnn" is clfza.solvers._pnp's solver (prior_solver)
            raise ClfzaError(f"reg={o.reg!r} does not run here (one frame at a time only)")
        w = o.weight
        self.rho = o.rho if o.rho is not None else RHO_PER_WEIGHT * w
        self.mu = (o.mu if o.mu is not None else MU_PER_WEIGHT * w) if o.nonneg else 0.0
        self.ops = AdmmOps.for_backend(B)
        self.xsolve = FourierSolve.for_backend(B)
        self.xsolve.setup(self.rho, self.mu)
        self.allocate(x0)
        self.xp = B.empty() if o.nonneg else None
        mon = self.mon
        self.need_obj = o.stop == "objective" or mon.truth is not None \
            or mon.callback is not None

    def stopper(self) -> Stopper:
        """The objective rule; over a window (``stop_window``) it reads the spread of the
        objective over it, as the exact model's split does: ADMM's objective is not monotone,
        and two values of a swing can coincide."""
        o = self.opts
        window = o.stop_window or 1
        return Stopper(o.stop, o.tol, o.min_iters, o.iters, window=window, spread=window > 1)

    def allocate(self, x0) -> None:
        """The iterate (a copy of ``x0``), the zeroed splits, the right-hand side, and the
        spare pair and previous iterate where they are used."""
        B = self.B
        self.x = B.empty()
        B.copy(self.x, x0)
        self.u1, self.u2, self.q1, self.q2, self.v, self.s = (B.zeros() for _ in range(6))
        # AdmmOps.update_rhs may write the new split there (and hand back the old pair)
        self.u_spare = (B.empty(), B.empty()) if self.ops.wants_spare else None
        self.rhs = B.empty()
        self.xprev = B.empty() if self.needs_step else None

    def start(self) -> None:
        # z = D x0, u = 0, v = max(x0, 0), s = x0 - v  (a shrink with threshold 0)
        self._update(0.0, want=False)  # and the first x-update's right-hand side
        return None

    def _update(self, thr: float, want: bool = True):
        """The split's update and the next x-update's right-hand side (``self.rhs``); its
        sums (None without ``want``)."""
        rv, (self.u1, self.u2), self.u_spare = self.ops.update_rhs(
            self.x, (self.u1, self.u2), self.u_spare, (self.q1, self.q2), self.v, self.s,
            self.rhs, thr, self.opts.nonneg, self.rho, self.mu, want)
        return rv

    def _xout(self, it: int):
        """The iterate a checkpoint sees: max(x, 0) with non-negativity (cheap: only at
        checkpoints, never in the loop otherwise)."""
        if self.xp is None or not self.mon.due(it):
            return self.x
        self.B.project_nonneg(self.xp, self.x)
        return self.xp

    #: the last iterates kept on the device when the stopping rule is read late
    #: (:meth:`keep_iterates`); empty: read at every iteration
    ring: list = []

    def step(self, it: int) -> Step:
        if self.ring:
            raise ClfzaError("step() reads at once: a solver keeping iterates runs "
                             "step_deferred() and resolve()")
        B, w = self.B, self.opts.weight
        if self.xprev is not None:
            B.copy(self.xprev, self.x)
        data = self.xsolve.solve(self.rhs, self.x, self.need_obj)
        rv = self._update(w / self.rho, self.need_obj)
        f = dh = None
        if self.need_obj:
            d, r = read_all(data, rv)
            dh = 0.5 * d[0]
            f = dh + w * r[0]
        step = None
        if self.xprev is not None:
            d = B.diffnorm(self.x, self.xprev).get()
            step = math.sqrt(d[0] / d[1]) if d[1] > 0 else 0.0
        return Step(f, self._xout(it), step=step, extra={"data": dh})

    # the stopping rule read late (clfza.solvers._driver.run, STOP_LAG) ----------------------
    def keep_iterates(self, lag: int) -> None:
        """Keep the last ``lag + 1`` iterates on the device (:attr:`ring`): iteration ``it``
        writes its ``x`` into slot ``it % (lag + 1)`` (the x-update reads only the right-hand
        side, so rotating its output buffer costs nothing, and the previous iterate of the
        step rule is the previous slot, no copy), so the stopping rule can be read ``lag``
        iterations late and the image of the iteration it stopped at is still there."""
        self.ring = [self.B.empty() for _ in range(lag + 1)] if lag > 0 else []

    def _rotate(self, it: int) -> None:
        """``x`` to iteration ``it``'s slot of the ring, the old one as ``xprev`` (or, without
        a ring, the old ``x`` copied into ``xprev`` where the step rule needs it)."""
        if self.ring:
            old = self.x
            self.x = self.ring[it % len(self.ring)]
            if self.xprev is not None:
                self.xprev = old
        elif self.xprev is not None:
            self.B.copy(self.xprev, self.x)

    def _thr(self) -> float:
        return self.opts.weight / self.rho

    def step_deferred(self, it: int) -> tuple:
        """Enqueue iteration ``it``; returns its sums (the objective's and the step's, None
        where the rule reads neither) with their reads to the host started, not waited for
        (:meth:`resolve` reads them)."""
        self._rotate(it)
        data = self.xsolve.solve(self.rhs, self.x, self.need_obj)
        rv = self._update(self._thr(), self.need_obj)
        diff = self.B.diffnorm(self.x, self.xprev) if self.xprev is not None else None
        sums = (data, rv, diff) if self.need_obj else (None, None, diff)
        for a in sums:
            if a is not None:
                a.start_read()
        return sums

    def resolve(self, sums: tuple) -> Step:
        """The :class:`Step` of an iteration's sums (:meth:`step_deferred`), read (a wait for
        that iteration's reads only); its ``x`` is the current iterate."""
        data, rv, diff = sums
        f = dh = None
        if data is not None:
            d, r = read_all(data, rv)
            dh = 0.5 * d[0]
            f = dh + self.opts.weight * r[0]
        step = None
        if diff is not None:
            d = diff.get()
            step = math.sqrt(d[0] / d[1]) if d[1] > 0 else 0.0
        return Step(f, self.x, step=step, extra={"data": dh})

    def finish_at(self, it: int):
        """:meth:`finish` with iteration ``it``'s iterate (from :attr:`ring`)."""
        if self.ring:
            self.x = self.ring[it % len(self.ring)]
        return self.finish()

    def finish(self):
        if self.opts.nonneg:
            self.B.project_nonneg(self.x, self.x)  # the returned image: max(x, 0)
        return self.x

    def stats(self, history: list[float]) -> dict:
        return {"rho": self.rho, "mu": self.mu, "weight": self.opts.weight}
