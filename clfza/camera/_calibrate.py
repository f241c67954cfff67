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
from collections.abc import Callable
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
        Aperture radius ``R'`` of the shadow in mm; None when the frame does not determine
        it (``undetermined["R_shadow"]`` says why: no edge, or too little of it, on the
        sensor).
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
    undetermined : dict
        Parameters the frame does not determine, each with the reason (``"R_shadow"``:
        the aperture's shadow reaches past the sensor; ``"fill"``: the fill factor ran to a
        bound). They carry no value and no error bar.
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
    undetermined: dict = field(default_factory=dict)

    @property
    def confident(self) -> bool:
        """True when no warning was raised."""
        return not self.warnings

    @property
    def mask_center(self) -> tuple[float, float]:
        """Centre offset (rows, cols) in pixels from the sensor pixel ``(N // 2)``."""
        return (self.center[0] - self.shape[0] // 2, self.center[1] - self.shape[1] // 2)

    def camera(self, z1: float, z2: float, r1: float | None = None,
               name: str = "calibrated", R: float | None = None) -> Camera:
        """The calibrated :class:`Camera` for a point source at ``z1``, mask at ``z2``.

        ``R = R' / (1 + z2/z1)`` and, unless given, ``r1 = r1' / (1 + z2/z1)`` (Methods).
        When the frame does not determine ``R'`` (:attr:`undetermined`), the camera gets the
        given ``R`` (mm, the mask's aperture radius) or none at all, never a fitted value.
        """
        scale = 1.0 + positive("z2", z2) / positive("z1", z1, allow_inf=True)
        r1p = math.sqrt(self.r1_shadow_squared)
        if self.R_shadow is not None:
            R = self.R_shadow / scale
        elif R is not None:
            R = positive("R", R)
        return Camera(pitch=self.pitch, shape=self.shape,
                      r1=r1p / scale if r1 is None else r1, z1=z1, z2=z2, R=R,
                      mask=self.mask, phase=self.phase, r1_shadow=r1p,
                      mask_center=self.mask_center, name=name)

    def to_dict(self) -> dict:
        d = asdict(self)
        d.update(center=list(self.center), center_std=list(self.center_std),
                 shape=list(self.shape), mask_center=list(self.mask_center),
                 confident=self.confident, undetermined=dict(self.undetermined))
        return d

    def summary_lines(self) -> list[str]:
        """One line per fitted parameter, with its uncertainty."""
        q, dq = self.r1_shadow_squared, self.r1_shadow_squared_std
        (cy, cx), (sy, sx) = self.center, self.center_std
        dy, dx = self.mask_center
        rr = (f"{self.R_shadow:.4f} +/- {self.R_shadow_std:.4f} mm" if self.R_shadow
              is not None else "not determined: "
              + self.undetermined.get("R_shadow", "no aperture edge on the sensor"))
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


def find_aperture(img: np.ndarray, center: tuple[float, float], q: float | None = None
                  ) -> float | None:
    """Radius (px) where the local mean of the pattern falls to the background, or None.

    The local mean at radius ``r`` is the mean over the annulus of one whole zone period,
    ``|r'^2 - r^2| <= q`` with ``q = r1'^2`` in px^2 (Eq. 1: the pattern's period in
    ``s = r^2`` is ``2 q``), so the zones average out at every radius however coarse they are;
    without ``q`` the rings are averaged over 9 px in ``r``. The edge counts when the lit
    level inside exceeds the dark level outside by at least 0.4 times the pattern's standard
    deviation; an annulus needs 40 pixels on the sensor.
    """
    r = _radii(img.shape, center)
    inner = int(0.5 * min(center[0], center[1], img.shape[0] - 1 - center[0],
                          img.shape[1] - 1 - center[1]))
    if inner < 8:
        return None
    if q is None:
        rb = np.floor(r).astype(np.int64)
        cnt = np.bincount(rb.ravel())
        prof = np.bincount(rb.ravel(), img.ravel())
        k = np.ones(9)
        n_win = np.convolve(cnt, k, mode="same")
        ms = np.convolve(prof, k, mode="same") / np.maximum(n_win, 1)
    else:
        sb = np.floor(r * r).astype(np.int64).ravel()
        c_n = np.concatenate([[0.0], np.cumsum(np.bincount(sb))])
        c_v = np.concatenate([[0.0], np.cumsum(np.bincount(sb, img.ravel()))])
        rr = np.arange(int(math.ceil(float(r.max()))) + 1) + 0.5
        lo = np.clip(np.floor(rr * rr - q).astype(np.int64), 0, c_n.size - 1)
        hi = np.clip(np.floor(rr * rr + q).astype(np.int64) + 1, 0, c_n.size - 1)
        n_win = c_n[hi] - c_n[lo]
        ms = (c_v[hi] - c_v[lo]) / np.maximum(n_win, 1)
    ok = n_win >= 40
    if not ok[inner:].any():
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
    return float(e - 1 + f + 0.5)  # samples sit at the bins' centres e + 0.5


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
           orders: tuple[int, ...], *, samples: int = 30000, seed: int = 0,
           progress: Callable[[str, int], None] | None = None) -> dict:
    """Least-squares fit of centre, ``q = r1'^2`` (px^2), fill factor and ``R'`` (px).

    Two passes: the inner half of the pattern (few zones, wide basin), then all sampled
    pixels. Returns the parameters, their standard errors from the Jacobian
    (``cov = s^2 (J^T J)^-1``), the linear amplitudes, the residual statistics and the
    bounds ``lo``, ``hi`` of the parameters (``R'`` at most the farthest sensor corner's
    distance plus 2 px). ``progress(stage, evaluations)`` is called at every model
    evaluation.
    """
    ny, nx = img.shape
    far = float(_radii(img.shape, center).max()) + 2.0
    p = np.array([center[0], center[1], q, 0.5] + ([min(R, far)] if R is not None else []))
    lo = np.array([-0.5, -0.5, 0.2 * q, 0.0] + ([1.0] if R is not None else []))
    hi = np.array([ny - 0.5, nx - 0.5, 5.0 * q, 1.5] + ([far] if R is not None else []))
    count = [0]
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

        stage = "fit (inner half)" if frac is not None else "fit (all)"

        def resid(z, m=m, stage=stage):
            count[0] += 1
            if progress is not None:
                progress(stage, count[0])
            return m.solve(z)[1]

        res = least_squares(resid, fit_p, method="trf",
                            bounds=(lo[:fit_p.size], hi[:fit_p.size]),
                            x_scale=np.array([0.1, 0.1, 1e-3 * q, 0.1, 0.5][:fit_p.size]),
                            diff_step=1e-6)
        p[:fit_p.size] = res.x
    coef, rv = m.solve(p)
    dof = max(rv.size - p.size - coef.size, 1)
    s2 = float(rv @ rv) / dof
    try:
        jac = np.asarray(res.jac)
        inv = np.linalg.pinv(jac.T @ jac)
        cov_white = inv * s2
        meat = (jac * (rv * rv)[:, None]).T @ jac * (rv.size / dof)
        cov = inv @ meat @ inv
        std = np.sqrt(np.clip(np.diag(cov), 0.0, None))
        std_white = np.sqrt(np.clip(np.diag(cov_white), 0.0, None))
    except np.linalg.LinAlgError:
        std = std_white = np.full(p.size, np.nan)
    cols = m.columns(p)
    try:  # the linear amplitudes' covariance, residual-robust like the parameters'
        bread = np.linalg.inv(cols @ cols.T)
        cov_coef = bread @ ((cols * (rv * rv)) @ cols.T) @ bread * (rv.size / dof)
        # plus the nonlinear parameters' share, through the amplitudes' dependence on them
        # (variable projection: c = c(p)); the phase leans on r1'^2 like an intercept on
        # a slope
        dc = np.empty((coef.size, p.size))
        for i in range(p.size):
            h = 1e-6 * max(1.0, abs(p[i]))
            dp = p.copy()
            dp[i] += h
            dc[:, i] = (m.solve(dp)[0] - coef) / h
        cov_coef = cov_coef + dc @ cov @ dc.T
    except (np.linalg.LinAlgError, NameError):
        cov_coef = np.full((coef.size, coef.size), np.nan)
    pattern = coef[1:] @ cols[1:]
    return {"p": p, "std": std, "coef": coef, "residual_rms": math.sqrt(s2),
            "signal_rms": float(np.std(pattern)), "success": bool(res.success),
            "nfev": int(res.nfev), "n": int(rv.size), "lo": lo, "hi": hi,
            "std_white": std_white, "cov_coef": cov_coef}


