"""``tau="auto"``: the regularisation weight chosen from the data, and the per-group context
the Wiener solve needs.

Transfer-function model: Morozov's discrepancy principle. The noise ``sigma`` is estimated
from the frame (:func:`clfza.noise.estimate_noise`); the residual target is ``KAPPA N
sigma^2`` (``KAPPA_UPPER`` where sigma is the Haar upper bound), floored at ``FLOOR^2
||y||^2`` (the model error that remains on a noise-free frame, where sigma measures mismatch,
not noise: without it tau collapsed, 29.3 dB where 0.01 gives 35 dB) and capped at ``CAP
||y||^2``. ``tau0 = lam_W * rms|D x_W|`` matches the TV weight to the Wiener solution; the
search (:func:`_search`) runs short warm-started stages (``STAGE_FRACTION`` of ``iters``) down
from ``x = 0`` at ``START_FACTOR * tau0`` in steps of ``STEP`` until the residual crosses the
target, interpolates the crossing in log-log and refines it with up to ``REFINE`` longer
stages; the full solve then runs at the chosen ``tau`` (about 2x one solve in all).

Exact model: ``tau = EXACT_FACTOR * tau0`` (one solve; see :func:`_exact_group`). ``tau``
keeps its user meaning there (the normalised operator's ``tau / s^2`` is applied inside).

The record: ``info.params["tau"]`` is the chosen ``tau`` (user units) and
``info.stats["tau_auto"]`` holds the criterion (rule, target, the residual at the chosen
``tau``, ``sigma``, the stages tried). Measured in ``bench/bench_tau.py``.
"""

from __future__ import annotations

import math

import numpy as np

from .errors import ClfzaError

KAPPA = 1.0           # residual target as a fraction of N sigma^2 (see bench/bench_tau.py)
EXACT_FACTOR = 16.0   # exact model: tau = EXACT_FACTOR * tau0 (see _exact_group)
START_FACTOR = 64.0   # the search starts at this multiple of the Wiener-matched tau0
STEP = 0.25           # tau ratio between the search's stages
REFINE = 3            # at most this many refinement stages (REFINE_FACTOR x longer)
REFINE_FACTOR = 3
REFINE_TOL = 0.05     # refinement stops when the residual is this close to the target
STAGE_FRACTION = 0.1  # iterations of one stage, as a fraction of iters (at least MIN_STAGE)
MIN_STAGE = 5
MAX_STAGES = 6
AUTO_METHODS = ("fista", "admm", "twist")
WIENER_X0 = ("fista", "admm")  # methods that start from the Wiener estimate by default
KAPPA_UPPER = 0.5     # ... when sigma is an upper bound (Haar MAD on a full-band frame)
FLOOR = 0.1           # model-error floor: the residual target is at least FLOOR^2 ||y||^2
CAP = 0.98            # ... and at most CAP ||y||^2 (x = 0 leaves ||y||^2)


def split_auto(options: dict, method: str) -> tuple[dict, bool]:
    """``options`` without ``tau="auto"`` and whether it was asked for."""
    tau = options.get("tau")
    if not (isinstance(tau, str) and tau.strip().lower() == "auto"):
        return options, False
    if method not in AUTO_METHODS:
        raise ClfzaError(f"tau='auto' is for the regularised solvers {AUTO_METHODS}, not "
                         f"{method!r}")
    if options.get("weight") is not None:
        raise ClfzaError("tau='auto' chooses the TV weight itself: leave weight= out")
    return {k: v for k, v in options.items() if k != "tau"}, True


def attach(B, camera, scale2: float, auto: bool = False) -> None:
    """Give the backend what per-group preparation needs (camera, normalisation)."""
    B.clfza_ctx = {"camera": camera, "scale2": float(scale2), "auto": bool(auto)}


