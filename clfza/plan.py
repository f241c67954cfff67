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
skipped in ``info.notes``; :meth:`Plan.explain` prints the plan with a reason for each choice.
"""

from __future__ import annotations

import math
import time
import warnings
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from scipy.ndimage import gaussian_filter
from scipy.signal import resample

from .camera import Camera
from .errors import ClfzaError, finite_image
from .noise import (  # noqa: F401  (re-exported: clfza.plan.estimate_noise & co.)
    _freq_radius,
    encoded_band_energy,
    estimate_noise,
    haar_mad_sigma,
    out_of_band_mask,
)

# --- thresholds (module constants so reports and tests can name them) -------------------
MIN_BIN = 2                 # bin only when 1/(2p) >= 2 rho_c (issue 6)
SATURATED_SKIP = 0.5        # more than half the pixels clipped: no solve
SATURATED_WARN = 1e-3       # more than 0.1 % clipped: warn, solve anyway
FLAT_SNR = 1.5              # (kept for reference; the flat decision is flat_test's)
FLAT_EFFECT = 0.05          # flat: any signal < 5% of the noise energy, band and whole frame
FLAT_CONFIDENCE = 0.99      # ... with this one-sided confidence
GREY_TOL = 2.0              # channel residual below 2 N sigma^2: the channels are equal
FLOAT32_MARGIN = 10.0       # noise floor / float32 rounding needed for float32
EPS32 = float(np.finfo(np.float32).eps) / 2.0  # unit roundoff 2^-24


class PlanWarning(UserWarning):
    """The planner skipped a solve or found a frame that violates the linear model."""


# ----------------------------------------------------------------------------------------
# measurements of the frame (the noise estimates live in clfza.noise)
# ----------------------------------------------------------------------------------------
def flat_test(y: np.ndarray, sigma: float, snr: float, n_band: int,
              effect: float = FLAT_EFFECT, confidence: float = FLAT_CONFIDENCE) -> dict:
    """Is the frame's variance explained by the noise model? (the "flat" decision)

    Under the noise-only hypothesis each encoded-band coefficient ``|Y(f)|^2 / (N sigma^2)``
    is exponential with mean 1, so their mean ``snr`` has standard deviation
    ``1 / sqrt(n_band)``, and the frame's variance over ``sigma^2`` has ``sqrt(2 / N)``. The
    frame is called flat -- and its solve skipped -- only when, at ``confidence`` (one-sided),
    both upper bounds stay below ``1 + effect``: any signal then holds less than ``effect``
    of the noise's energy in the band the mask encodes and in the whole frame. Failing to
    reject "noise only" is not enough (a photon-limited frame fails to reject it and still
    holds a scene); this is an equivalence test, so the default is to solve.
    """
    from scipy.stats import gamma, norm

    z = float(norm.ppf(confidence))
    a = np.asarray(y, dtype=np.float64)
    n_pix = a.size
    var_ratio = float(np.var(a)) / sigma**2 if sigma > 0 else math.inf
    up_band = snr + z / math.sqrt(n_band) if n_band else math.inf
    up_var = var_ratio + z * math.sqrt(2.0 / max(1, n_pix))
    p_noise = float(gamma.sf(snr, n_band, scale=1.0 / n_band)) if n_band else 0.0
    flat = bool(n_band and math.isfinite(up_band) and up_band < 1 + effect
                and up_var < 1 + effect)
    conf = f"{100 * confidence:g}%"
    if flat:
        reason = (f"the noise model explains the frame: encoded-band energy {snr:.3f}x the "
                  f"noise's (n = {n_band}; P(noise alone gives this much) = {p_noise:.2g}), "
                  f"frame variance {var_ratio:.3f}x; with {conf} confidence any signal holds "
                  f"< {100 * effect:g}% of the noise energy (bounds {up_band:.3f}, "
                  f"{up_var:.3f} < {1 + effect:g})")
    else:
        reason = (f"encoded-band energy {snr:.3g}x the noise's (n = {n_band}; P(noise alone "
                  f"gives this much) = {p_noise:.2g}), frame variance {var_ratio:.3g}x: the "
                  f"noise model does not explain the frame at {conf} confidence "
                  f"(upper bounds {up_band:.3g}, {up_var:.3g} vs {1 + effect:g}), so it is "
                  "solved")
    return {"flat": flat, "snr": snr, "var_ratio": var_ratio, "n_band": n_band,
            "upper_band": up_band, "upper_var": up_var, "p_noise": p_noise,
            "confidence": confidence, "effect": effect, "reason": reason}


def saturation(data: np.ndarray, level: float | None = None) -> tuple[float, float | None]:
    """Fraction of clipped pixels and the clipping level used.

    ``level`` given: pixels ``>= level``. Integer data: the dtype's maximum. Otherwise the
    maximum value counts as a clipping level when at least 0.1 % of the pixels sit exactly on
    it (continuous data has no such ties; clipped data keeps them through ``y = gain (frame -
    mean)``).
    """
    a = np.asarray(data)
    if a.size == 0:
        return 0.0, level
    if level is None and a.dtype.kind in "ui":
        level = float(np.iinfo(a.dtype).max)
        return float(np.mean(a >= level)), level
    if level is not None:
        return float(np.mean(a >= level)), float(level)
    mx = float(np.max(a))
    frac = float(np.mean(a == mx))
    if frac >= SATURATED_WARN and np.ptp(a) > 0:
        return frac, mx
    return 0.0, None


def grey_channels(y: np.ndarray, sigma: float, tol: float = GREY_TOL
                  ) -> tuple[bool, np.ndarray, float]:
    """Are the channels of an (H, W, C) observation one grey scene up to gains and noise?

    Fits ``y_c ~ a_c ybar`` by least squares and accepts when every residual energy is below
    ``tol * N * sigma^2`` (noise alone gives about ``(1 - 1/C) N sigma^2``) or, for noise-free
    data, below ``1e-8 ||y_c||^2``.

    Returns
    -------
    (is_grey, gains, worst_ratio)
        ``worst_ratio`` is the largest residual energy divided by ``N sigma^2``.
    """
    a = np.asarray(y, dtype=np.float64)
    ybar = a.mean(axis=2)
    nn = float(np.sum(ybar * ybar))
    if nn == 0:
        return True, np.ones(a.shape[2]), 0.0
    gains = np.array([float(np.sum(a[..., c] * ybar)) / nn for c in range(a.shape[2])])
    worst = 0.0
    ok = True
    n = ybar.size
    for c in range(a.shape[2]):
        r = float(np.sum((a[..., c] - gains[c] * ybar) ** 2))
        e = float(np.sum(a[..., c] ** 2))
        ratio = r / (n * sigma**2) if sigma > 0 else (0.0 if r == 0 else math.inf)
        worst = max(worst, ratio)
        if not (ratio <= tol or r <= 1e-8 * e):
            ok = False
    return ok, gains, worst


def float32_suffices(sigma: float, rms: float, n_pixels: int, iters: int,
                     quant_step: float | None = None, margin: float = FLOAT32_MARGIN
                     ) -> tuple[bool, float, float]:
    """The float32 rule.

    An FFT-based iteration in float32 adds rounding noise of relative size about
    ``u sqrt(log2 N)`` (``u = 2^-24``) per pass; accumulated as a random walk over ``iters``
    iterations it stays below ``u sqrt(iters log2 N) ||y||_rms``. float32 suffices when the
    measurement's own noise floor -- the estimated ``sigma``, or the quantisation noise
    ``q / sqrt(12)`` when larger -- exceeds that by ``margin`` (10: float32 then adds at most
    1 % to the error variance the data already carry).

    Returns
    -------
    (ok, floor, rounding)
    """
    floor = max(float(sigma), (quant_step or 0.0) / math.sqrt(12.0))
    rounding = EPS32 * math.sqrt(max(1, iters) * math.log2(max(2, n_pixels))) * float(rms)
    return floor >= margin * rounding, floor, rounding


def fov_from_geometry(camera: Camera, object_width: float,
                      center: tuple[float, float] = (0.0, 0.0)) -> tuple[int, int, int, int]:
    """Sensor box (row0, row1, col0, col1) covered by an object ``object_width`` mm wide (and
    as tall) at ``z1``: ``M w / p`` pixels with ``M = z2/z1`` (Eq. 2), centred at the image of
    ``center`` (x, y mm, inverted by the pinhole geometry), clipped to the sensor."""
    if math.isinf(camera.z1):
        raise ClfzaError("the field of view of an object at z1 = inf is a point; give z1")
    M = camera.magnification
    w = M * float(object_width) / camera.pitch
    ny, nx = camera.shape
    cy = ny / 2 - M * center[1] / camera.pitch
    cx = nx / 2 - M * center[0] / camera.pitch
    r0, r1_ = int(round(cy - w / 2)), int(round(cy + w / 2))
    c0, c1 = int(round(cx - w / 2)), int(round(cx + w / 2))
    return max(0, r0), min(ny, r1_), max(0, c0), min(nx, c1)


def fov_from_measurement(y: np.ndarray, camera: Camera, threshold: float = 0.5
                         ) -> tuple[int, int, int, int]:
    """Estimate the covered region from the measurement: back-propagate (Eqs. 11-12; high-passed
    and apodised as in :class:`clfza.focus.FastBP`, with the camera's calibrated ``r1'``), take
    the local energy of the gradient (Gaussian, 2 resolution cells), and keep, along rows and
    along columns, the span of its mean profile above ``threshold`` x the profile's peak. The
    in-focus image concentrates its edges on the object; the twin image (Eq. 12, third term)
    is spread and weaker. An estimate: prefer :func:`fov_from_geometry` when the object size
    is known."""
    from .focus import FastBP

    x = FastBP(y, camera).image_r1p(camera.r1p).astype(np.float64)
    gy, gx = np.gradient(x)
    cells = max(1.0, 2.0 * camera.resolution_sensor / camera.pitch)
    e = gaussian_filter(gx * gx + gy * gy, max(2.0, cells))

    def interval(profile: np.ndarray) -> tuple[int, int]:
        idx = np.nonzero(profile >= threshold * profile.max())[0]
        return int(idx.min()), int(idx.max()) + 1

    r0, r1_ = interval(e.mean(axis=1))
    c0, c1 = interval(e.mean(axis=0))
    return r0, r1_, c0, c1


def bin_measurement(y: np.ndarray, b: int) -> np.ndarray:
    """Resample an (H, W[, C]) image onto a grid ``b`` times coarser with an ideal
    anti-alias filter: keep the ``(H/b, W/b)`` lowest frequencies of the spectrum (Fourier
    resampling, ``scipy.signal.resample``, which splits the Nyquist bins of even sizes), so the
    values are the band-limited image sampled every ``b`` pixels. ``H`` and ``W`` must be
    multiples of ``b`` (see :func:`apply_plan`)."""
    a = np.asarray(y, dtype=np.float64)
    if a.ndim == 3:
        return np.stack([bin_measurement(a[..., c], b) for c in range(a.shape[2])], axis=-1)
    ny, nx = a.shape
    if ny % b or nx % b:
        raise ClfzaError(f"bin factor {b} does not divide the grid {a.shape}")
    out = resample(resample(a, ny // b, axis=0), nx // b, axis=1)
    return out


def upsample_image(x: np.ndarray, b: int, mode: str = "fourier") -> np.ndarray:
    """Back to the sensor grid: ``"fourier"`` zero-pads the spectrum (band-limited
    interpolation, the inverse of :func:`bin_measurement` on in-band images), ``"linear"``
    interpolates bilinearly (no ringing at TV edges)."""
    a = np.asarray(x, dtype=np.float64)
    if a.ndim == 3:
        return np.stack([upsample_image(a[..., c], b, mode) for c in range(a.shape[2])], -1)
    ny, nx = a.shape
    if mode == "fourier":
        return resample(resample(a, ny * b, axis=0), nx * b, axis=1)
    if mode == "linear":
        from scipy.ndimage import map_coordinates

        # coarse sample k sits at fine index k*b (as in bin_measurement); periodic edges
        iy = np.arange(ny * b) / b
        ix = np.arange(nx * b) / b
        coords = np.meshgrid(iy, ix, indexing="ij")
        return map_coordinates(a, coords, order=1, mode="grid-wrap")
    raise ClfzaError(f"upsample mode must be 'fourier' or 'linear', got {mode!r}")


# ----------------------------------------------------------------------------------------
# the plan
# ----------------------------------------------------------------------------------------
@dataclass
class Decision:
    """One planner decision: its value, whether it changes the work, why, and the saving."""

    name: str
    value: Any
    active: bool
    reason: str
    saving: float = 0.0  # estimated fraction of the solve's work removed (0..1)

    def line(self) -> str:
        tag = "SKIP" if self.active else "keep"
        sv = f" [saves ~{100 * self.saving:.0f}% of the work]" if self.saving > 0 else ""
        return f"  {tag} {self.name:<12} {self.value!s:<24} {self.reason}{sv}"


@dataclass
class Plan:
    """The planner's decisions for one measurement (see the module docstring).

    Attributes
    ----------
    camera, method
        What was planned for.
    bin : int
        Bin factor (1 = none); ``work_camera`` is the camera of the grid actually solved.
    frame_state : {"ok", "empty", "flat", "saturated"}
        Non-"ok" states skip the solve.
    grey : bool
        A grey scene in an RGB frame (solve once); ``gains`` per channel.
    sigma : float
        Estimated noise std of ``y`` per sensor pixel (``sigma_method`` says how).
    discrepancy_target : float or None
        ``tau_d N sigma^2`` on the work grid (None without noise estimate or for "bp").
    dtype : str
        "float32" or "float64".
    fov : (row0, row1, col0, col1)
        Sensor region the scene covers (``fov_source`` says how it was found).
    decisions : list of Decision
    warnings : list of str
    """

    camera: Camera
    method: str
    shape: tuple
    channels: int
    bin: int
    work_camera: Camera
    frame_state: str
    saturated_fraction: float
    grey: bool
    gains: np.ndarray | None
    sigma: float
    sigma_method: str
    discrepancy_target: float | None
    tau_d: float
    dtype: str
    fov: tuple[int, int, int, int]
    fov_source: str
    decisions: list = field(default_factory=list)
    warnings: list = field(default_factory=list)
    timings: dict = field(default_factory=dict)

    @property
    def skip_solve(self) -> bool:
        """True for empty, flat and saturated frames."""
        return self.frame_state != "ok"

    @property
    def work_fraction(self) -> float:
        """Estimated remaining fraction of the unplanned solve's work (product of savings)."""
        f = 1.0
        for d in self.decisions:
            if d.active:
                f *= 1.0 - d.saving
        return f

    def explain(self) -> str:
        """The plan as text, one line per decision with its reason (``--explain``)."""
        cam = self.camera
        head = [f"plan for {cam.name} {self.shape[0]}x{self.shape[1]}"
                f"{'x' + str(self.channels) if self.channels > 1 else ''}, method "
                f"{self.method}: r1' = {cam.r1p:.4g} mm, rho_c = R'/r1'^2 = "
                f"{cam.band_limit:.4g} cyc/mm, Nyquist 1/(2p) = {0.5 / cam.pitch:.4g} "
                f"cyc/mm, sampling ratio {cam.regime.ratio:.3g} ({cam.regime.name})"]
        lines = head + [d.line() for d in self.decisions]
        lines.append(f"  estimated work: {100 * self.work_fraction:.1f}% of the unplanned "
                     "solve")
        lines += [f"  warning: {w}" for w in self.warnings]
        return "\n".join(lines)

    def notes(self) -> list[str]:
        """The active decisions as one-line notes (for ``ReconInfo.notes``)."""
        return [f"plan: {d.name} = {d.value}: {d.reason}" for d in self.decisions if d.active]

    def to_dict(self) -> dict:
        return {
            "method": self.method, "shape": list(self.shape), "channels": self.channels,
            "bin": self.bin, "work_shape": list(self.work_camera.shape),
            "work_pitch_mm": self.work_camera.pitch, "frame_state": self.frame_state,
            "saturated_fraction": self.saturated_fraction, "grey": self.grey,
            "gains": None if self.gains is None else [float(g) for g in self.gains],
            "sigma": self.sigma, "sigma_method": self.sigma_method,
            "discrepancy_target": self.discrepancy_target, "tau_d": self.tau_d,
            "dtype": self.dtype, "fov": list(self.fov), "fov_source": self.fov_source,
            "work_fraction": self.work_fraction,
            "decisions": [{"name": d.name, "value": str(d.value), "active": d.active,
                           "reason": d.reason, "saving": d.saving} for d in self.decisions],
            "warnings": list(self.warnings), "timings": dict(self.timings),
        }


