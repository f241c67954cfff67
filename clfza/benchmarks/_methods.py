"""The benchmarked methods, their options, and the work model of one iteration.

The speed limit of one iteration (docs/design.md s.5) is ``fft_pairs * t_fft_pair +
arrays * N^2 * itemsize / bandwidth``: the real FFT pairs the method must do, plus one pass over
the arrays it must touch (counted in units of one real ``N x N`` array read *or* written; a
half spectrum of ``N (N/2 + 1)`` complex values counts as one array). The counts assume the
operations the backend interface (:mod:`clfza.backends._base`) fuses into single kernels:

===========================  ===========================================================
operation                    arrays touched
===========================  ===========================================================
``resid_grad``               spectrum multiply by ``H_T^2`` in place (read X, H^2 (0.5),
                             write X: 2.5) + ``g = K^T y - K^T K x`` (read 2, write 1): 5.5
Chambolle step (x k)         read p1, p2, f; write p1, p2: 5
Chambolle start + end        form ``v = x + g`` (read 2) and ``u = v - div p / lam``
                             (read p1, p2, v; write u): 6 (with the first step's p = 0)
TwIST two-step combine       read x_{t-1}, x_t, x_ist; write x_{t+1}: 4
FGP step (x k)               read r1, r2, b, p1, p2; write p1, p2, r1, r2: 9
FGP end                      read p1, p2, b; write u: 4
FISTA extrapolation          read the gradient steps w, w_prev; write y: 3
ADMM rhs                     read q1, q2, K^T y; write rhs: 4 (+2 with nonneg)
ADMM solve                   spectrum divide (read X, denominator 0.5, write X): 2.5
ADMM update                  read x, u1, u2; write u1, u2, q1, q2: 7 (+4 with nonneg)
BP                           spectrum multiply 2.5 (one FFT pair, once)
===========================  ===========================================================

Every iterative method needs one real FFT pair per objective evaluation: clfza's TwIST takes
the residual norm and the next gradient from one spectrum (the reference applies ``K`` and
``K^T`` separately, two pairs). An iteration that TwIST or MFISTA rejects (objective rose) costs
a second evaluation; the model counts one evaluation per iteration and the results report the
measured evaluations per iteration next to it.
"""

from __future__ import annotations

from dataclasses import dataclass, field

from ..errors import ClfzaError
from ..solvers import METHODS

# the paper's simulation settings (docs/design.md s.2): tau = 0.005, 200 iterations, 2 inner TV
PAPER_TAU = 0.005
PAPER_ITERS = 200
PAPER_TV_ITERS = 2


@dataclass(frozen=True)
class MethodSpec:
    """One benchmarked configuration of a reconstruction method.

    Attributes
    ----------
    key : str
        Short identifier used in result files (``"twist-tv-paper"``).
    label : str
        Human label for tables and plots.
    method : str
        The ``clfza.reconstruct`` method name.
    options : dict
        Method options (``iters`` is set by the benchmark).
    iters : int
        Iterations of a full run (the paper's 200 for the TwIST family).
    fft_pairs : float
        Real FFT pairs per iteration in the work model.
    arrays : float
        Real ``N x N`` arrays read or written per iteration in the work model.
    monotone : bool
        Whether the method promises a non-increasing objective.
    iterative : bool
        False for back-propagation (one application of ``K^T``).
    """

    key: str
    label: str
    method: str
    options: dict = field(default_factory=dict)
    iters: int = PAPER_ITERS
    fft_pairs: float = 1.0
    arrays: float = 0.0
    monotone: bool = False
    iterative: bool = True

    def limit_seconds(self, n_pixels: int, itemsize: int, t_fft_pair: float,
                      bandwidth: float) -> float:
        """The machine's limit for one iteration (for BP: the whole reconstruction)."""
        return self.fft_pairs * t_fft_pair + self.arrays * n_pixels * itemsize / bandwidth

    def bytes_model(self) -> str:
        return f"{self.fft_pairs:g} FFT pair(s) + {self.arrays:g} real arrays"


