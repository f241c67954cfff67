"""What to skip for this scene, and why (docs/design.md s.3).

Work that the physics says cannot change the answer should not be done, and clfza says what it
skipped. :func:`make_plan` looks at the camera and the measurement and decides:

* **binning** -- the aperture records spatial frequencies only up to ``rho_c = R'/r1'^2``
  (docs/design.md s.1; the sensor-side band limit of Eqs. 4-6). When the pixel Nyquist
  frequency ``1/(2p)`` exceeds it by a factor ``b >= 2`` the measurement is resampled onto a
  grid ``b`` times coarser with an ideal (Fourier-crop) anti-alias filter and reconstructed
  there. On that grid the transfer function ``H_T`` of Eq. 17 is sampled at exactly the same
  frequencies (``fftfreq(N/b, b p) = fftfreq(N, p)`` for ``|f| < 1/(2 b p)``), so the
  binned problem is the in-band part of the full one. With the TV weight scaled as
  ``tau_b = tau / b`` the binned objective (Eq. 19) is ``1/b^2`` times the in-band full one
  (data term ``~ pixels``, TV ``~ pixels^(1/2)``). Binning also moves the sampling ratio
  ``r1'^2 / (N p^2)`` to ``1/b`` of its value -- towards critical sampling for the paper's
  experiment (3.1 -> 1.04).
* **flat, empty or saturated frames** -- no iterative solve; a defined result (zeros: the DC
  is not recoverable, ``H_T(0) = 0``) and a warning.
* **grey scenes in RGB frames** -- channels equal up to a gain and the noise: solve once on
  their least-squares combination, replicate with the gains.
* **noise level and discrepancy principle** -- ``sigma`` from the spectrum outside the band
  limit (pure noise for a GZP; the median of ``|Y|^2`` over those frequencies is
  ``ln 2 * N sigma^2`` for white noise), else Donoho's MAD of the finest diagonal Haar band.
  Morozov's discrepancy principle stops an iterative solver at the first iterate with
  ``||y - K x||^2 <= tau_d * N * sigma^2`` (:class:`DiscrepancyStop`).
* **float32 where it suffices** -- see :func:`float32_suffices`.
* **field of view** -- the sensor region the scene actually covers: ``M w / p`` pixels for an
  object ``w`` mm wide at ``z1`` (Eq. 2; the paper's 200 mm display at 300 mm with z2 = 3 mm
  and 3.8 um pixels gives its central 526 x 526), or estimated from the measurement.

:func:`reconstruct_planned` runs :func:`clfza.reconstruct` with the plan and lists what it
skipped in ``info.notes`` (the plan itself is ``info.plan``); :meth:`Plan.explain` prints the
plan with a reason for each choice.
"""

from __future__ import annotations

import math
import time
import warnings

import numpy as np

from ..camera import Camera
from ..errors import ClfzaError, finite_image
from ..solvers import (  # noqa: F401  (re-exported: clfza.reconstruction._plan.estimate_noise & co.)
    DEFAULT_BACKEND,
    DEFAULT_METHOD,
    MethodOptions,
    ReconInfo,
    Reconstruction,
    encoded_band_energy,
    estimate_noise,
    freq_radius,
    haar_mad_sigma,
    method_model,
    option_names,
    out_of_band_mask,
    resolve_method,
)
from ..solvers import default_iters as registered
from ._plan_measure import (  # noqa: F401  (re-exported: the thresholds and measurements)
    EPS32,
    FLAT_CONFIDENCE,
    FLAT_EFFECT,
    FLOAT32_FACTOR,
    GREY_TOL,
    MIN_BIN,
    SATURATED_SKIP,
    SATURATED_WARN,
    flat_test,
    float32_suffices,
    fov_from_geometry,
    fov_from_measurement,
    grey_channels,
    saturation,
)
from ._plan_record import (  # noqa: F401  (re-exported: the record and its application)
    Decision,
    DiscrepancyStop,
    Plan,
    apply_plan,
    bin_measurement,
    binned_exact_model,
    finish_plan,
    upsample_image,
)
from ._reconstruct import balanced, method_and_options, reconstruct


