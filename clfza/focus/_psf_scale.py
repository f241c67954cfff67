"""Which PSF fits a frame: a measured PSF's scale (a point at another depth) or a stack's depth.

One search serves both. Each candidate PSF -- the captured PSF magnified by a trial scale
(:func:`clfza.models.magnify`), or one PSF of a captured depth stack -- deconvolves a binned
copy of the frame with a Wiener filter on a grid where nothing wraps (the linear-convolution
model, :mod:`clfza.models._psf`), and the result's sharpness (:func:`clfza.focus.sharpness`,
on the central region) is its score. With the right PSF the image is sharp; with a wrong
scale it breaks into crosses and smears.

The scale bias
--------------
A sharpness score also moves with the PSF alone: a larger PSF spreads the frame's energy
differently, and the raw scores of one PSF at scales 1.0-2.0 fell steadily with the scale, so
the smallest scale won for every metric. Each score is therefore taken relative to the same
PSF's score on *null frames*: the frame with its Fourier phases randomised (the same power
spectrum, so the same Wiener gain and noise, but no structure that any PSF explains), with the
same random phases for every candidate. ``score = log S(frame) - mean log S(null)``: what
the PSF alone does cancels, what fits the frame remains.

The search
----------
Coarse to fine over the magnification: a geometric grid over ``scale_range``, then a finer
grid between the coarse best's neighbours, then a parabola through the top three points (in
``log scale``). Confidence follows the same principles as the depth search's: never
confident when the coarse peak is at an end of the range, when the peak does not stand out
from the curve's own noise (:data:`MIN_PROMINENCE`), or when the peak is as wide as the range
(:data:`MAX_WIDTH_FRACTION`).
"""

from __future__ import annotations

import math
import time
import warnings
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np
import scipy.fft
from scipy.ndimage import gaussian_filter

from ..errors import ClfzaError, finite_image, in_range, positive, positive_int
from ..models import PSF, magnify
from ._metrics import BORDER_FRACTION, METRICS, central_mask, sharpness

#: Side (pixels) the frame is binned down to at the search's finest level.
WORK_SIZE = 160
#: Side (pixels) of the search's coarsest level (the whole range is searched there).
START_SIZE = 80
#: Wiener regularisation relative to the (high-passed) kernel spectrum's mean power.
WIENER_REG = 1.0
#: Standard deviation (pixels of the level searched) of the blur subtracted from frame and
#: kernels.
HIGHPASS_SIGMA = 2.0
#: Null frames (randomised Fourier phases) each score is taken relative to.
NULL_FRAMES = 2
#: Peak prominence over the curve's noise below which a scale is not claimed.
MIN_PROMINENCE = 8.0
#: A peak whose half-height width spans more than this fraction of the (log) range is not
#: claimed: the curve does not tell the scales apart.
MAX_WIDTH_FRACTION = 0.5
#: Distinct peaks of the coarsest level refined on the finer ones (a coarse curve has ghost
#: peaks, measured: docs/measurements.md).
CANDIDATES = 3
#: Coarse grid points between two distinct candidates.
SEPARATION = 4
#: Scales spread over the range that give the finest level's baseline and spread.
BACKGROUND = 9
#: The winner's finest-level peak over the range's spread there (:data:`BACKGROUND`
#: scales) below which a scale is not claimed.
MIN_FINE_PROMINENCE = 2.5
#: Largest height of the runner-up candidate (relative to the winner's, both above the
#: finest level's baseline) at which the winner is still claimed.
MAX_AMBIGUITY = 0.9
#: Default range's lower end below the scale of a scene at infinity (relative), for a camera
#: that knows its depths (the capture depth's and z2's own errors).
DEPTH_MARGIN = 0.05


class PSFScaleWarning(UserWarning):
    """The scale search is not confident (the evidence says why)."""