# ----------------------------------------------------------------------------------------
# 5. the whole calibration
# ----------------------------------------------------------------------------------------
def _locate(img: np.ndarray, timings: dict) -> tuple[tuple[float, float], float | None,
                                                     float]:
    """Centre, aperture radius and coarse ``r1'^2``, all in pixels (stages 1-3).

    ``r1'^2`` is measured first on the largest disc about the centre inside the frame, so
    that the aperture's edge is looked for with the zones averaged over a whole period
    (:func:`find_aperture`); an edge inside that disc then narrows the periodogram to it.
    """
    t0 = time.perf_counter()
    center = find_center(img)
    ny, nx = img.shape
    if not (0 <= center[0] <= ny - 1 and 0 <= center[1] <= nx - 1):
        raise ClfzaError("no zone pattern found: the frame has no point-symmetric centre")
    reach = min(center[0], center[1], ny - 1 - center[0], nx - 1 - center[1])
    if reach < 16:
        raise ClfzaError(f"no zone pattern found: the pattern's centre ({center[0]:.1f}, "
                         f"{center[1]:.1f}) px is too close to the frame's edge")
    timings["centre_s"] = time.perf_counter() - t0
    t0 = time.perf_counter()
    q, significance = coarse_r1p2(img, center, reach)
    R = find_aperture(img, center, q)
    if R is not None and R - 3.0 < reach:
        if R - 3.0 < 16:
            raise ClfzaError(f"no zone pattern found: the aperture's shadow ({R:.1f} px) is "
                             "too small to hold zones")
        q, significance = coarse_r1p2(img, center, R - 3.0)
    timings["periodogram_aperture_s"] = time.perf_counter() - t0
    if significance < 8.0:
        raise ClfzaError("no zone pattern found: the radial profile has no period in r^2 "
                         f"(peak only {significance:.1f}x the spectrum's median)")
    return center, R, q


