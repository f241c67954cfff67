"""The depth search of :mod:`clfza.focus`: :func:`autofocus` (a coarse grid uniform in ``1/z1``,
then golden-section or finer grids), :func:`find_depths` (tiles voting for the depths of a
3-D scene), the evidence test of a focus curve and their result records.
:mod:`clfza.focus` re-exports every public name here.
"""

from __future__ import annotations

import math
import time
import warnings
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field

import numpy as np

from ..camera import Camera
from ..errors import ClfzaError, positive
from ..solvers import DEFAULT_BACKEND
from ._fastbp import ENVELOPE_SIGMA, TAPER, FastBP, depth_resolution, r1p_at
from ._metrics import BORDER_FRACTION, METRICS, central_mask, sharpness

#: A focus peak is trusted when it stands above every score farther than the locality window
#: (:func:`focus_confidence`) by at least this fraction of its prominence above the curve's
#: median: the smallest value with no confident wrong depth on the calibration grid of scenes
#: x noise levels x depths, plus a margin of 0.05 (bench/bench_focus_confidence.py; measured:
#: docs/measurements.md, clfza.focus._search).
MIN_ISOLATION = 0.65
#: The locality window of that test, in units of the focus's half-width ``resolution``
#: (at least 2 grid steps): a sharpness peak is several depths of focus wide, because the low
#: frequencies stay in focus longer than the band limit (calibrated with MIN_ISOLATION).
PEAK_WIDTH = 8.0
#: No confident answer when the focus's own width (the depth of focus, both sides) is at least
#: this fraction of the searched range: the range then holds too few distinguishable depths.
MAX_RESOLUTION_FRACTION = 0.25
#: The peak-to-noise ratio of the former test (kept in the evidence for reference; it no
#: longer decides: pure noise reached 16x on the calibration grid, docs/measurements.md).
MIN_PEAK_RATIO = 6.0
#: the evidence test uses a curve of at least this many depths (a coarser search grid gets an
#: extra curve of this size for the test alone: one inverse FFT per depth)
EVIDENCE_POINTS = 41
#: How :func:`autofocus` refines the coarse grid's best depth (its ``search``).
SEARCHES = ("golden", "grid")


class FocusWarning(UserWarning):
    """The focus curve gives no evidence for one depth (flat, or peaked at a range end)."""


_GOLDEN = (math.sqrt(5.0) - 1.0) / 2.0


# ----------------------------------------------------------------------------------------
# results
# ----------------------------------------------------------------------------------------
@dataclass
class FocusResult:
    """Outcome of :func:`autofocus`.

    Attributes
    ----------
    z1_best : float
        Best object distance (mm).
    r1p_best : float
        Shadow constant ``r1'`` at ``z1_best`` (mm).
    scores : ndarray
        Sharpness on the coarse grid ``z_grid``.
    z_grid : ndarray
        Coarse grid of distances (uniform in ``1/z1``, i.e. in ``r1'``).
    metric : str
    evaluations : list of (z1, score)
        Every depth evaluated, in order (coarse grid then refinement).
    timings : dict
        Seconds: ``setup`` (one FFT), ``search``, ``per_depth`` and ``total``.
    depth_resolution : float
        Depth of focus at ``z1_best`` (:func:`depth_resolution`), mm.
    """

    z1_best: float
    r1p_best: float
    scores: np.ndarray
    z_grid: np.ndarray
    metric: str
    evaluations: list = field(default_factory=list)
    timings: dict = field(default_factory=dict)
    depth_resolution: float = math.nan
    evidence: dict = field(default_factory=dict)

    @property
    def confident(self) -> bool:
        """True when the curve has a clear interior peak (:func:`focus_evidence`)."""
        return bool(self.evidence.get("confident", True))

    def to_dict(self) -> dict:
        return {"z1_best": self.z1_best, "r1p_best": self.r1p_best,
                "confident": self.confident, "evidence": dict(self.evidence),
                "z_grid": self.z_grid.tolist(), "scores": self.scores.tolist(),
                "metric": self.metric, "evaluations": [list(e) for e in self.evaluations],
                "timings": dict(self.timings), "depth_resolution": self.depth_resolution}


