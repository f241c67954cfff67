"""Batches of frames: many frames of one camera solved together, one kernel launch per step
for all of them.

A stack of F frames (grey ``(F, H, W)``, or colour ``(F, H, W, 3)`` whose channels are planes
of the batch, or one batch of joint-colour frames) runs as one backend whose arrays hold every
frame's plane (:class:`~clfza.backends._opencl.OpenCLBackend` with ``frames``): each kernel,
each FFT and each reduction runs once per iteration for the whole batch, so the per-launch
costs (a GPU's launch latency and host round trips, PoCL's worker wake-up) are paid once per
batch instead of once per frame.

Each frame keeps its own:

* ``tau`` (a sequence of F values, or one for all), hence its own penalties (the kernels'
  per-frame factors, ``reduce.cl``'s ``fpar``, and ADMM's x-update's ``(rho, mu)``, from which
  its kernel forms the frame's inverse spectrum; FISTA's FGP prox takes the frame's weight
  as its threshold factor);
* FISTA's monotone step (MFISTA keeps ``x`` in the frames whose objective would rise, from
  the per-frame objectives read once per iteration as one frame's are) and extrapolation
  coefficients; the momentum ``t_k`` is shared, as the one-frame solver advances it whether
  its step is accepted or not;
* TwIST's decisions (:class:`BatchTwistSolver`): its ``max_svd``, monotone fallbacks, IST
  steps and doublings, each from its own objectives read once per round of candidates, and
  in efficient mode its warm Chambolle dual and the inner loop's stop on ``tv_tol``;
* start (the Wiener estimate with its own noise estimate and ``lam``);
* stopping rule and record: a frame that meets its rule stops there, its image is copied out
  at that iteration, and its kernels return at once from then on (the FFTs still transform
  its planes);
* :class:`~clfza.solvers._result.Reconstruction`, equal to the one-frame solve's to float32
  rounding (the tests hold them to it on every OpenCL implementation).

What batches: :data:`BATCH_METHODS` on the OpenCL backend, with a fixed ``tau`` or with
``tau="auto"`` on every frame (each frame's :class:`~clfza.solvers._tau.DiscrepancySearch`, the
stages of all frames run together round by round: the tau and image each frame gets alone).
Everything else (checkpoints, callbacks, a truth or ``x0``; the exact model; other methods;
frames that the noise routes to different models) runs frame by frame through
:func:`~clfza.solvers.run_solver`, and each record says why (:func:`batch_blocker`).
"""

from __future__ import annotations

import math
import time
import warnings
from collections import deque

import numpy as np

from .. import regularizers as R
from ..backends import get_backend, read_all
from ..cl import get_runtime
from ..errors import ClfzaError
from ._admm import MU_PER_WEIGHT, RHO_PER_WEIGHT, AdmmSolver
from ._admm_ops import AdmmOps, FourierSolve
from ._common import Monitor, SolveResult, relative_change
from ._context import SolveContext
from ._driver import STOP_LAG, Step, check_finite, solver_class
from ._fista import FistaSolver
from ._options import DEFAULT_BACKEND, RUN_CONTROLS
from ._result import ReconInfo, Reconstruction
from ._run import (
    ClfzaWarning,
    describe_backend,
    method_model,
    record_group,
    run_solver,
    to_solver_units,
)
from ._tau import (
    WIENER_X0,
    DiscrepancySearch,
    final_options,
    frame_starts,
    record_tau,
    split_auto,
)
from ._twist import MAX_SVD_LIMIT, TwistSolver
from ._wiener import measurement_pixels

#: (method, model) pairs that run as one batch; the rest run frame by frame
BATCH_METHODS = (("admm", "tf"), ("fista", "tf"), ("twist", "tf"))
#: run controls that need one frame at a time (they watch or steer one solve)
PER_FRAME_CONTROLS = ("truth", "x0", "checkpoints", "callback")
#: ``frames_per_solve="auto"``: the most frames a GPU solves together, the share of its
#: memory a batch may take, and the arrays of a frame's ADMM solve (images and half spectra,
#: with headroom; FISTA's, about 13 image-sized arrays with the split FGP's four dual pairs,
#: and TwIST's, about 14 with its two Chambolle dual pairs, fit in it too); CPU devices
#: solve one frame at a time (measured: docs/measurements.md, clfza.solvers._batch)
GPU_MAX_FRAMES = 64
GPU_MEMORY_SHARE = 0.5
ARRAYS_PER_FRAME = 32

__all__ = ["BATCH_METHODS", "batch_blocker", "frames_per_solve_for", "run_solver_batch"]


