"""The exact forward model of a real mask camera: linear convolution with the mask's shadow (or
a measured PSF) on a padded grid, cropped to the sensor, mean removed (float64 reference).

A real FZA camera sees ``frame = C (h * o)``: the sensor-plane object ``o`` convolved with the
shadow ``h`` of the mask as it is — binary (Eq. 1, with the higher orders of Eq. 7) or
sinusoidal (Eq. 9), inside the aperture ``circ(r/R')``, optionally Fresnel-diffracted over
``z2`` (Eq. 8) — and cropped to the sensor by ``C``. The open disc of the aperture adds the term
``(1/2) circ(r/R') * o``, the scene blurred by the disc, which the transfer-function model of
Eq. 17 cannot express (docs/design.md s.1, "The real camera"). Removing the frame's mean (``P``, an
orthogonal projection) drops the unknown dark level and the DC of the frame:

``K o = P C (h * o)``, ``K^T r = h (x) C^T P r`` (correlation with ``h``).

The unknown lives on a periodic grid ``G`` (the *model grid*) that holds the sensor plus a
margin; circular convolution on ``G`` equals the linear convolution of an object supported on
the sensor (plus margin) whenever ``G`` covers the sensor, the margin and the PSF's reach
(:func:`model_grid`), so ``K`` equals the simulator's map to rounding. Every solver works on
``G`` (as DiffuserCam does, Antipa et al., Optica 5, 1, 2018); the image is the sensor window
of ``G`` (:meth:`ExactModel.crop`).

Scale: the shadow is multiplied by ``2 p^2 / r1'^2`` (the paper's reference scaling, Eq. 17),
so the zone term has unit gain like ``H_T`` and ``tau`` means the same in both models; the
disc term gives ``||K||`` in the hundreds, which :attr:`ExactModel.norm` measures (power
iteration) and the solvers take their steps from.
"""

from __future__ import annotations

import hashlib
import math
import warnings
from dataclasses import dataclass
from functools import lru_cache

import numpy as np
import scipy.fft

from ..camera import FAR_FROM_CRITICAL, Camera, SamplingWarning
from ..cl import read_cache, write_cache
from ..errors import ClfzaError
from ..simulation import shadow_pattern


@dataclass(frozen=True)
class ModelGrid:
    """Where the sensor sits in the periodic model grid.

    Attributes
    ----------
    sensor : (int, int)
        Sensor (measurement) shape.
    grid : (int, int)
        Model grid ``G`` (the unknown's shape, an FFT-friendly size).
    offset : (int, int)
        Row/column of the sensor's first pixel in ``G``.
    margin : int
        Pixels of object plane modelled exactly around the sensor on each side.
    """

    sensor: tuple[int, int]
    grid: tuple[int, int]
    offset: tuple[int, int]
    margin: int

    def crop(self, x: np.ndarray) -> np.ndarray:
        """The sensor window ``C x`` of grid arrays (..., Gy, Gx) -> (..., Sy, Sx)."""
        (oy, ox), (sy, sx) = self.offset, self.sensor
        return x[..., oy:oy + sy, ox:ox + sx]

    def embed(self, y: np.ndarray, dtype=np.float64) -> np.ndarray:
        """``C^T y``: a sensor array (..., Sy, Sx) placed in a zero grid array of ``dtype``."""
        out = np.zeros(y.shape[:-2] + self.grid, dtype)
        (oy, ox), (sy, sx) = self.offset, self.sensor
        out[..., oy:oy + sy, ox:ox + sx] = y
        return out

    def sensor_mask(self) -> np.ndarray:
        """``C^T 1``: 1 on the sensor window, 0 elsewhere."""
        return self.embed(np.ones(self.sensor))


def _axis_grid(s: int, reach: tuple[int, int], margin: int) -> int:
    """Smallest FFT-friendly period for one axis (see :func:`model_grid`)."""
    a, b = reach
    need = max(s + 2 * margin, a + b + 1, s + margin + max(a, b))
    return scipy.fft.next_fast_len(need, real=True)