def set_group(B, yg: np.ndarray) -> dict:
    """Per channel group: the measurement (user units) and its noise estimate."""
    from .noise import estimate_noise

    ctx = getattr(B, "clfza_ctx", None) or {}
    cam = ctx.get("camera")
    y = np.asarray(yg, dtype=np.float64)
    sig, how = 0.0, None
    if cam is not None:
        est = [estimate_noise(c, cam) for c in y]
        sig, how = float(np.sqrt(np.mean([e[0] ** 2 for e in est]))), est[0][1]
    g = {"y": y, "sigma": sig, "sigma_method": how, "scale2": ctx.get("scale2", 1.0)}
    B.clfza_group = g
    return g


def _residual2(B, x) -> float:
    g = B.empty()
    return float(B.resid_grad(x, g).get()[0])


def _set_tau(opts, tau: float) -> None:
    opts.tau = tau
    if hasattr(opts, "weight"):
        opts.weight = tau / 2.0


def _rms_grad(B, x) -> float:
    from . import regularizers as R

    a = B.to_host(x)
    d1, d2 = R.grad_circ(a)
    return float(np.sqrt(np.mean(d1**2 + d2**2)))


def wiener_circulant(B, lam: float):
    """The exact model's circulant Wiener estimate (host FFTs, one pair): ``F^-1[F(K^T y) /
    (c |H|^2 + lam |D|^2)]`` with ``c`` the sensor's share of the model grid (the crop's
    average effect on ``K^T K``, as the PCG's preconditioner), zero off the sensor window."""
    import scipy.fft

    from .backends.numpy_backend import diff_symbol
    from .solvers.wiener import _h2, measurement_pixels

    share = measurement_pixels(B) / float(np.prod(B.shape))
    den = share * _h2(B) + lam * diff_symbol(tuple(B.shape))
    den[0, 0] = 1.0
    X = scipy.fft.rfft2(B.to_host(B.b)) / den
    X[..., 0, 0] = 0.0
    x = scipy.fft.irfft2(X, s=tuple(B.shape))
    grid = B.geom
    return B.from_host(grid.embed(grid.crop(x)))


def wiener_start(B, g: dict):
    """The Wiener solution (TF model: :func:`~clfza.solvers.wiener.wiener_tf`; exact model:
    :func:`wiener_circulant`), ``lam`` from the frame's noise, and the TV weight matched to it
    (backend units)."""
    from .solvers.wiener import is_exact, wiener_lam, wiener_tf

    lam, _ = wiener_lam(B, g["y"], g["sigma"])
    if is_exact(B):
        x = wiener_circulant(B, lam)
    else:
        x = B.empty()
        wiener_tf(B, lam, x)
    return x, lam * max(_rms_grad(B, x), 1e-30), lam


def default_start(B, method: str, mode: str | None):
    """The default starting point and a note for the record: on the transfer-function model
    the Wiener estimate for FISTA and ADMM (measured better than ``K^T y`` at every iteration
    count: simulation preset, 100 iterations, ADMM 33.5 -> 36.9 dB noise-free and 19.4 ->
    25.1 dB at the Fig. 7 noise; FISTA 14.9 -> 34.1 and 16.0 -> 26.0 dB); ``K^T y`` otherwise
    (TwIST, whose paper mode starts there); zeros for the exact model's ADMM."""
    g = getattr(B, "clfza_group", None) or {}
    exact = getattr(B, "geom", None) is not None
    # exact model: the circulant Wiener estimate is a worse start for the crop-split ADMM
    # than zeros (experiment preset binned to 300^2, 100 iterations: 23.7 against 41.0 dB)
    if method in WIENER_X0 and "y" in g and not exact:
        x, _, lam = wiener_start(B, g)
        return x, f"x0: the Wiener estimate (lam = {lam * g.get('scale2', 1.0):.3g})"
    if exact and method == "admm":
        return B.zeros(), None
    return B.b, None


def _rule(B, g: dict) -> tuple[float, float]:
    """``(kappa, floor)`` of the residual target. The transfer-function model's mismatch
    (circular against linear convolution, the object's edge) acts as noise of about
    ``FLOOR`` of ``||y||``; the exact model has none (floor 0). Where the frame has no band
    beyond the mask's (``sigma`` from the Haar MAD, an upper bound that holds the signal's
    Nyquist energy) the noise term is ``KAPPA_UPPER N sigma^2``."""
    from .solvers.wiener import is_exact

    kappa = KAPPA_UPPER if str(g.get("sigma_method") or "").startswith("Haar") else KAPPA
    return kappa, (0.0 if is_exact(B) else FLOOR)


