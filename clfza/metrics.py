"""Error metrics against ground truth: MSE (Eq. 22), PSNR and SSIM (scikit-image).

Reconstructions of ``K o = y`` are defined up to an offset (``H_T(0) = 0``: the DC is lost) and
a scale (unknown exposure), so comparisons first fit ``a x + b`` to the truth by least squares
with the gain constrained to ``a >= 0`` (docs/design.md s.5): an exposure is never negative, and a
free sign would let an image that is anti-correlated with the truth (back-propagation's twin
image, a wrong sign) score as if it were right. With ``a = 0`` the fit is the truth's mean
(the score of knowing nothing). ``compare`` reports the fit; ``fit=False`` compares the raw
values.
"""

from __future__ import annotations

import numpy as np
from skimage.metrics import structural_similarity

from .errors import ClfzaError


def affine_params(x: np.ndarray, truth: np.ndarray) -> tuple[float, float]:
    """``(a, b)`` minimising ``||a x + b - truth||^2`` subject to ``a >= 0`` (one channel)."""
    x = np.asarray(x, dtype=np.float64)
    t = np.asarray(truth, dtype=np.float64)
    xm, tm = float(x.mean()), float(t.mean())
    var = float(np.mean((x - xm) ** 2))
    a = 0.0 if var == 0 else float(np.mean((x - xm) * (t - tm))) / var
    a = max(a, 0.0)  # the constrained minimiser: the objective is a parabola in a
    return a, tm - a * xm


def fit_affine(x: np.ndarray, truth: np.ndarray) -> np.ndarray:
    """``a x + b`` with ``a >= 0, b`` minimising ``||a x + b - truth||^2`` (per channel for
    RGB)."""
    x = np.asarray(x, dtype=np.float64)
    t = np.asarray(truth, dtype=np.float64)
    if x.shape != t.shape:
        raise ClfzaError(f"image shape {x.shape} differs from the truth's {t.shape}")
    if x.ndim == 3:
        return np.stack([fit_affine(x[..., c], t[..., c]) for c in range(x.shape[2])], -1)
    a, b = affine_params(x, t)
    return a * x + b


def mse(x: np.ndarray, truth: np.ndarray) -> float:
    """Mean square error ``1/N sum (O - O_hat)^2`` (Eq. 22)."""
    return float(np.mean((np.asarray(x, float) - np.asarray(truth, float)) ** 2))


def psnr(x: np.ndarray, truth: np.ndarray, data_range: float | None = None) -> float:
    """Peak signal-to-noise ratio in dB with the truth's range as peak (default)."""
    t = np.asarray(truth, float)
    rng = float(t.max() - t.min()) if data_range is None else float(data_range)
    m = mse(x, truth)
    if m == 0:
        return float("inf")
    if rng <= 0:
        rng = 1.0
    return float(10 * np.log10(rng**2 / m))


def ssim(x: np.ndarray, truth: np.ndarray, data_range: float | None = None) -> float:
    """Structural similarity (scikit-image), channel-wise for RGB."""
    t = np.asarray(truth, float)
    rng = float(t.max() - t.min()) if data_range is None else float(data_range)
    return float(structural_similarity(np.asarray(x, float), t, data_range=rng or 1.0,
                                       channel_axis=-1 if t.ndim == 3 else None))


def compare(x: np.ndarray, truth: np.ndarray, fit: bool = True) -> dict:
    """MSE, PSNR and SSIM of ``x`` against ``truth`` after an optional affine fit ``a x + b``
    with ``a >= 0``; ``gain`` and ``offset`` report the fit (lists per channel for RGB; 1 and
    0 without a fit)."""
    xx = fit_affine(x, truth) if fit else np.asarray(x, float)
    xa, ta = np.asarray(x, float), np.asarray(truth, float)
    if not fit:
        gain, offset = 1.0, 0.0
    elif xa.ndim == 3:
        ab = [affine_params(xa[..., c], ta[..., c]) for c in range(xa.shape[2])]
        gain, offset = [p[0] for p in ab], [p[1] for p in ab]
    else:
        gain, offset = affine_params(xa, ta)
    return {"mse": mse(xx, truth), "psnr": psnr(xx, truth), "ssim": ssim(xx, truth),
            "affine_fit": bool(fit), "gain": gain, "offset": offset}
