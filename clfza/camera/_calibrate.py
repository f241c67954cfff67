"""Calibrate an FZA camera from a point-source capture (or a PSF image).

A point source at distance ``z1`` casts the mask's shadow on the sensor: a zone pattern with
the shadow constant ``r1' = (1 + z2/z1) r1`` (the paper's Methods), centred where the chief
ray through the mask centre meets the sensor, bounded by the aperture's shadow
``R' = (1 + z2/z1) R``. Its intensity is the binary FZA
``1/2 + 1/2 sgn(cos(pi r^2/r1'^2 + phase))`` (Eq. 1) or the Gabor zone plate
``1/2 + 1/2 cos(pi r^2/r1'^2 + phase)`` (Eq. 9). :func:`calibrate` measures these:

1. the centre, from the pattern's point symmetry: the cross-correlation of the frame with
   its 180-degree rotation peaks at twice the centre's offset (sub-pixel parabolic peak);
2. the aperture's shadow ``R'``, where the ring-averaged local mean drops to the background;
3. a coarse ``r1'^2``: the pattern is periodic in ``s = r^2`` with period ``2 r1'^2`` (Eq. 1),
   so the radial profile resampled uniformly in ``s`` has a periodogram peak at
   ``1 / (2 r1'^2)``;
4. a joint least-squares refinement (``scipy.optimize.least_squares``, variable projection)
   of centre, ``r1'^2``, ``R'`` and the pixel fill factor on a random subset of pixels. The
   model is the Fourier series of the binary FZA as a sum of Gabor zone plates (Eq. 7),
   ``sum_n a_n cos(n (pi s / r1'^2 + phase))`` over odd ``n``, each order attenuated by the
   pixel's box integration of its local frequency ``n (x, y) / r1'^2``; the amplitudes
   ``a_n`` (complex: they carry the phase), mean and background are solved linearly;
5. the mask type from the third harmonic: ``|a_3| / |a_1| = 1/3`` for the binary FZA
   (Eq. 7), 0 for the GZP (Eq. 9).

All internal lengths are in pixels of the (binned) frame; results are reported in mm and in
pixels of the input frame.

Diffraction. A shadow diffracted over ``z2`` (Eq. 8) is no longer one chirp: the fitted
``r1'^2`` is the effective constant of the captured pattern, not the geometric one (on the
experiment's fine outer zones it came out low by about ``lambda z2``: docs/measurements.md,
clfza.camera._calibrate), and
the beating of the diffracted terms raises the residual; the fit then reports low confidence.
"""

from __future__ import annotations

import math
import time
from dataclasses import asdict, dataclass, field

import numpy as np
import scipy.fft
from scipy.special import erfc

from ..errors import ClfzaError, finite_image, positive, positive_int
from ._camera import Camera, tomllib

MASK_CHOICES = ("auto", "fza", "gzp")
#: odd orders of the binary mask's Fourier series (Eq. 7) in the model
FZA_ORDERS = (1, 3, 5)
#: |a3| / |a1| above which the mask is binary (1/3 expected), below which it is sinusoidal
HARMONIC_FZA, HARMONIC_GZP = 0.2, 0.1
#: aperture edge: Gaussian-blurred step of this width (px), pixel integration and rounding
EDGE_SIGMA = 0.5


