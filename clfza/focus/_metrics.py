"""Sharpness metrics of :mod:`clfza.focus`: gradient energy, the Tamura coefficient of the
gradient, the Laplacian variance, their mix, and the central region they are scored on
(larger = sharper). :mod:`clfza.focus` re-exports every public name here.
"""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np

from ..errors import ClfzaError, in_range

METRICS = ("gradient", "tamura", "laplacian", "mix")


def _gradients(x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Forward differences cropped to a common (H-1, W-1) grid."""
    gx = x[:-1, 1:] - x[:-1, :-1]
    gy = x[1:, :-1] - x[:-1, :-1]
    return gx, gy


def _select(a: np.ndarray, mask: np.ndarray | None) -> np.ndarray:
    if mask is None:
        return a
    return a[mask[: a.shape[0], : a.shape[1]]]


def gradient_energy(x: np.ndarray, mask: np.ndarray | None = None) -> float:
    """Gradient energy ``mean(|grad x|^2)`` (squared-gradient focus measure).

    Subbarao, Choi & Nikzad, "Focusing techniques", Opt. Eng. 32, 2824 (1993); the "energy of
    gradient" of Groen, Young & Ligthart, Cytometry 6, 81 (1985). Not normalised by
    ``||x||^2``: during a depth search ``y`` is fixed and the energy of ``K^T y`` itself is part
    of the signal (in focus ``|H_T|^4`` averages 3/8 over a ring, out of focus 1/4).
    """
    gx, gy = _gradients(np.asarray(x, dtype=np.float64))
    return float(np.mean(_select(gx * gx + gy * gy, mask)))


def tamura(x: np.ndarray, mask: np.ndarray | None = None) -> float:
    """Tamura coefficient of the gradient magnitude, ``sqrt(std(|grad x|) / mean(|grad x|))``.

    The Tamura coefficient ``sqrt(sigma/mean)`` (Memmolo et al., Opt. Lett. 36, 1945 (2011))
    applied to the gradient magnitude ("Tamura of the gradient", ToG: Zhang, Wang, Wu, Tanaka
    & Lam, "Edge sparsity criterion for robust holographic autofocusing", Opt. Lett. 42, 3824
    (2017)). Scale invariant; large for sparse edges, small for the diffuse chirps of
    defocused points and of the twin image.
    """
    gx, gy = _gradients(np.asarray(x, dtype=np.float64))
    g = _select(np.hypot(gx, gy), mask)
    m = float(np.mean(g))
    if m <= 0:
        return 0.0
    return float(math.sqrt(float(np.std(g)) / m))


def laplacian_variance(x: np.ndarray, mask: np.ndarray | None = None) -> float:
    """Variance of the 5-point Laplacian (Pech-Pacheco et al., "Diatom autofocusing in
    brightfield microscopy: a comparative study", ICPR 2000, vol. 3, 314-317)."""
    a = np.asarray(x, dtype=np.float64)
    lap = (a[:-2, 1:-1] + a[2:, 1:-1] + a[1:-1, :-2] + a[1:-1, 2:] - 4.0 * a[1:-1, 1:-1])
    if mask is not None:
        lap = lap[mask[1:-1, 1:-1][: lap.shape[0], : lap.shape[1]]]
    return float(np.var(lap))


def mix_metric(x: np.ndarray, mask: np.ndarray | None = None, weight: float = 0.5) -> float:
    """Weighted gradient-norm / Tamura mix: ``w log GN + (1 - w) log ToG``.

    ``GN = sqrt(gradient_energy)`` is the gradient norm and ``ToG`` the Tamura coefficient of
    the gradient (:func:`tamura`). The log form is a weighted geometric mean, so neither
    measure's units dominate; the gradient norm sharpens the peak, the Tamura term rejects
    the twin image and border artefacts (compare Zhang et al. 2017, cited in :func:`tamura`,
    who combine gradient and sparsity criteria).
    """
    w = float(weight)
    ge = gradient_energy(x, mask)
    tg = tamura(x, mask)
    if ge <= 0 or tg <= 0:
        return -math.inf
    return float(w * 0.5 * math.log(ge) + (1.0 - w) * math.log(tg))


_METRIC_FUNCS: dict[str, Callable[..., float]] = {
    "gradient": gradient_energy,
    "tamura": tamura,
    "laplacian": laplacian_variance,
    "mix": mix_metric,
}


def sharpness(x: np.ndarray, metric: str = "mix", mask: np.ndarray | None = None) -> float:
    """Evaluate one of :data:`METRICS` on an image (larger = sharper)."""
    if metric not in _METRIC_FUNCS:
        raise ClfzaError(f"metric must be one of {METRICS}, got {metric!r}")
    return _METRIC_FUNCS[metric](x, mask)


#: The fraction of each side that the focus metrics leave out by default (the central 70 %).
BORDER_FRACTION = 0.15


def central_mask(shape: tuple[int, int], border_fraction: float = BORDER_FRACTION
                 ) -> np.ndarray:
    """Boolean mask of the central region: ``border_fraction`` of the rows and of the columns
    cut on each side (a fraction in [0, 0.5); 0.15 keeps the central 70 %).

    Examples
    --------
    >>> int(central_mask((10, 10), 0.2).sum())  # rows and columns 2..7
    36
    """
    f = in_range("border_fraction", border_fraction, 0.0, 0.5)
    if f >= 0.5:
        raise ClfzaError(f"border_fraction must be in [0, 0.5) (a fraction of each side), got "
                         f"{border_fraction!r}")
    ny, nx = shape
    my, mx = int(f * ny), int(f * nx)
    m = np.zeros((ny, nx), dtype=bool)
    m[my:ny - my, mx:nx - mx] = True
    return m