class PlanWarning(UserWarning):
    """The planner skipped a solve or found a frame that violates the linear model."""



def _fft_work(shape: tuple[int, int]) -> float:
    n = shape[0] * shape[1]
    return n * math.log2(max(2, n))


# ----------------------------------------------------------------------------------------
# the planner's steps, in the order make_plan takes them
# ----------------------------------------------------------------------------------------
def _observation(data: np.ndarray, camera: Camera, kind: str, frame: np.ndarray | None,
                 quant_step: float | None) -> tuple:
    """Check ``data`` against the camera and tell a raw frame from a DC-free ``y``.

    Returns ``(raw, a, y, kind, frame, quant_step)``: the input as given, as a finite float
    image, the DC-free observation, the resolved kind, the raw frame (if any) and the
    quantisation step (1 for integer frames unless given).
    """
    raw = np.asarray(data)
    if raw.ndim not in (2, 3) or raw.shape[:2] != tuple(camera.shape):
        raise ClfzaError(f"data has shape {raw.shape}, but the camera grid is "
                         f"{tuple(camera.shape)} (rows, cols[, channels])")
    is_int = raw.dtype.kind in "ui"
    a = finite_image("data", raw)
    if a.ndim == 3 and a.shape[2] == 1:
        a = a[..., 0]
    if kind == "auto":
        kind = "frame" if (is_int or (a.min() >= 0 and a.mean() > a.std())) else "y"
    if kind not in ("y", "frame"):
        raise ClfzaError(f"kind must be 'auto', 'y' or 'frame', got {kind!r}")
    if kind == "frame":
        frame = raw
        if quant_step is None and is_int:
            quant_step = 1.0
    y = a - a.mean(axis=(0, 1), keepdims=True) if kind == "frame" else a
    return raw, a, y, kind, frame, quant_step


def _frame_decision(y: np.ndarray, a: np.ndarray, raw: np.ndarray, frame: np.ndarray | None,
                    kind: str, camera: Camera, sigma: float,
                    saturation_level: float | None, warns: list[str]
                    ) -> tuple[str, float, Decision]:
    """The skip decision: is the frame empty, saturated or flat (no solve), or "ok"?

    Appends the clipping and skip warnings to ``warns``; returns ``(state,
    saturated_fraction, decision)``.
    """
    state = "ok"
    sat_frac, sat_level = saturation(frame if frame is not None else y, saturation_level)
    amp = float(np.max(np.abs(y))) if y.size else 0.0
    src = raw if frame is None else np.asarray(frame)
    if (kind == "frame" and float(np.max(np.abs(src))) == 0.0) or (kind == "y" and amp == 0):
        state, why = "empty", "the frame is all zeros: no light reached the sensor"
    elif sat_frac >= SATURATED_SKIP:
        state = "saturated"
        why = (f"{100 * sat_frac:.0f}% of the pixels are clipped at {sat_level:g}: the linear "
               "model y = K o (Eq. 17) does not hold; reduce the exposure")
    else:
        e_band, n_band = encoded_band_energy(y, camera)
        snr = e_band / sigma**2 if sigma > 0 else (math.inf if e_band > 0 else 0.0)
        if amp == 0 or float(np.std(y)) <= 1e-12 * max(1.0, float(np.abs(a).max())):
            state, why = "flat", "the frame is constant: a uniform scene (its DC is lost, " \
                                 "H_T(0) = 0)"
        else:
            test = flat_test(y, sigma, snr, n_band)
            if test["flat"]:
                state = "flat"
            why = test["reason"]
        if sat_frac >= SATURATED_WARN:
            warns.append(f"{100 * sat_frac:.2f}% of the pixels are clipped at "
                         f"{sat_level:g}; they violate the linear model")
    decision = Decision("frame", state, state != "ok",
                        ("no solve, result = zeros; " if state != "ok" else "") + why,
                        1.0 if state != "ok" else 0.0)
    if state != "ok":
        warns.append(f"{state} frame: {why}; returning zeros without solving")
    return state, sat_frac, decision