def focus_confidence(scores, positions, *, resolution: float | None = None,
                     labels=None, unit: str = "mm",
                     min_isolation: float = MIN_ISOLATION,
                     max_resolution_fraction: float = MAX_RESOLUTION_FRACTION,
                     peak_width: float = PEAK_WIDTH) -> dict:
    """Whether a focus curve supports its best point: the rule shared by the searches.

    A curve ``scores`` (larger = sharper) over a grid ``positions`` in the search's own
    coordinate (``1/z1`` for depths, the magnification for a PSF's scale) supports its
    maximum only when all of these hold:

    1. the curve is not flat (and finite);
    2. the maximum is not at either end of the grid, nor within ``resolution`` of one (the
       sharpest point may lie beyond the range);
    3. the focus's own width ``2 resolution`` (the depth of focus, in ``positions`` units) is
       below ``max_resolution_fraction`` of the grid's span: otherwise the range holds too
       few distinguishable points for any to be "the" focus;
    4. the peak is isolated: its height above the highest score farther than the locality
       window ``w = max(2 grid steps, peak_width * resolution)`` is at least
       ``min_isolation`` times its prominence above the curve's median. Noise and the slow
       trends of defocused structure make broad humps or several near-equal maxima; a focus
       makes one narrow peak. Both thresholds are calibrated on measured false-alarm and
       miss rates (:data:`MIN_ISOLATION`, :data:`PEAK_WIDTH`).

    Parameters
    ----------
    scores : array (n,)
        Sharpness at each grid point.
    positions : array (n,)
        The grid, monotonic, in the coordinate in which it is (about) uniform.
    resolution : float, optional
        Half-width of the in-focus region at the peak, in ``positions`` units (``inf``: no
        focus can be told); None leaves rules 2-3 to the grid alone.
    labels : array (n,), optional
        The grid in the units the reasons print (e.g. z1 in mm); default ``positions``.
    unit : str
        Unit of ``labels`` in the reasons.
    min_isolation, max_resolution_fraction : float
        Thresholds of rules 4 and 3.
    peak_width : float
        The locality window of rule 4 in units of ``resolution``.

    Returns
    -------
    dict
        ``confident``, ``reason`` (one sentence), ``best_index``, ``at_edge``,
        ``isolation``, ``resolution_fraction``, ``prominence``, ``curve_noise`` and
        ``ratio`` (prominence over the robust std of the curve's second differences, for
        reference), and the thresholds used.

    Examples
    --------
    >>> import numpy as np
    >>> u = np.linspace(0.0, 1.0, 41)
    >>> focus_confidence(np.exp(-((u - 0.4) / 0.02) ** 2), u)["confident"]
    True
    >>> focus_confidence(u, u)["at_edge"]  # rising to the end: the peak may lie beyond
    True
    """
    s = np.asarray(scores, dtype=np.float64).ravel()
    x = np.asarray(positions, dtype=np.float64).ravel()
    if x.shape != s.shape:
        raise ClfzaError(f"focus_confidence: {s.size} scores for {x.size} positions")
    lab = x if labels is None else np.asarray(labels, dtype=np.float64).ravel()
    base = {"min_isolation": float(min_isolation), "peak_width": float(peak_width),
            "max_resolution_fraction": float(max_resolution_fraction),
            "min_ratio": MIN_PEAK_RATIO}
    if s.size < 3 or not np.isfinite(s).all() or float(np.ptp(s)) == 0.0:
        return {**base, "confident": False, "ratio": 0.0, "prominence": 0.0,
                "curve_noise": math.nan, "at_edge": False, "isolation": 0.0,
                "resolution_fraction": math.nan, "relative_range": 0.0, "best_index": -1,
                "reason": "the focus score is the same (or not finite) at every point: the "
                          "curve is flat"}
    k = int(np.argmax(s))
    med = float(np.median(s))
    prom = float(s[k] - med)
    d2 = np.diff(s, 2)
    noise = float(1.4826 * np.median(np.abs(d2 - np.median(d2))) / math.sqrt(6.0))
    ratio = prom / noise if noise > 0 else math.inf
    span = float(np.ptp(x))
    step = span / max(s.size - 1, 1)
    res = math.inf if resolution is not None and not math.isfinite(resolution) else (
        abs(float(resolution)) if resolution is not None else 0.0)
    frac = 2.0 * res / span if span > 0 else math.inf
    at_edge = bool(k in (0, s.size - 1) or min(abs(x[k] - x[0]), abs(x[k] - x[-1])) < res)
    window = max(2.0 * step, float(peak_width) * res)
    far = np.abs(x - x[k]) > window * (1 + 1e-9)
    isolation = float((s[k] - s[far].max()) / prom) if far.any() and prom > 0 else 1.0
    ev = {**base, "prominence": prom, "curve_noise": noise, "ratio": ratio,
          "at_edge": at_edge, "isolation": isolation, "resolution_fraction": frac,
          "relative_range": float(np.ptp(s) / max(float(np.max(np.abs(s))), 1e-300)),
          "best_index": k}
    where = f"{float(lab[k]):.4g} {unit}".strip()
    if at_edge:
        end = "first" if abs(k) <= s.size // 2 else "last"
        ev.update(confident=False, reason=(
            f"the sharpest point is at the {end} end of the range ({where}): the peak may "
            "lie beyond it; widen the range"))
    elif frac >= max_resolution_fraction:
        ev.update(confident=False, reason=(
            f"the focus is as wide as the range: its width at {where} is "
            f"{'unbounded' if math.isinf(frac) else f'{100 * frac:.3g}% of the range'} (a "
            f"clear focus needs < {100 * max_resolution_fraction:g}%); the capture cannot tell "
            "these depths apart"))
    elif isolation < min_isolation:
        ev.update(confident=False, reason=(
            f"no isolated peak: a point farther than the focus's width scores within "
            f"{100 * (1 - isolation):.0f}% of the peak's prominence (a clear focus stands "
            f">= {100 * min_isolation:g}% above every other point); the curve's best "
            f"({where}) is not sharper than others beyond chance"))
    else:
        ev.update(confident=True, reason=(
            f"isolated peak (coarse grid) at {where}: {100 * isolation:.3g}% of its "
            f"prominence above every point farther than its width "
            f"(>= {100 * min_isolation:g}%)"))
    return ev


