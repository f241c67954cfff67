"""``tau="auto"``: the regularisation weight chosen from the data, and the per-group context
the Wiener solve needs.

Transfer-function model: Morozov's discrepancy principle. The noise ``sigma`` is estimated
from the frame (:func:`clfza.solvers._noise.estimate_noise`); the residual target is ``KAPPA N
sigma^2`` (``KAPPA_UPPER`` where sigma is the Haar upper bound), floored at ``FLOOR^2
||y||^2`` (the model error that remains on a noise-free frame, where sigma measures mismatch,
not noise: without it tau collapses) and capped at ``CAP ||y||^2``. ``tau0 = lam_W *
rms|D x_W|`` matches the TV weight to the Wiener solution; the search
(:class:`DiscrepancySearch`) runs short warm-started stages (``STAGE_FRACTION`` of
``iters``) down from ``x = 0`` at
``START_FACTOR * tau0`` in steps of ``STEP`` until the residual crosses the target,
interpolates the crossing in log-log and refines it with up to ``REFINE`` longer stages; the
full solve then runs at the chosen ``tau`` (about 2x one solve in all).

The exact model's rules are in :mod:`clfza.solvers._tau_exact`.

The record: ``info.params["tau"]`` is the chosen ``tau`` (user units) and
``info.stats["tau_auto"]`` holds the criterion (rule, target, the residual at the chosen
``tau``, ``sigma``, the stages tried; on the exact model ``sigma`` is in the units of the
frame the solver saw, see ``stats["data_scale_factor"]``). The constants were chosen by
measurement (``bench/bench_tau.py``; docs/measurements.md, clfza.solvers._tau).
"""

from __future__ import annotations

import dataclasses
import math
import os
import time
from concurrent.futures import ThreadPoolExecutor

import numpy as np
import scipy.fft

from .. import regularizers as R
from ..backends import diff_symbol
from ..errors import ClfzaError
from ..models import noise_gain
from . import _driver as driver
from ._common import Monitor
from ._context import ChannelGroup, SolveContext
from ._noise import estimate_noise, noise_from_power
from ._tau_exact import exact_group, residual2, set_tau
from ._wiener import (
    is_exact,
    measurement_pixels,
    spectrum_power,
    wiener_lam,
    wiener_lams,
    wiener_tf,
)

KAPPA = 1.0           # residual target as a fraction of N sigma^2 (see bench/bench_tau.py)
START_FACTOR = 64.0   # the search starts at this multiple of the Wiener-matched tau0
STEP = 0.25           # tau ratio between the search's stages
REFINE = 3            # at most this many refinement stages (REFINE_FACTOR x longer)
REFINE_FACTOR = 2     # ... each this many times a search stage (measured: clfza.solvers._tau)
REFINE_TOL = 0.05     # refinement stops when the residual is this close to the target
STAGE_FRACTION = 0.1  # iterations of one stage, as a fraction of iters (at least MIN_STAGE)
MIN_STAGE = 5
MAX_STAGES = 6
AUTO_METHODS = ("fista", "admm", "twist")
WIENER_X0 = ("fista", "admm")  # methods that start from the Wiener estimate by default
KAPPA_UPPER = 0.5     # ... when sigma is an upper bound (Haar MAD on a full-band frame)
FLOOR = 0.1           # model-error floor: the residual target is at least FLOOR^2 ||y||^2
CAP = 0.98            # ... and at most CAP ||y||^2 (x = 0 leaves ||y||^2)
# ADMM's final solve after the search, unless tol, stop or stop_window is given: the objective
# rule on the spread of the objective over FINAL_STOP_WINDOW iterations at FINAL_TOL per
# iteration (it starts at the search's last iterate, near its image: docs/measurements.md,
# clfza.solvers._tau)
FINAL_STOP_WINDOW = 20
FINAL_TOL = 5e-6


#: methods whose ``tau`` is ``"auto"`` when neither ``tau`` nor a TV ``weight`` is given (the
#: others keep the paper's 0.005: TwIST reproduces the paper's runs)
AUTO_BY_DEFAULT = ("admm",)


