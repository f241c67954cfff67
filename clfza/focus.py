"""Autofocus, depth finding and focal stacks: the operator ``K`` depends on the object distance.

A point at distance ``z1`` casts the mask's shadow magnified by ``1 + z2/z1``, so the shadow
constant is ``r1' = (1 + z2/z1) r1`` (docs/design.md s.1). Refocusing a single measurement is
choosing ``r1'`` in ``H_T = sin(pi r1'^2 rho^2)`` (Eq. 17): back-propagation (Eqs. 11-12) with
the right ``r1'`` is sharp, with a wrong one every point spreads as a chirp ("numerical
focusing for 3D scenes", text after Eq. 18). This module searches ``z1`` for the sharpest fast
back-propagation and then runs any solver at the best depth.

The fast path
-------------
``FFT(y)`` is computed once; each trial depth costs one pointwise multiply by
``H_T(r1'(z1))`` and one inverse real FFT (float32 ``scipy.fft`` with all cores, the fastest
FFT on the 2-core CPU this was written on, docs/design.md s.6; measured 1 ms per depth at
256^2). ``backend="opencl"`` does the same on a device: ``FFT(y)`` kept in device memory,
``H_T`` made by a kernel, one multiply kernel and one inverse FFT per depth (measured on the
2-core Xeon's CPU devices: 0.8 ms per depth at 256^2, 1.8 ms at 512^2, against 2.0 and 3.3 ms
when it built an operator per depth). The back-propagation is :func:`clfza.model.
back_propagate`'s, with the spectrum kept (:class:`FastBP`).

Before back-propagating, the measurement is high-passed (the slowly varying envelope of the
shadows is subtracted) and apodised with a Tukey window: the TF model is periodic, and the
jump at the wrapped sensor border otherwise dominates every sharpness metric. Metrics are
evaluated on the central region (default: 15 % margin cut on each side).

Depth sensitivity
-----------------
``r1'^2 = r1^2 (1 + z2/z1)^2`` changes with ``z1`` by
``d(r1'^2)/dz1 = -2 r1^2 (1 + z2/z1) z2 / z1^2``; the defocus phase at the band limit
``rho_c = R'/r1'^2`` is ``pi |Delta r1'^2| rho_c^2``. Allowing a quarter wave (``pi/2``) gives
the depth of focus ``dz = 1 / (2 rho_c^2 |d(r1'^2)/dz1|)`` (:func:`depth_resolution`). It grows
as ``z1^2 / z2``: the search is sharp for ``z1`` of a few ``z2`` (the paper's simulation:
z1 = 20 mm, z2 = 3 mm) and weak for ``z1 >> z2`` (the paper's experiment at 300 mm).
"""

from __future__ import annotations

import math
import os
import time
import warnings
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field

import numpy as np
import scipy.fft
from scipy.ndimage import gaussian_filter
from scipy.signal.windows import tukey

from .camera import Camera
from .errors import ClfzaError, finite_image, positive
from .model import apply_spectrum, transfer_function

METRICS = ("gradient", "tamura", "laplacian", "mix")
#: A focus peak is trusted when its prominence above the curve's median is at least this many
#: times the score curve's own noise (robust std of its second differences): pure-noise
#: measurements give 2-5, a scene in focus 15-30 (tests/test_trust.py).
MIN_PEAK_RATIO = 6.0
#: the evidence test uses a curve of at least this many depths (a coarser search grid gets an
#: extra curve of this size for the test alone: one inverse FFT per depth)
EVIDENCE_POINTS = 41


class FocusWarning(UserWarning):
    """The focus curve gives no evidence for one depth (flat, or peaked at a range end)."""
WORKERS = max(1, os.cpu_count() or 1)
_GOLDEN = (math.sqrt(5.0) - 1.0) / 2.0


# ----------------------------------------------------------------------------------------
# sharpness metrics
# ----------------------------------------------------------------------------------------
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


