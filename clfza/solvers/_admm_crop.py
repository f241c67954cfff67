"""ADMM with the crop split (DiffuserCam: Antipa et al., Optica 5, 1, 2018) for the exact model.

Problem: ``min 1/2 ||y - P C H x||^2 + w Phi(x) [+ x >= 0] [+ x = 0 off the object region]``
with ``H`` the periodic convolution on the model grid, ``C`` the sensor crop and ``P`` the mean
removal (:mod:`clfza.models._exact`). ``K^T K`` is not diagonal in any basis, so ADMM splits
it where each piece is::

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
``mu3 = rho`` as in :mod:`clfza.solvers._admm`.

Output: the iterate-weighted mean ``sum_k k x_k / sum_k k`` (``average``, default on; the
ergodic ADMM output, He & Yuan, SIAM J. Numer. Anal. 50, 2012), one ``lincomb`` per iteration.
The iterates themselves swing (their PSNR and objective rise and fall between checkpoints);
the mean does not, but it needs iterations to forget the first ones: the exact model's
default is 400 (:class:`AdmmExactOptions`; chosen by measurement: docs/measurements.md,
clfza.solvers._admm_crop).

Over-relaxation (``relax`` = alpha, Boyd et al. 2011, s. 3.4.3) of the v-split: the
v-update and its dual read ``alpha H x + (1 - alpha) v_prev`` in place of ``H x``, folded into
the dual before the v-update (``a += (1 - alpha) (v_prev - H x)``, one lincomb), so the
kernels and the data term (of ``H x`` itself) are unchanged. Default ``EXACT_RELAX`` = 1
(none): over-relaxation helps some regimes and hurts others (chosen by measurement:
docs/measurements.md, clfza.solvers._admm_crop).

High-pass (``highpass``, :mod:`clfza.models._highpass`): on a mask with a finite aperture the solver
is given the exact model of ``g * h`` on the sensor's interior and the frame ``g * y`` (``G =
delta - box``), which takes the open disc's low frequencies out of the problem; nothing here
changes. With it the iterates' path matters far less (docs/measurements.md,
clfza.solvers._admm_crop).

Continuing a run: :meth:`AdmmCropSolver.end_state` is where a run ended (its iterate, splits,
duals and penalties, :class:`CropAdmmState`); given as the next run's ``x0`` on the same
backend, that run continues it at its own ``tau``, keeping the penalties unless they are
given (``tau="auto"`` continues its last pilot pass so on noise-free frames; measured:
docs/measurements.md, clfza.solvers._admm_crop).

Order per iteration: x-update; then v (with its dual ``a``), w (with ``s``) and z (with ``u``),
each from the new ``x``. The data term ``||y - P C H x||^2`` of the new iterate comes out of the
v-update (``H x`` is already there), so the objective costs no FFT.
"""

from __future__ import annotations

from dataclasses import dataclass

from ..backends import Backend, read_all
from ..errors import ClfzaError
from ._admm import RHO_PER_WEIGHT, AdmmExactOptions
from ._admm_crop_ops import CropAdmmOps, CropFourierSolve
from ._admm_ops import AdmmOps
from ._apg_exact import APG_TV_ITERS, ApgExactSolver
from ._common import Stopper
from ._driver import Solver, Step, register
from ._options import choice, integer, option

#: the exact model's algorithms: the crop split (this module) and the accelerated proximal
#: gradient with restart (:mod:`clfza.solvers._apg_exact`)
EXACT_ALGORITHMS = ("split", "apg")
DEFAULT_EXACT_ALGORITHM = "split"

MU1_FACTOR = 0.01
#: ``rho / w`` of the crop split with a measured PSF (a mask's shadow: RHO_PER_WEIGHT)
PSF_RHO_PER_WEIGHT = 4.0
#: the crop split's default iterations with a measured PSF (a mask's shadow: 400,
#: AdmmExactOptions), at PSF_RHO_PER_WEIGHT
PSF_ITERS = 200
ADAPT_EVERY = 10
STOP_WINDOW = 20
ADAPT_RATIO = 10.0