def run_group(cls, B, opts, mon, x0d, default_x0: bool):
    """One channel group: ``tau="auto"`` continuation when asked for, else one driver run."""
    from .solvers import driver

    ctx = getattr(B, "clfza_ctx", None) or {}
    if not ctx.get("auto"):
        return driver.run(cls(B, opts, mon), x0d)
    g = getattr(B, "clfza_group", None) or {}
    from .solvers.wiener import is_exact, measurement_pixels

    s2 = ctx.get("scale2", 1.0)
    sig_b2 = g.get("sigma", 0.0) ** 2 / s2
    n = measurement_pixels(B) * B.nc
    y = np.asarray(g.get("y", 0.0), dtype=np.float64)
    y2 = float(np.sum((y - y.mean(axis=(-2, -1), keepdims=True)) ** 2)) / s2 if y.ndim else 0.0
    kappa, floor = _rule(B, g)
    noise_target = kappa * n * sig_b2
    target = min(max(noise_target, floor**2 * y2), CAP * y2) if y2 > 0 else noise_target
    xw, tau0, lam = wiener_start(B, g)
    x = xw if default_x0 else x0d
    if is_exact(B):
        x = default_start(B, cls.method, None)[0] if default_x0 else x0d
        return _exact_group(cls, B, opts, mon, x, g, tau0, lam, target, s2)
    stage_iters = max(MIN_STAGE, int(round(STAGE_FRACTION * opts.iters)))
    x, chosen, stages, total = _search(cls, B, opts, tau0 * START_FACTOR, target, y2,
                                       stage_iters)
    _set_tau(opts, chosen)
    if default_x0 and cls.method == "fista":
        # FISTA from the search's iterate (which came down from x = 0) is as slow as from
        # K^T y (simulation preset noise-free: 15.8 dB in 200 iterations); from the Wiener
        # estimate it is at 34 dB in 10
        x = xw
    res = driver.run(cls(B, opts, mon), x)
    r_final = _residual2(B, res.x)
    res.stats = dict(res.stats)
    res.stats["tau_auto"] = {
        "criterion": "discrepancy", "kappa": kappa, "sigma": g.get("sigma", 0.0),
        "sigma_method": g.get("sigma_method"), "floor": floor, "cap": CAP, "y_energy": y2 * s2,
        "target_rule": ("noise" if target == noise_target else
                        "floor" if target > noise_target else "cap"),
        "target_residual2": target * s2, "residual2": r_final * s2,
        "discrepancy_ratio": (r_final / (n * sig_b2)) if sig_b2 > 0 else None,
        "tau": chosen * s2, "tau0": tau0 * s2, "wiener_lam": None if lam is None else lam * s2,
        "stages": [[t * s2, rr * s2] for t, rr in stages], "stage_iters": stage_iters,
        "stage_iterations_total": total}
    return res


