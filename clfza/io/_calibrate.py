"""Calibration, cropping and the observation ``y`` of a raw frame (re-exported by
:mod:`clfza.io`).

Calibration and geometry
    :func:`subtract_dark`, :func:`flat_field`, :func:`demosaic` (2x2 superpixel binning of a
    Bayer mosaic) and :func:`center_crop` (the paper crops the 4656 x 3522 frame to 2048^2
    around its centre).

The observation
    :func:`frame_to_measurement` turns a raw frame into the DC-free observation ``y`` in the
    units of the operator ``K`` (see its docstring for the gain calibration).
"""

from __future__ import annotations

import math

import numpy as np

from ..camera import Camera
from ..errors import ClfzaError, in_range, positive
from ._read import MIN_SIDE

BAYER_PATTERNS = ("RGGB", "BGGR", "GRBG", "GBRG")
HUGE_VALUE = 1e150  # largest |value| whose square (and sums of squares) float64 holds


def _same_shape(frame: np.ndarray, other: np.ndarray, what: str) -> np.ndarray:
    if other.shape == frame.shape:
        return other
    if other.ndim == 2 and frame.ndim == 3 and other.shape == frame.shape[:2]:
        return other[..., None]
    raise ClfzaError(f"the {what} has shape {other.shape}, the frame {frame.shape}; they must "
                     "come from the same sensor mode")


def subtract_dark(frame: np.ndarray, dark: np.ndarray) -> np.ndarray:
    """``frame - dark`` (same shape; a grey dark frame applies to every colour channel).

    Negative results (read noise around a black level) are kept: clipping them would bias
    the mean that :func:`frame_to_measurement` divides by.
    """
    return frame - _same_shape(frame, np.asarray(dark, dtype=np.float64), "dark frame")


def flat_field(frame: np.ndarray, flat: np.ndarray) -> np.ndarray:
    """Divide by the flat field normalised to mean 1 (per channel for an RGB flat).

    The flat should already be dark-subtracted (or be bright enough that its dark level does
    not matter). Every flat pixel must be positive.
    """
    f = _same_shape(frame, np.asarray(flat, dtype=np.float64), "flat field")
    if f.min() <= 0:
        raise ClfzaError(f"the flat field has {int(np.count_nonzero(f <= 0))} pixel(s) <= 0; "
                         "a flat field must be positive everywhere")
    norm = f / f.mean(axis=(0, 1), keepdims=True)
    return frame / norm


