"""The one iteration loop every solver runs in, and the registry of solvers.

A solver is a :class:`Solver` subclass in one file: its options dataclass (``Options``, see
:mod:`clfza.solvers._options`), the models it runs on, ``setup`` (allocate, before the clock),
``start`` (the initial evaluation, on the clock), ``step`` (one iteration) and ``finish`` (the
iterate to return), written against the backend's core and, where that is not enough, the
solver's own operation family (:class:`clfza.backends._base.Ops`, ``Family.for_backend(B)`` in
``setup``). :func:`run` owns everything else, identically for every method:

* the solve clock and the checkpoints (:class:`~clfza.solvers._common.Monitor`: the clock is
  paused around checkpoints and callbacks, whose cost is reported as ``checkpoint_overhead``);
* the records: iteration 0 (when ``start`` evaluates the initial point), every iteration (a
  checkpoint or a callback), the final iterate;
* the stopping rule (:class:`~clfza.solvers._common.Stopper`, built by
  :meth:`Solver.stopper`), including ``stop_reason="callback"``;
* the objective history;
* the check that the result is finite.

Registering: decorate the class with :func:`register`; :data:`REGISTRY` maps a method name to
its solver classes (one per model family: ADMM on the exact model is the crop split of
:mod:`clfza.solvers._admm_crop`), and :func:`solver_class` picks the one for a model.
"""

from __future__ import annotations

from collections import deque
from dataclasses import dataclass, field

import numpy as np

from ..errors import ClfzaError
from ._common import Monitor, SolveResult, Stopper
from ._context import SolveContext

#: method name -> solver classes (in registration order), see :func:`register`
REGISTRY: dict[str, list[type[Solver]]] = {}


@dataclass
class Step:
    """What one iteration (or the initial evaluation) reports to the driver.

    ``objective``: the solver's objective of the iterate (None where not computed);
    ``x``: the backend array a checkpoint records; ``step``: the relative step change
    ``||x_k - x_{k-1}|| / ||x_k||`` when the stopping rule needs it; ``comparable``: False
    when the objective must not be compared with the previous one (FISTA's rejected steps:
    an unchanged objective is no sign of convergence); ``extra``: scalars for the record
    (``data`` = 1/2 ||y - K x||^2 and solver-specific ones such as ``max_svd``).
    """

    objective: float | None
    x: object
    step: float | None = None
    comparable: bool = True
    extra: dict = field(default_factory=dict)


class Solver:
    """One iterative method on one backend. Subclasses set ``method``, ``models`` and
    ``Options`` and write :meth:`setup`, :meth:`step` and :meth:`finish` (and
    :meth:`start` when the initial point is evaluated)."""

    method: str = ""
    models: tuple[str, ...] = ("tf", "padded", "exact")
    Options: type = object
    order: int = 100  # place in clfza.solvers.METHODS

    def __init__(self, B, opts, mon: Monitor, context: SolveContext | None = None):
        self.B = B
        self.opts = opts
        self.mon = mon
        self.context = context  # the solve's context (camera, scale, channel group), if any
        self.needs_step = False  # set by the driver: the stopping rule needs Step.step
        self.evaluations: int | None = None  # objective evaluations (None: one per iteration)
        self.notes: list[str] = []

    def stopper(self) -> Stopper:
        """The stopping rule of ``opts``: the objective rule over ``stop_window`` iterations
        (each iteration's change by default)."""
        o = self.opts
        return Stopper(o.stop, o.tol, o.min_iters, o.iters, window=o.stop_window or 1)

    def setup(self, x0) -> None:
        """Allocate and initialise from ``x0`` (backend array); off the clock."""
        raise NotImplementedError

    def start(self) -> Step | None:
        """On the clock, before the first iteration: evaluate the initial point (its record
        is iteration 0 and its objective the history's first entry), or None."""
        return None

    def step(self, it: int) -> Step:
        """Iteration ``it`` (1-based)."""
        raise NotImplementedError

    def finish(self):
        """The backend array to return (on the clock)."""
        raise NotImplementedError

    def stats(self, history: list[float]) -> dict:
        """Solver-specific counters for ``info.stats``."""
        return {}


def register(cls: type[Solver]) -> type[Solver]:
    """Class decorator: make ``cls`` the solver of ``cls.method`` on ``cls.models``."""
    REGISTRY.setdefault(cls.method, []).append(cls)
    return cls


def solver_class(method: str, model: str = "tf") -> type[Solver]:
    """The registered solver class of ``method`` for a model kind ("tf", "padded", "exact")."""
    classes = REGISTRY.get(method, ())
    for cls in classes:
        if model in cls.models:
            return cls
    if classes:
        runs_on = sorted({m for cls in classes for m in cls.models})
        raise ClfzaError(f"method {method!r} does not run on model {model!r}; it runs on "
                         f"model {', '.join(map(repr, runs_on))}")
    raise ClfzaError(f"unknown method {method!r}; available: {sorted(REGISTRY)}")