def _search(cls, B, opts, tau: float, target: float, y2: float, stage_iters: int):
    """The discrepancy search (backend units): returns the last iterate, the chosen ``tau``,
    the stages ``(tau, residual)`` and the iterations they took.

    It runs down from ``x = 0`` at a ``tau`` well above the Wiener-matched one: there x = 0
    is nearly the solution, and each stage's lag (it starts from the previous, larger-tau
    iterate) errs on the side of a larger residual. Started from the Wiener estimate and going
    up instead, the stages lag with too small a residual and overshoot (photon-limited frames,
    where ||y||^2 is within a few % of N sigma^2: 10.5 dB instead of 21.5 dB)."""
    from .solvers import driver
    from .solvers.common import Monitor

    quiet = Monitor(B)
    stages: list[tuple[float, float]] = []
    saved = (opts.iters, opts.min_iters)
    opts.iters, opts.min_iters = stage_iters, min(stage_iters, opts.min_iters or 1)
    direction, total = 0, 0
    x = B.zeros()
    try:
        for _ in range(MAX_STAGES):
            _set_tau(opts, tau)
            res = driver.run(cls(B, opts, quiet), x)
            x, total = res.x, total + res.iterations
            r = _residual2(B, x)
            stages.append((tau, r))
            above = r > target
            if direction == 0:
                direction = -1 if above else 1
            elif (direction == -1 and not above) or (direction == 1 and above):
                break
            if target <= 0 and len(stages) > 1 and r >= stages[-2][1] * 0.999:
                break  # noise-free: the residual no longer drops
            tau = tau * (STEP if direction == -1 else 1.0 / STEP)
        chosen = _interpolate(stages, target)
        # refinement: the short stages lag behind the tau they run at (their residual is
        # biased towards the previous stage's), so re-measure at the interpolated tau with
        # longer stages and re-interpolate against the bracket (regula falsi in log-log)
        opts.iters = opts.min_iters = REFINE_FACTOR * stage_iters
        for _ in range(REFINE if _crossed(stages, target) else 0):
            _set_tau(opts, chosen)
            res = driver.run(cls(B, opts, quiet), x)
            x, total = res.x, total + res.iterations
            r = _residual2(B, x)
            stages.append((chosen, r))
            if abs(r - target) <= REFINE_TOL * min(target, max(y2 - target, 0.0)):
                break  # within 5% of the target's distance to 0 and to ||y||^2
            chosen = _bracket(stages, target)
    finally:
        opts.iters, opts.min_iters = saved
    return x, chosen, stages, total


def _exact_group(cls, B, opts, mon, x, g: dict, tau0: float, lam: float, target: float,
                 s2: float):
    """The exact model: ``tau = EXACT_FACTOR * tau0`` (the Wiener-matched weight), one solve.
    The crop-split ADMM's short stages do not bring the residual near its limit (10 stages
    of 10 iterations stay 10x above it on the experiment preset), so the discrepancy search
    has nothing to read; the factor is calibrated on bench/bench_tau.py's exact-model cases."""
    from .solvers import driver

    chosen = EXACT_FACTOR * tau0
    _set_tau(opts, chosen)
    res = driver.run(cls(B, opts, mon), x)
    r_final = _residual2(B, res.x)
    res.stats = dict(res.stats)
    res.stats["tau_auto"] = {
        "criterion": "wiener_matched", "factor": EXACT_FACTOR, "sigma": g.get("sigma", 0.0),
        "sigma_method": g.get("sigma_method"), "wiener_lam": lam * s2, "tau0": tau0 * s2,
        "tau": chosen * s2, "residual2": r_final * s2, "target_residual2": target * s2,
        "stages": [], "stage_iters": 0, "stage_iterations_total": 0}
    return res


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
    independently solved channels)."""
    a = res.stats.get("tau_auto")
    if not a:
        return
    if a["criterion"] == "wiener_matched":
        _record(info, a)
        info.notes.append(
            f"tau=auto: tau = {a['tau']:.4g} ({a['factor']:g} x the Wiener-matched weight "
            f"{a['tau0']:.3g}: lam = {a['wiener_lam']:.3g} from sigma = {a['sigma']:.3g} "
            f"({a['sigma_method']}), times rms|D x_W|; exact model)")
        return
    _record(info, a)
    info.notes.append(
        f"tau=auto: tau = {a['tau']:.4g} (discrepancy: ||y - K x||^2 = {a['residual2']:.4g}, "
        f"target {a['target_residual2']:.4g} by the {a['target_rule']} rule (noise: "
        f"{a['kappa']:g} N sigma^2, sigma = {a['sigma']:.3g}; model-error floor "
        f"{a['floor']:g}^2 ||y||^2; cap {a['cap']:g} ||y||^2); {len(a['stages'])} stages of "
        f"{a['stage_iters']} iterations)")


def _record(info, a: dict) -> None:
    if info.params.get("tau_mode") == "auto":  # a further channel
        prev = info.params["tau"]
        info.params["tau"] = (prev if isinstance(prev, list) else [prev]) + [a["tau"]]
    else:
        info.params["tau"] = a["tau"]
    info.params["tau_mode"] = "auto"
    info.stats["tau_auto"] = a