def focus_evidence(scores: np.ndarray, grid: np.ndarray, min_ratio: float = MIN_PEAK_RATIO,
                   camera: Camera | None = None, **rule) -> dict:
    """:func:`focus_confidence` of a depth search's curve on ``grid`` (z1 in mm, uniform in
    ``1/z1``): positions ``1/z1``, and, with ``camera``, the depth of focus at the best
    depth as the resolution (:func:`depth_resolution`; unbounded when it reaches ``z1``).
    ``min_ratio`` is kept for callers of the former test and no longer decides; ``rule``
    passes thresholds on to :func:`focus_confidence`."""
    g = np.asarray(grid, dtype=np.float64)
    s = np.asarray(scores, dtype=np.float64)
    res = None
    if camera is not None and s.size and np.isfinite(s).all():
        zb = float(g[int(np.argmax(s))])
        dz = depth_resolution(camera, zb)
        res = math.inf if dz >= zb else 0.5 * abs(1.0 / (zb - dz) - 1.0 / (zb + dz))
    return focus_confidence(s, 1.0 / g, resolution=res, labels=g, unit="mm", **rule)


@dataclass
class DepthsResult:
    """Outcome of :func:`find_depths`: the depths found, strongest first.

    ``strengths`` are the number of tiles (or, for curve peaks, the peak prominence) that
    support each depth; ``curve`` is the whole-image focus curve; ``tile_depths`` the
    per-tile best depth (NaN for tiles without structure); ``masks`` the region used to
    refine each depth.
    """

    depths: list
    strengths: list
    curve: FocusResult
    tile_depths: np.ndarray
    masks: list = field(default_factory=list)



# ----------------------------------------------------------------------------------------
# search
# ----------------------------------------------------------------------------------------
def _check_range(z_range: Sequence[float]) -> tuple[float, float]:
    if len(z_range) != 2:
        raise ClfzaError(f"z_range must be (zmin, zmax), got {z_range!r}")
    lo, hi = positive("zmin", z_range[0]), positive("zmax", z_range[1])
    if not hi > lo:
        raise ClfzaError(f"z_range needs zmin < zmax, got {z_range!r}")
    return lo, hi


