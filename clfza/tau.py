"""``tau="auto"``: the regularisation weight chosen from the data (Morozov's discrepancy
principle with warm-started continuation), and the per-group context the Wiener solve needs.

The noise ``sigma`` is estimated from the frame (:func:`clfza.plan.estimate_noise`). The
continuation starts from a TV weight matched to the Wiener solution (``tau0 = lam_W *
rms|D x_W|``: the TV and Tikhonov gradients agree where ``|D x|`` is typical) and runs short
warm-started stages of the solver (``STAGE_FRACTION`` of ``iters`` each) over
``tau_k = tau0 * STEP^k`` (down while the residual ``||y - K x||^2`` is above the target, up
while it is below) until the residual crosses ``KAPPA N sigma^2``; the crossing is
interpolated in ``log tau`` and the full solve runs there, warm-started from the nearest
stage. At most ``MAX_STAGES`` stages, so the whole costs at most ~``1 + MAX_STAGES *
STAGE_FRACTION`` solves. ``tau`` keeps its user meaning on the exact model (the normalised
operator's ``tau / s^2`` is applied inside).

The record: ``info.params["tau"]`` is the chosen ``tau`` (user units) and
``info.stats["tau_auto"]`` holds the criterion (target, the residual at the chosen ``tau``,
``sigma``, the stages tried).
"""

from __future__ import annotations

import math

import numpy as np

from .errors import ClfzaError

KAPPA = 1.0           # residual target as a fraction of N sigma^2 (see bench/bench_tau.py)
STEP = 0.5            # tau ratio between stages
STAGE_FRACTION = 0.1  # iterations of one stage, as a fraction of iters (at least MIN_STAGE)
MIN_STAGE = 5
MAX_STAGES = 8
AUTO_METHODS = ("fista", "admm", "twist")


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
    sig = 0.0
    if cam is not None:
        sig = float(np.sqrt(np.mean([estimate_noise(c, cam)[0] ** 2 for c in y])))
    g = {"y": y, "sigma": sig, "scale2": ctx.get("scale2", 1.0)}
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


def wiener_start(B, g: dict):
    """The Wiener solution (TF model) or ``K^T y`` (exact model) and the TV weight matched to
    it (backend units)."""
    from .solvers.wiener import is_exact, wiener_lam, wiener_tf

    if is_exact(B):
        x = B.empty()
        B.copy(x, B.b)
        # no Wiener on the exact model: tau0 from the back-projection's scale
        lam = 1e-3
        return x, lam * max(_rms_grad(B, x), 1e-30), None
    lam, _ = wiener_lam(B, g["y"], g["sigma"])
    x = B.empty()
    wiener_tf(B, lam, x)
    return x, lam * max(_rms_grad(B, x), 1e-30), lam


def run_group(cls, B, opts, mon, x0d, default_x0: bool):
    """One channel group: ``tau="auto"`` continuation when asked for, else one driver run."""
    from .solvers import driver
    from .solvers.common import Monitor

    ctx = getattr(B, "clfza_ctx", None) or {}
    if not ctx.get("auto"):
        return driver.run(cls(B, opts, mon), x0d)
    g = getattr(B, "clfza_group", None) or {}
    from .solvers.wiener import measurement_pixels

    s2 = ctx.get("scale2", 1.0)
    sig_b2 = g.get("sigma", 0.0) ** 2 / s2
    n = measurement_pixels(B) * B.nc
    target = KAPPA * n * sig_b2
    xw, tau0, lam = wiener_start(B, g)
    x = xw if default_x0 else x0d
    iters_full = opts.iters
    stage_iters = max(MIN_STAGE, int(round(STAGE_FRACTION * iters_full)))
    quiet = Monitor(B)
    stages: list[tuple[float, float]] = []
    xs: dict[float, object] = {}
    saved = (opts.iters, opts.min_iters)
    opts.iters, opts.min_iters = stage_iters, min(stage_iters, opts.min_iters or 1)
    tau, direction = tau0, 0
    try:
        for _ in range(MAX_STAGES):
            _set_tau(opts, tau)
            res = driver.run(cls(B, opts, quiet), x)
            x = res.x
            r = _residual2(B, x)
            stages.append((tau, r))
            xk = B.empty()
            B.copy(xk, x)
            xs[tau] = xk
            above = r > target
            if direction == 0:
                direction = -1 if above else 1
            elif (direction == -1 and not above) or (direction == 1 and above):
                break
            if target <= 0 and len(stages) > 1 and r >= stages[-2][1] * 0.999:
                break  # noise-free: the residual no longer drops
            tau = tau * (STEP if direction == -1 else 1.0 / STEP)
    finally:
        opts.iters, opts.min_iters = saved
    chosen = _interpolate(stages, target)
    near = min(xs, key=lambda t: abs(math.log(t / chosen)))
    _set_tau(opts, chosen)
    res = driver.run(cls(B, opts, mon), xs[near])
    r_final = _residual2(B, res.x)
    res.stats = dict(res.stats)
    res.stats["tau_auto"] = {
        "criterion": "discrepancy", "kappa": KAPPA, "sigma": g.get("sigma", 0.0),
        "target_residual2": target * s2, "residual2": r_final * s2,
        "discrepancy_ratio": (r_final / (n * sig_b2)) if sig_b2 > 0 else None,
        "tau": chosen * s2, "tau0": tau0 * s2, "wiener_lam": None if lam is None else lam * s2,
        "stages": [[t * s2, rr * s2] for t, rr in stages], "stage_iters": stage_iters,
        "stage_iterations_total": stage_iters * len(stages)}
    return res


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
    if info.params.get("tau_mode") == "auto":  # a further channel
        prev = info.params["tau"]
        info.params["tau"] = (prev if isinstance(prev, list) else [prev]) + [a["tau"]]
    else:
        info.params["tau"] = a["tau"]
    info.params["tau_mode"] = "auto"
    info.stats["tau_auto"] = a
    info.notes.append(
        f"tau=auto: tau = {a['tau']:.4g} (discrepancy: ||y - K x||^2 = {a['residual2']:.4g}, "
        f"target {a['target_residual2']:.4g} = {a['kappa']:g} N sigma^2, sigma = "
        f"{a['sigma']:.3g}; {len(a['stages'])} stages of {a['stage_iters']} iterations)")
