"""What every solver shares: stopping rules, and checkpoints that do not distort the
timing.

Checkpoints. ``checkpoints`` is an int ``k`` (every k-th iteration), an iterable of iteration
numbers, or None (none; the final iterate is always recorded when a truth or a callback is
given). At a checkpoint the solver's queue is drained, the clock is stopped, the iterate is
copied to the host and, when ``truth`` is given, MSE/PSNR/SSIM (after the affine fit of
:func:`clfza.metrics.compare`) are computed; the callback gets the record; then the clock
restarts. The time spent inside checkpoints is excluded from ``solve`` and reported as
``checkpoint_overhead``; what remains is the cost of draining the queue (on CPU devices the host
FFTs drain it every iteration anyway, so nothing; on GPUs one synchronisation per checkpoint).

Callbacks. ``callback(record) -> bool | None`` receives a dict with

* ``iteration`` (int; 0 is the initial point), ``time`` (solve seconds so far, checkpoint time
  excluded), ``objective`` (the solver's objective, or None where it was not computed);
* ``data`` = ``1/2 ||y - K x||^2`` and ``residual_norm2`` = ``||y - K x||^2`` of the recorded
  iterate, where the solver has them without extra FFTs (TwIST, FISTA: always; ADMM: its
  data term comes out of the Fourier-space x-update);
* at checkpoints with a ``truth``: ``mse``, ``psnr``, ``ssim``; solver-specific extras (e.g.
  TwIST's ``max_svd``, ``inner`` TV iterations).

It is called at every checkpoint; with ``checkpoints=None`` it is called after *every*
iteration with the scalar-only record (no host copy of the iterate, so no extra cost beyond the
call), which is what stopping rules such as :class:`clfza.reconstruction._plan.DiscrepancyStop`
need. Returning True stops the solve after that iteration with ``stop_reason == "callback"`` (the
returned image is the recorded iterate); None or False continue.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable, Iterable
from dataclasses import dataclass, field

import numpy as np

from ..errors import ClfzaError, positive_int
from ..metrics import compare
from ._options import STOP_RULES


def relative_change(f: float, f_prev: float) -> float:
    """``|f - f_prev| / f_prev`` (TwIST's StopCriterion 1); inf when ``f_prev`` is 0."""
    if f_prev == 0:
        return 0.0 if f == 0 else math.inf
    return abs(f - f_prev) / abs(f_prev)


class Monitor:
    """The solve clock, the checkpoint schedule and the records.

    Parameters
    ----------
    backend : Backend
    checkpoints : int, iterable of int, or None
    callback : callable(dict) -> bool | None, optional
        See the module docstring; True stops the solve (``stop_reason="callback"``).
    truth : array (C, H, W), optional
        Ground truth for MSE/PSNR/SSIM (after the affine fit).
    to_image : callable
        Maps a host (C, H, W) iterate to the image the user sees.
    scale : float
        Factor from the solver's units to the user's for the objective and the data term
        (``s^2`` on the normalised exact model, see :func:`clfza.solvers.run_solver`).
    """

    def __init__(self, backend, checkpoints=None, callback: Callable | None = None,
                 truth: np.ndarray | None = None, to_image: Callable | None = None,
                 channel: int | None = None, scale: float = 1.0):
        self.B = backend
        self.callback = callback
        self.truth = truth
        self.to_image = to_image or (lambda a: a[0] if a.shape[0] == 1 else np.moveaxis(a, 0,
                                                                                        -1))
        self.channel = channel
        self.scale = float(scale)
        self.every = None
        self.at: set[int] = set()
        if checkpoints is None:
            pass
        elif isinstance(checkpoints, (int, np.integer)) and not isinstance(checkpoints, bool):
            self.every = positive_int("checkpoints", int(checkpoints))
        elif isinstance(checkpoints, Iterable):
            try:
                self.at = {int(i) for i in checkpoints}
            except (TypeError, ValueError):
                raise ClfzaError("checkpoints must be an int or iterable of ints") from None
        else:
            raise ClfzaError(f"checkpoints must be an int, an iterable of ints or None, got "
                             f"{checkpoints!r}")
        if callback is not None and not callable(callback):
            raise ClfzaError("callback must be callable")
        self.records: list[dict] = []
        self.overhead = 0.0
        self.t0 = None
        self.last_recorded = -1
        self.last_called = -1
        self.stop_requested = False  # a callback returned True

    def start(self) -> None:
        self.B.finish()
        self.t0 = time.perf_counter()
        self.overhead = 0.0

    def elapsed(self) -> float:
        return time.perf_counter() - self.t0 - self.overhead

    def due(self, it: int) -> bool:
        return (self.every is not None and it % self.every == 0) or it in self.at

    def record(self, it: int, x, objective: float | None, **extra) -> dict:
        """Drain the queue, stop the clock, measure, call back, restart the clock."""
        self.B.finish()
        t_in = time.perf_counter()
        rec = self._base_record(it, t_in, objective, extra)
        if self.truth is not None:

            img = self.to_image(self.B.to_host(x))
            m = compare(img, self.truth)
            rec.update(mse=m["mse"], psnr=m["psnr"], ssim=m["ssim"])
        self.records.append(rec)
        self.last_recorded = it
        self._call(it, rec)
        self.overhead += time.perf_counter() - t_in
        return rec

    def _base_record(self, it: int, t_in: float, objective: float | None, extra: dict
                     ) -> dict:
        """Iteration, solve-clock time, objective, channel and the solver's extra scalars."""
        rec = {"iteration": int(it), "time": t_in - self.t0 - self.overhead,
               "objective": None if objective is None else float(objective) * self.scale}
        if self.channel is not None:
            rec["channel"] = self.channel
        rec.update(extra)
        for k in ("data", "residual_norm2"):
            if rec.get(k) is not None:
                rec[k] = float(rec[k]) * self.scale
        return rec

    def _call(self, it: int, rec: dict) -> None:
        if self.callback is not None and self.last_called != it:
            self.last_called = it
            if self.callback(dict(rec)) is True:
                self.stop_requested = True

    @staticmethod
    def _data_fields(extra: dict) -> dict:
        d = extra.get("data")
        if d is not None and "residual_norm2" not in extra:
            extra["residual_norm2"] = 2.0 * float(d)
        return extra

    def maybe(self, it: int, x, objective: float | None, **extra) -> bool:
        """Record at a checkpoint, or (no checkpoints, a callback) call back with the
        scalar-only record. Returns True when the callback asked to stop."""
        extra = self._data_fields(extra)
        if self.due(it):
            self.record(it, x, objective, **extra)
        elif self.callback is not None and self.every is None and not self.at:
            t_in = time.perf_counter()
            self._call(it, self._base_record(it, t_in, objective, extra))
            self.overhead += time.perf_counter() - t_in
        return self.stop_requested

    def final(self, it: int, x, objective: float | None, **extra) -> None:
        if (self.truth is not None or self.callback is not None) and self.last_recorded != it:
            self.record(it, x, objective, **self._data_fields(extra))


@dataclass
class SolveResult:
    """What a solver returns to :func:`run_solver`."""

    x: object  # backend array (C, H, W)
    iterations: int
    stop_reason: str
    objective: list
    solve_s: float
    evaluations: int = 0
    notes: list = field(default_factory=list)
    stats: dict = field(default_factory=dict)
    image: np.ndarray | None = None  # host copy of x (set by run_solver)
    search_s: float = 0.0  # tau="auto": the search or pilot passes before the solve


class Stopper:
    """Stop on maximum iterations, relative objective change or relative step change.

    ``check(it, f, f_prev, step)`` after iteration ``it`` (1-based). With ``reference_count``
    (TwIST paper mode) the loop continues while ``it <= max_iters``, so min = max = K runs
    K + 1 iterations, as the reference does; otherwise it runs at most ``max_iters``.
    """

    def __init__(self, rule: str, tol: float, min_iters: int, max_iters: int,
                 reference_count: bool = False, window: int = 1, spread: bool = False):
        if rule not in STOP_RULES:
            raise ClfzaError(f"stop must be one of {STOP_RULES}, got {rule!r}")
        self.rule, self.tol = rule, tol
        self.min_iters, self.max_iters = min_iters, max_iters
        self.reference_count = reference_count
        # window > 1: the objective rule uses the mean relative change over the last `window`
        # iterations, |f_k - f_{k-window}| / |f_{k-window}| / window, so that one small step
        # (e.g. a monotone fallback) is not taken for convergence
        self.window = max(1, int(window))
        # spread: the criterion is (max - min) / |f_k| / window over the last window + 1 values
        # instead, so that an objective that swings (ADMM) is not taken for converged where two
        # values of a swing happen to coincide
        self.spread = bool(spread)
        self._f: list[float] = []

    @property
    def needs_step(self) -> bool:
        return self.rule == "step"

    def check(self, it: int, f: float | None, f_prev: float | None, step: float | None
              ) -> str | None:
        if self.rule == "objective" and self.window > 1:
            if f_prev is not None and not self._f:
                self._f.append(f_prev)
            small = False
            if f is not None:
                self._f.append(f)
                if len(self._f) > self.window:
                    last = self._f[-1 - self.window:]
                    crit = ((max(last) - min(last)) / abs(f) if self.spread and f else
                            relative_change(f, self._f[-1 - self.window])) / self.window
                    small = crit <= self.tol
                    del self._f[:-1 - self.window]
        elif self.rule == "objective" and f is not None and f_prev is not None:
            crit = relative_change(f, f_prev)
            small = crit <= self.tol
        elif self.rule == "step" and step is not None:
            small = step <= self.tol
        else:
            small = False
        reason = "objective_change" if self.rule == "objective" else "step_change"
        if self.reference_count:  # cont = (iter <= maxiter) & (crit > tol); iter <= min: cont
            cont = (it <= self.max_iters and not small) or it <= self.min_iters
            if cont:
                return None
            return "max_iters" if it > self.max_iters else reason
        if it >= self.max_iters:
            return "max_iters"
        if it < self.min_iters:
            return None
        return reason if small else None
