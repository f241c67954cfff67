"""Which PSF of a measured depth stack fits a frame: the same search as a single PSF's scale
(:mod:`clfza.focus._psf_scale`). Each PSF deconvolves the binned frame (Wiener, on a grid
where nothing wraps) and its sharpness is scored relative to null frames
(:func:`clfza.focus.score_psf_stack`), so the PSF's size alone does not move the score; the
curve over the stack is judged by the scale search's confidence rule
(:func:`clfza.focus._psf_scale.claim`)."""

from __future__ import annotations

import warnings
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np
import scipy.fft

from ..errors import ClfzaError
from ..models import PSF, PSFStack, check_depths
from ._metrics import BORDER_FRACTION, METRICS
from ._psf_scale import (
    NULL_FRAMES,
    START_SIZE,
    WIENER_REG,
    judge_candidates,
    null_noise,
    score_psf_stack,
    stack_grid,
)

#: Score spread (max - min of the normalised scores) below which a depth-score curve is
#: called flat.
FLAT_TOLERANCE = 0.01


class PSFDepthWarning(UserWarning):
    """The depth-selection score curve is flat, peaks at an end of the stack, or is not
    confident."""


@dataclass
class PSFDepthResult:
    """The stack search's answer (:func:`select_psf_depth` with ``full=True``).

    Attributes
    ----------
    index : int
        The best PSF of the stack (its position as given).
    depth : float or None
        Its depth (mm), where the stack's depths are known.
    confident : bool
        Whether the curve supports it (the scale search's rule; ``evidence["reason"]``).
    scores : ndarray
        The normalised score of every PSF, in the stack's order (larger = sharper).
    evidence : dict
        As :attr:`clfza.focus.PSFScaleResult.evidence`.
    bin : int
        The binning of frame and PSFs the scores were taken at.
    metric : str
    """

    index: int
    depth: float | None
    confident: bool
    scores: np.ndarray
    evidence: dict
    bin: int
    metric: str
    labels: list = field(default_factory=list)

    def to_dict(self) -> dict:
        """A JSON-ready dict of every field."""
        return {"index": self.index, "depth_mm": self.depth, "confident": self.confident,
                "scores": [float(v) for v in self.scores], "evidence": dict(self.evidence),
                "bin": self.bin, "metric": self.metric, "labels": list(self.labels)}