@dataclass
class CropAdmmState:
    """Where a crop-split run ended, to continue from at another ``tau``
    (:meth:`AdmmCropSolver.end_state`; pass it as the next run's ``x0`` on the same backend).

    The iterate ``x`` and ``hx`` = H x; the data split ``v`` with its scaled dual ``a`` and
    ``e`` = v - a; the differences' scaled dual ``u1``, ``u2``; the support split ``ww`` with
    its scaled dual ``s``; the next x-update's right-hand side ``rhs``; the penalties ``mu1``,
    ``mu3`` and ``rho`` the duals are scaled by, and the weight ``tau`` they were reached at.
    The arrays are the finished run's own (not copies)."""

    x: object
    hx: object
    v: object
    a: object
    e: object
    u1: object
    u2: object
    ww: object
    s: object
    rhs: object
    mu1: float
    mu3: float
    rho: float
    weight: float


@dataclass(kw_only=True)
class CropAdmmOptions(AdmmExactOptions):
    """The exact model's options (:class:`~clfza.solvers._admm.AdmmExactOptions`) and the
    algorithm that solves it."""

    algorithm: str = option(DEFAULT_EXACT_ALGORITHM, choice(*EXACT_ALGORITHMS),
                            "exact model: 'split' (the crop-split ADMM) or 'apg' (accelerated "
                            "proximal gradient with restart, clfza.solvers._apg_exact)")
    tv_iters: int | None = option(None, integer(1), "exact model, algorithm 'apg': inner FGP "
                                  f"iterations per prox ({APG_TV_ITERS})")


