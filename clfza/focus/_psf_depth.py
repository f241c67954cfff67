"""Which PSF of a measured stack fits a frame: each PSF correlated with the frame (the
linear-convolution model's adjoint), scored by the sharpness of :mod:`clfza.focus`."""

from __future__ import annotations

import math
import warnings
from collections.abc import Sequence

import numpy as np
import scipy.fft

from ..errors import ClfzaError, finite_image
from ..models import PSF, PSFStack, check_depths
from ._fastbp import ENVELOPE_SIGMA, TAPER, remove_envelope_and_taper
from ._metrics import BORDER_FRACTION, METRICS, central_mask, sharpness

#: Score spread (relative) below which a depth-score curve is called flat.
FLAT_TOLERANCE = 0.01


class PSFDepthWarning(UserWarning):
    """The depth-selection score curve is flat or peaks at an end of the stack."""



def back_project(y: np.ndarray, psf: np.ndarray) -> np.ndarray:
    """Correlate ``y`` with ``psf`` (the adjoint of the linear-convolution model), cropped to
    ``y``'s grid: ``out[q] = sum_p y[p] psf[p - q + c]`` with ``c = (Hp // 2, Wp // 2)``.

    Computed with scipy.fft on a zero-padded grid of at least ``(H + Hp - 1, W + Wp - 1)``,
    so nothing wraps around. Both arguments are 2-D.
    """
    h, w = y.shape
    hp, wp = psf.shape
    n = (scipy.fft.next_fast_len(h + hp - 1, real=True),
         scipy.fft.next_fast_len(w + wp - 1, real=True))
    spec = scipy.fft.rfft2(y, s=n) * np.conj(scipy.fft.rfft2(psf, s=n))
    corr = scipy.fft.irfft2(spec, s=n)
    return np.roll(corr, (hp // 2, wp // 2), axis=(0, 1))[:h, :w]


def _prepare_measurement(y: np.ndarray, envelope_sigma: float, taper: float) -> np.ndarray:
    a = finite_image("measurement", y)
    if a.ndim == 3:
        a = a.mean(axis=2)
    return remove_envelope_and_taper(a - a.mean(), envelope_sigma, taper)


def _flat_or_edge(scores: np.ndarray, metric: str, labels: Sequence[str],
                  flat: str) -> None:
    """Warn (or raise, ``flat="error"``) when the curve is flat within 1 %; warn when the
    maximum is at an end of a stack of three or more."""
    logs = scores if metric == "mix" else np.log(np.maximum(scores, 1e-300))
    spread = float(np.max(logs) - np.min(logs))
    k = int(np.argmax(scores))
    evidence = ", ".join(f"{d}: {s:.6g}" for d, s in zip(labels, scores, strict=True))
    if spread < math.log1p(FLAT_TOLERANCE):
        msg = (f"the {metric} sharpness is flat over the PSF stack (max/min within "
               f"{FLAT_TOLERANCE:.0%}; scores {evidence}): no depth is preferred, so the "
               f"choice of {labels[k]} is arbitrary")
        if flat == "error":
            raise ClfzaError(msg)
        warnings.warn(msg, PSFDepthWarning, stacklevel=3)
    elif len(scores) >= 3 and k in (0, len(scores) - 1):
        warnings.warn(f"the sharpest PSF is at the {'first' if k == 0 else 'last'} depth of "
                      f"the stack ({labels[k]}); the object may lie beyond the stack's "
                      f"range (scores {evidence})", PSFDepthWarning, stacklevel=3)


def select_psf_depth(y: np.ndarray, stack: PSFStack | np.ndarray | Sequence,
                     depths: Sequence[float] | None = None, metric: str = "mix", *,
                     envelope_sigma: float = ENVELOPE_SIGMA, taper: float = TAPER,
                     border_fraction: float = BORDER_FRACTION, flat: str = "warn"
                     ) -> tuple[int, np.ndarray]:
    """Pick the PSF of a depth stack under which the measurement back-propagates sharpest.

    ``y`` (DC-free; its mean is removed again) is high-passed and tapered as in
    :class:`clfza.focus.FastBP`, correlated with each PSF (:func:`back_project`, the adjoint
    of the convolution model; channels of ``y`` and of the PSFs are averaged) and scored with
    :func:`clfza.focus.sharpness` on the central region (``border_fraction`` of each side
    cut).

    Parameters
    ----------
    y : ndarray (H, W) or (H, W, 3)
        The measurement on the frame's grid (the PSFs' pitch).
    stack : PSFStack, ndarray (D, H, W[, 3]) or list of arrays/PSFs
    depths : sequence of float, optional
        Depth of each PSF (mm); taken from a PSFStack when omitted. Used in messages.
    metric : str
        One of :data:`clfza.focus.METRICS`. ``"mix"`` (default) and ``"tamura"`` are scale
        invariant enough to compare PSFs of different scale; ``"gradient"`` and
        ``"laplacian"`` favour the larger shadows (measured: docs/measurements.md,
        clfza.focus._psf_depth).
    envelope_sigma, taper : float
        Pre-processing of ``y``: the standard deviation in pixels of the Gaussian envelope
        subtracted, and the Tukey window fraction (as :class:`clfza.focus.FastBP`).
    border_fraction : float
        Fraction of each side left out of the scores (:func:`clfza.focus.central_mask`).
    flat : {"warn", "error"}
        What to do when the scores are flat (max/min within 1 %): warn with the scores
        (:class:`PSFDepthWarning`) or raise :class:`ClfzaError`. A maximum at an end of the
        stack always warns.

    Returns
    -------
    (index, scores)
        Index of the sharpest PSF and the score of every PSF (larger = sharper).

    Examples
    --------
    >>> from clfza.models import load_psf_stack  # doctest: +SKIP
    >>> stack = load_psf_stack("psfs.npy", depths=[100, 200, 300])  # mm  # doctest: +SKIP
    >>> k, scores = select_psf_depth(y, stack)  # y: the DC-free frame  # doctest: +SKIP
    """

    if metric not in METRICS:
        raise ClfzaError(f"metric must be one of {METRICS}, got {metric!r}")
    if flat not in ("warn", "error"):
        raise ClfzaError(f"flat must be 'warn' or 'error', got {flat!r}")
    if isinstance(stack, PSFStack):
        depths = stack.depths if depths is None else depths
        stack = stack.arrays
    kernels = [np.asarray(s.array if isinstance(s, PSF) else s, dtype=np.float64)
               for s in stack]
    if depths is None:
        labels = [f"PSF {k}" for k in range(len(kernels))]
    else:
        labels = [f"{d:g} mm" for d in check_depths(depths, len(kernels))]
    a = _prepare_measurement(y, envelope_sigma, taper)
    mask = central_mask(a.shape, border_fraction)
    scores = np.empty(len(kernels))
    for k, h in enumerate(kernels):
        h2 = finite_image(f"PSF {k}", h)
        h2 = h2.mean(axis=2) if h2.ndim == 3 else h2
        scores[k] = sharpness(back_project(a, h2), metric, mask)
    _flat_or_edge(scores, metric, labels, flat)
    return int(np.argmax(scores)), scores