def back_project(y: np.ndarray, psf: np.ndarray) -> np.ndarray:
    """Correlate ``y`` with ``psf`` (the adjoint of the linear-convolution model), cropped to
    ``y``'s grid: ``out[q] = sum_p y[p] psf[p - q + c]`` with ``c = (Hp // 2, Wp // 2)``.

    Computed with scipy.fft on a zero-padded grid of at least ``(H + Hp - 1, W + Wp - 1)``,
    so nothing wraps around. Both arguments are 2-D.

    Examples
    --------
    >>> import numpy as np
    >>> back_project(np.ones((4, 4)), np.ones((3, 3))).shape
    (4, 4)
    """
    h, w = y.shape
    hp, wp = psf.shape
    n = (scipy.fft.next_fast_len(h + hp - 1, real=True),
         scipy.fft.next_fast_len(w + wp - 1, real=True))
    spec = scipy.fft.rfft2(y, s=n) * np.conj(scipy.fft.rfft2(psf, s=n))
    corr = scipy.fft.irfft2(spec, s=n)
    return np.roll(corr, (hp // 2, wp // 2), axis=(0, 1))[:h, :w]


def _flat_or_edge(scores: np.ndarray, metric: str, labels: Sequence[str],
                  flat: str) -> bool:
    """Warn (or raise, ``flat="error"``) when the normalised scores are flat (max - min
    below :data:`FLAT_TOLERANCE`); warn when the maximum is at an end of a stack of three or
    more. Returns whether it warned."""
    spread = float(np.max(scores) - np.min(scores))
    k = int(np.argmax(scores))
    evidence = ", ".join(f"{d}: {s:.6g}" for d, s in zip(labels, scores, strict=True))
    if spread < FLAT_TOLERANCE:
        msg = (f"the {metric} score is flat over the PSF stack (max - min below "
               f"{FLAT_TOLERANCE:g}; scores {evidence}): no depth is preferred, so the "
               f"choice of {labels[k]} is arbitrary")
        if flat == "error":
            raise ClfzaError(msg)
        warnings.warn(msg, PSFDepthWarning, stacklevel=3)
        return True
    if len(scores) >= 3 and k in (0, len(scores) - 1):
        warnings.warn(f"the sharpest PSF is at the {'first' if k == 0 else 'last'} depth of "
                      f"the stack ({labels[k]}); the object may lie beyond the stack's "
                      f"range (scores {evidence})", PSFDepthWarning, stacklevel=3)
        return True
    return False


def select_psf_depth(y: np.ndarray, stack: PSFStack | np.ndarray | Sequence,
                     depths: Sequence[float] | None = None, metric: str = "tamura", *,
                     envelope_sigma: float | None = None, taper: float | None = None,
                     border_fraction: float = BORDER_FRACTION, flat: str = "warn",
                     work_size: int | None = START_SIZE, reg: float = WIENER_REG,
                     nulls: int = NULL_FRAMES, full: bool = False
                     ) -> tuple[int, np.ndarray] | PSFDepthResult:
    """Pick the PSF of a captured depth stack that fits a frame: the search of a single
    PSF's scale (:func:`clfza.focus.find_psf_scale`) over the stack's PSFs.

    Each PSF deconvolves the frame (Wiener, on a grid where nothing wraps: the
    linear-convolution model ``y = crop(o * h)``), both binned to the scale search's coarsest
    level, and the image's sharpness on the central region is scored relative to the same
    PSF's on null frames (the frame with randomised Fourier phases), so a PSF's size alone
    does not move its score (:func:`clfza.focus.score_psf_stack`). The curve over the stack
    (ordered by depth, placed at ``-1 / depth``, in which the magnification ``1 + z2 / z``
    is affine) is judged by
    the scale search's confidence rule: not at an end, prominent over the curve's noise,
    standing out from the stack's spread, no comparable second peak.

    Parameters
    ----------
    y : ndarray (H, W) or (H, W, 3)
        The measurement on the frame's grid (the PSFs' pitch); raw or DC-free.
    stack : PSFStack, ndarray (D, H, W[, 3]) or list of arrays/PSFs
        Each PSF centred at ``(H // 2, W // 2)``; sizes may differ.
    depths : sequence of float, optional
        Depth of each PSF (mm); taken from a PSFStack when omitted. Orders the curve and
        labels the messages (without depths: the stack's order).
    metric : str
        One of :data:`clfza.focus.METRICS`; ``"tamura"``, the scale search's.
    envelope_sigma, taper : None
        Deprecated, no longer used (the scorer's own high-pass and window apply): a value
        warns (``DeprecationWarning``).
    border_fraction : float
        Fraction of each side left out of the scores (:func:`clfza.focus.central_mask`).
    flat : {"warn", "error"}
        What to do when the scores are flat (max - min below :data:`FLAT_TOLERANCE`): warn
        (:class:`PSFDepthWarning`) or raise :class:`ClfzaError`. A maximum at an end of the
        stack, or a curve that is not confident, always warns.
    work_size : int or None
        The binned frame's longer side, pixels: the scale search's coarsest level
        (:data:`clfza.focus._psf_scale.START_SIZE`), on whose curve that search judges its
        confidence too (8-bit frames hold their scale information at low frequencies:
        docs/measurements.md); ``None``: the frame's resolution.
    reg, nulls : float, int
        Wiener regularisation and null frames (:class:`clfza.focus.PSFScaleResult`'s search).
    full : bool
        Return a :class:`PSFDepthResult` (confidence and evidence) instead of the pair.

    Returns
    -------
    (index, scores) or PSFDepthResult
        Index of the best PSF and the normalised score of every PSF (larger = sharper).

    Examples
    --------
    >>> from clfza.models import load_psf_stack  # doctest: +SKIP
    >>> stack = load_psf_stack("psfs.npy", depths=[100, 200, 300])  # mm  # doctest: +SKIP
    >>> k, scores = select_psf_depth(y, stack)  # doctest: +SKIP
    >>> select_psf_depth(y, stack, full=True).confident  # doctest: +SKIP
    True
    """

    if metric not in METRICS:
        raise ClfzaError(f"metric must be one of {METRICS}, got {metric!r}")
    if flat not in ("warn", "error"):
        raise ClfzaError(f"flat must be 'warn' or 'error', got {flat!r}")
    if envelope_sigma is not None or taper is not None:
        warnings.warn("select_psf_depth's envelope_sigma and taper are no longer used: the "
                      "stack is scored by the scale search's scorer (its own high-pass and "
                      "window)", DeprecationWarning, stacklevel=2)
    if isinstance(stack, PSFStack):
        depths = stack.depths if depths is None else depths
        stack = stack.arrays
    kernels = [np.asarray(s.array if isinstance(s, PSF) else s, dtype=np.float64)
               for s in stack]
    if not kernels:
        raise ClfzaError("the PSF stack is empty")
    if depths is None:
        labels = [f"PSF {k}" for k in range(len(kernels))]
        order = np.arange(len(kernels))
        xs = order.astype(np.float64)
    else:
        ds = check_depths(depths, len(kernels))
        labels = [f"{d:g} mm" for d in ds]
        inv = -1.0 / np.asarray(ds, dtype=np.float64)  # increasing with the depth
        order = np.argsort(inv, kind="stable")
        xs = inv[order]
        if len(xs) > 1 and not np.all(np.diff(xs) > 0):
            raise ClfzaError(f"the stack's depths must be distinct, got {list(ds)}")
    raw = score_psf_stack(y, kernels, metric=metric, reg=reg, nulls=nulls,
                          border_fraction=border_fraction, work_size=work_size, raw=True)
    scores = raw[:, 0] - (raw[:, 1:].mean(axis=1) if raw.shape[1] > 1 else 0.0)
    if len(kernels) == 1:
        ev = {"confident": False, "reason": "one PSF: nothing to choose between"}
    else:
        ev = judge_candidates(xs, scores[order], null_noise(raw))
        ev["order"] = order.tolist()
        if ev.get("runner_up") is not None:
            ev["runner_up"] = int(order[ev["runner_up"]])
    k = int(np.argmax(scores))
    warned = _flat_or_edge(scores[order], metric, [labels[i] for i in order], flat) \
        if len(kernels) > 1 else False
    if not ev["confident"] and not warned:
        warnings.warn(f"the stack's best PSF ({labels[k]}) is not reliable: {ev['reason']}",
                      PSFDepthWarning, stacklevel=2)
    if not full:
        return k, scores
    b = stack_grid(np.shape(y), work_size)
    return PSFDepthResult(index=k, depth=None if depths is None else float(
        check_depths(depths, len(kernels))[k]), confident=bool(ev["confident"]),
        scores=scores, evidence=ev, bin=b, metric=metric, labels=labels)