def _twist_arrays(tv_iters: int, reg: str) -> float:
    # prox: Chambolle (first step with p = 0 folded into the start) or soft threshold
    prox = 6 + 5 * max(tv_iters - 1, 0) if reg == "tv" else 3
    return float(5.5 + prox + 4)


def default_methods(tv_iters: int = PAPER_TV_ITERS, fgp_iters: int = 2) -> list[MethodSpec]:
    """The benchmarked methods: what :func:`clfza.reconstruct` does without a method (the
    default route, ``"auto"``: ADMM with ``tau="auto"`` on the model the camera and the
    frame's noise call for; its trace is its final solve, starting when its tau search
    ends), then the six of issue 5 at the paper's settings: BP; TwIST-TV paper mode; TwIST-TV
    efficient; TwIST-l1; FISTA-TV; ADMM-TV. Those TV methods use the paper's ``tau = 0.005``
    and the paper's transfer-function model (Eq. 17; the cost model below counts its one FFT
    pair per iteration); their labels say so. Last, FISTA-TV and ADMM-TV at their own setting,
    ``tau="auto"`` on Eq. 17 (traced as the default route is)."""
    tau = PAPER_TAU
    paper = f"(tau {tau:g})"
    return [
        MethodSpec("default", "default route (auto)", "auto", {}, iters=200, fft_pairs=1,
                   arrays=4 + 2.5 + 7, monotone=False),
        MethodSpec("bp", "BP (Eq. 12)", "bp", {}, iters=1, fft_pairs=1, arrays=2.5,
                   iterative=False),
        MethodSpec("twist-tv-paper", "TwIST-TV paper", "twist",
                   {"mode": "paper", "reg": "tv", "tau": tau, "tv_iters": tv_iters},
                   fft_pairs=1, arrays=_twist_arrays(tv_iters, "tv"), monotone=True),
        MethodSpec("twist-tv-efficient", "TwIST-TV efficient", "twist",
                   {"mode": "efficient", "reg": "tv", "tau": tau, "tv_iters": tv_iters},
                   fft_pairs=1, arrays=_twist_arrays(tv_iters, "tv"), monotone=True),
        MethodSpec("twist-l1", "TwIST-l1 paper", "twist",
                   {"mode": "paper", "reg": "l1", "tau": tau},
                   fft_pairs=1, arrays=_twist_arrays(0, "l1"), monotone=True),
        MethodSpec("fista-tv", f"FISTA-TV {paper}", "fista",
                   {"reg": "tv", "tau": tau, "model": "tf"},
                   fft_pairs=1, arrays=5.5 + 9 * fgp_iters + 4 + 3, monotone=True),
        MethodSpec("admm-tv", f"ADMM-TV {paper}", "admm",
                   {"reg": "tv", "tau": tau, "model": "tf"},
                   fft_pairs=1, arrays=4 + 2.5 + 7, monotone=False),
        MethodSpec("fista-tv-auto", "FISTA-TV (tau auto)", "fista",
                   {"reg": "tv", "tau": "auto", "model": "tf"},
                   fft_pairs=1, arrays=5.5 + 9 * fgp_iters + 4 + 3, monotone=True),
        MethodSpec("admm-tv-auto", "ADMM-TV (tau auto)", "admm",
                   {"reg": "tv", "tau": "auto", "model": "tf"},
                   fft_pairs=1, arrays=4 + 2.5 + 7, monotone=False),
    ]


def available(specs: list[MethodSpec] | None = None) -> list[MethodSpec]:
    """The specs whose method is registered in :data:`clfza.solvers.METHODS` (or is BP, or the
    default route)."""

    specs = default_methods() if specs is None else specs
    return [s for s in specs if s.method in ("bp", "auto") or s.method in METHODS]


def by_key(keys: list[str] | None, specs: list[MethodSpec] | None = None) -> list[MethodSpec]:
    """Select specs by key (None: all available)."""

    specs = available(specs)
    if not keys:
        return specs
    known = {s.key: s for s in default_methods()}
    bad = [k for k in keys if k not in known]
    if bad:
        raise ClfzaError(f"unknown method key(s) {bad}; choose from {sorted(known)}")
    have = {s.key for s in specs}
    return [known[k] for k in keys if k in have]