def demosaic(raw: np.ndarray, pattern: str) -> np.ndarray:
    """Turn a Bayer mosaic into an RGB frame by 2x2 superpixel binning.

    Each 2x2 cell (one red, two green, one blue photosite) becomes one RGB pixel: red and
    blue as measured, green the mean of the two greens. The result has half the rows and
    columns, and its pixel pitch is twice the sensor's (the CLI doubles the camera's pitch).

    Why binning rather than bilinear interpolation: every output value is a measurement, not
    an interpolation, so no demosaicing pattern (zipper, false colour) is imprinted on the
    fine zones of the FZA shadow, and the channels stay co-sited. What it gives up -- half the
    sampling rate -- is usually not there to lose: the system's band limit
    ``rho_c = R' / r1'^2`` lies below the pixel Nyquist frequency in typical FZA setups
    (``Camera.suggested_bin`` >= 2 for the paper's experiment), and the binned grid is closer to
    critical sampling of ``H_T``.

    Parameters
    ----------
    raw : array (H, W)
        The mosaic (odd trailing rows/columns are dropped).
    pattern : {"RGGB", "BGGR", "GRBG", "GBRG"}
        Colour of the 2x2 cell read row by row from the top-left photosite.
    """
    pat = str(pattern).upper()
    if pat not in BAYER_PATTERNS:
        raise ClfzaError(f"Bayer pattern must be one of {BAYER_PATTERNS}, got {pattern!r}")
    a = np.asarray(raw, dtype=np.float64)
    if a.ndim != 2:
        raise ClfzaError(f"a Bayer mosaic is a single-channel (H, W) frame, got shape {a.shape}")
    h, w = (a.shape[0] // 2) * 2, (a.shape[1] // 2) * 2
    if h < 2 * MIN_SIDE or w < 2 * MIN_SIDE:
        raise ClfzaError(f"the Bayer mosaic is too small ({a.shape[0]}x{a.shape[1]})")
    a = a[:h, :w]
    cells = {(0, 0): a[0::2, 0::2], (0, 1): a[0::2, 1::2], (1, 0): a[1::2, 0::2],
             (1, 1): a[1::2, 1::2]}
    where = {(0, 0): pat[0], (0, 1): pat[1], (1, 0): pat[2], (1, 1): pat[3]}
    r = next(cells[k] for k, c in where.items() if c == "R")
    b = next(cells[k] for k, c in where.items() if c == "B")
    g1, g2 = (cells[k] for k, c in where.items() if c == "G")
    return np.stack([r, 0.5 * (g1 + g2), b], axis=-1)


def parse_pair(text: str, what: str, *, integer: bool = True) -> tuple:
    """Parse ``"N"`` or ``"A,B"`` (also ``AxB``) into a pair; a single value repeats."""
    parts = [s for s in str(text).replace("x", ",").replace("X", ",").split(",")]
    if len(parts) not in (1, 2) or any(not s.strip() for s in parts):
        raise ClfzaError(f"{what} must be 'N' or 'A,B', got {text!r}")
    try:
        vals = [int(s) if integer else float(s) for s in parts]
    except ValueError:
        kind = "integers" if integer else "numbers"
        raise ClfzaError(f"{what} must be {kind} ('N' or 'A,B'), got {text!r}") from None
    if not integer and not all(math.isfinite(v) for v in vals):
        raise ClfzaError(f"{what} must be finite, got {text!r}")
    if len(vals) == 1:
        vals = vals * 2
    return tuple(vals)


def center_crop(frame: np.ndarray, shape: tuple[int, int],
                center: tuple[float, float] | None = None, align: int = 1
                ) -> tuple[np.ndarray, tuple[int, int]]:
    """Crop ``shape`` pixels around ``center`` (row, col; default the frame's centre).

    ``align`` rounds the crop's origin down to a multiple (2 keeps a Bayer mosaic's phase).

    The paper crops the sensor's 4656 x 3522 frame to 2048^2 around the centre of the FZA
    shadow; ``center`` lets the shadow's centre, when it is off the frame's, be given.

    Returns
    -------
    (crop, origin)
        The crop (a view) and the (row, col) of its top-left pixel in the frame.
    """
    H, W = frame.shape[:2]
    try:
        h, w = (int(s) for s in shape)
    except (TypeError, ValueError):
        raise ClfzaError(f"crop must be two integers (rows, cols), got {shape!r}") from None
    if h < MIN_SIDE or w < MIN_SIDE:
        raise ClfzaError(f"crop {h}x{w} is too small (at least {MIN_SIDE}x{MIN_SIDE})")
    if h > H or w > W:
        raise ClfzaError(f"crop {h}x{w} is larger than the frame ({H}x{W}); use a smaller "
                         "--crop or a camera file whose shape fits the frame")
    cy, cx = (H / 2, W / 2) if center is None else (float(center[0]), float(center[1]))
    if not (0 <= cy <= H and 0 <= cx <= W):
        raise ClfzaError(f"centre ({cy:g}, {cx:g}) lies outside the {H}x{W} frame")
    y0 = int(round(cy - h / 2))
    x0 = int(round(cx - w / 2))
    if align > 1:
        y0, x0 = max(0, y0 - y0 % align), max(0, x0 - x0 % align)
    if y0 < 0 or x0 < 0 or y0 + h > H or x0 + w > W:
        raise ClfzaError(f"a {h}x{w} crop centred at ({cy:g}, {cx:g}) extends past the "
                         f"{H}x{W} frame; move the centre or crop less")
    return frame[y0:y0 + h, x0:x0 + w], (y0, x0)


# ----------------------------------------------------------------------------------------
# the observation y
# ----------------------------------------------------------------------------------------
def effective_pixels(camera: Camera, samples: int = 40) -> float:
    """``N_eff``: the mean number of sensor pixels that see one object point through the
    aperture (an object point at sensor position q reaches the pixels within ``R'`` of q).

    Equal to ``H W`` for a mask whose shadow covers the whole sensor from every point;
    computed on a ``samples x samples`` grid of object and sensor positions otherwise.
    """
    ny, nx = camera.shape
    Rs = camera.R_shadow
    if Rs is None or Rs >= math.hypot(*camera.sensor_size):
        return float(ny * nx)
    hy, hx = camera.sensor_size
    ys = (np.arange(samples) + 0.5) / samples * hy
    xs = (np.arange(samples) + 0.5) / samples * hx
    yy, xx = np.meshgrid(ys, xs, indexing="ij")
    pts = np.stack([yy.ravel(), xx.ravel()], axis=1)
    d2 = ((pts[:, None, :] - pts[None, :, :]) ** 2).sum(axis=-1)
    frac = float(np.mean(d2 <= Rs * Rs))
    return frac * ny * nx


def frame_to_measurement(frame, camera: Camera, *, object_mean: float = 0.5,
                         n_eff: float | None = None) -> np.ndarray:
    """The DC-free observation ``y`` (units of ``K``) of a raw frame with an unknown gain.

    Derivation. The frame is ``F = g conv(O, T)``: the sensor-plane object ``O`` convolved
    with the mask's shadow ``T = 1/2 + 1/2 c(r)`` (``c`` the zone pattern, mean zero), times
    an unknown gain ``g`` (exposure, quantum efficiency, ADC). Two of its parts matter:

    * the DC: ``mean(F) ~ g (1/2) N_eff mean(O)`` -- each object pixel lights, through the
      mask's mean transmittance 1/2, the ``N_eff`` sensor pixels that see it within the
      aperture's shadow (:func:`effective_pixels`; ``H W`` for an unbounded mask);
    * the AC: ``F - mean(F) = g (r1'^2 / (2 p^2)) K O``, because the Fourier transform of
      ``cos(pi r^2 / r1'^2)`` is ``r1'^2 sin(pi r1'^2 rho^2)`` and a discrete convolution
      carries a factor ``1 / p^2`` (:mod:`clfza.simulation` uses the same scale).

    Eliminating ``g`` with an assumed object mean ``m = mean(O)``::

        y = K O = (F - mean(F)) / mean(F) * (N_eff p^2 / r1'^2) * m

    so reconstructions of real frames are scaled such that the object's mean is ``m``. Only
    the scale rests on the assumption; the image's shape does not. ``m`` is the mean over the
    part of the scene whose light reaches the sensor: for a scene filling the sensor this
    reproduces :attr:`clfza.simulation.Measurement.y` to within a few percent (tested), while
    light from a scene larger than the view raises ``mean(F)`` and lowers the recovered scale.
    Colour frames are handled per channel (each with its own mean).

    Parameters
    ----------
    frame : array (H, W) or (H, W, 3)
        Dark-subtracted (and flat-fielded) frame on the camera's grid.
    camera : Camera
        The camera; ``frame`` must have its shape.
    object_mean : float
        Assumed mean ``m`` of the sensor-plane object, in (0, 1]; 0.5 by default.
    n_eff : float, optional
        Override ``N_eff`` (e.g. from a calibration shot).

    Returns
    -------
    ndarray
        ``y`` with the frame's shape, float64.
    """
    f = np.asarray(frame, dtype=np.float64)
    if f.ndim not in (2, 3) or f.size == 0:
        raise ClfzaError(f"frame must be (H, W) or (H, W, 3), got shape {f.shape}")
    if f.shape[:2] != tuple(camera.shape):
        raise ClfzaError(f"frame is {f.shape[0]}x{f.shape[1]} but the camera grid is "
                         f"{camera.shape[0]}x{camera.shape[1]}; crop it (--crop) or fix the "
                         "camera's shape")
    m = in_range("object_mean", object_mean, 1e-6, 1e6)
    ne = effective_pixels(camera) if n_eff is None else positive("n_eff", n_eff)
    big = float(np.max(np.abs(f)))
    if big > HUGE_VALUE:
        raise ClfzaError(f"frame values reach {big:.3g}: their squares overflow float64 "
                         f"(limit {HUGE_VALUE:.0e}); rescale the frame to sensor units")
    mean = f.mean(axis=(0, 1), keepdims=True)
    if np.any(mean <= 0):
        raise ClfzaError("the frame's mean is <= 0 (after dark subtraction): it is black or "
                         "over-corrected; check the exposure and the dark frame")
    ac = f - mean
    spread = np.sqrt(np.mean(ac**2, axis=(0, 1)))
    if np.any(spread <= 1e-12 * np.abs(mean.reshape(spread.shape))):
        raise ClfzaError("the frame is flat (no modulation): there is no zone pattern to "
                         "reconstruct from")
    return ac / mean * (ne * camera.pitch**2 / camera.r1p**2) * m
