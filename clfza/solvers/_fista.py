"""Monotone FISTA (MFISTA, Beck & Teboulle 2009) for Eq. 19 with a fast-gradient-projection TV
prox.

Problem: ``min 1/2 ||y - K x||^2 + w R(x) [+ x >= 0]`` with ``R = Phi`` (circular TV, the
paper's objective regulariser) or l1; ``L = 1`` because ``|H_T| <= 1``. Default weight
``w = tau / 2``: the paper's Psi is ``tvdenoise(x, 2/th, .)``, i.e. ROF with weight ``th/2``,
so paper-mode TwIST's fixed points solve Eq. 19 with ``tau/2``; FISTA and ADMM target the
same image (and report the objective with their own ``w``).

Iteration (one FFT pair: ``u + K^T(y - K u)`` is affine in ``u``, so the gradient step at the
extrapolated point is the same combination of the gradient steps at ``x_{k-1}`` and ``z_k``,
which are kept instead of the points' gradients)::

    z_k = prox_w(b_k),  b_k = y_k + K^T (y - K y_k)     FGP, dual warm-started across iterations
    x_k = z_k if F(z_k) <= F(x_{k-1}) else x_{k-1}
    t_{k+1} = (1 + sqrt(1 + 4 t_k^2)) / 2
    y_{k+1} = x_k + t_k/t_{k+1} (z_k - x_k) + (t_k - 1)/t_{k+1} (x_k - x_{k-1})
    b_{k+1} = the same combination of z_k + K^T (y - K z_k) and x_{k-1} + K^T (y - K x_{k-1})

The gradient steps come out of the data term's pass (``resid_grad(.., step=True)``: on the TF
model the point is added to the spectrum before the inverse FFT), so the extrapolation reads
two arrays instead of two points and their two gradients.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from ..backends import ProxState, read_all
from ._driver import Solver, Step, register
from ._fista_ops import FistaOps
from ._options import MethodOptions, boolean, integer, option, positive

FGP_ITERS = 2  # inner FGP iterations per prox (dual warm-started across iterations)


@dataclass(kw_only=True)
class FistaOptions(MethodOptions):
    """FISTA's options (:class:`~clfza.solvers._options.MethodOptions` and these)."""

    monotone: bool = option(True, boolean, "MFISTA: keep x when the objective would rise")
    weight: float | None = option(None, positive, "regulariser weight w (default tau / 2)")
    tv_iters: int | None = option(None, integer(1), f"inner FGP iterations ({FGP_ITERS})")

    def resolve(self, exact: bool) -> None:
        if self.weight is None:
            self.weight = self.tau / 2.0
        if self.tv_iters is None:
            self.tv_iters = FGP_ITERS
        super().resolve(exact)


@register
class FistaSolver(Solver):
    """Monotone FISTA; state ``x`` (with its gradient step ``wx = x + K^T (y - K x)``), the
    prox point ``z`` (``wz``), the extrapolated point's gradient step ``bb``
    (:class:`~clfza.solvers._fista_ops.FistaOps`) and the momentum ``t``."""

    method = "fista"
    order = 1
    # not "padded": the step 1 / L needs ||K||, known on the TF model (<= 1) and the exact
    # operator (power iteration), not on the numpy linear-convolution reference (there the
    # aperture term gives norms in the hundreds: FISTA stalled at its first objective)
    models = ("tf", "exact")
    Options = FistaOptions

    def setup(self, x0) -> None:
        B = self.B
        self.ops = FistaOps.for_backend(B)
        self.x, self.wx = B.empty(), B.empty()
        self.z, self.wz = B.empty(), B.empty()
        # bb is dead from the prox, which reads it, to the extrapolation, which writes it,
        # and that is exactly while the data term uses its FFT scratch: where the backend
        # offers it, bb lives in that scratch's memory (Backend.scratch_image)
        scratch = B.scratch_image()
        self.bb = B.empty() if scratch is None else scratch
        B.copy(self.x, x0)
        self.state = ProxState(warm=True)
        self.t = 1.0
        self.evaluations = 1
        self.rejected = 0

    def _objective(self, data, regv) -> tuple[float, float]:
        """(objective, data term) of a point: one synchronisation."""
        d, r = read_all(data, regv)
        return 0.5 * d[0] + self.opts.weight * (r[0] if self.opts.reg == "tv" else r[1]), \
            0.5 * d[0]

    def start(self) -> Step:
        B = self.B
        self.fx, self.dx = self._objective(B.resid_grad(self.x, self.wx, step=True),
                                           B.reg_value(self.x))
        B.copy(self.bb, self.wx)
        return Step(self.fx, self.x, extra={"data": self.dx})

    def step(self, it: int) -> Step:
        B, o = self.B, self.opts
        rv = B.fgp_prox(o.reg, self.z, self.bb, o.weight, o.tv_iters, self.state, o.nonneg)
        fz, dz = self._objective(B.resid_grad(self.z, self.wz, step=True), rv)
        self.evaluations += 1
        t, t_new = self.t, 0.5 * (1 + math.sqrt(1 + 4 * self.t * self.t))
        accept = fz <= self.fx or not o.monotone
        step = None
        if self.needs_step:
            d = B.diffnorm(self.z, self.x).get() if accept else (0.0, 1.0)
            step = math.sqrt(d[0] / d[1]) if d[1] > 0 else 0.0
        if accept:
            c = (t - 1) / t_new
            self.ops.extrap(self.bb, 1 + c, self.wz, -c, self.wx)
            self.x, self.z = self.z, self.x
            self.wx, self.wz = self.wz, self.wx
            self.fx, self.dx = fz, dz
        else:
            a = t / t_new
            self.ops.extrap(self.bb, a, self.wz, 1 - a, self.wx)
            self.rejected += 1
        self.t = t_new
        # a rejected step leaves F unchanged: that is no sign of convergence
        return Step(self.fx, self.x, step=step, comparable=accept, extra={"data": self.dx})

    def finish(self):
        return self.x

    def stats(self, history: list[float]) -> dict:
        return {"rejected": self.rejected, "weight": self.opts.weight}
