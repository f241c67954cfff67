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

Measured (experiment preset binned to 300^2, 30 um pixels, ``r1' = 10.8`` pixels; ADMM 400
iterations, OpenCL; bench/bench_tau.py, the best ``tau`` of a 20-point grid without -> with
``k = 4``): noise-free natural / text / USAF 31.4 / 55.8 / 47.9 -> 62.7 / 97.3 / 88.9 dB;
Gaussian variance 1e-3 30.4 / 47.5 / 43.5 -> 39.8 / 45.4 / 45.0; 1e-2 29.1 / 39.1 / 36.9 ->
34.1 / 35.1 / 35.1; 1e4 photons 25.0 / 36.8 / 29.6 -> 17.0 / 34.3 / 27.9 (the bright natural
scene under photon noise loses most: the disc's low frequencies are its best-measured part).
Through the planner (2400^2 binned 3x) noise-free 31.2 / 30.7 / 30.5 -> 34.5 / 34.0 / 32.1 dB
(camera / astronaut / text). Box widths ``w`` = 9, 17, 33 pixels on the 300^2 camera: 9 and
17 within 1 dB of each other, 33 a few dB lower noise-free. Keeping some of the low band
(``G = delta - alpha box``): alpha 0.9 lifts the photon-limited natural scene 17 -> 23 dB but
costs 40 dB noise-free (convergence returns to the unfiltered problem's), 0.97 gives 21 and
62 dB; not adopted.
"""

from __future__ import annotations

from functools import lru_cache

import numpy as np
from scipy.ndimage import uniform_filter

from ..errors import ClfzaError
from ._exact import ExactModel, ModelGrid

HIGHPASS_R1 = 0.8
"""Default box width ``w = 2k + 1`` as a multiple of the shadow's first zone radius ``r1'`` in
pixels (:func:`default_halfwidth`); see the module docstring for the measurements."""
MIN_INTERIOR = 16  # pixels of sensor interior per axis that must remain
MIN_R1_PIXELS = 6.0
"""No default high-pass below this many pixels per ``r1'``: there the box reaches into the zone
band itself. Experiment preset binned to r1' = 3.5 / 5.4 / 7.2 pixels (96^2, 150^2, 200^2;
ADMM 400 iterations, the same tau without -> with): natural scene noise-free 36.0 -> 56.6,
38.9 -> 61.1, 23.7 -> 60.8 dB, but at Gaussian variance 1e-2 31.9 -> 26.2, 35.4 -> 32.7,
30.1 -> 30.5 dB; the stress suite's 96^2 noisy shot (1000 iterations) 35.6 -> 21.8 dB."""


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
    aperture (no disc term: the open mask's constant is the DC, which ``P`` removes exactly;
    the simulation preset at pitch 0.02, 256^2, lost 6 dB with it) and for a measured PSF
    (not measured there: give ``highpass`` to use it). ADMM also leaves it off by default
    with ``support=False``: nothing then pins the object's lowest frequencies, which ``G``
    hardly sees, and float32 drifted from float64 (the stress suite's 37^2 and 53^2
    experiment cameras: 16.8 against 17.8-19.5 dB)."""
    if camera is None or camera.R is None or (
            psf is not None and not getattr(psf, "mask_shadow", False)):
        return 0
    r1_px = camera.r1p / camera.pitch
    if r1_px < MIN_R1_PIXELS:
        return 0
    k = int(round((HIGHPASS_R1 * r1_px - 1) / 2))
    return max(k, 1) if min(camera.shape) - 2 * k >= MIN_INTERIOR else 0