def split_auto(options: dict, method: str, model: str = "tf") -> tuple[dict, bool]:
    """``options`` without ``tau="auto"`` and whether it was asked for (on ``model``); for
    :data:`AUTO_BY_DEFAULT` methods (not on ``model="padded"``) a missing ``tau`` (and
    ``weight``) is ``"auto"``."""
    tau = options.get("tau")
    if (tau is None and options.get("weight") is None and method in AUTO_BY_DEFAULT
            and model != "padded"):
        return options, True
    if not (isinstance(tau, str) and tau.strip().lower() == "auto"):
        return options, False
    if model == "padded":
        raise ClfzaError("tau='auto' is not available on model='padded' (the numpy reference "
                         "of the linear-convolution model); use model='exact'")
    if method not in AUTO_METHODS:
        raise ClfzaError(f"tau='auto' is for the regularised solvers {AUTO_METHODS}, not "
                         f"{method!r}")
    if options.get("weight") is not None:
        raise ClfzaError("tau='auto' chooses the TV weight itself: leave weight= out")
    return {k: v for k, v in options.items() if k != "tau"}, True


def channel_group(B, ctx: SolveContext, yg: np.ndarray,
                  y_given: np.ndarray | None = None) -> ChannelGroup:
    """One channel group: the measurement the backend sees (user units) and its noise,
    estimated on the frame as given (``y_given``, default ``yg``; a high-passed frame,
    :mod:`clfza.models._highpass`, keeps ``1 - 1/w^2`` of a white noise's variance)."""
    y = np.asarray(yg, dtype=np.float64)
    est = [estimate_noise(c, ctx.camera) for c in (y if y_given is None else y_given)]
    sig = float(np.sqrt(np.mean([e[0] ** 2 for e in est])))
    k = B.exact.highpass if B.exact is not None else 0
    if k:
        sig *= noise_gain(k)
    return ChannelGroup(y, sig, est[0][1])