def frames_per_solve_for(method: str, backend: str, device, shape: tuple[int, int],
                         channels: int = 1) -> int:
    """How many frames of ``shape`` (``channels`` planes each) to solve together by default
    (``frames_per_solve="auto"`` of :func:`clfza.reconstruct_many`): 1 for a method that does
    not batch or off OpenCL; on a GPU up to :data:`GPU_MAX_FRAMES` within
    :data:`GPU_MEMORY_SHARE` of its memory and its largest allocation; 1 on CPU devices,
    where a batch gains little (ADMM on PoCL with a fixed tau a little, otherwise nothing;
    FISTA loses: one frame's working set stays in the caches between iterations, a batch's
    does not; TwIST loses more: its frames' candidates diverge, and each round of candidates
    transforms every frame; measured: docs/measurements.md, clfza.solvers._batch): give 2 to
    take PoCL's gain for ADMM.

    Examples
    --------
    >>> frames_per_solve_for("bp", "opencl", None, (512, 512))
    1
    """
    if backend != "opencl" or not any(method == m for m, _ in BATCH_METHODS):
        return 1
    rt = get_runtime(device)
    plane = int(np.prod(shape)) * 4 * max(1, int(channels))  # float32
    if rt.is_cpu:
        return 1
    mem = int(rt.device.global_mem_size) * GPU_MEMORY_SHARE
    alloc = int(rt.device.max_mem_alloc_size)
    return int(max(1, min(GPU_MAX_FRAMES, mem // (ARRAYS_PER_FRAME * plane),
                          alloc // (2 * plane))))


def _rows(a, frames: int) -> np.ndarray:
    """A :class:`~clfza.backends.Scalars` read as one row per frame."""
    return np.asarray(a, dtype=np.float64).reshape(frames, -1)


def _images(B, res) -> np.ndarray:
    """Every frame's ``(C, H, W)`` image of batch array ``res`` on the host, float64: one
    conversion pass (on zero-copy CPU devices from the buffer's own host memory, elsewhere
    from one read)."""
    host = res.host_view() if res.host is not None else res.get()
    return host.astype(np.float64).reshape((B.frames, -1) + tuple(B.shape))


class BatchAdmmSolver(AdmmSolver):
    """ADMM-TV on the transfer-function model for a batch of frames (:mod:`._admm`'s
    iteration, with one weight and penalty pair per frame).

    The kernels take the scalars 1 (0 for a disabled term) and the per-frame values as
    factors (``OpenCLBackend.set_frame_params``), so each frame's arithmetic is that of its
    one-frame solve. ``weights``: the TV weight of each plane (solver units).
    """

    #: the stopping rule is read STOP_LAG iterations late where it reads sums
    late_reads = True

    def __init__(self, B, opts, mon: Monitor, weights: np.ndarray,
                 context: SolveContext | None = None):
        super().__init__(B, opts, mon, context)
        self.w = np.asarray(weights, dtype=np.float64)

    def setup(self, x0) -> None:
        B, o, w = self.B, self.opts, self.w
        P = B.frames
        self.rho = np.full(P, o.rho) if o.rho is not None else RHO_PER_WEIGHT * w
        self.mu = ((np.full(P, o.mu) if o.mu is not None else MU_PER_WEIGHT * w)
                   if o.nonneg else np.zeros(P))
        self.running = np.ones(P, bool)
        B.set_frame_params(rho=self.rho, mu=self.mu, thr=w / self.rho, running=self.running)
        self.ops = AdmmOps.for_backend(B)
        self.xsolve = FourierSolve.for_backend(B)
        self.xsolve.setup(self.rho, self.mu)  # each frame's pair (the kernel divides)
        self.allocate(x0)
        self.xp = None
        self.need_obj = o.stop == "objective"
        # each frame's image at its stop, copied on the device (read back once, at the end)
        self.result = B.empty()

    def _update(self, thr: float, want: bool = True):
        # the per-frame threshold is the factor: thr is 0 (the start: z = D x) or 1
        rv, (self.u1, self.u2), self.u_spare = self.ops.update_rhs(
            self.x, (self.u1, self.u2), self.u_spare, (self.q1, self.q2), self.v, self.s,
            self.rhs, 1.0 if thr else 0.0, self.opts.nonneg, 1.0, 1.0, want)
        return rv

    def step(self, it: int) -> Step:
        return self.resolve(self.step_deferred(it))

    def _thr(self) -> float:
        return 1.0  # the per-frame threshold is the factor (set_frame_params)

    def resolve(self, sums: tuple) -> Step:
        """The :class:`Step` of an iteration's sums (:meth:`step_deferred`): each frame's
        objective and step, read (a wait for that iteration's reads only)."""
        P = self.B.frames
        data, rv, diff = sums
        f = dh = None
        if data is not None:
            d, r = (_rows(a.get(), P) for a in (data, rv))
            dh = 0.5 * d[:, 0]
            f = dh + self.w * r[:, 0]
        step = None
        if diff is not None:
            d = _rows(diff.get(), P)
            step = np.sqrt(d[:, 0] / np.where(d[:, 1] > 0, d[:, 1], 1.0))
            step[d[:, 1] <= 0] = 0.0
        return Step(f, self.x, step=step, extra={"data": dh})

    def stop_frame(self, p: int, it: int | None = None) -> None:
        """Keep frame ``p``'s iterate (of iteration ``it``, from :attr:`ring`; default the
        current one) as its result (a copy on the device, queued) and turn its kernels off."""
        src = self.x if (it is None or not self.ring) else self.ring[it % len(self.ring)]
        self.B.copy_frame(self.result, src, p)
        self.running[p] = False
        if self.running.any():
            self.B.set_frame_params(rho=self.rho, mu=self.mu, thr=self.w / self.rho,
                                    running=self.running)

    def images(self) -> list[np.ndarray]:
        """Every frame's result on the host (one read), ``max(x, 0)`` with non-negativity."""
        out = _images(self.B, self.result)
        if self.opts.nonneg:
            np.maximum(out, 0.0, out=out)
        return list(out)

    def frame_stats(self, p: int, hist: list | None = None) -> dict:
        return {"rho": float(self.rho[p]), "mu": float(self.mu[p]),
                "weight": float(self.w[p])}


class BatchFistaSolver(FistaSolver):
    """Monotone FISTA on the transfer-function model for a batch of frames (:mod:`._fista`'s
    iteration, with one weight per frame).

    The FGP prox takes the weight 1 and each frame's weight as its threshold factor
    (``OpenCLBackend.set_frame_params``), so each frame's arithmetic is that of its one-frame
    solve. Every frame shares ``k`` and hence the momentum ``t_k`` (the one-frame solver
    advances ``t`` whether its monotone step accepts or not); the monotone decision is each
    frame's, from the per-frame objectives read once per iteration (the one-frame solver
    reads its objective every iteration too): the extrapolation takes each frame's
    coefficients (``FistaOps.extrap`` with one value per frame), and ``x`` moves to ``z`` in
    the frames that accept (the arrays swapped, the minority's frames copied back). A
    stopped frame's prox returns at once. ``weights``: the TV weight of each plane (solver
    units).
    """

    #: the monotone step reads each iteration's objectives: the rule is read at once
    late_reads = False

    def __init__(self, B, opts, mon: Monitor, weights: np.ndarray,
                 context: SolveContext | None = None):
        super().__init__(B, opts, mon, context)
        self.w = np.asarray(weights, dtype=np.float64)
        self.need_obj = True
        self.xprev = None

    def setup(self, x0) -> None:
        super().setup(x0)
        P = self.B.frames
        self.running = np.ones(P, bool)
        self.rejected_frames = np.zeros(P, int)
        self.B.set_frame_params(thr=self.w, running=self.running)
        self.result = self.B.empty()

    def keep_iterates(self, lag: int) -> None:
        if lag:
            raise NotImplementedError("batched FISTA reads its objectives every iteration")

    def _objective(self, data, regv) -> tuple[np.ndarray, np.ndarray]:
        """(objective, data term) of every frame's point: one synchronisation."""
        P = self.B.frames
        d, r = (_rows(a, P) for a in read_all(data, regv))
        dh = 0.5 * d[:, 0]
        return dh + self.w * (r[:, 0] if self.opts.reg == "tv" else r[:, 1]), dh

    def step(self, it: int) -> Step:
        B, o, P = self.B, self.opts, self.B.frames
        rv = B.fgp_prox(o.reg, self.z, self.bb, 1.0, o.tv_iters, self.state, o.nonneg)
        fz, dz = self._objective(B.resid_grad(self.z, self.wz, step=True), rv)
        self.evaluations += 1
        t, t_new = self.t, 0.5 * (1 + math.sqrt(1 + 4 * self.t * self.t))
        accept = (fz <= self.fx) | (not o.monotone)
        live = self.running
        step = None
        if self.needs_step:
            step = np.zeros(P)
            if (accept & live).any():
                d = _rows(B.diffnorm(self.z, self.x).get(), P)
                ok = accept & (d[:, 1] > 0)
                step[ok] = np.sqrt(d[ok, 0] / d[ok, 1])
        c, a = (t - 1) / t_new, t / t_new
        # each frame's coefficients, as the one-frame solver forms them (accept: 1 + c and -c;
        # reject: a and 1 - a): one kernel whatever the mix
        if accept[live].all():
            self.ops.extrap(self.bb, 1 + c, self.wz, -c, self.wx)
        elif not accept[live].any():
            self.ops.extrap(self.bb, a, self.wz, 1 - a, self.wx)
        else:
            self.ops.extrap(self.bb, np.where(accept, 1 + c, a), self.wz,
                            np.where(accept, -c, 1 - a), self.wx)
        n_acc = int((accept & live).sum())
        n_rej = int((~accept & live).sum())
        if n_acc >= n_rej and n_acc:  # x <- z in every frame, then the rejecting ones back
            self.x, self.z = self.z, self.x
            self.wx, self.wz = self.wz, self.wx
            moved = np.flatnonzero(~accept & live)
        else:  # x stays; the accepting frames' z copied in
            moved = np.flatnonzero(accept & live)
        for p in moved:
            B.copy_frame(self.x, self.z, p)
            B.copy_frame(self.wx, self.wz, p)
        self.fx = np.where(accept, fz, self.fx)
        self.dx = np.where(accept, dz, self.dx)
        self.rejected_frames += ~accept & live
        self.rejected += int(n_rej)
        self.t = t_new
        # a rejected step leaves F unchanged: that is no sign of convergence (per frame)
        return Step(self.fx, self.x, step=step, comparable=accept, extra={"data": self.dx})

    def step_deferred(self, it: int) -> Step:
        """The iteration itself (its monotone step needs its objectives at once)."""
        return self.step(it)

    def resolve(self, sums: Step) -> Step:
        return sums

    def stop_frame(self, p: int, it: int | None = None) -> None:
        """Keep frame ``p``'s current iterate as its result (a copy on the device, queued)
        and turn its prox off."""
        self.B.copy_frame(self.result, self.x, p)
        self.running[p] = False
        if self.running.any():
            self.B.set_frame_params(thr=self.w, running=self.running)

    def images(self) -> list[np.ndarray]:
        """Every frame's result on the host (one read)."""
        return list(_images(self.B, self.result))

    def frame_stats(self, p: int, hist: list | None = None) -> dict:
        return {"rejected": int(self.rejected_frames[p]), "weight": float(self.w[p])}


class BatchTwistSolver(TwistSolver):
    """TwIST on the transfer-function model for a batch of frames (:mod:`._twist`'s
    iteration, paper or efficient mode, with one ``tau`` per frame).

    Each frame keeps its own ``max_svd``, TwIST counter, previous objective and counts. The
    prox takes the step 1 and ``lam = 1`` with each frame's ``1 / max_svd`` and ``2 max_svd /
    tau`` as its factors (``OpenCLBackend.set_frame_params``: ``mu`` and the threshold), so
    each frame's arithmetic is that of its one-frame solve. An iteration runs in rounds, as
    the one-frame solver's candidates until one is accepted: each round forms every pending
    frame's candidate (the two-step combination, or the IST estimate copied into the same
    array), evaluates them all with one FFT pair and reads the objectives once; each frame
    then decides on its own (accept; monotone fallback to an IST step, reusing its estimate
    unless the ``sparse`` mask changed the past; ``max_svd`` doubled and the prox recomputed;
    the no-op step at :data:`~clfza.solvers._twist.MAX_SVD_LIMIT`), and the next round takes
    the frames still pending. The kernels of a round run only on the frames that take them
    (the running flags); the FFT pair transforms every frame, which gives the frames already
    accepted their own gradient again (the same values). ``weights``: ``tau / 2`` of each
    plane (solver units), as the other batch solvers take them.
    """

    #: each candidate's objective is read at once (the monotone test): the rule too
    late_reads = False

    def __init__(self, B, opts, mon: Monitor, weights: np.ndarray,
                 context: SolveContext | None = None):
        super().__init__(B, opts, mon, context)
        self.w = np.asarray(weights, dtype=np.float64)
        self.tau = 2.0 * self.w  # exact: the weight is tau / 2
        self.need_obj = True
        self.xprev = None

    def setup(self, x0) -> None:
        super().setup(x0)
        P = self.B.frames
        self.max_svd = np.ones(P)
        self.twist_iters = np.zeros(P, int)
        self.evals = np.ones(P, int)  # the start's evaluation, then one per candidate
        self.counts = {k: np.zeros(P, int) for k in ("fallbacks", "doublings", "inner",
                                                        "noops")}
        self.running = np.ones(P, bool)
        self.result = self.B.empty()

    def keep_iterates(self, lag: int) -> None:
        if lag:
            raise NotImplementedError("batched TwIST reads its objectives every iteration")

    def _on(self, frames: np.ndarray) -> None:
        """Turn the kernels on for ``frames`` only, with every frame's prox factors (queued:
        kernels already queued keep the flags they were queued with)."""
        s = 1.0 / self.max_svd
        lam = 2.0 / (self.tau / self.max_svd)  # as the one-frame prox forms 2 / th
        self.B.set_frame_params(rho=1.0, mu=s, thr=lam, running=frames)

    def start(self) -> Step:
        B, P = self.B, self.B.frames
        d, r = (_rows(a, P) for a in read_all(B.resid_grad(self.xm1, self.g),
                                              B.reg_value(self.xm1)))
        self.prev_d = d[:, 0]
        self.prev_f = 0.5 * self.prev_d + self.tau * self._reg_col(r)
        self.xm2 = B.empty()
        B.copy(self.xm2, self.xm1)
        return Step(self.prev_f.copy(), self.xm1, extra={"data": 0.5 * self.prev_d})

    def _reg_col(self, r: np.ndarray) -> np.ndarray:
        return r[:, 0] if self.opts.reg == "tv" else r[:, 1]

    def step(self, it: int) -> Step:
        """The one-frame solver's candidates until one is accepted, for every running frame
        (rounds; class docstring)."""
        B, o, P = self.B, self.opts, self.B.frames
        pending = self.running.copy()
        prox = pending.copy()  # frames whose IST estimate is to be (re)computed
        reuse = np.full(P, np.nan)  # a fallback's regulariser value of its IST estimate
        f_new, d_new = self.prev_f.copy(), self.prev_d.copy()
        noop = np.zeros(P, bool)
        c = self.counts
        while pending.any():
            if prox.any():
                self._on(prox)
                B.prox_step(o.reg, self.xm1, self.g, 1.0, 2.0, self.xist, o.tv_iters,
                            self.state, o.tv_tol or 0.0)
                c["inner"] += B.prox_frame_iters
                prox[:] = False
            two = pending & (self.twist_iters != 0)
            ist = pending & ~two
            rv = regv = None
            if two.any():
                self._on(two)
                rv = self.ops.combine(self.xnew, self.xm2, self.xm1, self.xist, self.alpha,
                                      self.beta, o.sparse, o.reg == "tv")
            for p in np.flatnonzero(ist):  # the IST candidates where the combinations are
                B.copy_frame(self.xnew, self.xist, p)
            data = B.resid_grad(self.xnew, self.gn)
            if (ist & np.isnan(reuse)).any():
                regv = B.reg_value(self.xist)
            sums = read_all(data, *(a for a in (rv, regv) if a is not None))
            d = _rows(sums[0], P)[:, 0]
            self.evals += pending
            if rv is not None:
                rr = _rows(sums[1], P)
                f = 0.5 * d + self.tau * rr[:, 0]
                masked = two & (rr[:, 1] > 0)
                if masked.any():  # the reference zeroes the past where x_ist == 0, for good
                    self._on(masked)
                    self.ops.mask_past(self.xm1, self.xm2, self.xist)
                back = two & (f > self.prev_f) & o.monotone
                self.twist_iters[back] = 0  # fall back to an IST step
                c["fallbacks"] += back
                # Psi(x_{t-1} + g/max_svd) again gives the same x_ist unless the mask changed
                # x_{t-1}: keep it and its regulariser value
                reuse[back & ~masked] = rr[back & ~masked, 2]
                prox |= back & masked
                ok = two & ~back
                self.twist_iters[ok] += 1
                self.max_svd[ok & (self.twist_iters % 10000 == 0)] *= 0.9
                f_new[ok], d_new[ok] = f[ok], d[ok]
                pending &= ~ok
            if ist.any():
                rg = self._reg_col(_rows(sums[-1], P)) if regv is not None else None
                for p in np.flatnonzero(ist):
                    rp = reuse[p] if not np.isnan(reuse[p]) else rg[p]
                    fp = 0.5 * d[p] + self.tau[p] * rp
                    reuse[p] = np.nan
                    if fp > self.prev_f[p] and self.max_svd[p] * 2.0 > MAX_SVD_LIMIT:
                        noop[p] = True  # below rounding: x_{t+1} = x_t (with x_t's gradient)
                        c["noops"][p] += 1
                    elif fp > self.prev_f[p]:
                        self.max_svd[p] *= 2.0  # max eig(K^T K) > max_svd: increase the guess
                        self.twist_iters[p] = 0
                        c["doublings"][p] += 1
                        prox[p] = True
                        continue
                    else:
                        f_new[p], d_new[p] = fp, d[p]
                    self.twist_iters[p] += 1
                    pending[p] = False
        # the no-op steps' iterate and gradient, after the rounds' FFTs (which rewrite every
        # frame's gradient from its candidate)
        for p in np.flatnonzero(noop):
            B.copy_frame(self.xnew, self.xm1, p)
            B.copy_frame(self.gn, self.g, p)
        return self._advance_frames(f_new, d_new)

    def _advance_frames(self, f: np.ndarray, d: np.ndarray) -> Step:
        """Every running frame's candidate in ``xnew`` becomes its x_{t+1}."""
        P = self.B.frames
        step = None
        if self.needs_step:
            step = np.zeros(P)
            dn = _rows(self.B.diffnorm(self.xnew, self.xm1).get(), P)
            ok = self.running & (dn[:, 1] > 0)
            step[ok] = np.sqrt(dn[ok, 0] / dn[ok, 1])
        free = self.xm2
        self.xm2, self.xm1, self.xnew = self.xm1, self.xnew, free
        self.g, self.gn = self.gn, self.g
        self.prev_f = np.where(self.running, f, self.prev_f)
        self.prev_d = np.where(self.running, d, self.prev_d)
        return Step(self.prev_f.copy(), self.xm1, step=step,
                    extra={"data": 0.5 * self.prev_d, "max_svd": self.max_svd.copy()})

    def step_deferred(self, it: int) -> Step:
        """The iteration itself (its monotone test needs its objectives at once)."""
        return self.step(it)

    def resolve(self, sums: Step) -> Step:
        return sums

    def stop_frame(self, p: int, it: int | None = None) -> None:
        """Keep frame ``p``'s current iterate as its result (a copy on the device, queued)
        and leave it out of the kernels from then on."""
        self.B.copy_frame(self.result, self.xm1, p)
        self.running[p] = False

    def images(self) -> list[np.ndarray]:
        """Every frame's result on the host (one read)."""
        return list(_images(self.B, self.result))

    def frame_evaluations(self, p: int) -> int:
        return int(self.evals[p])

    def frame_notes(self, p: int) -> list[str]:
        n = int(self.counts["noops"][p])
        return [f"stalled at rounding level: max_svd reached 2^50 and {n} IST steps were "
                "no-op steps (the reference doubles max_svd for ever instead)"] if n else []

    def frame_stats(self, p: int, hist: list | None = None) -> dict:
        c = self.counts
        return {"fallbacks": int(c["fallbacks"][p]), "max_svd_doublings": int(c["doublings"][p]),
                "max_svd": float(self.max_svd[p]), "alpha": self.alpha, "beta": self.beta,
                "inner_tv_iterations": int(c["inner"][p]), "noop_ist_steps": int(c["noops"][p]),
                "final_relative_change": relative_change(hist[-1], hist[-2])
                if hist is not None and len(hist) > 1 else None}


#: the batch solver of each method of :data:`BATCH_METHODS`
BATCH_SOLVERS = {"admm": BatchAdmmSolver, "fista": BatchFistaSolver, "twist": BatchTwistSolver}


def run_batch(solver: BatchAdmmSolver | BatchFistaSolver, x0, limits: tuple | None = None,
              running=None) -> tuple[list[SolveResult], list[np.ndarray], float]:
    """:func:`clfza.solvers._driver.run` for a batch: one stopping rule, history and result
    per frame; the loop ends when every frame has stopped. ``limits``: each frame's
    ``(iters, min_iters)`` (arrays; default the options'); ``running``: the frames to solve
    (the others keep ``x0``, with 0 iterations). Returns the results, the frames' host images
    and the batch's solve seconds (the iterations, as ``run`` times them: the images read back
    after the clock)."""
    P = solver.B.frames
    stoppers = [solver.stopper() for _ in range(P)]
    if limits is not None:  # the solver's rule with each frame's (iters, min_iters)
        for st, hi, lo in zip(stoppers, *limits, strict=True):
            st.min_iters, st.max_iters = int(lo), int(hi)
    solver.needs_step = stoppers[0].needs_step
    try:
        return _run_batch(solver, x0, stoppers, running)
    finally:  # the backend's per-frame factors back to ones: one-frame solves share it
        solver.B.set_frame_params()


def _run_batch(solver: BatchAdmmSolver | BatchFistaSolver, x0, stoppers: list, running
               ) -> tuple[list[SolveResult], list[np.ndarray], float]:
    P = solver.B.frames
    solver.setup(x0)
    mon = solver.mon
    mon.start()
    # ADMM's start evaluates nothing (z = D x0 only); FISTA's evaluates x0 (each frame's
    # history's first entry and the first comparison's previous objective, as run's)
    first = solver.start()
    if first is not None and solver.late_reads:
        raise NotImplementedError("a late-reading solver's start must not report an objective")
    # the stopping rule is read STOP_LAG iterations late when it reads sums (the queue then
    # never waits for the host; clfza.solvers._driver.STOP_LAG), from the iterates the ring
    # keeps; without sums to read, the rule is the iteration count, known without a read
    lag = STOP_LAG if (solver.late_reads and (solver.need_obj or solver.xprev is not None)
                       ) else 0
    solver.keep_iterates(lag)
    hist: list[list[float]] = [[] for _ in range(P)]
    done: list[tuple[int, str, float] | None] = [None] * P
    for p in range(P):
        if running is not None and not running[p]:
            solver.stop_frame(p)
            done[p] = (0, "not_run", 0.0)
        elif first is not None:
            hist[p].append(float(first.objective[p]))
    it, prev = 0, (None if first is None else first.objective)
    pending: deque = deque()
    # no frame's rule runs past its max_iters (TwIST's paper count: max_iters + 1)
    cap = max(s.max_iters + int(s.reference_count) for s in stoppers)
    while not all(done):
        more = it < cap
        if more:
            it += 1
            pending.append((it, solver.step_deferred(it)))
        if len(pending) <= lag and more:
            continue
        j, sums = pending.popleft()
        last = solver.resolve(sums)
        f, step, comp = last.objective, last.step, last.comparable
        stopped = []
        for p in range(P):
            if done[p] is not None:
                continue
            fp = None if f is None else float(f[p])
            if fp is not None:
                hist[p].append(fp)
            comparable = comp if np.ndim(comp) == 0 else comp[p]
            f_prev = None if (prev is None or not comparable) else float(prev[p])
            reason = stoppers[p].check(j, fp, f_prev, None if step is None else step[p])
            if reason is not None:
                stopped.append((p, reason))
        for p, reason in stopped:
            solver.stop_frame(p, j)
            done[p] = (j, reason, mon.elapsed())
        prev = f
    solver.B.finish()
    solve_s = mon.elapsed()  # as run's: the iterations done, the images still on the device
    results = []
    for p in range(P):
        iters, reason, t = done[p]
        # the start's evaluation counts, as the one-frame solver's (FISTA: 1 + iterations)
        evals = iters + (1 if first is not None and reason != "not_run" else 0)
        if hasattr(solver, "frame_evaluations"):  # TwIST: its candidates, counted per frame
            evals = solver.frame_evaluations(p)
        notes = solver.frame_notes(p) if hasattr(solver, "frame_notes") else []
        results.append(SolveResult(x=None, iterations=iters, stop_reason=reason,
                                   objective=hist[p], solve_s=min(t, solve_s),
                                   evaluations=evals, notes=notes,
                                   stats=solver.frame_stats(p, hist[p])))
    return results, solver.images(), solve_s


def _residuals(B, images) -> np.ndarray:
    """``||y - K x||^2`` of every frame's host image (backend units)."""
    x = B.from_host(np.concatenate(images))
    return _rows(B.resid_grad(x, B.empty()).get(), B.frames)[:, 0]


def _auto_taus(cls, B, ctx: SolveContext, opts, per: list, live: list, groups: list,
               lams: list, xw, planes: np.ndarray, subset
               ) -> tuple[list[DiscrepancySearch], object]:
    """``tau="auto"`` for every frame of the batch: each frame's discrepancy search
    (:class:`~clfza.solvers._tau.DiscrepancySearch`, as one frame runs it). Each round runs
    the next stage of every unfinished search, the frames with stages of one length together
    on a batch of just them (``subset(k)``: a backend of ``k`` frames; ``planes``: every
    frame's measurement), so a finished frame, or one with a shorter stage, costs no FFTs.
    ``cls``: the batch solver (:data:`BATCH_SOLVERS`). Returns the searches and the device
    array of their last iterates (ADMM's final solve starts there, as one frame's)."""
    P, s2, nc = B.frames, ctx.scale2, B.nc
    n = measurement_pixels(B) * nc
    searches = []
    starts = B.to_host(xw).reshape((P, nc) + tuple(B.shape))  # one read for all frames
    for i, (u, g) in enumerate(zip(live, groups, strict=True)):
        a = starts[i]
        d1, d2 = R.grad_circ(a)
        tau0 = lams[i] * max(float(np.sqrt(np.mean(d1**2 + d2**2))), 1e-30)
        searches.append(DiscrepancySearch.for_group(g, s2, n, tau0, per[u[0]]))
    xs = [np.zeros((nc,) + tuple(B.shape)) for _ in range(P)]
    while not all(sr.done for sr in searches):
        stages = [sr.stage() for sr in searches]
        for length in sorted({st[1] for st in stages if st is not None}):
            idx = [p for p, st in enumerate(stages) if st is not None and st[1] == length]
            Bk = subset(len(idx))
            Bk.set_measurement(np.concatenate([planes[p * nc:(p + 1) * nc] for p in idx]))
            tau = np.array([stages[p][0] for p in idx])
            limits = (np.array([stages[p][1] for p in idx]),
                      np.array([stages[p][2] for p in idx]))
            solver = cls(Bk, opts, Monitor(Bk), tau / 2.0, ctx)
            results, images, _ = run_batch(solver, Bk.from_host(
                np.concatenate([xs[p] for p in idx])), limits)
            r = _residuals(Bk, images)
            for k, p in enumerate(idx):
                xs[p] = images[k]
                searches[p].observe(float(r[k]), results[k].iterations)
    return searches, B.from_host(np.concatenate(xs))


def batch_blocker(method: str, kind: str, backend: str, options: dict,
                  auto_tau: bool) -> str | None:
    """Why a solve cannot run as one batch (None: it can)."""
    if (method, kind) not in BATCH_METHODS:
        return (f"{method} on the {kind!r} model runs one frame at a time (batched: "
                f"{', '.join(f'{m} on {k!r}' for m, k in BATCH_METHODS)})")
    if backend != "opencl":
        return f"the {backend} backend runs one frame at a time"
    if auto_tau and kind != "tf":
        return "tau='auto' on the exact model searches each frame's weight on its own"
    if options.get("reg") not in (None, "tv"):  # the batched kernels are TV's
        return f"reg={options['reg']!r} runs one frame at a time"
    given = [k for k in PER_FRAME_CONTROLS if options.get(k) is not None]
    if given:
        return f"{', '.join(given)} watch one solve at a time"
    return None


def _frame_taus(tau, frames: int) -> list:
    """One ``tau`` per frame from a scalar (or None: the method's default) or a sequence."""
    if tau is None or isinstance(tau, str) or np.ndim(tau) == 0:
        return [tau] * frames
    taus = list(np.asarray(tau, dtype=object).ravel())
    if len(taus) != frames:
        raise ClfzaError(f"tau has {len(taus)} values for {frames} frames: give one, or one "
                         "per frame")
    return taus


def run_solver_batch(frames, camera, method: str, *, backend: str = DEFAULT_BACKEND,
                     device=None, dtype=np.float32, fft: str = "auto", model: str = "auto",
                     psf=None, margin: int = 0, **options) -> list[Reconstruction]:
    """Run an iterative method on a stack of validated DC-free frames, as one batch where it
    can (:func:`batch_blocker`), else frame by frame.

    Parameters
    ----------
    frames : array, (F, H, W) or (F, H, W, 3)
        The frames, float64 (each as :func:`~clfza.solvers.run_solver` takes one).
    camera, method, backend, device, dtype, fft, model, psf, margin
        As :func:`~clfza.solvers.run_solver`.
    **options
        The method's options and the run controls; ``tau`` may be a sequence of one value
        per frame.

    Returns
    -------
    list of Reconstruction
        One per frame, in order; each ``info.stats["batch"]`` says how it ran: ``frames`` (the
        batch's planes), ``index`` (its first plane), or the reason it ran alone.

    Examples
    --------
    >>> import numpy as np
    >>> from clfza import Camera
    >>> cam = Camera.preset("simulation").with_shape((64, 64))
    >>> ys = np.random.default_rng(0).normal(size=(3, 64, 64))
    >>> out = run_solver_batch(ys, cam, "admm", tau=[0.01, 0.02, 0.05], iters=20)
    >>> [r.info.stats["batch"]["frames"] for r in out]
    [3, 3, 3]
    """
    ys = np.asarray(frames, dtype=np.float64)
    if ys.ndim not in (3, 4) or (ys.ndim == 4 and ys.shape[-1] != 3):
        raise ClfzaError(f"a batch is (F, H, W) or (F, H, W, 3) frames, got shape {ys.shape}")
    F = ys.shape[0]
    taus = _frame_taus(options.get("tau"), F)
    routes = [method_model(camera, model, method, options, psf=psf is not None, y=y)
              for y in ys]
    kind, why = routes[0]
    autos = [split_auto({"tau": t}, method, kind)[1] for t in taus]
    auto_tau = any(autos)
    blocker = batch_blocker(method, kind, backend, options, auto_tau)
    if blocker is None and auto_tau and not all(autos):
        blocker = "tau='auto' for some frames and a fixed tau for others"
    if blocker is None and any(k != kind for k, _ in routes):
        blocker = "the frames' noise routes them to different forward models"
    if blocker is not None or F == 1:
        note = blocker or "one frame"
        out = []
        for i in range(F):
            res = run_solver(ys[i], camera, method, backend=backend, device=device,
                             dtype=dtype, fft=fft, model=model, psf=psf, margin=margin,
                             **{**options, "tau": taus[i]})
            res.info.stats["batch"] = {"frames": 1, "index": 0, "alone": note}
            out.append(res)
        return out
    rest = {k: v for k, v in options.items() if k != "tau" and k not in RUN_CONTROLS}
    return _batched(ys, camera, method, kind, why, taus, rest, backend=backend, device=device,
                    dtype=dtype, fft=fft)


def _batched(ys: np.ndarray, camera, method: str, kind: str, why: str, taus: list,
             options: dict, *, backend: str, device, dtype, fft: str) -> list[Reconstruction]:
    """One batch: every plane of every frame (or every joint-colour frame) together."""
    t_all = time.perf_counter()
    F = ys.shape[0]
    cls = solver_class(method, kind)
    auto = [split_auto({"tau": t}, method, kind)[1] for t in taus]
    per = [cls.Options.from_options({**options, "tau": t} if t is not None and not a
                                    else options, method=method, exact=kind == "exact")
           for t, a in zip(taus, auto, strict=True)]
    opts = per[0]
    # (F, C, H, W): a view of the frames (np.stack of channels_first, without the copy)
    yc = ys[:, None] if ys.ndim == 3 else np.moveaxis(ys, -1, 1)
    C = yc.shape[1]
    joint = opts.colour == "joint" and C > 1
    nc = C if joint else 1
    # the batch's planes: (frame, channel) pairs (one per frame with joint colour); a plane
    # with nothing left after the DC removal is not solved (zeros, as run_solver returns)
    units = [(f, None) for f in range(F)] if joint else [(f, c) for f in range(F)
                                                          for c in range(C)]

    def data(u):
        f, c = u
        return yc[f] if c is None else yc[f, c:c + 1]

    live = [u for u in units if np.ptp(data(u)) > 0]
    infos = []
    for f in range(F):
        info = ReconInfo(method=method, backend=backend, device="", dtype="",
                         params={**per[f].params(), "model": kind})
        info.notes.append(f"model: {kind} ({why})")
        infos.append(info)
    # each frame's (C, H, W) image: a plane's result as it comes back (grey frames, joint
    # colour), the channels of colour frames gathered; None: zeros
    out: list = [None] * F
    if live:
        B = get_backend(backend, camera, nc=nc, device=device, dtype=dtype, fft=fft,
                        model=kind, frames=len(live))
        ctx = SolveContext(camera, B.data_scale ** 2, False)
        for o in per:
            to_solver_units(o, B.dtype, ctx.scale2)
        for info in infos:
            describe_backend(B, info)
        tp = time.perf_counter()
        # (P nc, H, W); every grey frame live: the frames themselves, without a copy
        planes = (ys if ys.ndim == 3 and len(live) == F else
                  np.concatenate([data(u) for u in live]))
        B.set_measurement(planes)
        # each plane's start: the Wiener estimate with its own noise and lam (one host FFT
        # of each plane for both, the frames' lam searches in lockstep, over the CPUs); TwIST
        # with a fixed tau starts at K^T y (the paper's run) and needs neither
        wiener = method in WIENER_X0 or any(auto)
        groups, lams = frame_starts(B, ctx, planes, nc) if wiener else ([], [])
        x0 = B.b
        if wiener:
            xsolve = FourierSolve.for_backend(B)
            xsolve.setup(np.array(lams), np.zeros(len(live)))
            x0 = B.empty()
            xsolve.solve(B.b, x0, False)
        plan_s = time.perf_counter() - tp
        searches = None
        search_s = 0.0
        if any(auto):  # every frame's tau="auto" (batch_blocker): the searches in lockstep
            ts = time.perf_counter()
            subs = {len(live): B}

            def subset(k: int):
                if k not in subs:
                    subs[k] = get_backend(backend, camera, nc=nc, device=device, dtype=dtype,
                                          fft=fft, model=kind, frames=k)
                return subs[k]

            searches, x_last = _auto_taus(BATCH_SOLVERS[method], B, ctx, opts, per, live,
                                          groups, lams, x0, planes, subset)
            # ADMM's final solve from the search's iterate; FISTA's from the Wiener estimate
            # (as clfza.solvers._tau runs one frame: from the search's iterate, which came
            # down from x = 0, FISTA is as slow as from K^T y)
            if method != "fista":
                x0 = x_last
            B.set_measurement(planes)  # the whole batch's again, for the final solve
            weights = np.array([sr.chosen / 2.0 for sr in searches])
            search_s = time.perf_counter() - ts
        else:
            # TwIST's options have no TV weight: tau / 2 (exact), as the others take it
            weights = np.array([getattr(per[u[0]], "weight", per[u[0]].tau / 2.0)
                                for u in live])
        mon = Monitor(B)
        # tau="auto": the final solve's stop as one frame's (clfza.solvers._tau.final_options)
        final, stop = (opts, None) if searches is None else final_options(opts, method)
        solver = BATCH_SOLVERS[method](B, final, mon, weights, ctx)
        results, images, solve_s = run_batch(solver, x0)
        if searches is not None:  # the records of tau="auto", as run_solver writes them
            r_final = _residuals(B, images)
            for i, res in enumerate(results):
                res.stats = {**res.stats, "tau_auto": searches[i].record(
                    groups[i], ctx.scale2, lams[i], r_final[i], stop)}
        for i, (u, res, img) in enumerate(zip(live, results, images, strict=True)):
            f, c = u
            info = infos[f]
            img = check_finite(method, img, taus[f])
            if c is None or C == 1:
                out[f] = img
            else:
                if out[f] is None:
                    out[f] = np.zeros(yc.shape[1:])
                out[f][c] = img[0]
            record_group(info, res, mon, ctx.scale2, not joint and C > 1)
            record_tau(info, res)
            if method in WIENER_X0:
                info.notes.append(f"x0: the Wiener estimate (lam = "
                                  f"{ctx.user_units(lams[i]):.3g})")
            info.timings["plan"] += plan_s / len(live)
            info.ffts = B.ffts // len(live)
        for f, info in enumerate(infos):
            first = next(i for i, u in enumerate(live) if u[0] == f) if any(
                u[0] == f for u in live) else None
            info.stats["batch"] = {"frames": len(live), "index": first,
                                   "solve_s": solve_s, "plan_s": plan_s}
            # a frame's share of the batch's solve: the batch's time over its planes
            share = sum(1 for u in live if u[0] == f) / len(live)
            info.timings["solve"] = solve_s * share
            if searches is not None:
                info.timings["tau_search"] = search_s * share
            info.timings["checkpoint_overhead"] = 0.0
            info.notes.append(f"batch: solved with {len(live)} plane(s) together; solve time "
                              f"is its share of the batch's {solve_s:.3g} s")
    for f, info in enumerate(infos):
        dead = [u for u in units if u[0] == f and u not in live]
        if dead and len(dead) == sum(1 for u in units if u[0] == f):
            warnings.warn(f"frame {f} of the batch is constant (all zero after removing the "
                          "DC): it holds no image information; returning a zero image",
                          ClfzaWarning, stacklevel=3)
            info.device, info.dtype, info.stop_reason = "none", "float64", "constant_measurement"
            info.notes.append("constant measurement: returned zeros")
            info.timings.update(solve=0.0, compile=0.0, plan=0.0)
        else:
            info.notes += [f"channel {u[1]} is constant: returned zeros" for u in dead]
        info.timings["total"] = time.perf_counter() - t_all
    out = [np.zeros(yc.shape[1:]) if a is None else a for a in out]
    return [Reconstruction(out[f][0] if ys.ndim == 3 else np.moveaxis(out[f], 0, -1), infos[f])
            for f in range(F)]