# ----------------------------------------------------------------------------------------
# geometry of the search
# ----------------------------------------------------------------------------------------
def r1p_at(camera: Camera, z1: float) -> float:
    """Shadow constant ``r1' = (1 + z2/z1) r1`` for an object at ``z1`` (docs/design.md s.1)."""
    return camera.at_depth(z1).r1p


def depth_resolution(camera: Camera, z1: float) -> float:
    """Depth of focus ``dz`` (mm) at ``z1``: the depth change that puts a quarter-wave
    defocus phase at the band limit, ``dz = 1 / (2 rho_c^2 |d(r1'^2)/dz1|)`` with
    ``d(r1'^2)/dz1 = -2 r1^2 (1 + z2/z1) z2 / z1^2`` (module docstring)."""
    z1 = positive("z1", z1)
    cam = camera.at_depth(z1)
    rho_c = min(cam.band_limit, 0.5 / cam.pitch * math.sqrt(2.0))
    d = 2.0 * cam.r1**2 * (1.0 + cam.z2 / z1) * cam.z2 / z1**2
    return float(1.0 / (2.0 * rho_c**2 * d))


def _mean_channels(y: np.ndarray) -> np.ndarray:
    a = finite_image("measurement", y)
    if a.ndim == 3:
        a = a.mean(axis=2)
    return a


def central_mask(shape: tuple[int, int], margin: float = 0.15) -> np.ndarray:
    """Boolean mask of the central region with ``margin`` (fraction) cut on each side."""
    ny, nx = shape
    my, mx = int(margin * ny), int(margin * nx)
    m = np.zeros((ny, nx), dtype=bool)
    m[my:ny - my, mx:nx - mx] = True
    return m