def model_grid(sensor: tuple[int, int], kernel_shape: tuple[int, int], margin: int = 0
               ) -> ModelGrid:
    """The model grid for a sensor and a centred kernel of ``kernel_shape``.

    Per axis, with sensor size ``S``, margin ``m`` and kernel offsets ``[-a, b]`` (a kernel of
    ``P`` samples centred at index ``P // 2``; offsets beyond ``S - 1 + m`` never connect the
    sensor to the object region and are dropped): the period ``G`` must hold the object region
    (``G >= S + 2m``), the kernel (``G >= a + b + 1``) and keep every sensor-object offset from
    wrapping into the kernel (``G >= S + m + max(a, b)``). ``G`` is then rounded up to a fast
    FFT length (``scipy.fft.next_fast_len``), not to ``2S``.
    """
    m = int(margin)
    if m < 0:
        raise ClfzaError(f"margin must be >= 0, got {margin}")
    grid, off = [], []
    for s, p in zip(sensor, kernel_shape, strict=True):
        lim = s - 1 + m
        reach = (min(p // 2, lim), min(p - 1 - p // 2, lim))
        g = _axis_grid(s, reach, m)
        grid.append(g)
        off.append(m)
    return ModelGrid(tuple(sensor), tuple(grid), tuple(off), m)


def place_kernel(kernel: np.ndarray, grid: tuple[int, int], reach: tuple[int, int]
                 ) -> np.ndarray:
    """A centred kernel on the periodic grid: offset ``d`` at index ``d mod G`` (zero
    elsewhere), keeping offsets within ``reach`` (rows, cols) of the centre."""
    py, px = kernel.shape[-2:]
    cy, cx = py // 2, px // 2
    ry2, rx2 = min(reach[0], py - 1 - cy), min(reach[1], px - 1 - cx)
    ry1, rx1 = min(reach[0], cy), min(reach[1], cx)
    out = np.zeros(kernel.shape[:-2] + tuple(grid))
    dy = np.arange(-ry1, ry2 + 1)
    dx = np.arange(-rx1, rx2 + 1)
    sub = kernel[..., cy - ry1:cy + ry2 + 1, cx - rx1:cx + rx2 + 1]
    out[..., (dy % grid[0])[:, None], (dx % grid[1])[None, :]] = sub
    return out


def shadow_kernel(camera: Camera, margin: int = 0, diffraction: bool = False) -> np.ndarray:
    """The mask's shadow for a point at ``z1``, scaled by ``2 p^2 / r1'^2``, sampled at every
    sensor-object offset (a centred ``(2(S+m) - 1)``-sample grid); without diffraction it is
    trimmed to the aperture's reach, which lets :func:`model_grid` choose a smaller grid.

    Sampled through :func:`clfza.simulation.shadow_pattern` on the simulator's own grid, so the
    operator and the simulator share the same samples (diffraction included).
    """

    sy, sx = camera.shape
    m = int(margin)
    t = shadow_pattern(camera, (2 * (sy + m), 2 * (sx + m)), diffraction)[1:, 1:]
    cy, cx = t.shape[0] // 2, t.shape[1] // 2
    reach = None if camera.R_shadow is None else (
        camera.R_shadow / camera.pitch - math.hypot(*camera.mask_center))
    if reach is not None and reach < math.hypot(cy, cx) and not diffraction:
        # trim to the aperture's reach (diffraction spreads light past the geometric shadow:
        # keep every offset then)
        r = int(math.ceil(camera.R_shadow / camera.pitch + math.hypot(
            *camera.mask_center))) + 2
        ry, rx = min(r, cy), min(r, cx)
        t = t[cy - ry:cy + ry + 1, cx - rx:cx + rx + 1]
    else:
        # The window holds every sensor-object offset, so a constant in the kernel adds
        # the same value to every sensor pixel, which the mean removal P takes out: drop
        # the window's mean. Exact for objects in the modelled region, and it removes the
        # open mask's huge DC gain (the "1/2" of Eqs. 1 and 9), which otherwise sets ||K||
        # hundreds of times above the zone term's gain and stalls every solver.
        t = t - t.mean()
    return t * (2.0 * camera.pitch**2 / camera.r1p**2)


class ExactModel:
    """``K o = P C (h * o)`` and its adjoint on the model grid (float64 reference).

    Parameters
    ----------
    kernel : array (Py, Px)
        The PSF on the sensor's pitch, centred at ``(Py // 2, Px // 2)``: the scaled mask
        shadow (:func:`shadow_kernel`) or a measured PSF (:mod:`clfza.models._psf`). It may be
        larger than the sensor.
    sensor : (int, int)
        Sensor shape.
    margin : int
        Object-plane pixels around the sensor modelled exactly (points outside the sensor's
        footprint whose shadows reach it).

    Attributes
    ----------
    geom, image_geom : ModelGrid
        Where the data (sensor) and the image sit on the grid: the same window, except for a
        high-passed model (:func:`clfza.models._highpass.highpass_model`), whose data is the
        sensor's interior and whose image is the whole sensor.
    mask_shadow : bool
        The kernel is a mask's shadow (:meth:`from_camera`, :func:`binned_model`).
    """

    def __init__(self, kernel: np.ndarray, sensor: tuple[int, int], margin: int = 0):
        kernel = np.asarray(kernel, dtype=np.float64)
        if kernel.ndim != 2 or not np.isfinite(kernel).all() or not kernel.any():
            raise ClfzaError("the model's kernel (PSF) must be a finite, non-zero 2-D array")
        self.kernel = kernel
        self.geom = model_grid(tuple(sensor), kernel.shape, margin)
        # where the image is (clfza.models._highpass: more than the data)
        self.image_geom = self.geom
        self.highpass = 0  # the data term's box high-pass half-width (clfza.models._highpass)
        self.mask_shadow = False  # the kernel is a mask's shadow (not a measured PSF)
        self.shape = self.geom.grid
        self.sensor = self.geom.sensor
        lim = (sensor[0] - 1 + margin, sensor[1] - 1 + margin)
        self.kernel_grid = place_kernel(kernel, self.shape, lim)
        self.Hs = scipy.fft.rfft2(self.kernel_grid)  # complex: a PSF need not be even
        self.n_sensor = int(np.prod(self.sensor))
        self._norm: float | None = None

    @classmethod
    def from_camera(cls, camera: Camera, margin: int = 0, diffraction: bool = False
                    ) -> ExactModel:
        """The model of an FZA camera's mask (see :func:`shadow_kernel`)."""
        out = cls(shadow_kernel(camera, margin, diffraction), camera.shape, margin)
        out.mask_shadow = True
        return out

    # -- pieces -------------------------------------------------------------------------
    def conv(self, x: np.ndarray) -> np.ndarray:
        """``h * x`` on the periodic grid (the uncropped convolution, ``H`` of DiffuserCam)."""
        return scipy.fft.irfft2(scipy.fft.rfft2(x, workers=-1) * self.Hs, s=self.shape,
                                workers=-1)

    def corr(self, v: np.ndarray) -> np.ndarray:
        """``H^T v``: correlation with the kernel on the periodic grid."""
        return scipy.fft.irfft2(scipy.fft.rfft2(v, workers=-1) * np.conj(self.Hs),
                                s=self.shape, workers=-1)

    @staticmethod
    def remove_mean(y: np.ndarray) -> np.ndarray:
        """``P y``: the frame minus its mean (over the last two axes)."""
        return y - y.mean(axis=(-2, -1), keepdims=True)

    def crop(self, x: np.ndarray) -> np.ndarray:
        return self.geom.crop(x)

    # -- the operator -------------------------------------------------------------------
    def forward(self, x: np.ndarray) -> np.ndarray:
        """``K x = P C (h * x)``: grid (Gy, Gx) -> sensor (Sy, Sx)."""
        x = np.asarray(x, dtype=np.float64)
        if x.shape[-2:] != self.shape:
            raise ClfzaError(f"object has shape {x.shape[-2:]}, the model grid is {self.shape}")
        return self.remove_mean(self.crop(self.conv(x)))

    def adjoint(self, y: np.ndarray) -> np.ndarray:
        """``K^T y = H^T C^T P y``: sensor -> grid."""
        y = np.asarray(y, dtype=np.float64)
        if y.shape[-2:] != self.sensor:
            raise ClfzaError(f"measurement has shape {y.shape[-2:]}, the sensor is "
                             f"{self.sensor}")
        return self.corr(self.geom.embed(self.remove_mean(y)))

    def normal(self, x: np.ndarray) -> np.ndarray:
        """``K^T K x`` (two real FFT pairs)."""
        return self.adjoint(self.forward(x))

    @property
    def norm(self) -> float:
        """``||K||`` by power iteration on ``K^T K`` (:func:`operator_norm`), measured once per
        operator: kept on the model, and by content (the kernel and the geometry) in memory
        and in clfza's cache folder (:data:`NORM_CACHE`), so another model of the same
        operator, in this process or a later one, reads it (the power iteration is seeded:
        the value read is the value measured)."""
        if self._norm is None:
            key = self._norm_key()
            norm = _NORMS.get(key)
            if norm is None:
                norm = _read_norm(key)
            if norm is None:
                gain = float(np.abs(self.Hs).max())  # taken out: no float32 overflow
                norm = gain * operator_norm(self._normal_single(gain), self.shape,
                                            dtype=np.float32)
                _write_norm(key, norm)
            _NORMS[key] = norm
            self._norm = norm
        return self._norm

    def _normal_single(self, gain: float = 1.0):
        """``K^T K / gain^2`` in single precision, for the power iteration of :attr:`norm`:
        faster than :meth:`normal`, and its rounding is far below the iteration's stopping
        tolerance (measured: docs/measurements.md, clfza.models._exact)."""
        hs = (self.Hs / gain).astype(np.complex64)
        hs_conj = np.conj(hs)
        geom = self.geom

        def normal(x: np.ndarray) -> np.ndarray:
            v = scipy.fft.irfft2(scipy.fft.rfft2(x, workers=-1) * hs, s=self.shape, workers=-1)
            g = geom.embed(self.remove_mean(geom.crop(v)), np.float32)
            return scipy.fft.irfft2(scipy.fft.rfft2(g, workers=-1) * hs_conj, s=self.shape,
                                    workers=-1)

        return normal

    def _norm_key(self) -> str:
        h = hashlib.blake2b(digest_size=16)
        h.update(f"{type(self).__name__} {self.geom} {self.image_geom} {NORM_METHOD}".encode())
        h.update(np.ascontiguousarray(self.kernel_grid, dtype=np.float64).tobytes())
        return h.hexdigest()


#: the cache file of measured operator norms (:attr:`ExactModel.norm`), in clfza's cache folder
NORM_CACHE = "operator_norms.json"
NORM_CACHE_SIZE = 64  # entries kept (the most recently measured)
NORM_METHOD = "power iteration: 50 iterations, tol 1e-3, seed 0, float32, v2"  # in the key
_NORMS: dict[str, float] = {}


def _read_norm(key: str) -> float | None:
    v = read_cache(NORM_CACHE).get(key)
    return float(v) if isinstance(v, (int, float)) and math.isfinite(v) and v >= 0 else None


def _write_norm(key: str, norm: float) -> None:
    data = read_cache(NORM_CACHE)
    data.pop(key, None)
    data[key] = norm
    order = data.pop("_order", [])
    order = [k for k in order if k in data and k != key] + [key]
    for old in order[:-NORM_CACHE_SIZE]:
        data.pop(old, None)
    data["_order"] = order[-NORM_CACHE_SIZE:]
    write_cache(NORM_CACHE, data)


def operator_norm(normal, shape: tuple[int, int], iters: int = 50, tol: float = 1e-3,
                  seed: int = 0, dtype=np.float64) -> float:
    """``||K||`` from power iteration on ``K^T K`` (stops when the estimate changes by less
    than ``tol`` relative). The estimate approaches the norm from below; solvers use it with
    a safety factor (:data:`NORM_SAFETY`). ``tol`` 1e-3: the high-passed models
    (:mod:`clfza.models._highpass`) have a flatter spectrum and converge slowly to a tighter
    tolerance, while the estimate at 1e-3 stays well inside the safety factor (measured:
    docs/measurements.md, clfza.models._exact)."""
    rng = np.random.default_rng(seed)
    x = rng.standard_normal(shape)
    x = (x / np.linalg.norm(x)).astype(dtype)
    lam = 0.0
    for _ in range(iters):
        z = normal(x)
        peak = float(np.abs(z).max())
        if peak == 0 or not math.isfinite(peak):
            return 0.0 if peak == 0 else peak
        # no under/overflow of the squares; the sum in float64 whatever ``dtype``
        new = peak * float(np.linalg.norm((z / peak).astype(np.float64, copy=False)))
        x = (z / new).astype(dtype, copy=False)
        if abs(new - lam) <= tol * new:
            lam = new
            break
        lam = new
    return math.sqrt(lam)


NORM_SAFETY = 1.02  # power iteration underestimates ||K||; steps use 1.02x the estimate


MODELS = ("auto", "tf", "exact", "padded")


def choose_model(camera: Camera | None, model: str = "auto", *, method: str = "bp",
                 mode: str | None = None, psf: bool = False) -> tuple[str, str]:
    """Which forward model runs, and why (for the info record and ``--explain``).

    ``"auto"``: the exact model (:class:`ExactModel`) wherever the transfer-function model of
    Eq. 17 is not the camera's map — a measured PSF, a finite aperture (its open disc adds the
    term ``(1/2) circ(r/R') * o``), a mask centre off the sensor centre, or sampling far from
    critical (``|r1'^2 / (N p^2) - 1| > 0.25``, where the sampled ``H_T`` wraps or aliases);
    TwIST in paper mode keeps the paper's model (it reproduces the authors' run), and so does
    back-propagation (Eqs. 11-12 are defined with ``H_T``; the exact ``K^T y`` adds the
    aperture's blur and is no sharper). Far from critical sampling without an aperture only
    ADMM switches: it gains on the exact model, while FISTA and efficient TwIST converge more
    slowly on it (both measured: docs/measurements.md, clfza.models._exact). Otherwise
    the transfer-function model, which is then exact and needs one FFT pair on the sensor grid.
    ``"padded"`` is the exact model restricted to objects on the sensor (numpy reference).
    ``mode`` is TwIST's mode (``"paper"`` or ``"efficient"``; ignored for other methods):
    :func:`clfza.solvers.method_model` fills in TwIST's own default.
    """

    if model not in MODELS:
        raise ClfzaError(f"model must be one of {MODELS}, got {model!r}")
    if psf:
        if model == "tf":
            raise ClfzaError("a measured PSF is used through the exact model (model='exact' "
                             "or 'auto'), not the transfer-function model")
        return "exact", "a measured PSF (or a given kernel) is the operator"
    if model != "auto":
        return model, f"model={model!r} was asked for"
    if method == "twist" and mode == "paper":
        return "tf", "TwIST paper mode runs the paper's transfer-function model (Eq. 17)"
    if method == "bp":
        return "tf", ("back-propagation is Eqs. 11-12, the correlation with H_T; the exact "
                      "model's K^T y adds the aperture's blur and is no sharper")
    if method == "wiener":
        if camera.R is not None or any(camera.mask_center):


            warnings.warn("Wiener runs on the transfer-function model (Eq. 17), which a mask "
                          "with a finite aperture or an off-centre mask does not follow (the "
                          "experiment preset: 12.7 dB); use method='admm' (exact model) here",
                          SamplingWarning, stacklevel=4)
        return "tf", ("the direct Wiener solve is one Fourier-space division on the "
                      "transfer-function model (clfza.solvers._wiener)")
    if camera.R is not None:
        return "exact", (f"the mask has a finite aperture (R = {camera.R:g} mm): its open disc "
                         "adds a term the transfer-function model cannot express")
    if any(camera.mask_center):
        return "exact", "the mask centre is off the sensor centre (calibrated mask_center)"
    ratio = camera.regime.ratio
    if abs(ratio - 1.0) > FAR_FROM_CRITICAL:
        if method == "admm":
            return "exact", (f"r1'^2/(N p^2) = {ratio:.2f} is far from critical sampling, "
                             "where the sampled H_T wraps or aliases")
        return "tf", (f"r1'^2/(N p^2) = {ratio:.2f} is off critical sampling, but {method} "
                      "converges faster on the transfer-function model without an aperture "
                      "(ADMM uses the exact model here)")
    return "tf", (f"no aperture and r1'^2/(N p^2) = {ratio:.2f}: the transfer-function model is "
                  "exact here and needs one FFT pair on the sensor grid")


@lru_cache(maxsize=4)
def camera_model(camera: Camera, margin: int = 0, diffraction: bool = False) -> ExactModel:
    """The exact model of a camera, cached per camera (the norm is measured once)."""
    return ExactModel.from_camera(camera, margin, diffraction)


def box_bin(y: np.ndarray, b: int) -> np.ndarray:
    """Pixel binning: the mean of each ``b x b`` block (what a sensor with ``b``-times larger
    pixels records), over the first two axes; the size must divide."""
    a = np.asarray(y, dtype=np.float64)
    ny, nx = a.shape[:2]
    if ny % b or nx % b:
        raise ClfzaError(f"bin factor {b} does not divide the grid {a.shape[:2]}")
    return a.reshape((ny // b, b, nx // b, b) + a.shape[2:]).mean(axis=(1, 3))


def binned_kernel(camera: Camera, b: int, margin: int = 0, diffraction: bool = False
                  ) -> np.ndarray:
    """The mask-shadow kernel of a full-resolution ``camera`` for frames binned by
    :func:`box_bin`.

    A binned pixel ``I`` averages ``b^2`` fine pixels; with the object constant over each
    ``b x b`` block (the binned unknown), ``y_b(I) = sum_J o_b(J) g(I - J)`` with
    ``g(D) = sum_e h(b D + e) (b - |e_y|)(b - |e_x|) / b^2``: the fine kernel filtered by the
    separable triangle of two boxes and sampled every ``b`` offsets. It matches the binned
    simulation up to the object's detail inside a block, far closer than the mask sampled at
    the coarse pitch (measured: docs/measurements.md, clfza.models._exact).
    """
    b = int(b)
    if b < 1:
        raise ClfzaError(f"bin factor must be >= 1, got {b}")
    k = shadow_kernel(camera, margin * b, diffraction)
    if b == 1:
        return k
    w = (b - np.abs(np.arange(1 - b, b))) / b
    kf = scipy.fft.irfft2(
        scipy.fft.rfft2(k, s=[n + 2 * b - 2 for n in k.shape])
        * scipy.fft.rfft2(np.outer(w, w), s=[n + 2 * b - 2 for n in k.shape]),
        s=[n + 2 * b - 2 for n in k.shape])  # full linear convolution: offsets shift by b - 1
    idx = []
    for n in k.shape:
        c = n // 2 + b - 1
        r = c // b
        idx.append(c + b * np.arange(-r, r + 1))
    return kf[np.ix_(*idx)]


@lru_cache(maxsize=4)
def binned_model(camera: Camera, b: int, margin: int = 0) -> ExactModel:
    """The exact model of a full-resolution camera for its frames binned by ``b``
    (:func:`box_bin`, :func:`binned_kernel`; cached)."""
    sy, sx = camera.shape
    if sy % b or sx % b:
        raise ClfzaError(f"bin factor {b} does not divide the sensor {camera.shape}")
    out = ExactModel(binned_kernel(camera, b, margin), (sy // b, sx // b), margin)
    out.mask_shadow = True
    return out