#: The aperture's shadow ``R'`` is measured only when at least this fraction of its edge (a
#: circle about the pattern's centre) lies on the sensor, :data:`EDGE_MARGIN` px inside its
#: border; less, and a handful of corner pixels would decide it (docs/measurements.md,
#: clfza.camera._calibrate).
ARC_MIN = 0.02
#: pixels by which the edge must lie inside the sensor's border to count as on the sensor
EDGE_MARGIN = 3.0


def edge_on_sensor(shape: tuple[int, int], center: tuple[float, float], radius: float,
                   margin: float = EDGE_MARGIN) -> float:
    """Fraction of the circle of ``radius`` px about ``center`` (row, col) that lies at least
    ``margin`` px inside a ``shape`` sensor (0 when the circle is off the sensor)."""
    t = np.linspace(0.0, 2.0 * np.pi, 1440, endpoint=False)
    y = center[0] + radius * np.sin(t)
    x = center[1] + radius * np.cos(t)
    inside = ((y >= margin - 0.5) & (y <= shape[0] - 0.5 - margin)
              & (x >= margin - 0.5) & (x <= shape[1] - 0.5 - margin))
    return float(np.mean(inside))


def _edge_reason(shape: tuple[int, int], center: tuple[float, float], R: float | None,
                 pitch: float) -> str | None:
    """Why the frame cannot determine ``R'`` (None when it can): no edge found, or too little
    of the edge on the sensor (:data:`ARC_MIN`). Lengths in px of the fitted frame, ``pitch``
    its pitch in mm."""
    far = float(_radii(shape, center).max())
    if R is None:
        return (f"no aperture edge on the sensor: the aperture's shadow reaches past the "
                f"sensor (the farthest corner is {far * pitch:.4g} mm from the centre)")
    arc = edge_on_sensor(shape, center, R)
    if arc < ARC_MIN:
        return (f"the aperture's shadow reaches past the sensor: an edge seen at "
                f"{R * pitch:.4g} mm has {100 * arc:.2g}% of its circle on the sensor (a "
                f"measurable one >= {100 * ARC_MIN:g}%; the farthest corner is "
                f"{far * pitch:.4g} mm from the centre)")
    return None


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
              samples: int = 30000, seed: int = 0,
              progress: Callable[[str, int], None] | None = None) -> Calibration:
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
    progress : callable, optional
        ``progress(stage, evaluations)``, called as the work goes (a stage's name and the
        model evaluations of the fit so far), e.g. to drive a progress bar.

    Returns
    -------
    Calibration
        With ``warnings`` (and ``confident`` False) when the fit is not trustworthy, and
        ``undetermined`` naming the parameters the frame does not determine: ``R'`` when
        less than :data:`ARC_MIN` of the aperture's edge lies on the sensor or its fit runs
        to the farthest corner (it is then left out of the fit and reported as None, not as
        a value with an error bar that the fit's curvature would wrongly make small).

    Examples
    --------
    >>> cal = calibrate(frame, 0.0055, z1=250.0, z2=2.0)  # doctest: +SKIP
    >>> cal.r1_shadow_squared, cal.undetermined.get("R_shadow")  # doctest: +SKIP
    """
    pitch = positive("pitch", pitch)
    for name, v in (("z1", z1), ("z2", z2), ("r1", r1)):
        if v is not None:
            positive(name, v, allow_inf=name == "z1")
    if mask not in MASK_CHOICES:
        raise ClfzaError(f"mask must be one of {MASK_CHOICES}, got {mask!r}")
    shape = tuple(int(n) for n in np.shape(image)[:2])
    b = positive_int("bin", bin)
    n_samples = positive_int("samples", samples, 1000)
    img = _prepare(image, b)
    timings: dict = {}
    t_all = time.perf_counter()
    say = progress or (lambda stage, n: None)
    say("locate", 0)
    center, R, q = _locate(img, timings)
    orders = (1,) if mask == "gzp" else FZA_ORDERS
    pb = pitch * b
    undetermined: dict[str, str] = {}
    why = _edge_reason(img.shape, center, R, pb)
    t0 = time.perf_counter()
    fit = refine(img, center, q, None if why else R, orders, samples=n_samples, seed=seed,
                 progress=progress)
    if why is None:
        p, hi = fit["p"], fit["hi"]
        if p[4] >= hi[4] - 0.5:
            why = (f"the fit of R' ran to its bound, the farthest sensor corner "
                   f"({(hi[4] - 2.0) * pb:.4g} mm): the aperture's shadow reaches past the "
                   "sensor")
        else:
            why = _edge_reason(img.shape, (p[0], p[1]), p[4], pb)
        if why is not None:  # refit without the edge that the frame does not hold
            why += f"; its fit ({p[4] * pb:.4g} mm) is not a measurement"
            fit = refine(img, (p[0], p[1]), p[2], None, orders, samples=n_samples,
                         seed=seed, progress=progress)
    if why is not None:
        undetermined["R_shadow"] = why
    timings["refine_s"] = time.perf_counter() - t0
    timings["total_s"] = time.perf_counter() - t_all
    return _result(fit, orders, mask, pitch, shape, b, why is None and R is not None,
                   timings, undetermined)


def _bounds(fit: dict, undetermined: dict[str, str], warnings: list[str]) -> None:
    """Parameters whose fit ended at a bound of the search: ``r1'^2`` and the centre make the
    calibration untrustworthy (a warning), the fill factor (not written to the camera) is
    only named undetermined."""
    p, lo, hi = fit["p"], fit["lo"], fit["hi"]
    at = [bool(p[i] <= lo[i] + 1e-6 * max(1.0, abs(lo[i]))
               or p[i] >= hi[i] - 1e-6 * max(1.0, abs(hi[i]))) for i in range(4)]
    if at[0] or at[1]:
        warnings.append("the pattern's centre ran to the frame's edge: it is not on the frame")
    if at[2]:
        warnings.append("r1'^2 ran to a bound of its search (0.2x or 5x the periodogram's "
                        "estimate): the zone period is not determined")
    if at[3]:
        undetermined["fill"] = (f"the pixel fill factor ran to its bound ({p[3]:.3g}); it is "
                                "a nuisance parameter of the fit, not written to the camera")


def _phase_std(fit: dict, first: int, a1: float) -> float:
    """Standard error of the phase ``atan2(-b_1, a_1)`` from the amplitudes' (robust)
    covariance: ``d phase = (b_1 da_1 - a_1 db_1) / |A|^2``."""
    a, b = fit["coef"][first], fit["coef"][first + 1]
    g = np.array([b, -a]) / max(a1 * a1, 1e-300)
    c = fit["cov_coef"][first:first + 2, first:first + 2]
    v = float(g @ c @ g)
    if not math.isfinite(v):
        return float(fit["residual_rms"] / max(a1, 1e-300) * math.sqrt(2 / fit["n"]))
    return math.sqrt(max(v, 0.0))


def _edge_interval(R: float, std: float, q: float, phase: float, mask: str
                   ) -> tuple[float, float]:
    """``R'`` and its error bar (px). A binary mask's edge that falls in a dark zone
    (``cos(pi R'^2 / q + phase) < 0``, Eq. 1) leaves no trace: the edge can sit anywhere in
    that zone or cut the next bright one by a pixel, so ``R'`` is the zone's middle and its
    error bar half the zone's width plus 2 px (at least the fit's standard error); elsewhere
    the fit's value and standard error."""
    theta = math.pi * R * R / q + phase
    if mask != "fza" or math.cos(theta) >= 0:
        return float(R), float(std)
    k = math.floor((theta - 0.5 * math.pi) / (2 * math.pi))
    t0 = 0.5 * math.pi + 2 * math.pi * k  # the dark zone is t0 < theta < t0 + pi
    r0 = math.sqrt(max(t0 - phase, 0.0) * q / math.pi)
    r1 = math.sqrt(max(t0 + math.pi - phase, 0.0) * q / math.pi)
    return 0.5 * (r0 + r1), max(0.5 * (r1 - r0) + 2.0, float(std))


def _result(fit: dict, orders: tuple[int, ...], mask: str, pitch: float,
            shape: tuple[int, int], b: int, has_R: bool, timings: dict,
            undetermined: dict[str, str] | None = None) -> Calibration:
    """Turn a refinement (binned pixels) into a :class:`Calibration` (mm, input pixels)."""
    p, std, coef = fit["p"], fit["std"], fit["coef"]
    warnings: list[str] = []
    undetermined = dict(undetermined or {})
    kind, ratio, phase = _mask_type(coef, orders, mask, warnings)
    _bounds(fit, undetermined, warnings)
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
    R_px, R_std_px = (_edge_interval(p[4], std[4], p[2], phase, kind) if has_R
                      else (math.nan, math.nan))
    return Calibration(
        r1_shadow_squared=float(p[2] * pb**2), r1_shadow_squared_std=float(std[2] * pb**2),
        center=(float(p[0] * b + (b - 1) / 2), float(p[1] * b + (b - 1) / 2)),
        center_std=(float(std[0] * b), float(std[1] * b)),
        R_shadow=float(R_px * pb) if has_R else None,
        R_shadow_std=float(R_std_px * pb) if has_R else None,
        mask=kind, harmonic_ratio=ratio, phase=phase,
        phase_std=_phase_std(fit, first, a1),
        amplitude=float(a1), mean=float(coef[1] if has_R else coef[0]),
        background=float(coef[0] if has_R else 0.0), fill=float(p[3]),
        residual_rms=float(fit["residual_rms"]), signal_rms=float(fit["signal_rms"]),
        pitch=pitch, shape=shape, bin=b, warnings=warnings, timings=timings,
        undetermined=undetermined)


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
                name: str = "calibrated", comment: str = "", R: float | None = None) -> str:
    """The calibrated camera as TOML text that :meth:`Camera.from_toml` reads.

    Writes ``r1_shadow_squared`` (the measured ``r1'^2``), ``R = R' / (1 + z2/z1)``,
    ``mask``, ``phase``, ``pitch``, ``shape`` and ``mask_center``; ``r1`` is the given one
    or ``r1' / (1 + z2/z1)`` (Methods). When the frame does not determine ``R'``, ``R`` is
    the given one or left out (:meth:`Calibration.camera`).
    """
    cam = cal.camera(z1, z2, r1, name, R=R)
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