def _fft_work(shape: tuple[int, int]) -> float:
    n = shape[0] * shape[1]
    return n * math.log2(max(2, n))


def make_plan(data: np.ndarray, camera: Camera, *, method: str = "bp", kind: str = "auto",
              frame: np.ndarray | None = None, saturation_level: float | None = None,
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
    channels = 1 if y.ndim == 2 else y.shape[2]
    decisions: list[Decision] = []
    warns: list[str] = []
    iters_ = int(iters) if iters is not None else default_iters(method)

    # --- noise -------------------------------------------------------------------------
    sigma, sigma_method = estimate_noise(y, camera)

    # --- frame state: empty, saturated, flat --------------------------------------------
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
    decisions.append(Decision("frame", state, state != "ok",
                              ("no solve, result = zeros; " if state != "ok" else "") + why,
                              1.0 if state != "ok" else 0.0))
    if state != "ok":
        warns.append(f"{state} frame: {why}; returning zeros without solving")

    # --- binning -------------------------------------------------------------------------
    b = camera.suggested_bin if allow_bin else 1
    nyq, rho_c = 0.5 / camera.pitch, camera.band_limit
    ny, nx = camera.shape
    if b >= MIN_BIN and ny // b >= 16 and nx // b >= 16:
        cyn, cxn = (ny // b) * b, (nx // b) * b
        work = camera.with_shape((cyn // b, cxn // b), pitch=b * camera.pitch)
        save = 1.0 - _fft_work(work.shape) / _fft_work(camera.shape)
        crop = "" if (cyn, cxn) == (ny, nx) else f" (grid cropped to {cyn}x{cxn} first)"
        decisions.append(Decision(
            "bin", b, True,
            f"1/(2p) = {nyq:.4g} cyc/mm is {nyq / rho_c:.2f}x the band limit R'/r1'^2 = "
            f"{rho_c:.4g} cyc/mm: binning by {b} with an ideal anti-alias filter keeps every "
            f"recorded frequency; solve on {work.shape[0]}x{work.shape[1]}{crop} (sampling "
            f"ratio {camera.regime.ratio:.3g} -> {work.regime.ratio:.3g}), tau scaled by 1/{b}",
            save))
    else:
        b = 1
        work = camera
        why_nb = (f"1/(2p) = {nyq:.4g} cyc/mm is {nyq / rho_c:.2f}x the band limit "
                  f"R'/r1'^2 = {rho_c:.4g} cyc/mm (< {MIN_BIN}x): every pixel carries "
                  "recorded frequencies") if allow_bin else "binning disabled"
        decisions.append(Decision("bin", 1, False, why_nb))

    # --- grey in RGB ----------------------------------------------------------------------
    grey, gains = False, None
    if channels > 1:
        grey, gains, worst = grey_channels(y, sigma)
        if grey:
            decisions.append(Decision(
                "colour", "grey", True,
                f"the {channels} channels equal one image times gains "
                f"{np.array2string(gains, precision=3)} up to the noise (residual "
                f"{worst:.2f} N sigma^2 <= {GREY_TOL}): solve once, replicate",
                1.0 - 1.0 / channels))
        else:
            decisions.append(Decision(
                "colour", "rgb", False,
                f"the channels differ beyond the noise (residual {worst:.3g} N sigma^2): "
                f"solve {channels} channels"))

    # --- noise and stopping -------------------------------------------------------------
    iterative = method != "bp"
    n_work = work.shape[0] * work.shape[1]
    sigma_work = sigma / b  # the ideal low-pass keeps 1/b^2 of white noise's variance
    target = tau_d * n_work * sigma_work**2 if (iterative and sigma > 0) else None
    if iterative:
        decisions.append(Decision(
            "stop", "discrepancy" if target else "solver rule", target is not None,
            (f"noise sigma = {sigma:.3g} ({sigma_method}); stop at the first iterate with "
             f"||y - K x||^2 <= tau_d N sigma^2 = {target:.4g} (tau_d = {tau_d}, N = {n_work}"
             f"{', sigma/b on the binned grid' if b > 1 else ''}; Morozov)")
            if target else "no noise estimate: the solver's own stopping rule"))
    else:
        decisions.append(Decision("noise", f"{sigma:.3g}", False,
                                  f"sigma from the {sigma_method}; back-propagation is direct, "
                                  "no iterations to stop"))

    # --- precision ----------------------------------------------------------------------
    rms = float(np.sqrt(np.mean(y**2))) if y.size else 0.0
    ok32, floor, rounding = float32_suffices(sigma, rms, n_work, iters_, quant_step)
    if dtype is not None:
        dt, why_dt = str(np.dtype(dtype)), "forced by the caller"
    elif ok32:
        dt = "float32"
        why_dt = (f"noise floor {floor:.3g} >= {FLOAT32_MARGIN:g} x float32 rounding "
                  f"{rounding:.2g} (u sqrt(iters log2 N) rms(y), {iters_} iterations)")
    else:
        dt = "float64"
        why_dt = (f"noise floor {floor:.3g} < {FLOAT32_MARGIN:g} x float32 rounding "
                  f"{rounding:.2g}: the data are cleaner than float32 arithmetic")
    decisions.append(Decision("dtype", dt, dt == "float32", why_dt, 0.0))

    # --- field of view ------------------------------------------------------------------
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
    decisions.append(Decision(
        "fov", f"{h}x{w} at ({box[0]}, {box[2]})", (h, w) != (ny, nx),
        src_fov + "; the solve still needs the whole sensor (each shadow spans R'), the output"
        " and its metrics are limited to this region"))

    plan = Plan(camera=camera, method=method, shape=(ny, nx), channels=channels, bin=b,
                work_camera=work, frame_state=state, saturated_fraction=sat_frac, grey=grey,
                gains=gains, sigma=sigma, sigma_method=sigma_method,
                discrepancy_target=target, tau_d=tau_d, dtype=dt, fov=box,
                fov_source=fov, decisions=decisions, warnings=warns)
    plan.timings["plan"] = time.perf_counter() - t0
    return plan


# ----------------------------------------------------------------------------------------
# execution
# ----------------------------------------------------------------------------------------
class DiscrepancyStop:
    """Solver callback for Morozov's discrepancy principle.

    Called once per iteration with a record (a mapping or an object) holding ``iteration``
    and one of ``residual_norm2`` / ``residual2`` (``||y - K x||^2``), ``data``
    (``1/2 ||y - K x||^2``, the data term of Eq. 19) or ``residual`` (``||y - K x||``);
    returns True (stop) at the first record with ``||y - K x||^2 <= target``.
    """

    def __init__(self, target: float):
        self.target = float(target)
        self.stopped_at: int | None = None
        self.last: float | None = None
        self.calls = 0

    @staticmethod
    def _get(rec, key):
        if isinstance(rec, dict):
            return rec.get(key)
        return getattr(rec, key, None)

    def residual2(self, rec) -> float | None:
        for key, f in (("residual_norm2", 1.0), ("residual2", 1.0), ("data", 2.0)):
            v = self._get(rec, key)
            if v is not None:
                return f * float(v)
        v = self._get(rec, "residual")
        return None if v is None else float(v) ** 2

    def __call__(self, rec) -> bool:
        self.calls += 1
        r2 = self.residual2(rec)
        if r2 is None:
            return False
        self.last = r2
        if r2 <= self.target:
            it = self._get(rec, "iteration")
            self.stopped_at = int(it) if it is not None else self.calls
            return True
        return False


def solver_options(method: str) -> set[str] | None:
    """Keywords ``method`` takes, from the solver registry (:mod:`clfza.solvers.driver`): its
    options and the run controls (``callback`` among them); an empty set for
    back-propagation; None for a method that is not a registered iterative solver."""
    from .solvers import option_names

    return set() if method == "bp" else option_names(method)


def default_iters(method: str) -> int:
    """Iterations ``method`` runs by default: its options' ``iters`` from the solver
    registry, 1 for direct methods (back-propagation). The float32 rule counts them."""
    from .solvers import default_iters as registered

    n = registered(method)
    return 1 if n is None else n


def apply_plan(y: np.ndarray, plan: Plan, box: bool = False) -> np.ndarray:
    """The observation the plan solves: cropped to a multiple of the bin factor and binned
    (:func:`bin_measurement`; with ``box``, pixel binning for the exact model,
    :func:`clfza.exact.box_bin`), and, for a grey scene in RGB, the channels combined by least
    squares ``sum_c a_c y_c / sum_c a_c^2``."""
    a = np.asarray(y, dtype=np.float64)
    if a.ndim == 3 and a.shape[2] == 1:
        a = a[..., 0]
    if plan.grey and a.ndim == 3:
        g = plan.gains
        a = np.tensordot(a, g, axes=([2], [0])) / float(np.sum(g * g))
    b = plan.bin
    if b > 1:
        ny, nx = plan.shape
        cy, cx = (ny // b) * b, (nx // b) * b
        oy, ox = (ny - cy) // 2, (nx - cx) // 2
        a = a[oy:oy + cy, ox:ox + cx]
        if box:
            from .exact import box_bin

            a = box_bin(a, b)
        else:
            a = bin_measurement(a, b)
    return a


def binned_exact_model(camera: Camera, plan: Plan):
    """The exact model for a frame that :func:`apply_plan` binned by pixel averaging: the
    camera cropped as the plan crops (the mask centre moves with the crop) and its kernel
    binned (:func:`clfza.exact.binned_model`)."""
    from dataclasses import replace

    from .exact import binned_model

    b = plan.bin
    ny, nx = plan.shape
    cy, cx = (ny // b) * b, (nx // b) * b
    oy, ox = (ny - cy) // 2, (nx - cx) // 2
    full = camera
    if (cy, cx) != (ny, nx):
        my, mx = camera.mask_center
        full = replace(camera, shape=(cy, cx), mask_center=(my + ny // 2 - oy - cy // 2,
                                                            mx + nx // 2 - ox - cx // 2))
    return binned_model(full, b)


def finish_plan(x: np.ndarray, plan: Plan, upsample: str | None = "fourier") -> np.ndarray:
    """Undo :func:`apply_plan` on a reconstruction: upsample to the sensor grid (``None``
    keeps the binned grid), pad a cropped border with edge values, replicate a grey
    solution into the channels with their gains."""
    a = np.asarray(x, dtype=np.float64)
    b = plan.bin
    if b > 1 and upsample is not None:
        a = upsample_image(a, b, upsample)
        ny, nx = plan.shape
        py, px = ny - a.shape[0], nx - a.shape[1]
        if py or px:
            pads = ((py // 2, py - py // 2), (px // 2, px - px // 2))
            a = np.pad(a, pads + (((0, 0),) if a.ndim == 3 else ()), mode="edge")
    if plan.grey and plan.gains is not None and a.ndim == 2:
        a = np.stack([g * a for g in plan.gains], axis=-1)
    return a


def _skipped_result(plan: Plan, backend: str):
    from .result import ReconInfo, Reconstruction

    shape = plan.shape + ((plan.channels,) if plan.channels > 1 else ())
    info = ReconInfo(method=plan.method, backend=backend, device="none (skipped)",
                     dtype=plan.dtype, iterations=0,
                     stop_reason=f"skipped: {plan.frame_state} frame")
    info.notes = plan.notes()
    info.params["plan"] = plan.to_dict()
    return Reconstruction(np.zeros(shape), info)


def reconstruct_planned(y: np.ndarray, camera: Camera, method: str = "bp", *,
                        plan: Plan | None = None, backend: str = "opencl",
                        upsample: str | None = "fourier", crop_fov: bool = False,
                        discrepancy: bool = True, plan_options: dict | None = None,
                        **options):
    """Run :func:`clfza.reconstruct` with the plan's decisions.

    Parameters
    ----------
    y : array
        DC-free observation (as for :func:`clfza.reconstruct`).
    camera : Camera
    method : str
        Reconstruction method.
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
    (Reconstruction, Plan)
        ``info.notes`` lists what was skipped and why.
    """
    from .api import reconstruct

    t0 = time.perf_counter()
    if plan is None:
        plan = make_plan(y, camera, method=method, kind="y", **(plan_options or {}))
    if plan.skip_solve:
        for w in plan.warnings:
            warnings.warn(w, PlanWarning, stacklevel=2)
        return _skipped_result(plan, backend), plan
    for w in plan.warnings:
        warnings.warn(w, PlanWarning, stacklevel=2)
    opts = dict(options)
    notes: list[str] = []
    from .exact import choose_model

    kind, why = choose_model(camera, opts.pop("model", "auto"), method=method,
                             mode=opts.get("mode", "paper"), psf=opts.get("psf") is not None)
    exact_binned = kind == "exact" and plan.bin > 1 and opts.get("psf") is None
    yw = apply_plan(y, plan, box=exact_binned)
    if exact_binned:
        opts["psf"] = binned_exact_model(camera, plan)
        notes.append(f"plan: exact model ({why}); the frame binned {plan.bin}x by pixel "
                     f"averaging and the mask kernel binned to match (clfza.exact."
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
    stopper = None
    if discrepancy and method != "bp" and plan.discrepancy_target is not None \
            and "callback" not in opts:
        accepted = solver_options(method)
        if accepted is not None and "callback" in accepted:
            stopper = DiscrepancyStop(plan.discrepancy_target)
            opts["callback"] = stopper
        else:
            notes.append("plan: the method takes no callback=, so the discrepancy stop was "
                         "not applied")
    rec = reconstruct(yw, plan.work_camera, method, backend=backend, **opts)
    img = finish_plan(rec.image, plan, upsample)
    if crop_fov:
        r0, r1_, c0, c1 = plan.fov
        if plan.bin > 1 and upsample is None:
            b = plan.bin
            r0, r1_, c0, c1 = r0 // b, -(-r1_ // b), c0 // b, -(-c1 // b)
        img = img[r0:r1_, c0:c1]
    rec.image = img
    rec.info.notes = list(rec.info.notes) + plan.notes() + notes
    if stopper is not None:
        if stopper.stopped_at is not None:
            rec.info.notes.append(
                f"plan: discrepancy principle stopped the solver at iteration "
                f"{stopper.stopped_at} (||y - K x||^2 = {stopper.last:.4g} <= "
                f"{stopper.target:.4g})")
        elif stopper.calls == 0:
            rec.info.notes.append("plan: the solver never called the discrepancy callback")
        else:
            rec.info.notes.append(
                f"plan: the discrepancy stop did NOT fire: ||y - K x||^2 = "
                f"{stopper.last if stopper.last is not None else float('nan'):.4g} stayed "
                f"above {stopper.target:.4g}; the solver ran {rec.info.iterations} iteration(s)"
                f" and stopped by {rec.info.stop_reason!r}")
    rec.info.params["plan"] = plan.to_dict()
    # what ran, not what was promised: the stop rule that fired and the grid solved on
    fired = ("discrepancy principle" if stopper is not None and stopper.stopped_at is not None
             else str(rec.info.stop_reason))
    rec.info.params["plan"].update(
        stop_rule_fired=fired, iterations_run=int(rec.info.iterations),
        discrepancy_promised=plan.discrepancy_target is not None and method != "bp",
        discrepancy_applied=stopper is not None,
        discrepancy_last=None if stopper is None else stopper.last)
    rec.info.timings["plan"] = plan.timings.get("plan", 0.0)
    rec.info.timings["planned_total"] = time.perf_counter() - t0
    return rec, plan


execute = reconstruct_planned