@register
class AdmmCropSolver(Solver):
    """The crop-split ADMM on an exact-model backend: ``x``, ``hx`` = H x, ``v`` (dual ``a``),
    the differences' split ``u``/``q`` and the support split ``ww`` (dual ``s``). With
    ``algorithm="apg"`` the entry builds :class:`~clfza.solvers._apg_exact.ApgExactSolver`
    instead (same problem, same options)."""

    method = "admm"
    models = ("exact",)
    Options = CropAdmmOptions

    def __new__(cls, B, opts, mon, context=None):
        if getattr(opts, "algorithm", DEFAULT_EXACT_ALGORITHM) == "apg":
            return ApgExactSolver(B, opts, mon, context)
        if getattr(opts, "tv_iters", None) is not None:  # the split's z-update is exact
            raise ClfzaError("tv_iters is for algorithm='apg' (its inner FGP iterations); the "
                             "crop-split ADMM has no inner TV iterations")
        return super().__new__(cls)

    def stopper(self) -> Stopper:
        """The objective rule over a window of ``STOP_WINDOW`` iterations, on the spread of
        the objective: the iterates swing, and two values of a swing can coincide, where a
        one-step rule stops far too early (docs/measurements.md, clfza.solvers._admm_crop)."""
        o = self.opts
        return Stopper(o.stop, o.tol, o.min_iters, o.iters, window=o.stop_window or STOP_WINDOW,
                       spread=True)

    def setup(self, x0) -> None:
        B, o = self.B, self.opts
        w = o.weight
        self.warm = isinstance(x0, CropAdmmState)
        st = x0 if self.warm else None
        # a continued run keeps its penalties unless given: ADMM converges at any penalty,
        # and a change of penalty throws the iterate off first (measured:
        # docs/measurements.md, clfza.solvers._admm_crop)
        self.rho = o.rho if o.rho is not None else (
            st.rho if self.warm else penalty_per_weight(B.exact) * w)
        self.split_w = o.nonneg or o.support
        self.mu3 = (o.mu if o.mu is not None else st.mu3 if self.warm and st.mu3 > 0
                    else self.rho) if self.split_w else 0.0
        self.ops, self.xsolve = CropAdmmOps.for_backend(B), CropFourierSolve.for_backend(B)
        self.zops = AdmmOps.for_backend(B)  # the split z = D x
        if self.warm:  # continue a run (its arrays, its mu1; s in units of this mu3)
            self.mu1 = st.mu1
            self.x, self.hx, self.v, self.a, self.e = st.x, st.hx, st.v, st.a, st.e
            self.u1, self.u2, self.ww, self.s = st.u1, st.u2, st.ww, st.s
            # the support's multiplier mu3 s follows the data: s to this mu3; the
            # differences' multiplier rho u follows tau (it lies in tau's ball)
            if self.split_w and st.mu3 > 0 and st.mu3 != self.mu3:
                B.lincomb(self.s, st.mu3 / self.mu3, self.s)
            f = st.rho / self.rho * (w / st.weight) if st.weight > 0 else 1.0
            if f != 1.0:
                B.lincomb(self.u1, f, self.u1)
                B.lincomb(self.u2, f, self.u2)
            self.q1, self.q2 = B.zeros(), B.zeros()
            # the right-hand side stands where the penalties and tau are the run's
            self.rhs_ready = (st.mu3, st.rho, st.weight) == (self.mu3, self.rho, w)
            self.rhs = st.rhs
        else:
            self.mu1 = o.mu1 or MU1_FACTOR * self.ops.default_mu1(self.rho)
            self.x, self.hx, self.v, self.a, self.e = (B.empty() for _ in range(5))
            B.copy(self.x, x0)
            self.u1, self.u2, self.q1, self.q2, self.ww, self.s = (B.zeros() for _ in range(6))
        # the split's update writes the next x-update's image part rho D^T q + mu3 (w - s)
        # (AdmmOps.update_rhs with a zero K^T y: the data enter through H^T), its new pair
        # to a spare pair where the implementation wants one
        if not self.warm:
            self.rhs = B.empty()
        self.zero = B.zeros()
        self.u_spare = (B.empty(), B.empty()) if self.zops.wants_spare else None
        self.v_old = B.empty() if o.adapt else None
        self.xbar = B.zeros() if o.average else None
        self.xsolve.setup(self.mu1, self.rho, self.mu3)
        self.adaptations = 0

    def start(self) -> None:
        if self.warm:  # the splits as the run left them: the right-hand side at this tau
            if not self.rhs_ready:
                self._split(self.opts.weight / self.rho, want=False)
            return None
        self.ops.init(self.x, self.hx, self.v, self.a, self.e)
        self._w_update()
        self._split(0.0, want=False)  # z = D x0, u = 0, and the first right-hand side
        return None

    def end_state(self) -> CropAdmmState:
        """Where this run ended (after :func:`~clfza.solvers._driver.run`), for the next run
        to continue from (its ``x0``): the last iterate, not the returned mean."""
        return CropAdmmState(self.x, self.hx, self.v, self.a, self.e, self.u1, self.u2,
                             self.ww, self.s, self.rhs, self.mu1, self.mu3, self.rho,
                             self.opts.weight)

    def _w_update(self) -> None:
        if self.split_w:
            self.ops.w_update(self.x, self.ww, self.s, self.opts.nonneg, self.opts.support)

    def _split(self, thr: float, want: bool = True):
        """The split ``z = D x`` (shrink at ``thr``) and the next x-update's image part
        (reading ``w`` and ``s``, so after :meth:`_w_update`); its sums (None without
        ``want``)."""
        rv, (self.u1, self.u2), self.u_spare = self.zops.update_rhs(
            self.x, (self.u1, self.u2), self.u_spare, (self.q1, self.q2), self.ww, self.s,
            self.rhs, thr, False, self.rho, self.mu3, want, b=self.zero)
        return rv

    def step(self, it: int) -> Step:
        B, w = self.B, self.opts.weight
        check = self.opts.adapt and it % ADAPT_EVERY == 0
        if check:
            B.copy(self.v_old, self.v)
        self.xsolve.solve_rhs(self.x, self.hx, self.e, self.rhs, self.mu1)
        alpha = self.opts.relax
        if alpha != 1.0:  # over-relaxation: the v-update reads alpha H x + (1 - alpha) v + a
            B.lincomb(self.a, 1.0, self.a, 1.0 - alpha, self.v, alpha - 1.0, self.hx)
        data = self.ops.v_update(self.hx, self.v, self.a, self.e, self.mu1)
        self._w_update()
        rv = self._split(w / self.rho)
        d, r = read_all(data, rv)
        dh = 0.5 * d[0]
        f = dh + w * r[0]
        if self.xbar is not None:  # weights proportional to the iteration number
            g = 2.0 / (it + 1)
            B.lincomb(self.xbar, 1.0 - g, self.xbar, g, self.x)
        if check:
            self.mu1, changed = _balance(B, self.hx, self.v, self.v_old, self.a, self.e,
                                         self.mu1, self.rho, self.mu3)
            self.adaptations += changed
        # no step change: the stopping rule "step" never fires here (as before the driver)
        return Step(f, self.x if self.xbar is None else self.xbar,
                    extra={"data": dh, "mu1": self.mu1})

    def finish(self):
        B, o = self.B, self.opts
        if self.xbar is None:
            if o.nonneg:
                B.project_nonneg(self.x, self.x)
            return self.x
        # the mean or the last iterate, whichever has the lower objective once projected
        s = B.empty()
        cands = {}
        for name, x in (("last", self.x), ("mean", self.xbar)):
            p = B.empty()
            if self.split_w:
                B.lincomb(s, 0.0, x)
                self.ops.w_update(x, p, s, o.nonneg, o.support)  # p = proj(x)
            else:
                B.copy(p, x)
            f = 0.5 * B.data_term(p) + o.weight * B.reg_value(p).get()[0]
            cands[name] = (f, p)
        self.returned = min(cands, key=lambda k: cands[k][0])
        self.f_final = {k: v[0] for k, v in cands.items()}
        return cands[self.returned][1]

    def stats(self, history: list[float]) -> dict:
        out = {"rho": self.rho, "mu3": self.mu3, "mu1_final": self.mu1,
               "mu1_adaptations": self.adaptations, "weight": self.opts.weight,
               "support": self.opts.support}
        if self.xbar is not None:
            out.update(returned=self.returned, objective_last=self.f_final["last"],
                       objective_mean=self.f_final["mean"])
        return out