class FastBP:
    """Back-propagation at many depths with one forward FFT (module docstring).

    ``K^T y`` is :func:`clfza.model.back_propagate` (the float64 specification), computed
    here for speed across many depths: the spectrum of the (pre-processed, float32) ``y`` is
    taken once and kept, and each depth costs ``H_T(r1'(z1))`` (:func:`clfza.model.
    transfer_function`, or the same table made on the device by :func:`clfza.cl.operator.
    device_transfer_function`), one spectrum multiply and one inverse real FFT
    (:func:`clfza.model.apply_spectrum` on the host). Nothing is built per depth.

    Parameters
    ----------
    y : array (H, W) or (H, W, 3)
        DC-free observation (channels are averaged).
    camera : Camera
        Camera; its ``z1`` is ignored (each call names the depth).
    highpass : float
        Standard deviation in pixels of the Gaussian whose blur (the shadows' envelope) is
        subtracted before the transform; 0 disables it.
    taper : float
        Tukey window fraction (0 = none) applied to ``y`` to suppress the wrap-around edge.
    backend : {"numpy", "opencl"}
        Host float32 ``scipy.fft`` (default, fastest on CPUs) or an OpenCL device (its FFT
        engine and the spectrum multiply kernel of :class:`clfza.cl.operator.OpenCLOperator`).
    """

    def __init__(self, y: np.ndarray, camera: Camera, *, highpass: float = 8.0,
                 taper: float = 0.25, backend: str = "numpy", device: str | None = None):
        a = _mean_channels(y)
        if a.shape != tuple(camera.shape):
            raise ClfzaError(f"measurement has shape {a.shape}, but the camera grid is "
                             f"{tuple(camera.shape)}")
        if not np.any(a):
            raise ClfzaError("the measurement is all zeros: no light reached the sensor, so no "
                             "depth can be found from it")
        from . import limits

        limits.check_memory(f"focusing a {a.shape[0]}x{a.shape[1]} measurement",
                            limits.grid_bytes(a.shape, 1, 8, 8.0),
                            "the measurement, its spectrum, the frequency grid and one image "
                            "per depth", f"crop or bin the frame, or raise the limit with "
                            f"{limits.ENV}")
        if backend not in ("numpy", "opencl"):
            raise ClfzaError(f"backend must be 'numpy' or 'opencl', got {backend!r}")
        self.camera = camera
        self.shape = a.shape
        self.backend = backend
        t0 = time.perf_counter()
        if highpass > 0:
            a = a - gaussian_filter(a, float(highpass), mode="nearest")
        if taper > 0:
            ny, nx = a.shape
            a = a * np.outer(tukey(ny, taper), tukey(nx, taper))
        if not np.any(a):
            raise ClfzaError("the measurement has no structure (all zeros, or constant once "
                             "the shadows' envelope is removed): no depth can be found from it")
        self.y = a.astype(np.float32)
        if backend == "numpy":
            self.Y = scipy.fft.rfft2(self.y, workers=WORKERS)
        else:
            self._device_setup(device)
        self.setup_s = time.perf_counter() - t0

    def _device_setup(self, device: str | None) -> None:
        """The OpenCL path's one-time work: FFT plan, ``rfft2(y)`` kept on the device, the
        spectrum buffer and output image every depth reuses."""
        from .cl import DeviceArray, get_runtime
        from .cl.arrays import complex_of
        from .cl.operator import make_fft_engine

        ny, nx = self.shape
        spec = (ny, nx // 2 + 1)
        self.rt = rt = get_runtime(device)
        self.fft = make_fft_engine(rt, self.shape, np.float32)
        yd = DeviceArray.from_host(rt, self.y, np.float32)
        self.Yd = DeviceArray.empty(rt, spec, complex_of(np.float32))
        self.fft.rfft2(yd, self.Yd)
        self.Xd = DeviceArray.empty(rt, spec, complex_of(np.float32))
        self.out = DeviceArray.empty(rt, self.shape, np.float32)
        self._mul = rt.kernel("spectrum", "multiply_real", np.float32)
        self._n_spec = np.int32(spec[0] * spec[1])
        rt.finish()

    def image(self, z1: float) -> np.ndarray:
        """``K^T y`` with ``r1' = r1'(z1)`` (Eqs. 11-12) as a float32 host array."""
        return self.image_r1p(r1p_at(self.camera, z1))

    def image_r1p(self, r1p: float) -> np.ndarray:
        """``K^T y`` for a given shadow constant ``r1'`` (mm)."""
        pitch = self.camera.pitch
        if self.backend == "numpy":
            H = transfer_function(self.shape, pitch, r1p).astype(np.float32)
            return apply_spectrum(self.Y, H, self.shape, workers=WORKERS)
        from .cl.operator import device_transfer_function

        rt = self.rt
        H = device_transfer_function(rt, self.shape, pitch, r1p, 1, np.float32)
        rt.cl.enqueue_copy(rt.queue, self.Xd.buf, self.Yd.buf)  # the kept spectrum, per depth
        self._mul(rt.queue, (int(self._n_spec),), None, self.Xd.buf, H.buf, self._n_spec)
        self.fft.irfft2(self.Xd, self.out)
        return self.out.get()


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


def focus_evidence(scores: np.ndarray, grid: np.ndarray, min_ratio: float = MIN_PEAK_RATIO
                   ) -> dict:
    """How much the coarse focus curve supports its best depth.

    The test: the peak's prominence above the curve's median, against the curve's own noise
    (``1.4826 MAD`` of its second differences ``/ sqrt(6)``, the std of white noise on the
    scores). A curve without a peak ``min_ratio`` times its noise is flat (no depth is
    sharper than another); a maximum at either end of the range is no peak (the sharpest
    depth may lie beyond the range).
    """
    s = np.asarray(scores, dtype=np.float64)
    finite = np.isfinite(s)
    if s.size < 3 or not finite.all() or float(np.ptp(s)) == 0.0:
        return {"confident": False, "ratio": 0.0, "prominence": 0.0, "curve_noise": math.nan,
                "at_edge": False, "relative_range": 0.0, "min_ratio": min_ratio,
                "reason": "the focus score is the same (or not finite) at every depth: the "
                          "curve is flat"}
    k = int(np.argmax(s))
    prom = float(s[k] - np.median(s))
    d2 = np.diff(s, 2)
    noise = float(1.4826 * np.median(np.abs(d2 - np.median(d2))) / math.sqrt(6.0))
    ratio = prom / noise if noise > 0 else math.inf
    rel = float(np.ptp(s) / max(float(np.max(np.abs(s))), 1e-300))
    at_edge = k in (0, s.size - 1)
    ev = {"prominence": prom, "curve_noise": noise, "ratio": ratio, "at_edge": at_edge,
          "relative_range": rel, "min_ratio": min_ratio, "best_index": k}
    if at_edge:
        end = "near" if k == 0 else "far"
        ev.update(confident=False, reason=(
            f"the sharpest depth is the {end} end of the range ({float(grid[k]):.4g} mm): the "
            "peak may lie beyond it; widen the range"))
    elif ratio < min_ratio:
        ev.update(confident=False, reason=(
            f"the focus curve is flat: its peak stands {ratio:.2g}x the curve's noise above "
            f"its median (a clear focus needs >= {min_ratio:g}x); no depth in the range is "
            "sharper than another beyond chance"))
    else:
        ev.update(confident=True, reason=(
            f"peak {ratio:.3g}x the curve's noise above its median (>= {min_ratio:g}x)"))
    return ev


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


@dataclass
class FocalStack:
    """Reconstructions at a list of depths: ``images[k]`` belongs to ``depths[k]``."""

    depths: list
    images: np.ndarray
    infos: list
    sharpness: list

    def best(self) -> tuple[float, np.ndarray]:
        """The depth with the highest sharpness and its image."""
        k = int(np.argmax(self.sharpness))
        return self.depths[k], self.images[k]


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
            *, method: str, coarse: int, tol: float, evals: list) -> tuple[float, np.ndarray,
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
    if method == "golden" and hi_u > lo_u:
        ub, _ = _golden_max(f_u, lo_u, hi_u, tol_u)
        if f_u(ub) >= s[k]:
            ubest = ub
    elif method == "grid":
        step = du
        while step > tol_u and step > 0:
            fine = np.linspace(ubest - step, ubest + step, 9)
            fine = fine[(fine >= 1.0 / zmax) & (fine <= 1.0 / zmin)]
            vals = [f_u(v) for v in fine]
            ubest = float(fine[int(np.argmax(vals))])
            step = step / 4.0
    elif method not in ("golden", "grid"):
        raise ClfzaError(f"method must be 'golden' or 'grid', got {method!r}")
    return 1.0 / ubest, grid, s


def autofocus(y: np.ndarray, camera: Camera, z_range: Sequence[float] = (10.0, 1000.0), *,
              metric: str = "mix", method: str = "golden", coarse: int = 41,
              tol: float = 1e-3, backend: str = "numpy", device: str | None = None,
              roi: np.ndarray | tuple[slice, slice] | None = None, margin: float = 0.15,
              highpass: float = 8.0, taper: float = 0.25,
              engine: FastBP | None = None, warn: bool = True) -> FocusResult:
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
    method : {"golden", "grid"}
        Refinement after the coarse grid: golden-section search (unimodal near the peak) or
        repeated finer grids (coarse-to-fine, 9 points per level, step / 4).
    coarse : int
        Points of the coarse grid, uniform in ``1/z1`` (``r1'`` is linear in ``1/z1``).
    tol : float
        Relative tolerance in ``z1`` of the refinement.
    backend : {"numpy", "opencl"}
        ``"numpy"``: float32 scipy.fft, one inverse FFT per depth (about 0.8 ms per depth at
        256^2 on the 2-core CPU). ``"opencl"``: the same on an OpenCL device (spectrum kept
        in device memory; on a par with the host on that CPU, for GPUs).
    roi : bool mask or (slice, slice), optional
        Region whose sharpness is scored; default the centre with ``margin`` cut per side.
    margin : float
        Border fraction excluded when ``roi`` is None.
    highpass, taper : float
        Pre-processing of ``y`` (see :class:`FastBP`).
    engine : FastBP, optional
        Reuse a prepared engine (its FFT of ``y``).
    warn : bool
        Warn (:class:`FocusWarning`) when the curve gives no evidence for the depth.

    Returns
    -------
    FocusResult
        ``evidence`` / ``confident`` say whether the curve has a clear interior peak
        (:func:`focus_evidence`); an all-zero measurement raises :class:`ClfzaError`.
    """
    t0 = time.perf_counter()
    zmin, zmax = _check_range(z_range)
    if metric not in METRICS:
        raise ClfzaError(f"metric must be one of {METRICS}, got {metric!r}")
    if int(coarse) < 3:
        raise ClfzaError(f"coarse must be >= 3, got {coarse!r}")
    eng = engine or FastBP(y, camera, highpass=highpass, taper=taper, backend=backend,
                           device=device)
    mask = _as_mask(roi, eng.shape, margin)
    evals: list = []

    def score(img: np.ndarray) -> float:
        return sharpness(img, metric, mask)

    t1 = time.perf_counter()
    zbest, grid, s = _search(eng, score, zmin, zmax, method=method, coarse=int(coarse),
                             tol=float(tol), evals=evals)
    t2 = time.perf_counter()
    timings = {"setup": eng.setup_s if engine is None else 0.0, "search": t2 - t1,
               "per_depth": (t2 - t1) / max(1, len(evals)), "total": t2 - t0,
               "evaluations": len(evals)}
    if len(grid) >= EVIDENCE_POINTS:
        ev = focus_evidence(s, grid)
    else:  # too few points to tell a peak from the curve's noise: a denser curve for the test
        t3 = time.perf_counter()
        eg = inverse_depth_grid(zmin, zmax, EVIDENCE_POINTS)
        ev = focus_evidence(np.array([score(eng.image(z)) for z in eg]), eg)
        timings["evidence"] = time.perf_counter() - t3
    if not ev["confident"] and warn:
        warnings.warn(f"autofocus: no reliable depth in {zmin:g}..{zmax:g} mm: "
                      f"{ev['reason']}", FocusWarning, stacklevel=2)
    return FocusResult(z1_best=float(zbest), r1p_best=r1p_at(camera, zbest), scores=s,
                       z_grid=grid, metric=metric, evaluations=evals, timings=timings,
                       depth_resolution=depth_resolution(camera, zbest), evidence=ev)


def _as_mask(roi, shape: tuple[int, int], margin: float) -> np.ndarray:
    if roi is None:
        return central_mask(shape, margin)
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
                tol: float = 1e-3, margin: float = 0.1, min_separation: float = 3.0,
                backend: str = "numpy", device: str | None = None,
                highpass: float = 8.0, taper: float = 0.25) -> DepthsResult:
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
    min_separation : float
        Merge distance between depths, in units of :func:`depth_resolution`.

    Returns
    -------
    DepthsResult
    """
    zmin, zmax = _check_range(z_range)
    eng = FastBP(y, camera, highpass=highpass, taper=taper, backend=backend, device=device)
    ny, nx = eng.shape
    region = central_mask((ny, nx), margin)
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
    grid = inverse_depth_grid(zmin, zmax, coarse)
    curves = np.zeros((len(tile_masks), len(grid)))
    whole = np.zeros(len(grid))
    for k, z in enumerate(grid):
        img = eng.image(z)
        whole[k] = sharpness(img, metric, region)
        for t, m in enumerate(tile_masks):
            curves[t, k] = sharpness(img, metric, m)
    tile_best = np.full(len(tile_masks), np.nan)
    for t in range(len(tile_masks)):
        c = curves[t]
        rng = c.max() - c.min()
        if rng > 0 and c.max() - np.median(c) > 0.25 * rng and 0 < np.argmax(c) < len(c) - 1:
            tile_best[t] = grid[int(np.argmax(c))]
    # cluster the votes in 1/z
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
    depths: list[float] = []
    strengths: list[float] = []
    masks: list[np.ndarray] = []
    curve_res = FocusResult(z1_best=float(grid[int(np.argmax(whole))]),
                            r1p_best=r1p_at(camera, float(grid[int(np.argmax(whole))])),
                            scores=whole, z_grid=grid, metric=metric,
                            depth_resolution=depth_resolution(camera,
                                                              float(grid[int(np.argmax(whole))])))
    for cl in clusters[:n]:
        m = np.any([tile_masks[t] for t in cl], axis=0)
        zc = float(np.median(tile_best[cl]))
        dz = 2.0 * (grid[1] / grid[0] - 1.0) * zc if len(grid) > 1 else 0.1 * zc
        lo, hi = max(zmin, zc - abs(dz) - 1e-9), min(zmax, zc + abs(dz) + 1e-9)
        fr = autofocus(y, camera, (lo, hi), metric=metric, method="golden", coarse=5, tol=tol,
                       roi=m, engine=eng, warn=False)
        depths.append(fr.z1_best)
        strengths.append(float(len(cl)))
        masks.append(m)
    if len(depths) < n:
        for i in _local_maxima(whole):
            z = float(grid[i])
            if all(abs(1.0 / z - 1.0 / d) > abs(1.0 / d - 1.0 / (d + min_separation *
                                                                   depth_resolution(camera, d)))
                   for d in depths):
                depths.append(z)
                strengths.append(float(whole[i] - np.median(whole)))
                masks.append(region)
            if len(depths) >= n:
                break
    return DepthsResult(depths=depths, strengths=strengths, curve=curve_res,
                        tile_depths=tile_best.reshape(tiles, tiles), masks=masks)


# ----------------------------------------------------------------------------------------
# focal stacks and refocused reconstructions
# ----------------------------------------------------------------------------------------
def focal_stack(y: np.ndarray, camera: Camera, depths: Sequence[float], method: str = "bp",
                *, metric: str = "mix", **options) -> FocalStack:
    """Reconstructions of one measurement at a list of object distances (a 3-D scene).

    Each slice is ``clfza.reconstruct(y, camera.at_depth(z), method, **options)``; for
    ``"bp"`` that is ``K_z^T y`` (Eqs. 11-12), for an iterative method the solution of Eq. 19
    with ``K_z``. ``sharpness`` holds ``metric`` of the pre-processed fast back-propagation
    at each depth (:class:`FastBP`, central 70 %), the same score :func:`autofocus` uses, so
    the slices of different methods are ranked alike.
    """
    from .api import reconstruct

    ds = [positive("depth", d) for d in depths]
    if not ds:
        raise ClfzaError("focal_stack needs at least one depth")
    eng = FastBP(y, camera)
    mask = central_mask(eng.shape)
    imgs, infos, sh = [], [], []
    for z in ds:
        rec = reconstruct(y, camera.at_depth(z), method, **options)
        imgs.append(rec.image)
        infos.append(rec.info)
        sh.append(sharpness(eng.image(z), metric, mask))
    return FocalStack(depths=ds, images=np.stack(imgs), infos=infos, sharpness=sh)


def reconstruct_autofocus(y: np.ndarray, camera: Camera, method: str = "bp", *,
                          z_range: Sequence[float] = (10.0, 1000.0), metric: str = "mix",
                          search: str = "golden", focus_backend: str = "numpy", **options):
    """Autofocus with fast back-propagation, then run ``method`` at the best depth.

    Returns ``(Reconstruction, FocusResult)``; the reconstruction's ``info.notes`` records the
    depth found and the search's cost.
    """
    from .api import reconstruct

    fr = autofocus(y, camera, z_range, metric=metric, method=search, backend=focus_backend)
    rec = reconstruct(y, camera.at_depth(fr.z1_best), method, **options)
    rec.info.notes.append(
        f"autofocus: z1 = {fr.z1_best:.4g} mm (r1' = {fr.r1p_best:.5g} mm, metric {metric}, "
        f"{fr.timings['evaluations']} depths in {fr.timings['total'] * 1e3:.0f} ms; depth "
        f"of focus +/- {fr.depth_resolution:.3g} mm; "
        f"{'evidence' if fr.confident else 'NOT RELIABLE'}: {fr.evidence.get('reason', '')})")
    rec.info.params["z1_autofocus"] = fr.z1_best
    return rec, fr