def frame_starts(B, ctx: SolveContext, planes: np.ndarray, nc: int = 1,
                 workers: int | None = None) -> tuple[list[ChannelGroup], list[float]]:
    """:func:`channel_group` and the Wiener start's ``lam`` (:func:`wiener_lam`) of every
    frame of a batch at once, on the transfer-function model.

    ``planes``: ``(F nc, H, W)``, each frame's ``nc`` channels in turn (user units, DC-free).
    One real FFT of each plane serves the noise estimate (:func:`noise_from_power`) and the
    ``lam`` search (:func:`wiener_lams`, the frames' searches in lockstep), instead of one FFT
    each; the frames are split over ``workers`` threads (default: the CPUs; numpy and
    scipy.fft release the GIL). Each frame gets, bit for bit, the group and ``lam`` it gets
    alone (:func:`channel_group`, :func:`wiener_start`).

    Examples
    --------
    >>> import numpy as np
    >>> from clfza import Camera
    >>> from clfza.backends import get_backend
    >>> cam = Camera.preset("simulation").with_shape((32, 32))
    >>> B = get_backend("numpy", cam)
    >>> ctx = SolveContext(cam, 1.0, False)
    >>> ys = np.random.default_rng(0).normal(size=(2, 32, 32))
    >>> groups, lams = frame_starts(B, ctx, ys)
    >>> lams[1] == wiener_lam(B, ys[1:2], channel_group(B, ctx, ys[1:2]).sigma)[0]
    True
    """
    if is_exact(B):
        raise ClfzaError("frame_starts is for the transfer-function model")
    planes = np.asarray(planes, dtype=np.float64)
    F = planes.shape[0] // nc
    k = B.exact.highpass if B.exact is not None else 0
    H2 = spectrum_power(B)  # read here: the threads below touch no OpenCL object

    def chunk(lo: int, hi: int):
        a = planes[lo * nc:hi * nc]
        means = a.mean(axis=(-2, -1))
        # plane by plane (a stack's transform leaves the caches: slower, the same values),
        # each mean-free plane and |Y|^2 in reused buffers, written into one power array:
        # the values of |rfft2(a - mean)|^2 without a stack-sized copy or a list to stack
        power = np.empty((len(a),) + H2.shape)
        c = np.empty(a.shape[1:])
        mag = np.empty(H2.shape)

        def fill_power(scale: float) -> None:  # power[i] = |rfft2((a[i] - mean) / scale)|^2
            for i, p in enumerate(a):
                np.subtract(p, means[i], out=c)
                np.abs(scipy.fft.rfft2(c if scale == 1.0 else c / scale), out=mag)
                np.square(mag, out=power[i])

        fill_power(1.0)
        est = noise_from_power(power, a, ctx.camera)
        groups = []
        for f in range(hi - lo):
            e = est[f * nc:(f + 1) * nc]
            sig = float(np.sqrt(np.mean([v[0] ** 2 for v in e])))
            if k:
                sig *= noise_gain(k)
            groups.append(ChannelGroup(a[f * nc:(f + 1) * nc], sig, e[0][1]))
        if B.data_scale != 1.0:  # wiener_lam's spectrum is of the frame in backend units
            fill_power(B.data_scale)
        # one channel: the power itself (a sum over one plane is that plane)
        y2 = power if nc == 1 else power.reshape((hi - lo, nc) + power.shape[1:]).sum(axis=1)
        lams = wiener_lams(B, y2, [g.sigma for g in groups], nc, H2=H2)
        return groups, [lam for lam, _ in lams]

    T = max(1, min(F, workers or os.cpu_count() or 1))
    edges = [F * i // T for i in range(T + 1)]
    if T == 1:
        parts = [chunk(0, F)]
    else:
        with ThreadPoolExecutor(T) as pool:
            parts = list(pool.map(chunk, edges[:-1], edges[1:]))
    return ([g for p in parts for g in p[0]], [lam for p in parts for lam in p[1]])


def _rms_grad(B, x) -> float:

    a = B.to_host(x)
    d1, d2 = R.grad_circ(a)
    return float(np.sqrt(np.mean(d1**2 + d2**2)))


def wiener_circulant(B, lam: float):
    """The exact model's circulant Wiener estimate (host FFTs, one pair): ``F^-1[F(K^T y) /
    (c |H|^2 + lam |D|^2)]`` with ``c`` the sensor's share of the model grid (the crop's
    average effect on ``K^T K``, as the PCG's preconditioner), zero off the image window."""


    share = measurement_pixels(B) / float(np.prod(B.shape))
    den = share * spectrum_power(B) + lam * diff_symbol(tuple(B.shape))
    den[0, 0] = 1.0
    X = scipy.fft.rfft2(B.to_host(B.b)) / den
    X[..., 0, 0] = 0.0
    x = scipy.fft.irfft2(X, s=tuple(B.shape))
    grid = B.exact.image_geom
    return B.from_host(grid.embed(grid.crop(x)))


def wiener_start(B, g: ChannelGroup, tv_weight: bool = True):
    """The Wiener solution (TF model: :func:`~clfza.solvers._wiener.wiener_tf`; exact model:
    :func:`wiener_circulant`), ``lam`` from the frame's noise, and the TV weight matched to it
    (backend units; None unless ``tv_weight``: one host pass over the image, that only
    ``tau="auto"`` reads; its cost: docs/measurements.md, clfza.solvers._tau)."""

    lam, _ = wiener_lam(B, g.y, g.sigma)
    if is_exact(B):
        x = wiener_circulant(B, lam)
    else:
        x = B.empty()
        wiener_tf(B, lam, x)
    return x, (lam * max(_rms_grad(B, x), 1e-30) if tv_weight else None), lam


def default_start(B, ctx: SolveContext, method: str):
    """The default starting point and a note for the record: on the transfer-function model
    the Wiener estimate for FISTA and ADMM (``WIENER_X0``; better than ``K^T y`` at every
    iteration count, measured: docs/measurements.md, clfza.solvers._tau); ``K^T y`` otherwise
    (TwIST, whose paper mode starts there, and every method on the numpy ``"padded"`` model,
    whose ``K^T K`` is not Fourier-diagonal, so it has no Wiener division); zeros for the exact
    model's ADMM."""
    g = ctx.group
    exact = B.exact is not None
    # exact model: the circulant Wiener estimate is a worse start for the crop-split ADMM
    # than zeros (measured: docs/measurements.md, clfza.solvers._tau)
    if method in WIENER_X0 and g is not None and not exact and B.fourier_diagonal:
        x, _, lam = wiener_start(B, g, tv_weight=False)
        return x, f"x0: the Wiener estimate (lam = {ctx.user_units(lam):.3g})"
    if exact and method == "admm":
        return B.zeros(), None
    return B.b, None


def _rule(g: ChannelGroup) -> tuple[float, float]:
    """``(kappa, floor)`` of the transfer-function model's residual target. Its mismatch
    (circular against linear convolution, the object's edge) acts as noise of about
    ``FLOOR`` of ``||y||``. Where the frame has no band beyond the mask's (``sigma`` from the
    Haar MAD, an upper bound that holds the signal's Nyquist energy) the noise term is
    ``KAPPA_UPPER N sigma^2``."""
    kappa = KAPPA_UPPER if str(g.sigma_method or "").startswith("Haar") else KAPPA
    return kappa, FLOOR


def run_group(cls, B, opts, mon, x0d, default_x0: bool, ctx: SolveContext):
    """One channel group (``ctx.group``): ``tau="auto"`` continuation when asked for, else
    one driver run."""
    if not ctx.auto_tau:
        return driver.run(cls(B, opts, mon, ctx), x0d)
    t0 = time.perf_counter()
    res = _auto_group(cls, B, opts, mon, x0d, default_x0, ctx)
    # what the final solve did not spend: the search (its checkpoints' overhead is the
    # monitor's, counted apart in timings["checkpoint_overhead"])
    res.search_s = max(time.perf_counter() - t0 - res.solve_s - mon.overhead, 0.0)
    return res


def _auto_group(cls, B, opts, mon, x0d, default_x0: bool, ctx: SolveContext):
    """``tau="auto"`` for one channel group (see :func:`run_group`)."""
    g = ctx.group
    s2 = ctx.scale2
    n = measurement_pixels(B) * B.nc
    if is_exact(B):
        y = g.y
        y2 = float(np.sum((y - y.mean(axis=(-2, -1), keepdims=True)) ** 2)) / s2 if y.ndim \
            else 0.0
        x = default_start(B, ctx, cls.method)[0] if default_x0 else x0d
        return exact_group(cls, B, opts, mon, x, ctx, n, y2)
    xw, tau0, lam = wiener_start(B, g)
    x = xw if default_x0 else x0d
    search = DiscrepancySearch.for_group(g, s2, n, tau0, opts)
    x = _search(cls, B, opts, search, ctx)
    set_tau(opts, search.chosen)
    if default_x0 and cls.method == "fista":
        # FISTA from the search's iterate (which came down from x = 0) is as slow as from
        # K^T y; from the Wiener estimate it is far faster (measured: docs/measurements.md,
        # clfza.solvers._tau)
        x = xw
    final, stop = final_options(opts, cls.method)
    res = driver.run(cls(B, final, mon, ctx), x)
    res.stats = dict(res.stats)
    res.stats["tau_auto"] = search.record(g, s2, lam, residual2(B, res.x), stop)
    return res


def final_options(opts, method: str) -> tuple[object, dict | None]:
    """The options of the final solve after the discrepancy search, and the stop they set
    (None: ``opts`` as given). For ADMM, where none of ``tol``, ``stop`` and
    ``stop_window`` is given: a copy of ``opts`` that stops on the spread of the objective
    over ``FINAL_STOP_WINDOW`` iterations at ``FINAL_TOL``. The solve starts at the search's
    last iterate, near its image, where the one-step rule runs on long after the image has
    settled, or stops at one flat step.

    Examples
    --------
    >>> from clfza.solvers import AdmmOptions
    >>> final_options(AdmmOptions(), "admm")[1]
    {'stop_window': 20, 'tol': 5e-06}
    >>> final_options(AdmmOptions(tol=1e-7), "admm")[1] is None
    True
    """
    if method != "admm" or {"tol", "stop", "stop_window"} & set(opts.given()):
        return opts, None
    stop = {"stop_window": FINAL_STOP_WINDOW, "tol": FINAL_TOL}
    return dataclasses.replace(opts, **stop), stop


class DiscrepancySearch:
    """The discrepancy search of one channel group as a state machine (backend units), so
    that one group (:func:`_search`) and a batch of frames in lockstep
    (:mod:`clfza.solvers._batch`) run the same steps: :meth:`stage` says what to run next
    (``tau``, ``iters``, ``min_iters``; None when done), :meth:`observe` takes the residual
    ``||y - K x||^2`` of the stage's iterate.

    It runs down from ``x = 0`` at a ``tau`` well above the Wiener-matched one: there x = 0
    is nearly the solution, and each stage's lag (it starts from the previous, larger-tau
    iterate) errs on the side of a larger residual. Started from the Wiener estimate and going
    up instead, the stages lag with too small a residual and overshoot (seen on photon-limited
    frames, where ||y||^2 is close to N sigma^2; measured: docs/measurements.md,
    clfza.solvers._tau). Then the refinement: the short stages lag behind the tau they run at
    (their residual is biased towards the previous stage's), so it re-measures at the
    interpolated tau with longer stages and re-interpolates against the bracket (regula falsi
    in log-log).
    """

    def __init__(self, tau: float, target: float, y2: float, stage_iters: int,
                 min_iters: int | None, noise_target: float, tau0: float):
        self.tau, self.target, self.y2 = tau, target, y2
        self.stage_iters = stage_iters
        self.search_min = min(stage_iters, min_iters or 1)
        self.noise_target, self.tau0 = noise_target, tau0
        self.stages: list[tuple[float, float]] = []
        self.phase = "search"
        self.direction = 0
        self.count = 0
        self.refine_left = 0
        self.chosen = tau
        self.total = 0  # iterations the stages took

    @classmethod
    def for_group(cls, g: ChannelGroup, s2: float, n: int, tau0: float, opts
                  ) -> DiscrepancySearch:
        """The search of a group: target ``KAPPA N sigma^2`` (:func:`_rule`), floored at
        ``FLOOR^2 ||y||^2`` and capped at ``CAP ||y||^2``; stages of ``STAGE_FRACTION`` of
        ``opts.iters``, from ``START_FACTOR tau0``."""
        y = g.y
        y2 = float(np.sum((y - y.mean(axis=(-2, -1), keepdims=True)) ** 2)) / s2 if y.ndim \
            else 0.0
        kappa, floor = _rule(g)
        noise_target = kappa * n * g.sigma ** 2 / s2
        target = min(max(noise_target, floor**2 * y2), CAP * y2) if y2 > 0 else noise_target
        stage_iters = max(MIN_STAGE, int(round(STAGE_FRACTION * opts.iters)))
        out = cls(tau0 * START_FACTOR, target, y2, stage_iters, opts.min_iters, noise_target,
                  tau0)
        out.kappa, out.floor = kappa, floor
        return out

    @property
    def done(self) -> bool:
        return self.phase == "done"

    def stage(self) -> tuple[float, int, int] | None:
        """``(tau, iters, min_iters)`` of the next stage, or None when the search is over."""
        if self.phase == "search":
            return self.tau, self.stage_iters, self.search_min
        if self.phase == "refine":
            k = REFINE_FACTOR * self.stage_iters
            return self.chosen, k, k
        return None

    def observe(self, r: float, iterations: int) -> None:
        """The residual of the stage just run (and its iterations)."""
        self.total += iterations
        target = self.target
        if self.phase == "refine":
            self.stages.append((self.chosen, r))
            self.refine_left -= 1
            if abs(r - target) <= REFINE_TOL * min(target, max(self.y2 - target, 0.0)):
                self.phase = "done"  # within 5% of the target's distance to 0 and ||y||^2
                return
            self.chosen = _bracket(self.stages, target)
            if self.refine_left == 0:
                self.phase = "done"
            return
        self.stages.append((self.tau, r))
        above = r > target
        end = False
        if self.direction == 0:
            self.direction = -1 if above else 1
        elif (self.direction == -1 and not above) or (self.direction == 1 and above):
            end = True
        if not end and target <= 0 and len(self.stages) > 1 \
                and r >= self.stages[-2][1] * 0.999:
            end = True  # noise-free: the residual no longer drops
        if not end:
            self.tau = self.tau * (STEP if self.direction == -1 else 1.0 / STEP)
            self.count += 1
            end = self.count == MAX_STAGES
        if end:
            self.chosen = _interpolate(self.stages, target)
            self.refine_left = REFINE if _crossed(self.stages, target) else 0
            self.phase = "refine" if self.refine_left else "done"

    def record(self, g: ChannelGroup, s2: float, lam, r_final: float,
               final_stop: dict | None = None) -> dict:
        """``info.stats["tau_auto"]`` of the search (user units), with the final residual
        and the final solve's stop where :func:`final_options` set it."""
        n_sig = self.noise_target / self.kappa if self.kappa else 0.0  # N sigma^2 (backend)
        return {
            "criterion": "discrepancy", "kappa": self.kappa, "sigma": g.sigma,
            "sigma_method": g.sigma_method, "floor": self.floor, "cap": CAP,
            "y_energy": self.y2 * s2,
            "target_rule": ("noise" if self.target == self.noise_target else
                            "floor" if self.target > self.noise_target else "cap"),
            "target_residual2": self.target * s2, "residual2": r_final * s2,
            "discrepancy_ratio": (r_final / n_sig) if n_sig > 0 else None,
            "tau": self.chosen * s2, "tau0": self.tau0 * s2,
            "wiener_lam": None if lam is None else lam * s2,
            "stages": [[t * s2, rr * s2] for t, rr in self.stages],
            "stage_iters": self.stage_iters, "stage_iterations_total": self.total,
            "final_stop": final_stop}


def _search(cls, B, opts, search: DiscrepancySearch, ctx: SolveContext):
    """Run ``search``'s stages on one group, each from the previous stage's iterate (the
    first from ``x = 0``); returns the last iterate."""
    quiet = Monitor(B)
    saved = (opts.iters, opts.min_iters)
    x = B.zeros()
    try:
        while (st := search.stage()) is not None:
            tau, opts.iters, opts.min_iters = st
            set_tau(opts, tau)
            res = driver.run(cls(B, opts, quiet, ctx), x)
            x = res.x
            search.observe(residual2(B, x), res.iterations)
    finally:
        opts.iters, opts.min_iters = saved
    return x


def _crossed(stages: list[tuple[float, float]], target: float) -> bool:
    return target > 0 and any(r > target for _, r in stages) and any(r <= target
                                                                      for _, r in stages)


def _bracket(stages: list[tuple[float, float]], target: float) -> float:
    """``tau`` where the residual crosses ``target``, interpolated in log-log between the
    latest stage above the target and the latest below it."""
    above = [s for s in stages if s[1] > target]
    below = [s for s in stages if s[1] <= target]
    return _interpolate([above[-1], below[-1]], target)


def _interpolate(stages: list[tuple[float, float]], target: float) -> float:
    """``tau`` where the residual crosses ``target`` (log-log between the last two stages);
    the last stage's ``tau`` when it never crossed."""
    if len(stages) < 2:
        return stages[-1][0]
    (t1, r1), (t2, r2) = stages[-2], stages[-1]
    if target <= 0 or (r1 - target) * (r2 - target) > 0 or r1 <= 0 or r2 <= 0 or r1 == r2:
        return t2
    a = (math.log(target) - math.log(r1)) / (math.log(r2) - math.log(r1))
    return float(math.exp(math.log(t1) + a * (math.log(t2) - math.log(t1))))


def record_tau(info, res) -> None:
    """Put the chosen ``tau`` of a channel group into the info record (a list over
    independently solved channels) and its note."""
    a = res.stats.get("tau_auto")
    if not a:
        return
    _record(info, a)
    info.notes.append(tau_auto_note(a))


def tau_auto_note(a: dict) -> str:
    """The one-line note of a ``tau="auto"`` choice from its record
    (``info.stats["tau_auto"]``), in the record's units.

    Parameters
    ----------
    a : dict
        The choice's record: ``criterion`` (``"residual_noise"`` or ``"noise_proportional"``
        on the exact model, else the discrepancy search's) and the fields that rule records.

    Returns
    -------
    str
        ``"tau=auto: tau = ... (how it was chosen)"``.

    Examples
    --------
    >>> tau_auto_note({"criterion": "noise_proportional", "tau": 0.02, "factor": 1.0,
    ...                "w": 1.0, "noise_fraction": 0.1, "sigma_method": "Haar MAD",
    ...                "rule": "noise"})[:26]
    'tau=auto: tau = 0.02 (exac'
    """
    if a["criterion"] == "residual_noise":
        n = len(a["stages"]) - bool(a.get("pilot_start"))
        after = f"{n} pilot passes of {a['stage_iters']} iterations"
        if a.get("pilot_start"):
            after = ("the pilot estimate given as the start" if n == 0
                     else f"the pilot estimate given as the start and {after}")
        passes = (f"the Haar MAD of the model's residual after {after}, the frame's own "
                  f"estimate {a['sigma_frame']:.3g}"
                  + (("; the final solve continues the last pass (its image, splits and "
                      "duals)" if a.get("continued") else
                      "; the final solve starts from the last pass's image" if n else
                      "; the final solve starts from it") if a["stages"] else ""))
        if a["rule"] == "noise_free":
            ratio = a["stages"][-1][2]
            form = a.get("noise_free_form") or f"{a['noise_free_tau']:g} x rms(y)"
            return (f"tau=auto: tau = {a['tau']:.4g} ({form}: no "
                    f"noise found; the residual still holds signal (Haar scale ratio "
                    f"{ratio:.2f} > {a['white_max']:g}, white noise gives 1) and fell to sigma "
                    f"= {a['sigma']:.3g}, {passes})")
        psf = a.get("kernel") == "measured_psf"  # no r1': PSF_TAU_FACTOR x sigma
        r1_form = (f"(p / r1' capped at {a['pixel_r1']:g}) x " if a.get("pixel_r1_capped")
                   else "(p / r1') x ")
        form = f"{a['factor']:g} x " + ("" if psf else r1_form) + "sigma"
        tone = a.get("tone_factor") or 1.0
        sparse = a.get("w", 1.0) / tone
        if sparse != 1.0:  # the sparse-scene multiple (clfza.solvers._tau_exact.energy_support)
            form += (f" x {sparse:g}: the pilot estimate's energy lies in "
                     f"{a['energy_support']:.3g} of its pixels, a sparse scene")
        if tone != 1.0:  # the continuous-tone multiple (clfza.solvers._tau_exact.tone_factor)
            form += (f" x {tone:.3g}: {a['mid_tone_share']:.0%} of the pilot estimate's "
                     f"pixels are mid-tones, a continuous-tone scene at noise fraction "
                     f"{a['noise_fraction']:.3g}")
        floor = (f"; raised to the floor {a['floor']:g} x rms(y)" if a["rule"] == "floor"
                 else "")
        return (f"tau=auto: tau = {a['tau']:.4g} ("
                + ("measured PSF" if psf else "exact model")
                + f"{' with the data high-pass' if a.get('highpass', True) else ''}: "
                f"{form}; sigma = {a['sigma']:.3g}, {passes}{floor})")
    if a["criterion"] == "noise_proportional":
        return (f"tau=auto: tau = {a['tau']:.4g} (exact model: {a['factor']:g} x sigma x ||K||"
                f" x {a['w']:.3g} for the frame's noise fraction {a['noise_fraction']:.3g}; "
                f"sigma from the {a['sigma_method']}"
                + ("; the floor " + f"{a['floor']:g} x rms(y) x ||K||" if a["rule"] == "floor"
                   else "") + ")")
    return (f"tau=auto: tau = {a['tau']:.4g} (discrepancy: ||y - K x||^2 = {a['residual2']:.4g}, "
            f"target {a['target_residual2']:.4g} by the {a['target_rule']} rule (noise: "
            f"{a['kappa']:g} N sigma^2, sigma = {a['sigma']:.3g}; model-error floor "
            f"{a['floor']:g}^2 ||y||^2; cap {a['cap']:g} ||y||^2); {len(a['stages'])} stages of "
            f"{a['stage_iters']} iterations"
            + (f"; the final solve stops when the objective's spread over "
               f"{stop['stop_window']} iterations, per iteration, falls to {stop['tol']:g} "
               f"of its value" if (stop := a.get("final_stop")) else "") + ")")


def _record(info, a: dict) -> None:
    if info.params.get("tau_mode") == "auto":  # a further channel
        prev = info.params["tau"]
        info.params["tau"] = (prev if isinstance(prev, list) else [prev]) + [a["tau"]]
    else:
        info.params["tau"] = a["tau"]
    info.params["tau_mode"] = "auto"
    if a.get("final_stop"):  # the final solve's stop (final_options), as it ran
        info.params.update(a["final_stop"])
    info.stats["tau_auto"] = a