def inverse_depth_grid(zmin: float, zmax: float, n: int) -> np.ndarray:
    """``n`` distances uniform in ``1/z1`` (hence in ``r1'``), from near to far."""
    u = np.linspace(1.0 / zmin, 1.0 / zmax, int(n))
    return 1.0 / u


def _golden_max(f: Callable[[float], float], lo: float, hi: float, tol: float,
                max_iter: int = 60) -> tuple[float, float]:
    """Golden-section search for the maximum of a unimodal ``f`` on ``[lo, hi]``."""
    a, b = lo, hi
    c = b - _GOLDEN * (b - a)
    d = a + _GOLDEN * (b - a)
    fc, fd = f(c), f(d)
    for _ in range(max_iter):
        if abs(b - a) <= tol:
            break
        if fc >= fd:
            b, d, fd = d, c, fc
            c = b - _GOLDEN * (b - a)
            fc = f(c)
        else:
            a, c, fc = c, d, fd
            d = a + _GOLDEN * (b - a)
            fd = f(d)
    return (c, fc) if fc >= fd else (d, fd)


def _search(engine: FastBP, score: Callable[[np.ndarray], float], zmin: float, zmax: float,
            *, search: str, coarse: int, tol: float, evals: list) -> tuple[float, np.ndarray,
                                                                           np.ndarray]:
    """Coarse grid over ``1/z1`` then golden-section or finer grids around the best point."""
    cache: dict[float, float] = {}

    def f_u(u: float) -> float:
        z = 1.0 / u
        if z not in cache:
            cache[z] = score(engine.image(z))
            evals.append((z, cache[z]))
        return cache[z]

    grid = inverse_depth_grid(zmin, zmax, coarse)
    s = np.array([f_u(1.0 / z) for z in grid])
    k = int(np.argmax(s))
    u = 1.0 / grid
    du = abs(u[1] - u[0]) if len(u) > 1 else 0.0
    lo_u = u[min(k + 1, len(u) - 1)]
    hi_u = u[max(k - 1, 0)]
    ubest = u[k]
    # tolerance in u from the relative tolerance in z: du/u = dz/z
    tol_u = tol * ubest
    if search == "golden" and hi_u > lo_u:
        ub, _ = _golden_max(f_u, lo_u, hi_u, tol_u)
        if f_u(ub) >= s[k]:
            ubest = ub
    elif search == "grid":
        step = du
        while step > tol_u and step > 0:
            fine = np.linspace(ubest - step, ubest + step, 9)
            fine = fine[(fine >= 1.0 / zmax) & (fine <= 1.0 / zmin)]
            vals = [f_u(v) for v in fine]
            ubest = float(fine[int(np.argmax(vals))])
            step = step / 4.0
    return 1.0 / ubest, grid, s


def _check_search_options(metric: str, coarse: int, search: str) -> None:
    """Reject an unknown metric or search, or a coarse grid of fewer than 3 depths."""
    if metric not in METRICS:
        raise ClfzaError(f"metric must be one of {METRICS}, got {metric!r}")
    if search not in SEARCHES:
        raise ClfzaError(f"search must be 'golden' or 'grid', got {search!r}")
    if int(coarse) < 3:
        raise ClfzaError(f"coarse must be >= 3, got {coarse!r}")


def _search_evidence(engine: FastBP, score: Callable[[np.ndarray], float], grid: np.ndarray,
                     s: np.ndarray, zmin: float, zmax: float, timings: dict) -> dict:
    """:func:`focus_evidence` of the coarse curve ``s`` on ``grid``, or, when the grid has
    fewer than :data:`EVIDENCE_POINTS` depths (too few to tell a peak from the curve's
    noise), of a denser curve made for the test alone (its seconds go to
    ``timings["evidence"]``)."""
    if len(grid) >= EVIDENCE_POINTS:
        return focus_evidence(s, grid, camera=engine.camera)
    t3 = time.perf_counter()
    eg = inverse_depth_grid(zmin, zmax, EVIDENCE_POINTS)
    ev = focus_evidence(np.array([score(engine.image(z)) for z in eg]), eg,
                        camera=engine.camera)
    timings["evidence"] = time.perf_counter() - t3
    return ev