#: iterations by which a solver that can (``step_deferred``: ADMM) reads its stopping rule
#: late: each iteration's sums have their reads started at once and are waited for STOP_LAG
#: iterations later, so the device always has that many iterations queued and the loop never
#: waits for a host round trip; the solver keeps its last STOP_LAG + 1 iterates, so the
#: result (image, iterations, history) is the one reading at every iteration gives. At most
#: 3: on CPU devices the sums are read from the reducers' rings of 8 results, two per
#: iteration. Not with a monitor (truth, checkpoints, callback), which reads every iteration
#: (docs/measurements.md, clfza.solvers._batch)
STOP_LAG = 2


def _late_reads(solver: Solver, stopper: Stopper) -> bool:
    mon = solver.mon
    return (hasattr(solver, "step_deferred") and stopper.rule in ("objective", "step")
            and mon.truth is None and mon.callback is None and mon.every is None
            and not mon.at)


def run(solver: Solver, x0) -> SolveResult:
    """Run ``solver`` from ``x0`` (measurement already set) until its stopping rule, a
    callback or ``iters``; returns the iterate, its host copy and the run's record."""
    mon = solver.mon
    stopper = solver.stopper()
    solver.needs_step = stopper.needs_step
    if _late_reads(solver, stopper):
        return _run_late(solver, x0, stopper)
    solver.setup(x0)
    mon.start()
    hist: list[float] = []
    last = solver.start()
    if last is not None:
        hist.append(last.objective)
        mon.maybe(0, last.x, last.objective, **last.extra)
    it, reason = 0, None
    while reason is None:
        it += 1
        prev = last
        last = solver.step(it)
        if last.objective is not None:
            hist.append(last.objective)
        stop = mon.maybe(it, last.x, last.objective, **last.extra)
        f_prev = prev.objective if (prev is not None and last.comparable) else None
        reason = "callback" if stop else stopper.check(it, last.objective, f_prev, last.step)
    x = solver.finish()
    solve_s = mon.elapsed()
    mon.final(it, x, last.objective, data=last.extra.get("data"))
    evals = solver.evaluations if solver.evaluations is not None else it
    return SolveResult(x=x, iterations=it, stop_reason=reason, objective=hist,
                       solve_s=solve_s, evaluations=evals, notes=solver.notes,
                       stats=solver.stats(hist))


def _run_late(solver: Solver, x0, stopper: Stopper) -> SolveResult:
    """:func:`run` with the stopping rule read :data:`STOP_LAG` iterations late (the same
    result; no monitor reads, :func:`_late_reads`)."""
    mon = solver.mon
    solver.setup(x0)
    solver.keep_iterates(STOP_LAG)
    mon.start()
    if solver.start() is not None:
        raise NotImplementedError("a late-reading solver's start must not report an objective")
    hist: list[float] = []
    pending: deque = deque()
    it, j, last, reason = 0, 0, None, None
    while reason is None:
        more = it < stopper.max_iters
        if more:
            it += 1
            pending.append((it, solver.step_deferred(it)))
        if len(pending) <= STOP_LAG and more:
            continue
        j, sums = pending.popleft()
        prev = last
        last = solver.resolve(sums)
        if last.objective is not None:
            hist.append(last.objective)
        f_prev = prev.objective if (prev is not None and last.comparable) else None
        reason = stopper.check(j, last.objective, f_prev, last.step)
    x = solver.finish_at(j)
    solve_s = mon.elapsed()
    mon.final(j, x, last.objective, data=last.extra.get("data"))
    evals = solver.evaluations if solver.evaluations is not None else j
    return SolveResult(x=x, iterations=j, stop_reason=reason, objective=hist,
                       solve_s=solve_s, evaluations=evals, notes=solver.notes,
                       stats=solver.stats(hist))


def check_finite(method: str, image: np.ndarray, tau: float) -> np.ndarray:
    """The host image of a solve, or a one-line error when it holds NaN or inf."""
    a = np.asarray(image)
    if a.dtype.kind == "f":
        # a finite sum has no NaN or inf among its terms (either makes the sum NaN or inf):
        # one pass without a boolean array; a sum that overflows is decided value by value
        with np.errstate(all="ignore"):
            if np.isfinite(np.sum(a)):
                return image
    if not np.isfinite(a).all():
        raise ClfzaError(f"{method} produced non-finite values (tau={tau}); this is a bug or a "
                         "far out-of-range input, please report it")
    return image
