"""The noise level of a DC-free FZA observation, and the energy in the band the mask encodes.

Below the solvers and the planner: :mod:`clfza.reconstruction._plan` (flat frames, the discrepancy
stop, the float32 rule) and ``tau="auto"`` (:mod:`clfza.solvers._tau`) both read the noise from
here.
"""

from __future__ import annotations

import math

import numpy as np
import scipy.fft

from ..camera import Camera

__all__ = ["encoded_band_energy", "estimate_noise", "haar_mad_sigma", "haar_scale_ratio",
           "noise_from_power", "out_of_band_mask"]


def freq_radius(shape: tuple[int, int], pitch: float) -> np.ndarray:
    """The radial spatial frequency (cycles/mm) of each bin of an ``rfft2`` of ``shape`` with
    pixels ``pitch`` mm apart."""
    fy = scipy.fft.fftfreq(shape[0], pitch)[:, None]
    fx = scipy.fft.rfftfreq(shape[1], pitch)[None, :]
    return np.sqrt(fy**2 + fx**2)


def out_of_band_mask(camera: Camera, guard: float = 1.15) -> np.ndarray:
    """rfft2 half-spectrum mask of frequencies above ``guard * rho_c`` (pure noise for a GZP;
    the binary FZA's higher orders (Eq. 7) and the aperture edge leak a little there)."""
    rho = freq_radius(camera.shape, camera.pitch)
    m = rho > guard * camera.band_limit
    m[0, :] = False
    m[:, 0] = False
    if camera.shape[1] % 2 == 0:
        m[:, -1] = False
    return m


_MAD_GAUSS = 0.6744897501960817  # median |z| of a standard normal z