def autofocus(y: np.ndarray, camera: Camera, z_range: Sequence[float] = (10.0, 1000.0), *,
              metric: str = "mix", search: str = "golden", coarse: int = 41,
              tol: float = 1e-3, backend: str = DEFAULT_BACKEND, device: str | None = None,
              roi: np.ndarray | tuple[slice, slice] | None = None,
              border_fraction: float = BORDER_FRACTION, envelope_sigma: float = ENVELOPE_SIGMA,
              taper: float = TAPER, engine: FastBP | None = None, warn: bool = True
              ) -> FocusResult:
    """Find the object distance ``z1`` whose back-propagation is sharpest.

    Parameters
    ----------
    y : array (H, W) or (H, W, 3)
        DC-free observation (colour channels are averaged).
    camera : Camera
        The camera; only ``z1`` is searched (a calibrated ``r1_shadow`` is rescaled with
        depth, see :meth:`Camera.at_depth`).
    z_range : (zmin, zmax)
        Search interval in mm.
    metric : {"gradient", "tamura", "laplacian", "mix"}
        Sharpness metric (:func:`sharpness`).
    search : {"golden", "grid"}
        The search strategy, refining the coarse grid's best depth: golden-section search
        (unimodal near the peak) or repeated finer grids (coarse-to-fine, 9 points per level,
        step / 4).
    coarse : int
        Points of the coarse grid, uniform in ``1/z1`` (``r1'`` is linear in ``1/z1``).
    tol : float
        Relative tolerance in ``z1`` of the refinement.
    backend : {"opencl", "numpy"}
        Where the fast back-propagation runs (:class:`FastBP`): an OpenCL device (the default,
        :data:`clfza.solvers.DEFAULT_BACKEND`, as every entry point's; the spectrum is kept
        in device memory) or the host (float32 ``scipy.fft``, one inverse FFT per depth).
    device : str, optional
        OpenCL device spec (see :func:`clfza.cl.get_runtime`).
    roi : bool mask or (slice, slice), optional
        Region whose sharpness is scored; default the centre, ``border_fraction`` of each side
        cut.
    border_fraction : float
        Fraction of each side excluded when ``roi`` is None (:func:`central_mask`).
    envelope_sigma, taper : float
        Pre-processing of ``y`` (see :class:`FastBP`): the Gaussian envelope's standard
        deviation in pixels and the Tukey window fraction.
    engine : FastBP, optional
        Reuse a prepared engine (its FFT of ``y``).
    warn : bool
        Warn (:class:`FocusWarning`) when the curve gives no evidence for the depth.

    Returns
    -------
    FocusResult
        ``evidence`` / ``confident`` say whether the curve has a clear interior peak
        (:func:`focus_evidence`); an all-zero measurement raises :class:`ClfzaError`.

    Examples
    --------
    >>> fr = autofocus(y, camera, (100.0, 1000.0), search="golden")  # doctest: +SKIP
    >>> fr.z1_best, fr.confident  # doctest: +SKIP
    """
    t0 = time.perf_counter()
    zmin, zmax = _check_range(z_range)
    _check_search_options(metric, coarse, search)
    eng = engine or FastBP(y, camera, envelope_sigma=envelope_sigma, taper=taper,
                           backend=backend, device=device)
    mask = _as_mask(roi, eng.shape, border_fraction)
    evals: list = []

    def score(img: np.ndarray) -> float:
        return sharpness(img, metric, mask)

    t1 = time.perf_counter()
    zbest, grid, s = _search(eng, score, zmin, zmax, search=search, coarse=int(coarse),
                             tol=float(tol), evals=evals)
    t2 = time.perf_counter()
    timings = {"setup": eng.setup_s if engine is None else 0.0, "search": t2 - t1,
               "per_depth": (t2 - t1) / max(1, len(evals)), "total": t2 - t0,
               "evaluations": len(evals)}
    ev = _search_evidence(eng, score, grid, s, zmin, zmax, timings)
    if not ev["confident"] and warn:
        warnings.warn(f"autofocus: no reliable depth in {zmin:g}..{zmax:g} mm: "
                      f"{ev['reason']}", FocusWarning, stacklevel=2)
    return FocusResult(z1_best=float(zbest), r1p_best=r1p_at(camera, zbest), scores=s,
                       z_grid=grid, metric=metric, evaluations=evals, timings=timings,
                       depth_resolution=depth_resolution(camera, zbest), evidence=ev)


