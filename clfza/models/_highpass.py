"""The exact model's data term seen through a box high-pass: ``1/2 ||G (y - K x)||^2``.

A real FZA's kernel (:mod:`clfza.models._exact`) is ``(1/2) circ + (1/2) zones``: the open disc of
the aperture gives ``||K||`` in the hundreds at the lowest frequencies, the zones (which carry the
image) a gain of about one. ``K^T K`` is then conditioned like ``(||K|| / 1)^2 ~ 10^4-10^5``
on the band that matters, and the crop-split ADMM (:mod:`clfza.solvers._admm_crop`) is far
from its minimiser after hundreds of iterations (its PSNR depends on its path more than on
``tau``). Weighing the data term by ``G = delta - box_w / w^2`` (``w = 2k + 1`` pixels) takes
the disc's low frequencies out of the problem and leaves the zone frequencies (periods below
``w``) with gain ~1::

    min_x 1/2 || C' G (y - P C H x) ||^2 + tau TV(x) = 1/2 || y' - C' (g * h) * x ||^2 + ...

``G`` is a finite filter, so on the sensor's interior ``C'`` (the sensor less ``k`` pixels at
each edge) ``C' G C = C' G`` exactly: the filtered problem is the exact model of the kernel
``g * h`` (:func:`highpass_model`) with the frame ``y' = C' (g * y)`` (:func:`highpass_frame`),
its sensor the interior and its margin ``k`` larger, so the object still covers the whole
sensor (the image returned has the sensor's shape). What is discarded: the frame's constant and
linear ramps (``G`` passes neither; ``P`` already dropped the constant) and its ``k``-pixel
border as data (4 k / S of the pixels; the object there is still solved for, seen through its
shadow on the interior). White noise stays white-ish with variance ``(1 - 1/w^2) sigma^2``.

What the filter gains and costs (noise-free and noisy frames, through the planner), the box
width and a partial filter ``G = delta - alpha box`` that was not adopted were measured:
docs/measurements.md, clfza.models._highpass.
"""

from __future__ import annotations

from functools import lru_cache

import numpy as np
from scipy.ndimage import uniform_filter

from ..errors import ClfzaError
from ._exact import ExactModel, ModelGrid

HIGHPASS_R1 = 0.8
"""Default box width ``w = 2k + 1`` as a multiple of the shadow's first zone radius ``r1'`` in
pixels (:func:`default_halfwidth`; chosen by measurement: docs/measurements.md,
clfza.models._highpass)."""
MIN_INTERIOR = 16  # pixels of sensor interior per axis that must remain
MIN_R1_PIXELS = 6.0
"""No default high-pass below this many pixels per ``r1'``: there the box reaches into the zone
band itself, and the filter, which still helps noise-free frames there, costs noisy ones
(measured: docs/measurements.md, clfza.models._highpass)."""


def _minus_box(a: np.ndarray, k: int) -> np.ndarray:
    """``a - box_{2k+1}(a)`` over the last two axes, zero outside ``a`` (float64)."""
    size = (1,) * (a.ndim - 2) + (2 * k + 1, 2 * k + 1)
    return a - uniform_filter(a, size=size, mode="constant", cval=0.0)


def noise_gain(k: int) -> float:
    """The factor ``G`` applies to white noise's standard deviation: ``||g|| = sqrt(1 -
    1/w^2)`` (``w = 2k + 1``)."""
    return float(np.sqrt(1.0 - 1.0 / (2 * k + 1) ** 2))


def highpass_frame(y: np.ndarray, k: int) -> np.ndarray:
    """``y' = C' (g * y)``: the frame (..., H, W) through ``G = delta - box_{2k+1}``, kept
    where the box lies inside the frame, (..., H - 2k, W - 2k)."""
    y = np.asarray(y, dtype=np.float64)
    if k == 0:
        return y
    y = y - y.mean(axis=(-2, -1), keepdims=True)  # G drops the constant; keeps sums small
    return _minus_box(y, k)[..., k:-k, k:-k]


def highpass_kernel(kernel: np.ndarray, k: int) -> np.ndarray:
    """``g * h``: the centred kernel (Py, Px) through ``G`` (full convolution), (Py + 2k,
    Px + 2k), still centred at ``(P // 2)`` of its own shape."""
    padded = np.pad(np.asarray(kernel, dtype=np.float64), k)
    return _minus_box(padded, k)


@lru_cache(maxsize=4)
def highpass_model(model: ExactModel, k: int) -> ExactModel:
    """The exact model of the filtered problem: kernel ``g * h``, sensor the interior of
    ``model``'s sensor (``k`` pixels less at each edge), margin ``k`` larger; its
    ``image_geom`` is ``model``'s sensor window on the new grid (the image keeps the sensor's
    shape). Cached per model and ``k`` (its norm is measured once)."""
    k = int(k)
    if k == 0:
        return model
    sy, sx = model.sensor
    if min(sy, sx) - 2 * k < MIN_INTERIOR:
        raise ClfzaError(f"highpass={k} leaves {sy - 2 * k}x{sx - 2 * k} pixels of a "
                         f"{sy}x{sx} sensor as data (at least {MIN_INTERIOR} per axis): "
                         f"use a smaller highpass or 0")
    m = model.geom.margin
    out = ExactModel(highpass_kernel(model.kernel, k), (sy - 2 * k, sx - 2 * k), m + k)
    oy, ox = out.geom.offset
    out.image_geom = ModelGrid((sy, sx), out.geom.grid, (oy - k, ox - k), m)
    out.highpass = k
    out.mask_shadow = model.mask_shadow
    return out


def default_halfwidth(camera, psf) -> int:
    """The default ``k``: ``w = 2k + 1 ~ HIGHPASS_R1 r1' / pitch`` for the shadow of a mask
    with a finite aperture sampled with at least ``MIN_R1_PIXELS`` pixels per ``r1'`` (the
    camera's own model or a model built from it, e.g. the planner's binned one); 0 without an
    aperture (no disc term: the open mask's constant is the DC, which ``P`` removes exactly,
    and the filter only loses signal) and for a measured PSF (not measured there: give
    ``highpass`` to use it). ADMM also leaves it off by default with ``support=False``:
    nothing then pins the object's lowest frequencies, which ``G`` hardly sees, and float32
    drifted from float64 (both measured: docs/measurements.md, clfza.models._highpass)."""
    if camera is None or camera.R is None or (
            psf is not None and not getattr(psf, "mask_shadow", False)):
        return 0
    r1_px = camera.r1p / camera.pitch
    if r1_px < MIN_R1_PIXELS:
        return 0
    k = int(round((HIGHPASS_R1 * r1_px - 1) / 2))
    return max(k, 1) if min(camera.shape) - 2 * k >= MIN_INTERIOR else 0