def _haar_level(a: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """One orthonormal 2-D Haar level of ``a`` (odd last row/column dropped): the diagonal
    band ``(a - b - c + d) / 2`` and the approximation ``(a + b + c + d) / 2`` of 2x2 blocks."""
    ny, nx = (a.shape[0] // 2) * 2, (a.shape[1] // 2) * 2
    a = a[:ny, :nx]
    p, q, r, s = a[0::2, 0::2], a[0::2, 1::2], a[1::2, 0::2], a[1::2, 1::2]
    return (p - q - r + s) / 2.0, (p + q + r + s) / 2.0


def haar_mad_sigma(y: np.ndarray) -> float:
    """Donoho's robust noise estimate ``median(|HH|) / 0.6745`` on the finest diagonal Haar
    band ``HH = (a - b - c + d) / 2`` of 2x2 blocks (Donoho & Johnstone, Biometrika 81, 425,
    1994). Signal at the Nyquist corner biases it upwards: an upper bound for FZA data."""
    a = np.asarray(y, dtype=np.float64)
    ny, nx = (a.shape[0] // 2) * 2, (a.shape[1] // 2) * 2
    a = a[:ny, :nx]
    # _haar_level's diagonal band alone (its approximation is not needed here), in place:
    # the same operations in the same order, a third of the passes over the frame
    hh = np.subtract(a[0::2, 0::2], a[0::2, 1::2])
    hh -= a[1::2, 0::2]
    hh += a[1::2, 1::2]
    hh /= 2.0
    np.abs(hh, out=hh)
    return float(median_flat(hh.reshape(-1)) / _MAD_GAUSS)


#: :func:`median_flat`: the sample's least size (arrays below 4 times it go to np.median)
MEDIAN_SAMPLE = 2048


def median_flat(v: np.ndarray) -> np.float64:
    """``np.median(v)`` of a 1-D array, bit for bit, without partitioning all of it (floats;
    other types: np.median itself).

    An evenly strided sample of ``max(MEDIAN_SAMPLE, n^(2/3))`` values gives a window
    ``[lo, hi]`` around the middle rank (the sample's order statistics about 4 standard
    deviations of its quantile's rank either side); two comparison passes count the values
    below ``lo`` and gather those in the window, whose partition gives the middle order
    statistics, the very values np.median takes, averaged as np.median averages them. Where
    the window misses the middle (an unrepresentative sample) or holds NaN: np.median
    itself. ``v`` is not modified.

    Examples
    --------
    >>> v = np.random.default_rng(0).exponential(size=10001)
    >>> bool(median_flat(v) == np.median(v))
    True
    """
    n = v.size
    if n < 4 * MEDIAN_SAMPLE or v.dtype.kind != "f":
        return np.median(v)
    k = n // 2
    ks = [k - 1, k] if n % 2 == 0 else [k]
    sample = v[::n // max(MEDIAN_SAMPLE, int(n ** (2 / 3)))].copy()
    m = sample.size
    j, d = (k * m) // n, 2 * math.isqrt(m) + 2
    a, b = max(j - d, 0), min(j + d, m - 1)
    sample.partition([a, b])
    lt, gt = v < sample[a], v > sample[b]
    below = int(np.count_nonzero(lt))
    np.logical_or(lt, gt, out=lt)
    np.logical_not(lt, out=lt)
    mid = v[lt]  # the window, and every NaN (it fails both comparisons)
    if not (below <= ks[0] and below + mid.size > ks[-1]) or np.isnan(mid).any():
        return np.median(v)
    mid.partition([q - below for q in ks])
    if len(ks) == 1:
        return mid[ks[0] - below]
    return (mid[ks[0] - below] + mid[ks[1] - below]) / 2.0


def haar_scale_ratio(y: np.ndarray) -> float:
    """Whiteness of ``y``: the MAD noise estimate of the second Haar level's diagonal band
    over the first's (:func:`haar_mad_sigma`). The transform is orthonormal, so white noise
    of any variance gives 1 at every level (within ``~2/sqrt(N)``); a residual that still
    holds signal (smooth, correlated) has more energy at the coarser scale: > 1. Infinite
    for a residual whose finest band is zero; NaN for one that is zero everywhere.
    :func:`clfza.solvers._tau_exact.is_white` reads it on the pilot residuals of the exact
    model (the values it gives there: docs/measurements.md, clfza.solvers._noise)."""
    hh1, low = _haar_level(np.asarray(y, dtype=np.float64))
    hh2, _ = _haar_level(low)
    s1, s2 = np.median(np.abs(hh1)), np.median(np.abs(hh2))
    if s1 == 0:
        return math.nan if s2 == 0 else math.inf
    return float(s2 / s1)


def estimate_noise(y: np.ndarray, camera: Camera, *, min_fraction: float = 0.02
                   ) -> tuple[float, str]:
    """Noise standard deviation of a DC-free observation ``y`` (per pixel, units of ``y``).

    Uses the spectrum beyond the band limit when at least ``min_fraction`` of the frequencies
    lie there: for white noise of variance ``sigma^2`` each DFT coefficient ``Y(f)`` is complex
    Gaussian with ``E|Y|^2 = N sigma^2``, so ``|Y|^2`` is exponential and
    ``median |Y|^2 = ln 2 * N sigma^2``. Otherwise falls back on :func:`haar_mad_sigma`.

    Returns
    -------
    (sigma, method)
    """
    a = np.asarray(y, dtype=np.float64)
    if a.ndim == 3:
        vals = [estimate_noise(a[..., c], camera, min_fraction=min_fraction) for c in
                range(a.shape[2])]
        return float(np.sqrt(np.mean([v[0] ** 2 for v in vals]))), vals[0][1]
    m = out_of_band_mask(camera)
    if m.mean() >= min_fraction:
        Y = scipy.fft.rfft2(a - a.mean())
        p = np.abs(Y[m]) ** 2
        return float(np.sqrt(median_flat(p) / (math.log(2.0) * a.size))), "out-of-band spectrum"
    return haar_mad_sigma(a), "Haar MAD (upper bound)"


def noise_from_power(power: np.ndarray, planes: np.ndarray, camera: Camera, *,
                     min_fraction: float = 0.02) -> list[tuple[float, str]]:
    """:func:`estimate_noise` of many planes at once, from their power spectra.

    Parameters
    ----------
    power : array, (F, H, W//2+1)
        ``|rfft2(y - mean(y))|^2`` of each plane (user units).
    planes : array, (F, H, W)
        The planes (for the Haar fallback where the camera has no out-of-band spectrum).
    camera, min_fraction
        As :func:`estimate_noise`.

    Returns
    -------
    list of (sigma, method)
        Each plane's, bit for bit what :func:`estimate_noise` returns for it alone.

    Examples
    --------
    >>> import numpy as np, scipy.fft
    >>> from clfza import Camera
    >>> cam = Camera.preset("simulation").with_shape((64, 64))
    >>> y = np.random.default_rng(0).normal(size=(2, 64, 64))
    >>> p = np.abs(scipy.fft.rfft2(y - y.mean(axis=(1, 2), keepdims=True))) ** 2
    >>> noise_from_power(p, y, cam) == [estimate_noise(a, cam) for a in y]
    True
    """
    m = out_of_band_mask(camera)
    if m.mean() >= min_fraction:
        size = int(np.prod(np.shape(planes)[-2:]))
        med = [median_flat(row) for row in np.asarray(power)[:, m]]
        return [(float(np.sqrt(v / (math.log(2.0) * size))), "out-of-band spectrum")
                for v in med]
    return [(haar_mad_sigma(a), "Haar MAD (upper bound)") for a in planes]


def encoded_band_energy(y: np.ndarray, camera: Camera) -> tuple[float, int]:
    """Mean ``|Y(f)|^2 / N`` over frequencies the mask encodes (``|H_T| >= 0.3`` and
    ``rho <= rho_c``) and their number: compare with ``sigma^2`` to tell signal from noise."""
    a = np.asarray(y, dtype=np.float64)
    if a.ndim == 3:
        a = a.mean(axis=2)
    rho = freq_radius(camera.shape, camera.pitch)
    H = np.abs(np.sin(np.pi * np.mod(camera.r1p**2 * rho**2, 2.0)))
    m = (H >= 0.3) & (rho <= camera.band_limit)
    m[0, 0] = False
    if not m.any():
        return 0.0, 0
    Y = scipy.fft.rfft2(a - a.mean())
    return float(np.mean(np.abs(Y[m]) ** 2) / a.size), int(m.sum())