def _as_mask(roi, shape: tuple[int, int], border_fraction: float) -> np.ndarray:
    if roi is None:
        return central_mask(shape, border_fraction)
    if isinstance(roi, tuple):
        m = np.zeros(shape, dtype=bool)
        m[roi] = True
        return m
    m = np.asarray(roi, dtype=bool)
    if m.shape != tuple(shape):
        raise ClfzaError(f"roi mask has shape {m.shape}, expected {tuple(shape)}")
    return m


def _local_maxima(s: np.ndarray) -> list[int]:
    """Indices of strict interior local maxima plus the ends when they are higher than their
    neighbour, ordered by prominence above the curve's median."""
    idx = [i for i in range(1, len(s) - 1) if s[i] > s[i - 1] and s[i] >= s[i + 1]]
    return sorted(idx, key=lambda i: -s[i])


def find_depths(y: np.ndarray, camera: Camera, z_range: Sequence[float] = (10.0, 1000.0), *,
                n: int = 2, metric: str = "tamura", tiles: int = 4, coarse: int = 61,
                tol: float = 1e-3, border_fraction: float = 0.1, min_separation: float = 3.0,
                backend: str = DEFAULT_BACKEND, device: str | None = None,
                envelope_sigma: float = ENVELOPE_SIGMA, taper: float = TAPER
                ) -> DepthsResult:
    """Depths of up to ``n`` objects at different distances (a 3-D scene).

    Every depth of the coarse grid is back-propagated once (:class:`FastBP`); the sharpness
    is scored on each of ``tiles x tiles`` tiles of the central region and on the whole
    region. Each tile votes for the depth of its own sharpest image, if its focus curve has a
    clear peak (peak above the curve's median by more than a quarter of the curve's range
    above its minimum). Votes within ``min_separation`` depth resolutions of each other are
    merged (in ``1/z1``), the ``n`` best-supported clusters are refined by golden-section
    search on the union of their tiles. When fewer than ``n`` clusters have votes, the local
    maxima of the whole-region curve fill in.

    Parameters
    ----------
    n : int
        Number of depths wanted.
    metric : str
        Sharpness metric (:data:`METRICS`); the Tamura coefficient is the default because it
        is scale invariant, so tiles of different brightness vote alike.
    tiles : int
        Tiles per side of the central region.
    border_fraction : float
        Fraction of each side left out of the central region that is tiled.
    min_separation : float
        Merge distance between depths, in units of :func:`depth_resolution`.
    backend, device, envelope_sigma, taper
        As for :func:`autofocus`.

    Returns
    -------
    DepthsResult

    Examples
    --------
    >>> res = find_depths(y, camera, (10.0, 60.0), n=2)  # doctest: +SKIP
    >>> sorted(res.depths)  # doctest: +SKIP
    """
    zmin, zmax = _check_range(z_range)
    eng = FastBP(y, camera, envelope_sigma=envelope_sigma, taper=taper, backend=backend,
                 device=device)
    region = central_mask(eng.shape, border_fraction)
    tile_masks = _tile_masks(region, tiles)
    grid = inverse_depth_grid(zmin, zmax, coarse)
    whole, curves = _focus_curves(eng, grid, metric, region, tile_masks)
    tile_best = _tile_votes(curves, grid)
    clusters = _cluster_votes(tile_best, camera, min_separation)
    depths: list[float] = []
    strengths: list[float] = []
    masks: list[np.ndarray] = []
    zw = float(grid[int(np.argmax(whole))])
    curve_res = FocusResult(z1_best=zw, r1p_best=r1p_at(camera, zw), scores=whole, z_grid=grid,
                            metric=metric, depth_resolution=depth_resolution(camera, zw))
    for cl in clusters[:n]:
        m = np.any([tile_masks[t] for t in cl], axis=0)
        zc = float(np.median(tile_best[cl]))
        dz = 2.0 * (grid[1] / grid[0] - 1.0) * zc if len(grid) > 1 else 0.1 * zc
        lo, hi = max(zmin, zc - abs(dz) - 1e-9), min(zmax, zc + abs(dz) + 1e-9)
        fr = autofocus(y, camera, (lo, hi), metric=metric, search="golden", coarse=5, tol=tol,
                       roi=m, engine=eng, warn=False)
        depths.append(fr.z1_best)
        strengths.append(float(len(cl)))
        masks.append(m)
    if len(depths) < n:
        for z, strength in _curve_peaks(whole, grid, camera, min_separation, depths, n):
            depths.append(z)
            strengths.append(strength)
            masks.append(region)
    return DepthsResult(depths=depths, strengths=strengths, curve=curve_res,
                        tile_depths=tile_best.reshape(tiles, tiles), masks=masks)