def penalty_per_weight(model) -> float:
    """The crop split's default ``rho / w`` for an exact model: ``PSF_RHO_PER_WEIGHT`` for a
    measured PSF (``model.mask_shadow`` False), ``RHO_PER_WEIGHT`` for a mask's shadow.

    The lower penalty reaches a given image in fewer iterations on measured-PSF captures and
    loses on a mask's shadow (noise-free, high-passed frames); both measured:
    docs/measurements.md, clfza.solvers._admm_crop.

    >>> import numpy as np
    >>> from clfza.models import ExactModel
    >>> penalty_per_weight(ExactModel(np.ones((3, 3)), (8, 8)))
    4.0
    """
    return RHO_PER_WEIGHT if model.mask_shadow else PSF_RHO_PER_WEIGHT


def default_iterations(model) -> int:
    """The crop split's default iterations for an exact model: ``PSF_ITERS`` for a measured
    PSF (at its penalty, :func:`penalty_per_weight`; ``algorithm="split"``), the exact
    model's 400 for a mask's shadow (:class:`~clfza.solvers._admm.AdmmExactOptions`).
    Chosen by measurement: docs/measurements.md, clfza.solvers._admm_crop.

    >>> import numpy as np
    >>> from clfza.models import ExactModel
    >>> default_iterations(ExactModel(np.ones((3, 3)), (8, 8)))
    200
    """
    return AdmmExactOptions().iters if model.mask_shadow else PSF_ITERS


def _balance(B: Backend, hx, v, v_old, a, e, mu1: float, rho: float, mu3: float
             ) -> tuple[float, int]:
    """Residual balancing of ``mu1`` (one extra FFT pair); returns the new ``mu1`` and 1 when
    it changed."""
    primal, dual = CropAdmmOps.for_backend(B).residuals(hx, v, v_old, mu1)
    if primal > ADAPT_RATIO * dual:
        factor = 2.0
    elif dual > ADAPT_RATIO * primal:
        factor = 0.5
    else:
        return mu1, 0
    B.lincomb(a, 1.0 / factor, a)  # the scaled dual a = lambda / mu1
    B.lincomb(e, 1.0, v, -1.0, a)  # the next x-update's input e = v - a, with the new a
    mu1 *= factor
    CropFourierSolve.for_backend(B).setup(mu1, rho, mu3)
    return mu1, 1