@dataclass
class Calibration:
    """A fitted FZA camera (see :func:`calibrate`).

    Attributes
    ----------
    r1_shadow_squared, r1_shadow_squared_std : float
        Shadow constant ``r1'^2`` in mm^2 and its standard error.
    center, center_std : (float, float)
        Pattern centre (row, col) in pixels of the input frame, and its standard error.
    R_shadow, R_shadow_std : float or None
        Aperture radius ``R'`` of the shadow in mm; None when no aperture edge is on the
        sensor.
    mask : str
        ``"fza"`` (binary, Eq. 1) or ``"gzp"`` (sinusoidal, Eq. 9).
    harmonic_ratio : float
        ``|a3| / |a1|`` of the fitted series: 1/3 for the FZA, 0 for the GZP (Eq. 7).
    phase, phase_std : float
        Phase offset of the zones in radians.
    amplitude, mean, background : float
        Fundamental's amplitude, the mask's mean level and the dark level outside the
        aperture (frame units; without an aperture edge the background is part of ``mean``
        and reported as 0).
    fill : float
        Pixel fill factor of the box-integration model (0: point samples, 1: full pixels).
    residual_rms, signal_rms : float
        RMS of the fit residual and of the fitted zone pattern (frame units).
    pitch, shape, bin : float, (int, int), int
        Pixel pitch (mm) and shape of the input frame; the bin factor used for the fit.
    warnings : list of str
        Reasons for low confidence; empty when the fit is trustworthy.
    timings : dict
        Seconds spent per stage.
    """

    r1_shadow_squared: float
    r1_shadow_squared_std: float
    center: tuple[float, float]
    center_std: tuple[float, float]
    R_shadow: float | None
    R_shadow_std: float | None
    mask: str
    harmonic_ratio: float
    phase: float
    phase_std: float
    amplitude: float
    mean: float
    background: float
    fill: float
    residual_rms: float
    signal_rms: float
    pitch: float
    shape: tuple[int, int]
    bin: int = 1
    warnings: list[str] = field(default_factory=list)
    timings: dict = field(default_factory=dict)

    @property
    def confident(self) -> bool:
        """True when no warning was raised."""
        return not self.warnings

    @property
    def mask_center(self) -> tuple[float, float]:
        """Centre offset (rows, cols) in pixels from the sensor pixel ``(N // 2)``."""
        return (self.center[0] - self.shape[0] // 2, self.center[1] - self.shape[1] // 2)

    def camera(self, z1: float, z2: float, r1: float | None = None,
               name: str = "calibrated") -> Camera:
        """The calibrated :class:`Camera` for a point source at ``z1``, mask at ``z2``.

        ``R = R' / (1 + z2/z1)`` and, unless given, ``r1 = r1' / (1 + z2/z1)`` (Methods).
        """
        scale = 1.0 + positive("z2", z2) / positive("z1", z1, allow_inf=True)
        r1p = math.sqrt(self.r1_shadow_squared)
        return Camera(pitch=self.pitch, shape=self.shape,
                      r1=r1p / scale if r1 is None else r1, z1=z1, z2=z2,
                      R=None if self.R_shadow is None else self.R_shadow / scale,
                      mask=self.mask, phase=self.phase, r1_shadow=r1p,
                      mask_center=self.mask_center, name=name)

    def to_dict(self) -> dict:
        d = asdict(self)
        d.update(center=list(self.center), center_std=list(self.center_std),
                 shape=list(self.shape), mask_center=list(self.mask_center),
                 confident=self.confident)
        return d

    def summary_lines(self) -> list[str]:
        """One line per fitted parameter, with its uncertainty."""
        q, dq = self.r1_shadow_squared, self.r1_shadow_squared_std
        (cy, cx), (sy, sx) = self.center, self.center_std
        dy, dx = self.mask_center
        rr = ("none on the sensor" if self.R_shadow is None else
              f"{self.R_shadow:.4f} +/- {self.R_shadow_std:.4f} mm")
        snr = self.signal_rms / max(self.residual_rms, 1e-300)
        return [
            f"r1'^2   {q:.6f} +/- {dq:.6f} mm^2 (r1' = {math.sqrt(q):.5f} mm, "
            f"{100 * dq / q:.2g}%)",
            f"centre  row {cy:.2f} +/- {sy:.2f}, col {cx:.2f} +/- {sx:.2f} px "
            f"(offset {dy:+.2f}, {dx:+.2f} px from pixel N//2)",
            f"R'      {rr}",
            f"mask    {self.mask} (|a3|/|a1| = {self.harmonic_ratio:.3f}; FZA 1/3, GZP 0)",
            f"phase   {self.phase:+.4f} +/- {self.phase_std:.4f} rad",
            f"fit     residual {self.residual_rms:.4g} vs signal {self.signal_rms:.4g} rms "
            f"(SNR {snr:.1f}), fill factor {self.fill:.2f}, bin {self.bin}",
        ]


# ----------------------------------------------------------------------------------------
# input
# ----------------------------------------------------------------------------------------
def _prepare(image, bin_: int) -> np.ndarray:
    """Validate a frame (grey, or colour summed to grey) and bin it ``bin_ x bin_``."""
    a = finite_image("calibration frame", image)
    if a.ndim == 3:
        a = a.sum(axis=2)
    b = positive_int("bin", bin_)
    h, w = a.shape[0] // b, a.shape[1] // b
    if min(h, w) < 32:
        raise ClfzaError(f"calibration needs at least 32x32 pixels after binning, got {h}x{w}")
    a = a[:h * b, :w * b].reshape(h, b, w, b).sum(axis=(1, 3)) if b > 1 else a
    if not np.any(a):
        raise ClfzaError("the calibration frame is all zero: no light reached the sensor")
    if np.ptp(a) == 0:
        raise ClfzaError("the calibration frame is flat (one value everywhere): no zone "
                         "pattern to fit")
    return a


# ----------------------------------------------------------------------------------------
# 1. centre from point symmetry
# ----------------------------------------------------------------------------------------
def _parabolic(m1: float, m0: float, p1: float) -> float:
    """Sub-sample offset of a peak from three samples around it."""
    den = m1 - 2 * m0 + p1
    return 0.0 if den >= 0 else float(np.clip(0.5 * (m1 - p1) / den, -0.5, 0.5))


def find_center(img: np.ndarray) -> tuple[float, float]:
    """Centre (row, col) of a point-symmetric pattern, in pixels.

    With ``I(x) = P(x - c)`` and ``P(-u) = P(u)``, the 180-degree rotation
    ``I(N - 1 - x)`` is ``P`` centred at ``N - 1 - c``; their cross-correlation peaks at the
    shift ``t = 2c - (N - 1)``, found to a fraction of a pixel by a parabola per axis.
    """
    a = img - img.mean()
    ny, nx = a.shape
    s = (2 * ny, 2 * nx)
    fa = scipy.fft.rfft2(a, s=s)
    fb = scipy.fft.rfft2(a[::-1, ::-1], s=s)
    c = scipy.fft.irfft2(fa * np.conj(fb), s=s)
    c = scipy.fft.fftshift(c)  # shift t sits at index t + (ny, nx)
    i, j = np.unravel_index(int(np.argmax(c)), c.shape)
    i = int(np.clip(i, 1, s[0] - 2))
    j = int(np.clip(j, 1, s[1] - 2))
    ty = i - ny + _parabolic(c[i - 1, j], c[i, j], c[i + 1, j])
    tx = j - nx + _parabolic(c[i, j - 1], c[i, j], c[i, j + 1])
    return 0.5 * (ty + ny - 1), 0.5 * (tx + nx - 1)


# ----------------------------------------------------------------------------------------
# 2. aperture edge and 3. coarse r1'^2
# ----------------------------------------------------------------------------------------
def _radii(shape: tuple[int, int], center: tuple[float, float]) -> np.ndarray:
    yy = np.arange(shape[0])[:, None] - center[0]
    xx = np.arange(shape[1])[None, :] - center[1]
    return np.sqrt(yy**2 + xx**2)


def find_aperture(img: np.ndarray, center: tuple[float, float]) -> float | None:
    """Radius (px) where the ring-averaged local mean falls to the background, or None.

    The rings' mean is smoothed over 9 px in ``r`` (several local periods where the zones
    are fine enough for the edge to matter). The edge counts when the lit level inside
    exceeds the dark level outside by at least 0.4 times the pattern's standard deviation.
    """
    r = _radii(img.shape, center)
    rb = np.floor(r).astype(np.int64)
    cnt = np.bincount(rb.ravel())
    prof = np.bincount(rb.ravel(), img.ravel()) / np.maximum(cnt, 1)
    k = np.ones(9)
    num = np.convolve(prof * cnt, k, mode="same")
    ms = num / np.maximum(np.convolve(cnt, k, mode="same"), 1)
    ok = np.convolve(cnt, k, mode="same") >= 40
    inner = int(0.5 * min(center[0], center[1], img.shape[0] - 1 - center[0],
                          img.shape[1] - 1 - center[1]))
    if inner < 8 or not ok[inner:].any():
        return None
    lit = float(np.median(ms[4:max(inner, 5)]))
    idx = np.arange(ms.size)
    dark = float(np.min(ms[ok & (idx > inner)]))
    if lit - dark < 0.4 * float(np.std(img[r < inner])):
        return None
    thr = 0.5 * (lit + dark)
    below = np.nonzero((ms < thr) & ok & (idx > inner))[0]
    if below.size == 0:
        return None
    e = int(below[0])
    f = (ms[e - 1] - thr) / max(ms[e - 1] - ms[e], 1e-300)  # crossing between e-1 and e
    return float(e - 1 + f + 0.5)  # bins hold [e, e+1): their centre is e + 0.5


def coarse_r1p2(img: np.ndarray, center: tuple[float, float], r_max: float
                ) -> tuple[float, float]:
    """``r1'^2`` (px^2) from the periodogram of the radial profile in ``s = r^2`` (Eq. 1).

    Returns ``(q, significance)``: the period ``2 q`` in ``s`` of the strongest peak, and
    that peak's height over the median of the spectrum.
    """
    r = _radii(img.shape, center)
    inside = r < r_max
    s = (r[inside] ** 2).astype(np.float64)
    sb = np.floor(s).astype(np.int64)
    cnt = np.bincount(sb)
    prof = np.bincount(sb, img[inside]) / np.maximum(cnt, 1)
    good = cnt > 0
    x = np.arange(prof.size)
    prof = np.interp(x, x[good], prof[good])
    prof = prof - prof.mean()
    n = prof.size
    nfft = scipy.fft.next_fast_len(8 * n)
    spec = np.abs(scipy.fft.rfft(prof * np.hanning(n), n=nfft))
    f = np.arange(spec.size) / nfft  # cycles per px^2
    band = (f >= 2.0 / n) & (f <= 0.25)  # at least 2 periods; r1'^2 >= 2 px^2
    if not band.any():
        raise ClfzaError("the frame is too small to contain a zone pattern")
    k = int(np.argmax(np.where(band, spec, -1.0)))
    k = int(np.clip(k, 1, spec.size - 2))
    lg = np.log(spec[k - 1:k + 2] + 1e-300)
    fk = (k + _parabolic(lg[0], lg[1], lg[2])) / nfft
    sig = float(spec[k] / max(np.median(spec[band]), 1e-300))
    return 1.0 / (2.0 * fk), sig


# ----------------------------------------------------------------------------------------
# 4. joint least-squares refinement (variable projection)
# ----------------------------------------------------------------------------------------
@dataclass
class _Model:
    """Zone-pattern model on sampled pixels: nonlinear ``p = [cy, cx, q, fill(, R)]``."""

    yk: np.ndarray
    xk: np.ndarray
    data: np.ndarray
    orders: tuple[int, ...]
    aperture: bool

    def columns(self, p: np.ndarray) -> np.ndarray:
        """Basis functions (rows): background, mean, per order ``att cos(n t), att sin(n t)``.

        ``t = pi s / q`` (Eq. 1); ``att = sinc(n u w / q) sinc(n v w / q)`` is a box pixel of
        width ``w`` integrating the local frequency ``n (u, v) / q`` of order ``n`` (Eq. 7).
        """
        cy, cx, q, w = p[:4]
        u, v = self.yk - cy, self.xk - cx
        theta = np.pi * (u * u + v * v) / q
        edge = (0.5 * erfc((np.sqrt(u * u + v * v) - p[4]) / (EDGE_SIGMA * math.sqrt(2)))
                if self.aperture else np.ones_like(u))
        k = 1 + int(self.aperture) + 2 * len(self.orders)
        cols = np.empty((k, u.size))
        cols[0] = 1.0
        if self.aperture:
            cols[1] = edge
        e1 = np.exp(1j * theta)
        en = e1
        i = 1 + int(self.aperture)
        for n in range(1, max(self.orders) + 1):
            if n in self.orders:
                att = edge * np.sinc(n * u * w / q) * np.sinc(n * v * w / q)
                cols[i], cols[i + 1] = att * en.real, att * en.imag
                i += 2
            en = en * e1
        return cols

    def solve(self, p: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Linear amplitudes and residual for nonlinear parameters ``p``."""
        a = self.columns(p)
        try:  # normal equations: a few well-scaled basis functions; lstsq is far slower
            # (measured: docs/measurements.md, clfza.camera._calibrate)
            coef = np.linalg.solve(a @ a.T, a @ self.data)
        except np.linalg.LinAlgError:
            coef = np.linalg.lstsq(a.T, self.data, rcond=None)[0]
        return coef, self.data - coef @ a


def _sample(shape: tuple[int, int], n: int, seed: int,
            keep: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Up to ``n`` random pixel positions (all of them when the frame is small)."""
    idx = np.arange(shape[0] * shape[1]) if keep is None else np.flatnonzero(keep)
    if idx.size > n:
        idx = np.sort(np.random.default_rng(seed).choice(idx, n, replace=False))
    return np.divmod(idx, shape[1])


def refine(img: np.ndarray, center: tuple[float, float], q: float, R: float | None,
           orders: tuple[int, ...], *, samples: int = 30000, seed: int = 0) -> dict:
    """Least-squares fit of centre, ``q = r1'^2`` (px^2), fill factor and ``R'`` (px).

    Two passes: the inner half of the pattern (few zones, wide basin), then all sampled
    pixels. Returns the parameters, their standard errors from the Jacobian
    (``cov = s^2 (J^T J)^-1``), the linear amplitudes and the residual statistics.
    """
    ny, nx = img.shape
    p = np.array([center[0], center[1], q, 0.5] + ([R] if R is not None else []))
    lo = np.array([-0.5, -0.5, 0.2 * q, 0.0] + ([1.0] if R is not None else []))
    hi = np.array([ny - 0.5, nx - 0.5, 5.0 * q, 1.5] + ([np.inf] if R is not None else []))
    r = _radii(img.shape, center)
    rmax = float(r.max())
    res = None
    for frac in (0.5, None):
        keep = None if frac is None else r <= frac * rmax
        yk, xk = _sample(img.shape, samples if frac is None else samples // 2, seed, keep)
        m = _Model(yk.astype(float), xk.astype(float), img[yk, xk], orders, R is not None)
        use_r = R is not None and frac is None
        if R is not None and not use_r:  # the edge lies outside the inner pass
            m.aperture = False
        fit_p = p if use_r else p[:4]
        # lazy: scipy.optimize loads only when a camera is calibrated, not with clfza.camera
        from scipy.optimize import least_squares

        res = least_squares(lambda z, m=m: m.solve(z)[1], fit_p, method="trf",
                            bounds=(lo[:fit_p.size], hi[:fit_p.size]),
                            x_scale=np.array([0.1, 0.1, 1e-3 * q, 0.1, 0.5][:fit_p.size]),
                            diff_step=1e-6)
        p[:fit_p.size] = res.x
    coef, resid = m.solve(p)
    dof = max(resid.size - p.size - coef.size, 1)
    s2 = float(resid @ resid) / dof
    try:
        cov = np.linalg.pinv(res.jac.T @ res.jac) * s2
        std = np.sqrt(np.clip(np.diag(cov), 0.0, None))
    except np.linalg.LinAlgError:
        std = np.full(p.size, np.nan)
    pattern = coef[1:] @ m.columns(p)[1:]
    return {"p": p, "std": std, "coef": coef, "residual_rms": math.sqrt(s2),
            "signal_rms": float(np.std(pattern)), "success": bool(res.success),
            "nfev": int(res.nfev), "n": int(resid.size)}


# ----------------------------------------------------------------------------------------
# 5. the whole calibration
# ----------------------------------------------------------------------------------------
def _locate(img: np.ndarray, timings: dict) -> tuple[tuple[float, float], float | None,
                                                     float]:
    """Centre, aperture radius and coarse ``r1'^2``, all in pixels (stages 1-3)."""
    t0 = time.perf_counter()
    center = find_center(img)
    ny, nx = img.shape
    if not (0 <= center[0] <= ny - 1 and 0 <= center[1] <= nx - 1):
        raise ClfzaError("no zone pattern found: the frame has no point-symmetric centre")
    R = find_aperture(img, center)
    timings["centre_aperture_s"] = time.perf_counter() - t0
    t0 = time.perf_counter()
    reach = min(center[0], center[1], ny - 1 - center[0], nx - 1 - center[1])
    reach = reach if R is None else min(reach, R - 3.0)
    if reach < 16:
        raise ClfzaError(f"no zone pattern found: the pattern's centre ({center[0]:.1f}, "
                         f"{center[1]:.1f}) px is too close to the frame's edge")
    q, significance = coarse_r1p2(img, center, reach)
    timings["periodogram_s"] = time.perf_counter() - t0
    if significance < 8.0:
        raise ClfzaError("no zone pattern found: the radial profile has no period in r^2 "
                         f"(peak only {significance:.1f}x the spectrum's median)")
    return center, R, q


def _mask_type(coef: np.ndarray, orders: tuple[int, ...], mask: str,
               warnings: list[str]) -> tuple[str, float, float]:
    """Mask kind, ``|a3| / |a1|`` and phase from the fitted series (Eqs. 1, 7, 9).

    ``a_1 cos t + b_1 sin t = |A| cos(t + phase)`` gives ``phase = atan2(-b_1, a_1)``.
    """
    first = len(coef) - 2 * len(orders)
    amp = coef[first::2] - 1j * coef[first + 1::2]
    ratio = float(abs(amp[1]) / abs(amp[0])) if len(orders) > 1 else 0.0
    phase = float(np.angle(amp[0]))
    if mask == "auto":
        mask = "fza" if ratio >= 0.5 * (HARMONIC_FZA + HARMONIC_GZP) else "gzp"
        if HARMONIC_GZP < ratio < HARMONIC_FZA:
            warnings.append(f"the mask type is ambiguous (|a3|/|a1| = {ratio:.3f}: binary "
                            "FZA 1/3, sinusoidal GZP 0); pass mask='fza' or 'gzp'")
    return mask, ratio, phase


def calibrate(image, pitch: float, *, z1: float | None = None, z2: float | None = None,
              r1: float | None = None, mask: str = "auto", bin: int = 1,
              samples: int = 30000, seed: int = 0) -> Calibration:
    """Fit an FZA camera to a point-source capture or a PSF image (module docstring).

    Parameters
    ----------
    image : array (H, W) or (H, W, C)
        The frame (dark-subtracted if possible); colour channels are summed.
    pitch : float
        Pixel pitch of ``image`` in mm.
    z1, z2, r1 : float, optional
        Source and mask distances (mm) and the mask's ``r1``; only checked and passed on
        to :meth:`Calibration.camera` (``R = R' / (1 + z2/z1)``, Methods).
    mask : {"auto", "fza", "gzp"}
        Mask type, or "auto" to decide from the third harmonic (Eq. 7).
    bin : int
        Sum ``bin x bin`` pixel blocks before fitting (faster on large frames).
    samples : int
        Pixels drawn at random for the least-squares refinement.
    seed : int
        Seed of that draw.

    Returns
    -------
    Calibration
        With ``warnings`` (and ``confident`` False) when the fit is not trustworthy.
    """
    pitch = positive("pitch", pitch)
    for name, v in (("z1", z1), ("z2", z2), ("r1", r1)):
        if v is not None:
            positive(name, v, allow_inf=name == "z1")
    if mask not in MASK_CHOICES:
        raise ClfzaError(f"mask must be one of {MASK_CHOICES}, got {mask!r}")
    shape = tuple(int(n) for n in np.shape(image)[:2])
    b = positive_int("bin", bin)
    img = _prepare(image, b)
    timings: dict = {}
    t_all = time.perf_counter()
    center, R, q = _locate(img, timings)
    orders = (1,) if mask == "gzp" else FZA_ORDERS
    t0 = time.perf_counter()
    fit = refine(img, center, q, R, orders, samples=positive_int("samples", samples, 1000),
                 seed=seed)
    timings["refine_s"] = time.perf_counter() - t0
    timings["total_s"] = time.perf_counter() - t_all
    return _result(fit, orders, mask, pitch, shape, b, R is not None, timings)


def _result(fit: dict, orders: tuple[int, ...], mask: str, pitch: float,
            shape: tuple[int, int], b: int, has_R: bool, timings: dict) -> Calibration:
    """Turn a refinement (binned pixels) into a :class:`Calibration` (mm, input pixels)."""
    p, std, coef = fit["p"], fit["std"], fit["coef"]
    warnings: list[str] = []
    kind, ratio, phase = _mask_type(coef, orders, mask, warnings)
    snr = fit["signal_rms"] / max(fit["residual_rms"], 1e-300)
    if snr < 1.0:
        warnings.append(f"the fit residual ({fit['residual_rms']:.3g} rms) is as large as the "
                        f"zone signal ({fit['signal_rms']:.3g} rms): the frame is not (only) a "
                        "zone pattern, or too noisy (average frames, or bin them)")
    if not fit["success"]:
        warnings.append("the least-squares refinement did not converge")
    pb = pitch * b
    first = len(coef) - 2 * len(orders)
    a1 = abs(complex(coef[first], coef[first + 1]))
    if not np.all(np.isfinite(std)) or std[2] > 1e-3 * p[2] or max(std[:2]) > 0.25:
        warnings.append(f"the parameters are poorly determined (r1'^2 +/- "
                        f"{100 * std[2] / p[2]:.2g}%, centre +/- {max(std[:2]) * b:.2g} px)")
    return Calibration(
        r1_shadow_squared=float(p[2] * pb**2), r1_shadow_squared_std=float(std[2] * pb**2),
        center=(float(p[0] * b + (b - 1) / 2), float(p[1] * b + (b - 1) / 2)),
        center_std=(float(std[0] * b), float(std[1] * b)),
        R_shadow=float(p[4] * pb) if has_R else None,
        R_shadow_std=float(std[4] * pb) if has_R else None,
        mask=kind, harmonic_ratio=ratio, phase=phase,
        phase_std=float(fit["residual_rms"] / max(a1, 1e-300) * math.sqrt(2 / fit["n"])),
        amplitude=float(a1), mean=float(coef[1] if has_R else coef[0]),
        background=float(coef[0] if has_R else 0.0), fill=float(p[3]),
        residual_rms=float(fit["residual_rms"]), signal_rms=float(fit["signal_rms"]),
        pitch=pitch, shape=shape, bin=b, warnings=warnings, timings=timings)


def _toml_value(v) -> str:
    if isinstance(v, str):
        return '"' + v.replace("\\", "\\\\").replace('"', '\\"') + '"'
    if isinstance(v, (list, tuple)):
        return "[" + ", ".join(_toml_value(x) for x in v) + "]"
    if isinstance(v, (int, np.integer)) and not isinstance(v, bool):
        return str(int(v))
    f = float(v)
    return "inf" if math.isinf(f) else repr(f)


def camera_toml(cal: Calibration, z1: float, z2: float, r1: float | None = None,
                name: str = "calibrated", comment: str = "") -> str:
    """The calibrated camera as TOML text that :meth:`Camera.from_toml` reads.

    Writes ``r1_shadow_squared`` (the measured ``r1'^2``), ``R = R' / (1 + z2/z1)``,
    ``mask``, ``phase``, ``pitch``, ``shape`` and ``mask_center``; ``r1`` is the given one
    or ``r1' / (1 + z2/z1)`` (Methods).
    """
    cam = cal.camera(z1, z2, r1, name)
    keys = {"name": cam.name, "pitch": cam.pitch, "shape": list(cam.shape), "r1": cam.r1,
            "z1": cam.z1, "z2": cam.z2, "R": cam.R, "mask": cam.mask, "phase": cam.phase,
            "r1_shadow_squared": cal.r1_shadow_squared,
            "mask_center": [round(c, 4) for c in cam.mask_center]}
    lines = [f"# {c}" for c in comment.splitlines()]
    lines += [f"# {s}" for s in cal.summary_lines()] + ["[camera]"]
    lines += [f"{k} = {_toml_value(v)}" for k, v in keys.items() if v is not None]
    text = "\n".join(lines) + "\n"
    Camera.from_dict(tomllib.loads(text), source="calibrated camera")  # round trip
    return text