def _tile_masks(region: np.ndarray, tiles: int) -> list[np.ndarray]:
    """Masks of the ``tiles x tiles`` tiles of the bounding box of ``region``, row by row."""
    ny, nx = region.shape
    ys, xs = np.nonzero(region)
    y0, y1, x0, x1 = ys.min(), ys.max() + 1, xs.min(), xs.max() + 1
    ey = np.linspace(y0, y1, tiles + 1).astype(int)
    ex = np.linspace(x0, x1, tiles + 1).astype(int)
    tile_masks = []
    for i in range(tiles):
        for j in range(tiles):
            m = np.zeros((ny, nx), dtype=bool)
            m[ey[i]:ey[i + 1], ex[j]:ex[j + 1]] = True
            tile_masks.append(m)
    return tile_masks


def _focus_curves(engine: FastBP, grid: np.ndarray, metric: str, region: np.ndarray,
                  tile_masks: list[np.ndarray]) -> tuple[np.ndarray, np.ndarray]:
    """Sharpness at every depth of ``grid``, one back-propagation per depth: the curve of the
    whole ``region`` (``len(grid)``) and of each tile (``len(tile_masks) x len(grid)``)."""
    curves = np.zeros((len(tile_masks), len(grid)))
    whole = np.zeros(len(grid))
    for k, z in enumerate(grid):
        img = engine.image(z)
        whole[k] = sharpness(img, metric, region)
        for t, m in enumerate(tile_masks):
            curves[t, k] = sharpness(img, metric, m)
    return whole, curves


def _tile_votes(curves: np.ndarray, grid: np.ndarray) -> np.ndarray:
    """Each tile's vote: the depth of its sharpest image when its curve has a clear interior
    peak (above the median by more than a quarter of its range), else NaN."""
    tile_best = np.full(len(curves), np.nan)
    for t in range(len(curves)):
        c = curves[t]
        rng = c.max() - c.min()
        if rng > 0 and c.max() - np.median(c) > 0.25 * rng and 0 < np.argmax(c) < len(c) - 1:
            tile_best[t] = grid[int(np.argmax(c))]
    return tile_best


def _cluster_votes(tile_best: np.ndarray, camera: Camera, min_separation: float
                   ) -> list[list[int]]:
    """Tiles whose votes lie within ``min_separation`` depth resolutions of a cluster's median
    (in ``1/z1``), most-supported cluster first."""
    clusters: list[list[int]] = []
    order = np.argsort(1.0 / np.where(np.isnan(tile_best), np.inf, tile_best))
    for t in order:
        if np.isnan(tile_best[t]):
            continue
        z = tile_best[t]
        sep = min_separation * depth_resolution(camera, z)
        for cl in clusters:
            zc = float(np.median(tile_best[cl]))
            if abs(1.0 / z - 1.0 / zc) <= abs(1.0 / zc - 1.0 / (zc + sep)):
                cl.append(int(t))
                break
        else:
            clusters.append([int(t)])
    clusters.sort(key=len, reverse=True)
    return clusters


def _curve_peaks(whole: np.ndarray, grid: np.ndarray, camera: Camera, min_separation: float,
                 depths: list[float], n: int) -> list[tuple[float, float]]:
    """Local maxima of the whole-region curve, as ``(depth, prominence above the median)``,
    that are more than ``min_separation`` depth resolutions from every depth already found
    and from each other, until ``depths`` and these make ``n``."""
    found = list(depths)
    peaks: list[tuple[float, float]] = []
    for i in _local_maxima(whole):
        z = float(grid[i])
        if all(abs(1.0 / z - 1.0 / d) > abs(1.0 / d - 1.0 / (d + min_separation *
                                                               depth_resolution(camera, d)))
               for d in found):
            found.append(z)
            peaks.append((z, float(whole[i] - np.median(whole))))
        if len(found) >= n:
            break
    return peaks