@dataclass
class PSFScaleResult:
    """The scale search's answer (:func:`find_psf_scale`).

    Attributes
    ----------
    scale : float
        The magnification to apply to the PSF (after resampling it to the frame's pitch).
    confident : bool
        Whether the curve supports the answer (``evidence["reason"]`` says why or why not).
    scale_uncertainty : float
        Half the width of the peak at half its height above the curve's median (relative
        scale): the scales the curve cannot tell apart.
    scales, scores : list of float
        Every scale tried (coarse and fine, sorted) and its normalised score.
    coarse_scales, coarse_scores : list of float
        The coarse grid's curve (the one the confidence is judged on).
    evidence : dict
        ``at_edge``, ``prominence``, ``noise``, ``width_fraction``, ``reason``.
    depth : float or None
        The scene depth (mm) the scale means, with the camera's ``psf_z1`` and ``z2``.
    bin : int
        The binning of the frame (and PSF) the search ran on.
    metric : str
    timings : dict
        Seconds: ``total``.
    """

    scale: float
    confident: bool
    scale_uncertainty: float
    scales: list
    scores: list
    coarse_scales: list
    coarse_scores: list
    evidence: dict
    bin: int
    metric: str
    levels: list = field(default_factory=list)
    depth: float | None = None
    timings: dict = field(default_factory=dict)

    def to_dict(self) -> dict:
        """A JSON-ready dict of every field."""
        return {"scale": self.scale, "confident": self.confident,
                "scale_uncertainty": self.scale_uncertainty, "depth_mm": self.depth,
                "bin": self.bin, "metric": self.metric, "evidence": dict(self.evidence),
                "scales": list(self.scales), "scores": list(self.scores),
                "coarse_scales": list(self.coarse_scales),
                "coarse_scores": list(self.coarse_scores), "levels": list(self.levels),
                "timings": dict(self.timings)}


# ----------------------------------------------------------------------------------------
# the scorer both searches share
# ----------------------------------------------------------------------------------------
def _grey(a: np.ndarray, name: str) -> np.ndarray:
    a = finite_image(name, a)
    return a.mean(axis=2) if a.ndim == 3 else a