def _bin_decision(camera: Camera, allow_bin: bool) -> tuple[int, Camera, Decision]:
    """The binning decision (module docstring): ``(bin factor, work camera, decision)``."""
    b = camera.suggested_bin if allow_bin else 1
    nyq, rho_c = 0.5 / camera.pitch, camera.band_limit
    ny, nx = camera.shape
    if b >= MIN_BIN and ny // b >= 16 and nx // b >= 16:
        cyn, cxn = (ny // b) * b, (nx // b) * b
        work = camera.with_shape((cyn // b, cxn // b), pitch=b * camera.pitch)
        save = 1.0 - _fft_work(work.shape) / _fft_work(camera.shape)
        crop = "" if (cyn, cxn) == (ny, nx) else f" (grid cropped to {cyn}x{cxn} first)"
        return b, work, Decision(
            "bin", b, True,
            f"1/(2p) = {nyq:.4g} cyc/mm is {nyq / rho_c:.2f}x the band limit R'/r1'^2 = "
            f"{rho_c:.4g} cyc/mm: binning by {b} with an ideal anti-alias filter keeps every "
            f"recorded frequency; solve on {work.shape[0]}x{work.shape[1]}{crop} (sampling "
            f"ratio {camera.regime.ratio:.3g} -> {work.regime.ratio:.3g}), tau scaled by 1/{b}",
            save)
    why_nb = (f"1/(2p) = {nyq:.4g} cyc/mm is {nyq / rho_c:.2f}x the band limit "
              f"R'/r1'^2 = {rho_c:.4g} cyc/mm (< {MIN_BIN}x): every pixel carries "
              "recorded frequencies") if allow_bin else "binning disabled"
    return 1, camera, Decision("bin", 1, False, why_nb)


def _colour_decision(y: np.ndarray, sigma: float, channels: int
                     ) -> tuple[bool, np.ndarray | None, Decision | None]:
    """Grey scene in RGB: ``(grey, gains, decision)``; no decision for one channel."""
    if channels <= 1:
        return False, None, None
    grey, gains, worst = grey_channels(y, sigma)
    if grey:
        return grey, gains, Decision(
            "colour", "grey", True,
            f"the {channels} channels equal one image times gains "
            f"{np.array2string(gains, precision=3)} up to the noise (residual "
            f"{worst:.2f} N sigma^2 <= {GREY_TOL}): solve once, replicate",
            1.0 - 1.0 / channels)
    return grey, gains, Decision(
        "colour", "rgb", False,
        f"the channels differ beyond the noise (residual {worst:.3g} N sigma^2): "
        f"solve {channels} channels")


def _stop_decision(method: str, sigma: float, sigma_method: str, b: int, n_work: int,
                   tau_d: float) -> tuple[float | None, Decision]:
    """The discrepancy target ``tau_d N (sigma/b)^2`` on the work grid (None for
    back-propagation or without a noise estimate) and its decision."""
    iterative = method != "bp"
    sigma_work = sigma / b  # the ideal low-pass keeps 1/b^2 of white noise's variance
    target = tau_d * n_work * sigma_work**2 if (iterative and sigma > 0) else None
    if iterative:
        return target, Decision(
            "stop", "discrepancy" if target else "solver rule", target is not None,
            (f"noise sigma = {sigma:.3g} ({sigma_method}); stop at the first iterate with "
             f"||y - K x||^2 <= tau_d N sigma^2 = {target:.4g} (tau_d = {tau_d}, N = {n_work}"
             f"{', sigma/b on the binned grid' if b > 1 else ''}; Morozov)")
            if target else "no noise estimate: the solver's own stopping rule")
    return target, Decision("noise", f"{sigma:.3g}", False,
                            f"sigma from the {sigma_method}; back-propagation is direct, "
                            "no iterations to stop")


BINNED_MODEL_ERROR = 5e-4
"""Relative model error of the binned exact model (:func:`clfza.models._exact.binned_kernel`:
0.05 % of the binned frame's RMS): a floor below which the data are not known, whatever the
sensor noise, so that a noise-free frame solved there needs no float64 (measured:
docs/measurements.md, clfza.reconstruction._plan)."""


def _dtype_decision(y: np.ndarray, sigma: float, n_work: int, iters: int,
                    quant_step: float | None, dtype: str | None, model_floor: float = 0.0
                    ) -> tuple[str, Decision]:
    """The working precision (:func:`float32_suffices` on the larger of the noise and the
    model's error, unless forced): ``(dtype, decision)``."""
    rms = float(np.sqrt(np.mean(y**2))) if y.size else 0.0
    ok32, floor, rounding = float32_suffices(max(sigma, model_floor), rms, n_work, iters,
                                             quant_step)
    what = ("model-error floor (binned exact model, "
            f"{BINNED_MODEL_ERROR:.2%} of rms(y))" if model_floor > sigma else "noise floor")
    if dtype is not None:
        dt, why_dt = str(np.dtype(dtype)), "forced by the caller"
    elif ok32:
        dt = "float32"
        why_dt = (f"{what} {floor:.3g} >= {FLOAT32_FACTOR:g} x float32 rounding "
                  f"{rounding:.2g} (u sqrt(iters log2 N) rms(y), {iters} iterations)")
    else:
        dt = "float64"
        why_dt = (f"noise floor {floor:.3g} < {FLOAT32_FACTOR:g} x float32 rounding "
                  f"{rounding:.2g}: the data are cleaner than float32 arithmetic")
    return dt, Decision("dtype", dt, dt == "float32", why_dt, 0.0)


def _model_floor(y: np.ndarray, camera: Camera, method: str, b: int) -> float:
    """The binned exact model's error in the units of ``y`` (0 where that model is not the
    one that runs)."""
    if b <= 1 or method == "bp":
        return 0.0

    if method_model(camera, "auto", method)[0] != "exact":
        return 0.0
    return BINNED_MODEL_ERROR * (float(np.sqrt(np.mean(y**2))) if y.size else 0.0)


def _fov_decision(fov: str, y: np.ndarray, camera: Camera, object_width: float | None,
                  center: tuple[float, float]) -> tuple[tuple[int, int, int, int], str, Decision]:
    """The field of view: ``(box, how it was found, decision)``."""
    ny, nx = camera.shape
    if fov == "auto":
        fov = "geometry" if object_width is not None else "sensor"
    if fov == "geometry":
        if object_width is None:
            raise ClfzaError("fov='geometry' needs object_width (mm at z1)")
        box = fov_from_geometry(camera, object_width, center)
        src_fov = (f"an object {object_width:g} mm wide at z1 = {camera.z1:g} mm images to "
                   f"M w / p = {camera.magnification * object_width / camera.pitch:.0f} px "
                   "(Eq. 2)")
    elif fov == "measurement":
        box = fov_from_measurement(y, camera)
        src_fov = "estimated from the back-propagated edge energy"
    elif fov == "sensor":
        box = (0, ny, 0, nx)
        src_fov = "object size unknown (give object_width): the whole sensor"
    else:
        raise ClfzaError(f"fov must be 'auto', 'geometry', 'measurement' or 'sensor', got "
                         f"{fov!r}")
    h, w = box[1] - box[0], box[3] - box[2]
    return box, fov, Decision(
        "fov", f"{h}x{w} at ({box[0]}, {box[2]})", (h, w) != (ny, nx),
        src_fov + "; the solve still needs the whole sensor (each shadow spans R'), the output"
        " and its metrics are limited to this region")


def make_plan(data: np.ndarray, camera: Camera, *, method: str = DEFAULT_METHOD,
              kind: str = "auto", frame: np.ndarray | None = None,
              saturation_level: float | None = None,
              object_width: float | None = None, center: tuple[float, float] = (0.0, 0.0),
              fov: str = "auto", allow_bin: bool = True, tau_d: float = 1.0,
              iters: int | None = None, quant_step: float | None = None,
              dtype: str | None = None) -> Plan:
    """Decide what this measurement needs (module docstring).

    Parameters
    ----------
    data : array (H, W) or (H, W, C)
        A DC-free observation ``y`` or a raw frame (see ``kind``).
    camera : Camera
        The camera; ``data`` must have its shape.
    method : str
        The reconstruction method the plan is for ("bp", "twist", "fista", "admm").
    kind : {"auto", "y", "frame"}
        What ``data`` is. "auto": integer data or non-negative data with a mean above its
        standard deviation is a raw frame, anything else a DC-free ``y``. A frame is planned
        on ``frame - mean(frame)`` (frame units).
    frame : array, optional
        The raw frame behind ``y`` (for the saturation check when ``data`` is ``y``).
    saturation_level : float, optional
        Clipping level of the frame (default: integer dtype max, or inferred; see
        :func:`saturation`).
    object_width : float, optional
        Physical object width in mm at ``z1`` (e.g. the display): the FOV from geometry.
    center : (float, float)
        Object centre (x, y) in mm.
    fov : {"auto", "geometry", "measurement", "sensor"}
        How to find the field of view ("auto": geometry when ``object_width`` is given, else
        the whole sensor; "measurement": :func:`fov_from_measurement`).
    allow_bin : bool
        Allow the binning skip.
    tau_d : float
        Discrepancy factor of Morozov's principle (1 = the expected noise energy).
    iters : int, optional
        Expected iteration count for the float32 rule (default by method).
    quant_step : float, optional
        Quantisation step in the units of ``data`` (integer frames: 1).
    dtype : {"float32", "float64"}, optional
        Force the working precision.

    Returns
    -------
    Plan
    """
    t0 = time.perf_counter()
    method = resolve_method(method, {})[0]  # "auto": the default route's method
    raw, a, y, kind, frame, quant_step = _observation(data, camera, kind, frame, quant_step)
    channels = 1 if y.ndim == 2 else y.shape[2]
    decisions: list[Decision] = []
    warns: list[str] = []
    iters_ = int(iters) if iters is not None else default_iters(method, camera)
    sigma, sigma_method = estimate_noise(y, camera)
    state, sat_frac, d_frame = _frame_decision(y, a, raw, frame, kind, camera, sigma,
                                               saturation_level, warns)
    decisions.append(d_frame)
    b, work, d_bin = _bin_decision(camera, allow_bin)
    decisions.append(d_bin)
    grey, gains, d_colour = _colour_decision(y, sigma, channels)
    if d_colour is not None:
        decisions.append(d_colour)
    n_work = work.shape[0] * work.shape[1]
    target, d_stop = _stop_decision(method, sigma, sigma_method, b, n_work, tau_d)
    decisions.append(d_stop)
    dt, d_dtype = _dtype_decision(y, sigma, n_work, iters_, quant_step, dtype,
                                  _model_floor(y, camera, method, b))
    decisions.append(d_dtype)
    box, fov, d_fov = _fov_decision(fov, y, camera, object_width, center)
    decisions.append(d_fov)
    plan = Plan(camera=camera, method=method, shape=tuple(camera.shape), channels=channels,
                bin=b, work_camera=work, frame_state=state, saturated_fraction=sat_frac,
                grey=grey, gains=gains, sigma=sigma, sigma_method=sigma_method,
                discrepancy_target=target, tau_d=tau_d, dtype=dt, fov=box,
                fov_source=fov, decisions=decisions, warnings=warns)
    plan.timings["plan"] = time.perf_counter() - t0
    return plan


# ----------------------------------------------------------------------------------------
# execution
# ----------------------------------------------------------------------------------------
def solver_options(method: str) -> set[str] | None:
    """Keywords ``method`` takes, from the solver registry (:mod:`clfza.solvers._driver`): its
    options and the run controls (``callback`` among them); an empty set for
    back-propagation; None for a method that is not a registered iterative solver."""

    return set() if method == "bp" else option_names(method)


def default_iters(method: str, camera: Camera | None = None) -> int:
    """Iterations ``method`` runs by default on the model ``model="auto"`` chooses for
    ``camera``: its options' ``iters`` from the solver registry, 1 for direct methods
    (back-propagation). The float32 rule counts them."""

    model = None
    if camera is not None and method != "bp":

        model = method_model(camera, "auto", method)[0]
    n = registered(method, model)
    return 1 if n is None else n


def _skipped_result(plan: Plan, backend: str) -> Reconstruction:

    shape = plan.shape + ((plan.channels,) if plan.channels > 1 else ())
    info = ReconInfo(method=plan.method, backend=backend, device="none (skipped)",
                     dtype=plan.dtype, iterations=0,
                     stop_reason=f"skipped: {plan.frame_state} frame")
    info.notes = plan.notes()
    info.params["plan"] = plan.to_dict()
    info.plan = plan
    return Reconstruction(np.zeros(shape), info)


def _planned_inputs(y: np.ndarray, camera: Camera, method: str, plan: Plan, opts: dict,
                    notes: list[str]) -> np.ndarray:
    """The observation the plan solves, with ``opts`` completed in place: the model (the
    exact model's kernel binned as the frame is), ``tau`` scaled to the binned grid and the
    plan's dtype. Appends notes on what was done to ``notes``."""

    kind, why = method_model(camera, opts.pop("model", "auto"), method, opts,
                             psf=opts.get("psf") is not None)
    exact_binned = kind == "exact" and plan.bin > 1 and opts.get("psf") is None
    yw = apply_plan(y, plan, box=exact_binned)
    if exact_binned:
        opts["psf"] = binned_exact_model(camera, plan)
        notes.append(f"plan: exact model ({why}); the frame binned {plan.bin}x by pixel "
                     f"averaging and the mask kernel binned to match (clfza.models._exact."
                     f"binned_kernel)")
    opts["model"] = kind
    auto_tau = isinstance(opts.get("tau"), str) and opts["tau"].strip().lower() == "auto"
    if plan.bin > 1 and auto_tau:
        notes.append(f"plan: tau=auto chooses tau on the grid binned by {plan.bin} (the "
                     f"recorded tau is in that grid's units: x {plan.bin} for the sensor's)")
    elif plan.bin > 1 and "tau" in opts:
        opts["tau"] = float(opts["tau"]) / plan.bin
    elif plan.bin > 1 and method != "bp":
        notes.append(f"plan: tau not given; the solver's default tau is used on the grid "
                     f"binned by {plan.bin} (Eq. 19's balance wants tau / {plan.bin})")
    opts.setdefault("dtype", np.float32 if plan.dtype == "float32" else np.float64)
    return yw


def _discrepancy_stopper(method: str, plan: Plan, discrepancy: bool, opts: dict,
                         notes: list[str]) -> DiscrepancyStop | None:
    """A :class:`DiscrepancyStop` passed as ``callback=`` in ``opts`` when the plan has a
    target and the solver takes a callback (else None, with a note when it does not)."""
    if not (discrepancy and method != "bp" and plan.discrepancy_target is not None
            and "callback" not in opts):
        return None
    accepted = solver_options(method)
    if accepted is not None and "callback" in accepted:
        stopper = DiscrepancyStop(plan.discrepancy_target)
        opts["callback"] = stopper
        return stopper
    notes.append("plan: the method takes no callback=, so the discrepancy stop was "
                 "not applied")
    return None


def _stop_note(stopper: DiscrepancyStop, info) -> str:
    """What the discrepancy stop did, as a note for ``info.notes``."""
    if stopper.stopped_at is not None:
        return (f"plan: discrepancy principle stopped the solver at iteration "
                f"{stopper.stopped_at} (||y - K x||^2 = {stopper.last:.4g} <= "
                f"{stopper.target:.4g})")
    if stopper.calls == 0:
        return "plan: the solver never called the discrepancy callback"
    return (f"plan: the discrepancy stop did NOT fire: ||y - K x||^2 = "
            f"{stopper.last if stopper.last is not None else float('nan'):.4g} stayed "
            f"above {stopper.target:.4g}; the solver ran {info.iterations} iteration(s)"
            f" and stopped by {info.stop_reason!r}")


def _planned_image(image: np.ndarray, plan: Plan, upsample: str | None,
                   crop_fov: bool) -> np.ndarray:
    """The reconstruction back on the sensor grid (:func:`finish_plan`), cropped to the field
    of view when asked (on the binned grid when ``upsample`` is None)."""
    img = finish_plan(image, plan, upsample)
    if crop_fov:
        r0, r1_, c0, c1 = plan.fov
        if plan.bin > 1 and upsample is None:
            b = plan.bin
            r0, r1_, c0, c1 = r0 // b, -(-r1_ // b), c0 // b, -(-c1 // b)
        img = img[r0:r1_, c0:c1]
    return img


def _record_plan(info, plan: Plan, method: str, stopper: DiscrepancyStop | None) -> None:
    """``info.params["plan"]``: the plan, and what ran rather than what was promised -- the
    stop rule that fired and the iterations run."""
    info.params["plan"] = plan.to_dict()
    fired = ("discrepancy principle" if stopper is not None and stopper.stopped_at is not None
             else str(info.stop_reason))
    info.params["plan"].update(
        stop_rule_fired=fired, iterations_run=int(info.iterations),
        discrepancy_promised=plan.discrepancy_target is not None and method != "bp",
        discrepancy_applied=stopper is not None,
        discrepancy_last=None if stopper is None else stopper.last)


def reconstruct_planned(y: np.ndarray, camera: Camera,
                        method: str | MethodOptions = DEFAULT_METHOD, *,
                        plan: Plan | None = None, backend: str = DEFAULT_BACKEND,
                        upsample: str | None = "fourier", crop_fov: bool = False,
                        discrepancy: bool = True, plan_options: dict | None = None,
                        **options) -> Reconstruction:
    """Run :func:`clfza.reconstruct` with the plan's decisions.

    Parameters
    ----------
    y : array
        DC-free observation (as for :func:`clfza.reconstruct`).
    camera : Camera
    method : str or options instance
        Reconstruction method, as for :func:`clfza.reconstruct` (a name with keyword options,
        or ``clfza.ADMM(...)`` and the like).
    plan : Plan, optional
        A plan made earlier; default ``make_plan(y, camera, method=method, kind="y",
        **plan_options)``.
    backend : str
        Passed on; the plan's dtype is used unless ``dtype`` is in ``options``.
    upsample : {"fourier", "linear", None}
        How a binned result returns to the sensor grid (None: stay on the binned grid).
    crop_fov : bool
        Return only the field-of-view region.
    discrepancy : bool
        Pass a :class:`DiscrepancyStop` as ``callback=`` to iterative solvers.
    **options
        Solver options; ``tau`` is divided by the bin factor (module docstring).

    Returns
    -------
    Reconstruction
        Unpacks as ``image, info``, like :func:`clfza.reconstruct`'s; ``info.plan`` is the
        :class:`Plan` that ran (its record in ``info.params["plan"]``), ``info.notes`` lists
        what was skipped and why.

    Examples
    --------
    >>> image, info = reconstruct_planned(y, camera, "admm", tau=0.01)  # doctest: +SKIP
    >>> print(info.plan.explain())  # doctest: +SKIP
    """

    t0 = time.perf_counter()
    method, options = method_and_options(method, options)
    method, options, _ = resolve_method(method, options)  # "auto": the default route
    if plan is None:
        plan = make_plan(y, camera, method=method, kind="y", **(plan_options or {}))
    if plan.skip_solve:
        for w in plan.warnings:
            warnings.warn(w, PlanWarning, stacklevel=2)
        return _skipped_result(plan, backend)
    for w in plan.warnings:
        warnings.warn(w, PlanWarning, stacklevel=2)
    opts = dict(options)
    notes: list[str] = []
    yw = _planned_inputs(y, camera, method, plan, opts, notes)
    stopper = _discrepancy_stopper(method, plan, discrepancy, opts, notes)
    rec = reconstruct(yw, plan.work_camera, method, backend=backend, **opts)
    rec.image = _planned_image(rec.image, plan, upsample, crop_fov)
    if plan.grey:  # solved once in grey and replicated with the sensor's gains: balance here
        rec = balanced(rec, opts.get("white_balance", "psf"), None)
    rec.info.notes = list(rec.info.notes) + plan.notes() + notes
    if stopper is not None:
        rec.info.notes.append(_stop_note(stopper, rec.info))
    _record_plan(rec.info, plan, method, stopper)
    rec.info.timings["plan"] = plan.timings.get("plan", 0.0)
    rec.info.timings["planned_total"] = time.perf_counter() - t0
    rec.info.plan = plan
    return rec
