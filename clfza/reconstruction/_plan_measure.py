"""Measurements of a frame for the planner (:mod:`clfza.reconstruction._plan`): is it flat, clipped,
grey in RGB, noisy enough for float32, and which sensor region does the scene cover.

The thresholds are module constants so reports and tests can name them;
:mod:`clfza.reconstruction._plan` re-exports everything here. The noise estimates themselves live in
:mod:`clfza.solvers._noise`.
"""

from __future__ import annotations

import math

import numpy as np
from scipy.ndimage import gaussian_filter

from ..camera import Camera
from ..errors import ClfzaError
from ..focus import FastBP

# --- thresholds (module constants so reports and tests can name them) -------------------
MIN_BIN = 2                 # bin only when 1/(2p) >= 2 rho_c (issue 6)
SATURATED_SKIP = 0.5        # more than half the pixels clipped: no solve
SATURATED_WARN = 1e-3       # more than 0.1 % clipped: warn, solve anyway
FLAT_EFFECT = 0.05          # flat: any signal < 5% of the noise energy, band and whole frame
FLAT_CONFIDENCE = 0.99      # ... with this one-sided confidence
GREY_TOL = 2.0              # channel residual below 2 N sigma^2: the channels are equal
FLOAT32_FACTOR = 10.0       # noise floor / float32 rounding needed for float32
EPS32 = float(np.finfo(np.float32).eps) / 2.0  # unit roundoff 2^-24


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
    from scipy.stats import (  # lazy: scipy.stats takes ~0.7 s to import; only this test needs it
        gamma,
        norm,
    )

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
                     quant_step: float | None = None, factor: float = FLOAT32_FACTOR
                     ) -> tuple[bool, float, float]:
    """The float32 rule.

    An FFT-based iteration in float32 adds rounding noise of relative size about
    ``u sqrt(log2 N)`` (``u = 2^-24``) per pass; accumulated as a random walk over ``iters``
    iterations it stays below ``u sqrt(iters log2 N) ||y||_rms``. float32 suffices when the
    measurement's own noise floor -- the estimated ``sigma``, or the quantisation noise
    ``q / sqrt(12)`` when larger -- exceeds that by the safety ``factor`` (10: float32 then
    adds at most 1 % to the error variance the data already carry).

    Returns
    -------
    (ok, floor, rounding)
    """
    floor = max(float(sigma), (quant_step or 0.0) / math.sqrt(12.0))
    rounding = EPS32 * math.sqrt(max(1, iters) * math.log2(max(2, n_pixels))) * float(rms)
    return floor >= factor * rounding, floor, rounding


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