def _bin_mean(a: np.ndarray, b: int) -> np.ndarray:
    if b == 1:
        return a
    h, w = (a.shape[0] // b) * b, (a.shape[1] // b) * b
    return a[:h, :w].reshape(h // b, b, w // b, b).mean(axis=(1, 3))


class PSFScorer:
    """Scores of candidate PSFs on one frame: Wiener deconvolution on a grid where nothing
    wraps, sharpness on the central region, relative to the same PSF's score on null frames
    (the module's docstring).

    Parameters
    ----------
    y : ndarray (H, W) or (H, W, 3)
        The frame (DC-free or raw; its mean is removed), on the PSFs' pitch times ``bin``.
    kernel_shape : (int, int)
        The largest candidate kernel's shape (the FFT grid is sized for it).
    highpass : float
        Standard deviation (pixels) of the Gaussian blur subtracted from the frame and from
        every kernel (0: none).
    metric : str
        One of :data:`clfza.focus.METRICS`.
    reg : float
        Wiener regularisation relative to the kernel spectrum's peak power.
    nulls : int
        Null frames (0: raw scores, the scale bias left in).
    seed : int
        Seed of the null frames' phases.
    """

    def __init__(self, y: np.ndarray, kernel_shape: tuple[int, int], metric: str = "tamura", *,
                 reg: float = WIENER_REG, nulls: int = NULL_FRAMES,
                 border_fraction: float = BORDER_FRACTION, seed: int = 0,
                 highpass: float = HIGHPASS_SIGMA) -> None:
        if metric not in METRICS:
            raise ClfzaError(f"metric must be one of {METRICS}, got {metric!r}")
        self.metric = metric
        self.reg = positive("reg", reg)
        self.highpass = float(highpass)
        a = self._hp(np.asarray(y, dtype=np.float64))
        from scipy.signal.windows import tukey  # lazy: scipy.signal loads scipy.stats (slow start)

        win = np.outer(tukey(a.shape[0], 0.2), tukey(a.shape[1], 0.2))
        a = a * win
        self.shape = a.shape
        h, w = n = self.shape
        self.fshape = tuple(scipy.fft.next_fast_len(n[i] + int(kernel_shape[i]), real=True)
                            for i in range(2))
        amp = np.abs(scipy.fft.rfft2(a))
        rng = np.random.default_rng(seed)
        self.spectra = [scipy.fft.rfft2(a, s=self.fshape)]
        for _ in range(int(nulls)):
            # a surrogate: the frame's power spectrum with random phases (from real noise, so
            # its inverse is real), on the frame's support and window: no PSF explains it
            ph = scipy.fft.rfft2(rng.standard_normal(n))
            sur = scipy.fft.irfft2(amp * ph / np.maximum(np.abs(ph), 1e-300), s=n) * win
            self.spectra.append(scipy.fft.rfft2(sur, s=self.fshape))
        self.mask = central_mask(n, border_fraction)

    def _hp(self, a: np.ndarray) -> np.ndarray:
        """``a`` less its Gaussian blur (``highpass`` pixels): the PSF's bright disc and the
        frame's smooth part carry no scale information, and the frame's unknown surround
        (the crop) otherwise swamps the Wiener image. Frame and kernels alike, so the model
        ``y = crop(o * h)`` holds for the filtered pair."""
        a = a - a.mean()
        return a - gaussian_filter(a, self.highpass, mode="nearest") if self.highpass else a

    def kernel_spectrum(self, k: np.ndarray) -> np.ndarray:
        """The spectrum of kernel ``k`` (centre at ``k.shape // 2``) on the search grid, its
        centre moved to the origin, normalised to unit sum."""
        k = np.asarray(k, dtype=np.float64)
        total = float(k.sum())
        if not np.isfinite(total) or total <= 0:
            raise ClfzaError(f"a candidate PSF has no light (sum {total:.3g})")
        kh, kw = k.shape
        if kh > self.fshape[0] - self.shape[0] or kw > self.fshape[1] - self.shape[1]:
            raise ClfzaError(f"kernel {k.shape} larger than the search grid allows")
        big = np.zeros(self.fshape)
        big[:kh, :kw] = self._hp(k / total)
        big = np.roll(big, (-(kh // 2), -(kw // 2)), axis=(0, 1))
        return scipy.fft.rfft2(big)

    def raw_scores(self, k: np.ndarray) -> np.ndarray:
        """``log`` sharpness of the Wiener image of the frame and of each null frame."""
        hk = self.kernel_spectrum(k)
        p = np.abs(hk) ** 2
        if not float(p.max()) > 0:
            raise ClfzaError(f"a candidate PSF {np.shape(k)} has no detail left after the "
                             f"high-pass (a flat kernel): it cannot be scored")
        filt = np.conj(hk) / (p + self.reg * float(p.mean()))
        out = np.empty(len(self.spectra))
        h, w = self.shape
        for i, sp in enumerate(self.spectra):
            x = scipy.fft.irfft2(sp * filt, s=self.fshape)[:h, :w]
            v = sharpness(x, self.metric, self.mask)
            out[i] = v if self.metric == "mix" else math.log(max(v, 1e-300))
        return out

    def score(self, k: np.ndarray) -> float:
        """The normalised score of kernel ``k`` (larger = fits the frame better)."""
        r = self.raw_scores(k)
        return float(r[0] - (r[1:].mean() if len(r) > 1 else 0.0))


# ----------------------------------------------------------------------------------------
# confidence
# ----------------------------------------------------------------------------------------
def curve_noise(scores: np.ndarray) -> float:
    """The curve's own noise: the median absolute second difference over ``sqrt(6)`` (the
    standard deviation of independent noise on each point; smooth trends and one peak barely
    move the median)."""
    s = np.asarray(scores, dtype=np.float64)
    if len(s) < 5:
        return float("nan")
    d2 = np.abs(np.diff(s, 2))
    return float(1.4826 * np.median(d2) / math.sqrt(6.0))


def judge(xs: np.ndarray, scores: np.ndarray, *, min_prominence: float = MIN_PROMINENCE,
          max_width_fraction: float = MAX_WIDTH_FRACTION, index: int | None = None,
          noise: float | None = None) -> dict:
    """Whether a curve's maximum is a clear peak: not at an end of the grid, ``prominence``
    (peak over the curve's median, in units of :func:`curve_noise`) at least
    ``min_prominence``, and the half-height width of the peak (in ``xs``' units) at most
    ``max_width_fraction`` of the grid's span. ``index``: judge that point instead of the
    maximum (the peak the finer levels chose). ``noise``: the curve's noise when known
    otherwise (:func:`null_noise`), instead of :func:`curve_noise`. Returns the evidence
    with ``confident`` and a one-line ``reason``."""
    xs, s = np.asarray(xs, float), np.asarray(scores, float)
    k = int(np.argmax(s)) if index is None else int(index)
    at_edge = k in (0, len(s) - 1)
    base = float(np.median(s))
    height = float(s[k] - base)
    noise = curve_noise(s) if noise is None else float(noise)
    floor = max(noise, 1e-12 * max(1.0, abs(float(s[k]))))
    prom = height / floor if math.isfinite(noise) else 0.0
    half = base + 0.5 * height
    lo = k
    while lo > 0 and s[lo - 1] > half:
        lo -= 1
    hi = k
    while hi < len(s) - 1 and s[hi + 1] > half:
        hi += 1
    width = float(xs[hi] - xs[lo]) if hi > lo else float(np.min(np.diff(xs)))
    frac = width / float(xs[-1] - xs[0])
    if at_edge:
        reason = (f"the best score is at the {'lower' if k == 0 else 'upper'} end of the range: "
                  "the answer may lie beyond it")
    elif prom < min_prominence:
        reason = (f"the peak is {prom:.1f}x the curve's noise; a clear peak needs >= "
                  f"{min_prominence:g}x")
    elif frac > max_width_fraction:
        reason = (f"the peak spans {frac:.0%} of the range at half height: the curve does not "
                  "tell the candidates apart")
    else:
        reason = f"clear peak: {prom:.1f}x the curve's noise, {frac:.0%} of the range wide"
    return {"confident": not at_edge and prom >= min_prominence and frac <= max_width_fraction,
            "at_edge": at_edge, "prominence": prom, "noise": noise, "height": height,
            "width_fraction": frac, "reason": reason}


# ----------------------------------------------------------------------------------------
# the searches
# ----------------------------------------------------------------------------------------
def _refine(xs: np.ndarray, s: np.ndarray) -> float:
    """The vertex of the parabola through the best point and its neighbours (in ``xs``),
    kept within them; the best point itself at an end."""
    k = int(np.argmax(s))
    if k in (0, len(s) - 1):
        return float(xs[k])
    x0, x1, x2 = xs[k - 1:k + 2]
    y0, y1, y2 = s[k - 1:k + 2]
    den = (x0 - x1) * (x0 - x2) * (x1 - x2)
    a = (x2 * (y1 - y0) + x1 * (y0 - y2) + x0 * (y2 - y1)) / den
    b = (x2 * x2 * (y0 - y1) + x1 * x1 * (y2 - y0) + x0 * x0 * (y1 - y2)) / den
    if a >= 0:
        return float(x1)
    return float(np.clip(-b / (2 * a), x0, x2))


def work_bin(shape: tuple[int, ...], work_size: int) -> int:
    """The bin factor that brings the frame's longer side to about ``work_size`` pixels."""
    return max(1, int(round(max(shape[:2]) / positive_int("work_size", work_size))))


def pyramid(shape: tuple[int, ...], work_size: int, start_size: int) -> list[int]:
    """Bin factors of the search's levels, coarsest first: the frame at about
    ``start_size`` pixels, doubled per level up to about ``work_size``.

    A scale error ``d`` moves the PSF's detail at radius ``r`` by ``d r``: the finer the
    level, the narrower the peak, so each level searches around the previous one's answer.
    """
    last = work_bin(shape, work_size)
    first = max(last, work_bin(shape, start_size))
    out = [first]
    while out[-1] > last:
        out.append(max(last, out[-1] // 2))
    return out


def _peaks(s: np.ndarray, separation: int, count: int) -> list[int]:
    """Indices of up to ``count`` local maxima of ``s`` (ends included), best first, each at
    least ``separation`` points from every better one."""
    n = len(s)
    loc = [k for k in range(n) if (k == 0 or s[k] >= s[k - 1]) and (k == n - 1 or s[k] >= s[k + 1])]
    out: list[int] = []
    for k in sorted(loc, key=lambda i: -s[i]):
        if all(abs(k - j) >= separation for j in out):
            out.append(k)
        if len(out) == count:
            break
    return out


def _robust_noise(v: np.ndarray) -> float:
    v = np.asarray(v, dtype=np.float64)
    return float(1.4826 * np.median(np.abs(v - np.median(v))))


def default_scale_range(camera=None) -> tuple[float, float]:
    """The magnifications of a measured PSF that :func:`find_psf_scale` searches by default.

    ``(0.5, 2.0)``; for a camera that knows its depths (``psf_z1`` and ``z2``), from
    :data:`DEPTH_MARGIN` below the scale of a scene at infinity (no scene lies beyond it)
    up to 2.

    Parameters
    ----------
    camera : Camera, optional
        The measured-PSF camera, if any.

    Returns
    -------
    (float, float)
        The lowest and highest magnification (dimensionless).

    Examples
    --------
    >>> from clfza.focus import default_scale_range
    >>> default_scale_range()
    (0.5, 2.0)
    """
    if getattr(camera, "knows_depth", False):
        return (camera.scale_of_depth(math.inf) * (1.0 - DEPTH_MARGIN), 2.0)
    return (0.5, 2.0)


def find_psf_scale(y: np.ndarray, psf: PSF | np.ndarray,
                   scale_range: tuple[float, float] | None = None, *, metric: str = "tamura",
                   coarse: int = 97, fine: int = 13, work_size: int = WORK_SIZE,
                   start_size: int = START_SIZE, candidates: int = CANDIDATES,
                   reg: float = WIENER_REG, nulls: int = NULL_FRAMES, camera=None,
                   warn: bool = True) -> PSFScaleResult:
    """Find the magnification of a measured PSF that fits a frame (a scene at another depth
    than the point source's).

    A point at depth ``z`` casts the mask's shadow magnified by ``1 + z2/z``, so a PSF
    captured at ``z_psf`` fits a scene at ``z`` once magnified by
    ``(1 + z2/z) / (1 + z2/z_psf)``. The frame and PSF are binned (a pyramid up to about
    ``work_size`` pixels); each trial scale deconvolves the frame (Wiener) with the magnified
    PSF and scores the sharpness relative to null frames (the module's docstring). The
    coarsest level scans the whole range; its ``candidates`` best distinct peaks are each
    refined on the finer levels, where the best one wins (the module's docstring: a coarse
    curve has ghost peaks that a finer level tells apart).

    Parameters
    ----------
    y : ndarray (H, W) or (H, W, 3)
        The frame (raw or DC-free; channels averaged), on the PSF's pitch.
    psf : PSF or ndarray
        The captured PSF at the frame's pitch, centred at ``(H // 2, W // 2)``.
    scale_range : (float, float), optional
        The magnifications searched (``0 < lo < hi``); default
        :func:`default_scale_range` (physical scales only when the camera knows depths).
    metric : str
        Sharpness metric (:data:`clfza.focus.METRICS`).
    coarse, fine : int
        Points of the coarse grid (geometric over the range) and of each candidate's fine
        grid (two coarse steps either side of it).
    work_size, start_size : int
        The binned frame's longer side at the finest and at the coarsest level, pixels.
    candidates : int
        Distinct coarse peaks refined on the finer levels.
    reg : float
        Wiener regularisation relative to the kernel spectrum's mean power.
    nulls : int
        Null frames the scores are taken relative to (0: raw scores, biased by scale).
    camera : Camera, optional
        A measured-PSF camera with ``psf_z1`` and ``z2``: the result's ``depth`` and the
        default range.
    warn : bool
        Warn (:class:`PSFScaleWarning`) when not confident.

    Returns
    -------
    PSFScaleResult

    Examples
    --------
    >>> from clfza.simulation import simulate_psf_capture
    >>> cap = simulate_psf_capture(np.eye(48), shape=(96, 96))  # doctest: +SKIP
    >>> res = find_psf_scale(cap.y, cap.psf, (0.8, 1.6))        # doctest: +SKIP
    >>> abs(res.scale / cap.true_scale - 1) < 0.02              # doctest: +SKIP
    True
    """
    t0 = time.perf_counter()
    if scale_range is None:
        scale_range = default_scale_range(camera)
    lo, hi = (positive("scale_range", v) for v in scale_range)
    if not lo < hi:
        raise ClfzaError(f"scale_range must satisfy 0 < lo < hi, got {scale_range!r}")
    coarse = positive_int("coarse", coarse, 5)
    fine = positive_int("fine", fine, 3)
    candidates = positive_int("candidates", candidates)
    in_range("reg", reg, 1e-8, 1e3)
    a = _grey(y, "measurement")
    h = _grey(np.asarray(getattr(psf, "array", psf)), "PSF")
    bins = pyramid(a.shape, work_size, start_size)

    def level(lb: int):
        ab = _bin_mean(a, lb)
        hb = _bin_mean(h, lb) if lb > 1 else h
        n = ab.shape
        cap = (2 * n[0] - 1, 2 * n[1] - 1)  # no object-to-sensor offset reaches further
        kshape = tuple(min(cap[i], int(round(hb.shape[i] * hi)) + 1) for i in range(2))
        scorer = PSFScorer(ab, kshape, metric, reg=reg, nulls=nulls)
        return lambda xs: np.array([scorer.score(magnify(hb, float(x), cap)) for x in xs])

    score0 = level(bins[0])
    xs0 = np.geomspace(lo, hi, coarse)
    c0 = score0(xs0)
    levels = [{"bin": bins[0], "scales": xs0.tolist(), "scores": c0.tolist()}]
    step0 = float(np.log(xs0[1] / xs0[0]))
    picks = _peaks(c0, SEPARATION, candidates)
    tracks = []
    for k in picks:
        w = slice(max(0, k - 1), k + 2)
        tracks.append({"coarse_index": k, "centre": math.exp(_refine(np.log(xs0[w]), c0[w])),
                       "step": step0, "peak": float(c0[k]), "scales": [], "scores": []})
    score_f = score0
    for lb in bins[1:]:
        score_f = level(lb)
        for t in tracks:
            r_lo = max(lo, t["centre"] * math.exp(-2 * t["step"]))
            r_hi = min(hi, t["centre"] * math.exp(2 * t["step"]))
            xs = np.geomspace(r_lo, r_hi, fine)
            cs = score_f(xs)
            t.update(centre=math.exp(_refine(np.log(xs), cs)), step=float(np.log(xs[1] / xs[0])),
                     peak=float(cs.max()), scales=xs.tolist(), scores=cs.tolist())
            levels.append({"bin": lb, "scales": xs.tolist(), "scores": cs.tolist(),
                           "candidate": t["coarse_index"]})
    # the finest level's baseline and noise: the range at a few spread scales
    if len(bins) > 1:
        xb = np.geomspace(lo, hi, BACKGROUND)
        cb = score_f(xb)
        levels.append({"bin": bins[-1], "scales": xb.tolist(), "scores": cb.tolist(),
                       "background": True})
    else:
        cb = c0
    order = sorted(range(len(tracks)), key=lambda i: -tracks[i]["peak"])
    win = tracks[order[0]]
    base, spread = float(np.median(cb)), _robust_noise(cb)
    height = win["peak"] - base
    fine_prom = height / max(spread, 1e-12 * max(1.0, abs(win["peak"])))
    ambiguity = ((tracks[order[1]]["peak"] - base) / height
                 if len(order) > 1 and height > 0 else 0.0)
    ev = judge(np.log(xs0), c0, index=win["coarse_index"])
    ev.update(fine_prominence=fine_prom, ambiguity=ambiguity,
              levels_agree=bool(win["coarse_index"] == int(np.argmax(c0))), candidates=[
        {"scale": t["centre"], "coarse_scale": float(xs0[t["coarse_index"]]), "peak": t["peak"]}
        for t in (tracks[i] for i in order)])
    confident, ev["reason"] = claim(ev, tracks[order[1]]["centre"] if len(order) > 1 else None)
    ev["confident"] = confident
    best = win["centre"]
    if win["scales"]:
        width = _half_width(np.log(win["scales"]), np.array(win["scores"]), base)
    else:
        width = _half_width(np.log(xs0), c0, float(np.median(c0)))
    all_x = np.array([x for lv in levels for x in lv["scales"]])
    all_s = np.array([v for lv in levels for v in lv["scores"]])
    o = np.argsort(all_x)
    depth = camera.depth_of_scale(best) if getattr(camera, "knows_depth", False) else None
    res = PSFScaleResult(scale=best, confident=confident, scale_uncertainty=width,
                         scales=all_x[o].tolist(), scores=all_s[o].tolist(),
                         coarse_scales=xs0.tolist(), levels=levels,
                         coarse_scores=c0.tolist(), evidence=ev, bin=bins[-1], metric=metric,
                         depth=depth, timings={"total": time.perf_counter() - t0})
    if warn and not res.confident:
        warnings.warn(f"PSF scale {best:.4g} in {lo:.4g}..{hi:.4g} is not reliable: "
                      f"{ev['reason']}", PSFScaleWarning, stacklevel=2)
    return res


def claim(ev: dict, runner_up: float | None = None) -> tuple[bool, str]:
    """Whether the search's evidence supports its scale, and why (one line): the coarse
    curve's test (:func:`judge` at the winner: not at an end, prominent, narrow), the levels
    agree (the finest level's winner is the coarse curve's maximum), the winner stands out
    at the finest level (:data:`MIN_FINE_PROMINENCE`) and the runner-up candidate scores at
    most :data:`MAX_AMBIGUITY` of it there (calibration: docs/measurements.md)."""
    if not ev["confident"]:
        return False, ev["reason"]
    if not ev.get("levels_agree", True):
        return False, ("the coarse and fine levels disagree (the finest level's best scale "
                       "is not the coarse curve's maximum)")
    if ev.get("fine_prominence", math.inf) < MIN_FINE_PROMINENCE:
        return False, (f"at the finest level the peak is {ev['fine_prominence']:.1f}x the "
                       f"scores' spread over the range; a clear scale needs >= "
                       f"{MIN_FINE_PROMINENCE:g}x")
    if ev.get("ambiguity", 0.0) > MAX_AMBIGUITY:
        other = f" ({runner_up:.4g})" if runner_up is not None else ""
        return False, (f"another scale{other} scores {ev['ambiguity']:.0%} as high at the "
                       f"finest level; a clear scale needs <= {MAX_AMBIGUITY:.0%}")
    return True, ev["reason"]


def _half_width(lx: np.ndarray, s: np.ndarray, base: float) -> float:
    """Half the width (relative scale) of the peak at half its height above ``base``."""
    k = int(np.argmax(s))
    half = base + 0.5 * (s[k] - base)
    lo = k
    while lo > 0 and s[lo - 1] > half:
        lo -= 1
    hi = k
    while hi < len(s) - 1 and s[hi + 1] > half:
        hi += 1
    return float(math.expm1(0.5 * (lx[hi] - lx[lo]))) if hi > lo else \
        float(math.expm1(0.5 * float(np.min(np.diff(lx)))))


def stack_grid(shape: tuple[int, ...], work_size: int | None) -> int:
    """The bin factor a captured stack is scored at (:func:`work_bin` of ``work_size``), or
    1 (``work_size=None``: the frame's own resolution)."""
    return 1 if work_size is None else work_bin(shape, work_size)


def score_psf_stack(y: np.ndarray, kernels: Sequence[np.ndarray], *, metric: str = "tamura",
                    reg: float = WIENER_REG, nulls: int = NULL_FRAMES,
                    border_fraction: float = BORDER_FRACTION,
                    work_size: int | None = START_SIZE, raw: bool = False) -> np.ndarray:
    """The normalised score of each captured PSF on frame ``y``: the scale search's scorer
    (:class:`PSFScorer`) at its coarsest level (where it judges its confidence), so a
    captured depth stack and a scaled PSF are judged alike (:func:`clfza.focus.select_psf_depth`).

    Parameters
    ----------
    y : ndarray (H, W) or (H, W, 3)
        The frame (raw or DC-free; channels averaged), on the PSFs' pitch.
    kernels : sequence of ndarray (Hk, Wk) or (Hk, Wk, 3)
        The candidate PSFs, each centred at ``(Hk // 2, Wk // 2)`` (channels averaged).
    metric, reg, nulls, border_fraction
        As :class:`PSFScorer`.
    work_size : int or None
        Frame and PSFs are binned (block means) so that the frame's longer side is about
        ``work_size`` pixels, as at the scale search's coarsest level (:data:`START_SIZE`);
        ``None``: scored at the frame's resolution.
    raw : bool
        Return the raw scores instead (:meth:`PSFScorer.raw_scores`, frame first).

    Returns
    -------
    ndarray (len(kernels),) or (len(kernels), 1 + nulls)
        ``log S(frame) - mean log S(null frames)`` per kernel (larger = fits better); with
        ``raw``, ``log S`` of the frame and of each null frame.

    Examples
    --------
    >>> s = score_psf_stack(y, [psf_a, psf_b])  # doctest: +SKIP
    """
    a = _grey(y, "measurement")
    if len(kernels) == 0:
        raise ClfzaError("the PSF stack is empty")
    b = stack_grid(a.shape, work_size)
    a = _bin_mean(a, b)
    n = a.shape
    cap = (2 * n[0] - 1, 2 * n[1] - 1)  # no object-to-sensor offset reaches further

    def prepare(k: np.ndarray, i: int) -> np.ndarray:
        k = _bin_mean(_grey(np.asarray(k, dtype=np.float64), f"PSF {i}"), b)
        h, w = k.shape
        ch, cw = min(h, cap[0]), min(w, cap[1])
        y0, x0 = h // 2 - ch // 2, w // 2 - cw // 2
        return k[y0:y0 + ch, x0:x0 + cw]

    ks = [prepare(k, i) for i, k in enumerate(kernels)]
    kshape = (max(k.shape[0] for k in ks), max(k.shape[1] for k in ks))
    scorer = PSFScorer(a, kshape, metric, reg=reg, nulls=nulls,
                       border_fraction=border_fraction)
    if raw:
        return np.array([scorer.raw_scores(k) for k in ks])
    return np.array([scorer.score(k) for k in ks])


def null_noise(raw: np.ndarray) -> float:
    """The noise of the normalised scores across candidates, from the null frames alone:
    how much the score of a frame with the same power spectrum and no structure
    (``log S(null_i) - mean log S(other nulls)``) wobbles from one candidate to the next.
    ``raw``: ``(candidates, 1 + nulls)`` raw scores (:func:`score_psf_stack` with ``raw``);
    each null's curve less the nulls' mean curve and its own mean over the candidates, the
    pooled variance times ``n / (n - 1)`` (one null's), times ``1 + 1/n`` (a frame less the
    mean of ``n`` nulls). NaN with fewer than 2 nulls or 2 candidates."""
    r = np.asarray(raw, dtype=np.float64)
    n, k = r.shape[1] - 1, r.shape[0]
    if n < 2 or k < 2:
        return float("nan")
    e = r[:, 1:] - r[:, 1:].mean(axis=1, keepdims=True)
    e = e - e.mean(axis=0, keepdims=True)
    var = float((e ** 2).sum()) / ((k - 1) * n) * n / (n - 1)
    return math.sqrt(var * (1.0 + 1.0 / n))


def judge_candidates(xs: Sequence[float], scores: Sequence[float],
                     noise: float | None = None) -> dict:
    """The scale search's confidence rule (:func:`claim`) on a curve of discrete candidates
    (a captured stack), scored at one level: the curve's test (:func:`judge`: not at an
    end, prominent over the curve's noise, narrow), the winner over the candidates' spread
    (as the finest level's ``fine_prominence`` over its spread scales) and the runner-up
    distinct peak's height (``ambiguity``). ``xs``: the candidates' positions, increasing
    (for depths, ``-1 / depth``: the magnification ``1 + z2 / z`` is affine in it).
    ``noise``: the scores' noise across candidates (:func:`null_noise`); a few candidates
    hold too few points for the curve's own noise (:func:`curve_noise`, the default), and a
    peak over a coarse stack spans most of its points, so the spread test of the finest
    level does not apply."""
    xs, s = np.asarray(xs, dtype=np.float64), np.asarray(scores, dtype=np.float64)
    ev = judge(xs, s)
    k = int(np.argmax(s))
    base = float(np.median(s))
    height = float(s[k] - base)
    if noise is not None and math.isfinite(noise):
        ev = judge(xs, s, noise=noise)
    peaks = _peaks(s, 2, 2)
    runner = [j for j in peaks if j != k]
    ev["ambiguity"] = (float(s[runner[0]] - base) / height if runner and height > 0 else 0.0)
    ev["runner_up"] = runner[0] if runner else None
    ev["levels_agree"] = True
    if len(s) < 3:
        ev["confident"] = False
        ev["reason"] = f"{len(s)} candidates: a peak between two others needs >= 3"
    confident, reason = claim(ev)
    ev["confident"], ev["reason"] = confident, reason
    return ev
