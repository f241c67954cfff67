"""Scene -> raw frame: pinhole projection (Eq. 2), linear convolution with the mask's shadow
(Eq. 14), optional Fresnel diffraction of the mask (Eq. 8), and sensor noise.

The simulator is independent of the reconstruction operator (no inverse crime): it convolves
linearly with the *sampled, finite* mask (binary or sinusoidal, with its aperture) on a grid
large enough that nothing wraps, where ``K`` is a periodic transfer-function model.

Units. The noise-free raw frame is ``conv(O, T)`` with ``O`` the sensor-plane object in [0, 1].
The DC-free observation in the units of ``K`` (the paper's reference scaling) is
``y = (frame - mean(frame)) * 2 p^2 / r1'^2``. Gaussian noise "of variance 0.01", as in the
paper's Fig. 7, is that observation's; the physical noises (photon, read, quantisation,
saturation) act on the raw frame first, and the Gaussian term is then added to the raw frame in
frame units, so that ``y = (frame - mean(frame)) * frame_scale`` for every noise model.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
import scipy.fft
from skimage.transform import resize

from .camera import Camera, zone_plate
from .errors import ClfzaError, finite_image, in_range, nonnegative, positive, positive_int
from .io import LIMIT_ENV, check_memory


@dataclass(frozen=True)
class Noise:
    """Noise model of a simulated frame.

    Parameters
    ----------
    gaussian_var : float
        Variance of zero-mean Gaussian noise on the DC-free observation ``y`` (the paper's
        Fig. 7 uses 0.01); 0 disables it. It is added to the raw frame in frame units
        (std ``sqrt(var) / frame_scale``), so the frame written to a file carries it too.
    photons : float or None
        Photo-electrons at the frame's brightest pixel (full well x exposure); Poisson noise
        when given.
    read_noise : float
        Read-noise standard deviation in electrons (needs ``photons``).
    bit_depth : int or None
        Quantise to this many bits (8..16), full scale = ``full_well``.
    exposure : float
        Brightest pixel as a fraction of full scale; above 1 the frame saturates.
    seed : int or None
        Seed of the random generator (reproducible frames).
    """

    gaussian_var: float = 0.0
    photons: float | None = None
    read_noise: float = 0.0
    bit_depth: int | None = None
    exposure: float = 0.9
    seed: int | None = 0

    def __post_init__(self) -> None:
        nonnegative("gaussian_var", self.gaussian_var)
        if self.photons is not None:
            positive("photons", self.photons)
        nonnegative("read_noise", self.read_noise)
        if self.read_noise and self.photons is None:
            raise ClfzaError("read_noise needs photons (the electron scale) to be set")
        if self.bit_depth is not None:
            b = positive_int("bit_depth", self.bit_depth, 1)
            if not 1 <= b <= 32:
                raise ClfzaError(f"bit_depth must be in [1, 32], got {b}")
        in_range("exposure", self.exposure, 1e-6, 1e3)
        if self.photons is not None and self.photons > 1e15:
            raise ClfzaError(f"photons must be <= 1e15 (Poisson counts beyond that are not "
                             f"representable exactly), got {self.photons!r}")
        if self.seed is not None:
            positive_int("seed", self.seed, 0)

    @property
    def is_clean(self) -> bool:
        return (self.gaussian_var == 0 and self.photons is None and self.bit_depth is None
                and self.exposure <= 1)


@dataclass
class Measurement:
    """A simulated shot.

    Attributes
    ----------
    frame : ndarray
        Raw sensor frame (digital numbers when quantised, else electrons or relative units).
    y : ndarray
        DC-free observation in the units of ``K`` (what the solvers take), noise included.
    truth : ndarray
        The sensor-plane object ``O`` on the sensor grid (Eq. 14): the reconstruction target.
    camera : Camera
    clean_y : ndarray
        The noise-free observation.
    frame_scale : float
        Multiply ``frame - mean(frame)`` by this to get ``y`` (before the Gaussian term).
    info : dict
        Parameters and statistics of the simulation.
    """

    frame: np.ndarray
    y: np.ndarray
    truth: np.ndarray
    camera: Camera
    clean_y: np.ndarray
    frame_scale: float
    info: dict = field(default_factory=dict)

    def frame_to_y(self, frame: np.ndarray) -> np.ndarray:
        """DC-free observation of a raw frame with this simulation's known gain."""
        f = np.asarray(frame, dtype=np.float64)
        axes = (0, 1)
        return (f - f.mean(axis=axes, keepdims=True)) * self.frame_scale


# ----------------------------------------------------------------------------------------
# projection (Eq. 2)
# ----------------------------------------------------------------------------------------
def as_scene(image, name: str = "scene") -> np.ndarray:
    """Validate a scene: grey (H, W) or colour (H, W, 3) real data, scaled to [0, 1] when it
    is an integer image."""
    a = np.asarray(image)
    kind = a.dtype.kind
    maxv = np.iinfo(a.dtype).max if kind in "ui" else None
    a = finite_image(name, a)
    if a.ndim == 3 and a.shape[2] not in (1, 3):
        raise ClfzaError(f"{name} must be grey (H, W) or RGB (H, W, 3), got shape {a.shape}")
    if a.ndim == 3 and a.shape[2] == 1:
        a = a[..., 0]
    if maxv is not None:
        a = a / maxv
    if a.min() < 0:
        raise ClfzaError(f"{name} has negative intensities (min {a.min():.3g}); intensities "
                         "are >= 0")
    if a.max() > MAX_SCENE_VALUE:
        raise ClfzaError(f"{name}'s values reach {a.max():.3g}: resampling, the convolution "
                         f"and y = K o would overflow float64 (limit {MAX_SCENE_VALUE:.0e}); "
                         "scale the scene to [0, 1]")
    return a


def project_scene(scene, camera: Camera, object_width: float,
                  center: tuple[float, float] = (0.0, 0.0)) -> tuple[np.ndarray, int]:
    """Pinhole projection of a scene onto the sensor-plane grid (Eq. 2).

    The scene, ``object_width`` mm wide at distance ``z1`` and centred at ``center`` (x, y in
    mm, object plane), images to ``M * object_width`` on the sensor, rotated by 180 degrees
    (the chief ray through the mask centre inverts it). It is resampled with an anti-alias
    filter to the pixel pitch.

    Returns
    -------
    (O, margin)
        ``O``: the object on a grid that contains the sensor and the whole image, with the
        sensor in its centre; ``margin``: rows/cols of extra grid on each side (0 when the
        image fits on the sensor).
    """
    s = as_scene(scene)
    if math.isinf(camera.z1):
        raise ClfzaError("a scene at z1 = inf images to a point; give a finite z1")
    w = positive("object_width", object_width)
    M = camera.magnification
    h, wpx = s.shape[:2]
    width_px = M * w / camera.pitch
    height_px = width_px * h / wpx
    ny, nx = max(1, round(height_px)), max(1, round(width_px))
    if ny > 16384 or nx > 16384:
        raise ClfzaError(f"the projected scene would be {ny}x{nx} pixels; use a smaller "
                         "object_width or a larger z1")

    shape = (ny, nx) + s.shape[2:]
    img = resize(s, shape, order=1, anti_aliasing=(ny < h or nx < wpx), preserve_range=True)
    img = np.clip(img, 0.0, None)[::-1, ::-1]  # pinhole inversion
    sy, sx = camera.shape
    # image centre on the sensor: -M * center (inverted)
    cy = sy // 2 - round(M * center[1] / camera.pitch)
    cx = sx // 2 - round(M * center[0] / camera.pitch)
    margin = max(0, ny // 2 + 1 - cy, cy + (ny - ny // 2) - sy,
                 nx // 2 + 1 - cx, cx + (nx - nx // 2) - sx)
    check_simulation_memory(camera, margin, 1 if s.ndim == 2 else s.shape[2])
    big = np.zeros((sy + 2 * margin, sx + 2 * margin) + s.shape[2:])
    y0 = cy + margin - ny // 2
    x0 = cx + margin - nx // 2
    big[y0:y0 + ny, x0:x0 + nx] = img
    return big, margin


def point_sources(camera: Camera, points) -> np.ndarray:
    """Sensor-plane object of point sources at object-plane positions (Eq. 2).

    ``points``: iterable of ``(x_mm, y_mm, intensity)``; a point at ``(x, y)`` lands at
    ``(-M x, -M y)`` on the sensor (axes: x along columns, y along rows, origin at pixel
    ``(N // 2)``), split bilinearly between the four nearest pixels.
    """
    ny, nx = camera.shape
    out = np.zeros((ny, nx))
    M = camera.magnification
    for x, y, a in points:
        px = nx // 2 - M * float(x) / camera.pitch
        py = ny // 2 - M * float(y) / camera.pitch
        i0, j0 = math.floor(py), math.floor(px)
        fy, fx = py - i0, px - j0
        for di, wy in ((0, 1 - fy), (1, fy)):
            for dj, wx in ((0, 1 - fx), (1, fx)):
                i, j = i0 + di, j0 + dj
                if 0 <= i < ny and 0 <= j < nx:
                    out[i, j] += float(a) * wy * wx
    return out


# ----------------------------------------------------------------------------------------
# the mask's shadow and its diffraction (Eq. 8)
# ----------------------------------------------------------------------------------------
def shadow_pattern(camera: Camera, shape: tuple[int, int], diffraction: bool = False
                   ) -> np.ndarray:
    """The mask's intensity shadow on the sensor for a point at ``z1`` (centred grid).

    Geometric: the mask at ``r1' = (1 + z2/z1) r1`` with aperture ``R'``. With
    ``diffraction``, the amplitude ``sqrt(T)`` is Fresnel-propagated over ``z2`` at the
    camera's wavelength (Fresnel scaling theorem for a point source at ``z1``: propagate the
    magnified mask over ``z2 (1 + z2/z1)``), which lowers the zone contrast where the local
    period ``r1^2 / r`` makes ``z2`` an odd multiple of half a Talbot length (Eq. 8).
    The pattern's centre is offset from index ``n // 2`` by ``camera.mask_center`` pixels.
    """
    t = zone_plate(shape, camera.pitch, camera.r1p, kind=camera.mask, R=camera.R_shadow,
                   phase=camera.phase, center=camera.mask_center)
    if not diffraction:
        return t
    if camera.wavelength is None:
        raise ClfzaError("diffraction needs the camera's wavelength (mm), e.g. 5.5e-4")
    z = camera.z2 * camera.shadow_scale
    fy = scipy.fft.fftfreq(shape[0], camera.pitch)[:, None]
    fx = scipy.fft.fftfreq(shape[1], camera.pitch)[None, :]
    tf = np.exp(-1j * np.pi * camera.wavelength * z * (fx**2 + fy**2))
    field_ = scipy.fft.ifft2(scipy.fft.fft2(np.sqrt(t)) * tf)
    return np.abs(field_) ** 2


def convolve_with_shadow(obj: np.ndarray, camera: Camera, margin: int,
                         diffraction: bool = False) -> np.ndarray:
    """Linear convolution of a sensor-plane object with the mask's shadow, cropped to the
    sensor (Eq. 14). ``obj`` is the extended grid from :func:`project_scene`."""
    sy, sx = camera.shape
    my, mx = obj.shape[:2]
    # The PSF covers every object-to-sensor offset, so the linear convolution is exact.
    psf = shadow_pattern(camera, (my + sy, mx + sx), diffraction)
    py, px = psf.shape
    # Sensor pixel s sits at object-grid index s + margin; the PSF centre is at index P // 2,
    # so sensor pixel s is full-convolution index s + margin + P // 2.
    oy, ox = margin + py // 2, margin + px // 2

    full = (my + py - 1, mx + px - 1)
    fshape = tuple(scipy.fft.next_fast_len(n, real=True) for n in full)
    psf_hat = scipy.fft.rfft2(psf, s=fshape)

    def one(ch: np.ndarray) -> np.ndarray:
        # linear convolution: zero-padding to at least the full size leaves nothing to wrap
        conv = scipy.fft.irfft2(scipy.fft.rfft2(ch, s=fshape) * psf_hat, s=fshape)
        return conv[oy:oy + sy, ox:ox + sx]

    if obj.ndim == 2:
        return one(obj)
    return np.stack([one(obj[..., c]) for c in range(obj.shape[2])], axis=-1)


# ----------------------------------------------------------------------------------------
# the whole shot
# ----------------------------------------------------------------------------------------
#: the largest scene value accepted: a linear convolution sums up to (object pixels) x (max
#: value) and the observation squares it; 1e100 leaves float64 room for both
MAX_SCENE_VALUE = 1e100


def simulation_bytes(camera: Camera, margin: int = 0, channels: int = 1) -> float:
    """Peak bytes of :func:`simulate`: the object grid, the shadow on the linear-convolution
    grid, its real FFT and one channel's, the result, the noise and ``y``."""
    sy, sx = camera.shape
    my, mx = sy + 2 * margin, sx + 2 * margin
    fy = scipy.fft.next_fast_len(my + (my + sy) - 1, real=True)
    fx = scipy.fft.next_fast_len(mx + (mx + sx) - 1, real=True)
    spectrum = fy * (fx // 2 + 1) * 16.0
    return (8.0 * my * mx * channels + 8.0 * (my + sy) * (mx + sx) + 2 * spectrum
            + 8.0 * fy * fx + 8.0 * sy * sx * channels * 6)


def check_simulation_memory(camera: Camera, margin: int = 0, channels: int = 1) -> float:
    """Refuse a simulation whose grids do not fit the memory limit (:mod:`clfza.io._limits`),
    before anything is allocated."""

    sy, sx = camera.shape
    return check_memory(
        f"simulating a {sy}x{sx} camera", simulation_bytes(camera, margin, channels),
        f"the scene on a {sy + 2 * margin}x{sx + 2 * margin} grid convolved with the mask's "
        "shadow on a grid of twice that",
        f"use a smaller camera shape or scene, or raise the limit with {LIMIT_ENV}")


def _apply_sensor(frame: np.ndarray, noise: Noise, rng: np.random.Generator
                  ) -> tuple[np.ndarray, float, dict]:
    """Exposure, photon and read noise, saturation and quantisation of a clean frame.

    Returns the raw frame, the factor that maps raw units back to clean-frame units, and
    statistics (saturated fraction).
    """
    peak = float(frame.max())
    if peak <= 0:
        return frame.copy(), 1.0, {"saturated_fraction": 0.0}
    stats: dict = {}
    # FFT convolution leaves ~1e-16 negative values where the frame is dark; intensities >= 0
    rel = np.clip(frame, 0.0, None) * (noise.exposure / peak)  # 1.0 = full scale
    to_clean = peak / noise.exposure  # rel -> clean units
    if noise.photons is not None:
        full_well = noise.photons / noise.exposure
        e = rng.poisson(rel * full_well).astype(np.float64)
        if noise.read_noise:
            e += rng.normal(0.0, noise.read_noise, size=e.shape)
        rel = e / full_well
    stats["saturated_fraction"] = float(np.mean(rel >= 1.0))
    rel = np.clip(rel, 0.0, 1.0)
    if noise.bit_depth is not None:
        levels = 2**noise.bit_depth - 1
        dn = np.round(rel * levels)
        return dn, to_clean / levels, stats
    return rel, to_clean, stats


def _sensor_object(scene, camera: Camera, object_width: float | None,
                   center: tuple[float, float], sensor_plane: bool
                   ) -> tuple[np.ndarray, int, float | None]:
    """The sensor-plane object ``O`` with its margin (:func:`project_scene`, or ``scene`` as
    it is for ``sensor_plane``) and the object width used (the default fills 60% of the
    sensor)."""
    if sensor_plane:
        obj = as_scene(scene)
        if obj.shape[:2] != tuple(camera.shape):
            raise ClfzaError(f"a sensor-plane scene must have the camera's shape "
                             f"{tuple(camera.shape)}, got {obj.shape[:2]}")
        return obj, 0, object_width
    if object_width is None:
        object_width = 0.6 * camera.shape[1] * camera.pitch / camera.magnification
    obj, margin = project_scene(scene, camera, object_width, center)
    return obj, margin, object_width


def _add_gaussian(raw: np.ndarray, noise: Noise, rng: np.random.Generator,
                  frame_scale: float) -> np.ndarray:
    """The Gaussian term (variance of y, the paper's Fig. 7) written into the frame, in frame
    units, so that the frame a file holds is the frame y describes: then
    ``y = (frame - mean(frame)) * frame_scale`` holds for every noise model."""
    n = rng.normal(0.0, math.sqrt(noise.gaussian_var) / frame_scale, size=raw.shape)
    if noise.bit_depth is not None:  # a quantised frame stays digital numbers
        return np.clip(np.round(raw + n), 0.0, 2.0**noise.bit_depth - 1)
    return raw + n


def simulate(scene, camera: Camera, *, object_width: float | None = None,
             center: tuple[float, float] = (0.0, 0.0), noise: Noise | None = None,
             diffraction: bool = False, sensor_plane: bool = False) -> Measurement:
    """Simulate one shot of a scene through the FZA camera.

    Parameters
    ----------
    scene : array (H, W) or (H, W, 3)
        Scene intensities (float in [0, 1], or an integer image scaled by its dtype's max).
    camera : Camera
        The camera (mask, geometry, sensor grid).
    object_width : float, optional
        Width of the scene in mm at distance ``z1``; default: the width that fills 60% of the
        sensor (``0.6 N p / M``), the paper's 300-of-512 pixel fill.
    center : (float, float)
        Scene centre (x, y) in mm in the object plane.
    noise : Noise, optional
        Noise model; default noise-free.
    diffraction : bool
        Propagate the mask's shadow over z2 at the camera's wavelength (Eq. 8).
    sensor_plane : bool
        ``scene`` is already the sensor-plane object ``O`` on the sensor grid (no projection).

    Returns
    -------
    Measurement
    """
    noise = noise or Noise()
    check_simulation_memory(camera)  # the smallest grids, before the scene is touched
    obj, margin, object_width = _sensor_object(scene, camera, object_width, center,
                                               sensor_plane)
    sy, sx = camera.shape
    truth = obj[margin:margin + sy, margin:margin + sx].copy()
    with np.errstate(over="raise", invalid="raise"):
        try:
            clean = convolve_with_shadow(obj, camera, margin, diffraction)
        except FloatingPointError:
            raise ClfzaError("the scene's values overflow float64 in the convolution; scale "
                             "the scene to [0, 1]") from None
    scale = 2.0 * camera.pitch**2 / camera.r1p**2
    rng = np.random.default_rng(noise.seed)
    raw, to_clean, stats = _apply_sensor(clean, noise, rng)
    frame_scale = to_clean * scale

    def dc_free(f: np.ndarray) -> np.ndarray:
        return (f - f.mean(axis=(0, 1), keepdims=True)) * 1.0

    clean_y = dc_free(clean) * scale
    if noise.gaussian_var:
        raw = _add_gaussian(raw, noise, rng, frame_scale)
    y = dc_free(raw) * frame_scale
    if not (np.isfinite(y).all() and np.isfinite(clean_y).all()):
        raise ClfzaError("the simulated observation is not finite (the scene's values "
                         "overflow float64); scale the scene to [0, 1]")
    info = {
        "object_width_mm": object_width,
        "center_mm": list(center),
        "margin_px": margin,
        "diffraction": diffraction,
        "noise": noise.__dict__.copy(),
        "frame_noise": ("every noise term is in the frame: y = (frame - mean(frame)) * "
                        "frame_scale" + (f"; the Gaussian term is N(0, {noise.gaussian_var:g}) "
                                         "on y, i.e. std sqrt(var) / frame_scale in frame units"
                                         if noise.gaussian_var else "")),
        "snr_db": float(10 * np.log10(np.sum(clean_y**2) / max(np.sum((y - clean_y) ** 2),
                                                                  1e-300))),
        **stats,
    }
    return Measurement(frame=raw, y=y, truth=truth, camera=camera, clean_y=clean_y,
                       frame_scale=frame_scale, info=info)


# ----------------------------------------------------------------------------------------
# real captures with a measured PSF (issue 34, item 5)
# ----------------------------------------------------------------------------------------
#: the sensor of a point-source capture and of the scene frames: 8-bit, twenty thousand
#: photo-electrons at the brightest pixel, 2 e- read noise
CAPTURE_NOISE = Noise(photons=20000.0, read_noise=2.0, bit_depth=8, exposure=0.9, seed=0)


@dataclass
class PSFCapture:
    """A simulated measured-PSF camera: a point-source capture at one depth and a scene frame
    at another (:func:`simulate_psf_capture`).

    Attributes
    ----------
    psf : ndarray
        The point-source capture, 8-bit digital numbers as float64 (``psf_shape``, RGB when
        the scene is): what :func:`clfza.models.load_psf` reads.
    frame : ndarray
        The scene's raw frame, 8-bit digital numbers as float64.
    y : ndarray
        ``frame`` less its per-channel mean (the DC-free observation of a measured-PSF solve).
    truth : ndarray
        The sensor-plane object (grey or RGB, channel gains not applied).
    true_scale : float
        ``(1 + z2/scene_z1) / (1 + z2/psf_z1)``: the magnification that takes the captured
        PSF to the scene's depth.
    camera : Camera
        The measured-PSF camera of the frame (pitch, shape, ``z2`` and ``psf_z1``).
    mask_camera : Camera
        The FZA camera that cast the shadows (its mask, aperture and geometry).
    gains : tuple of float
        The per-channel gains (sensor response x source spectrum) of both captures.
    info : dict
        Depths, gains, noise and the captures' saturated fractions.
    """

    psf: np.ndarray
    frame: np.ndarray
    y: np.ndarray
    truth: np.ndarray
    true_scale: float
    camera: Camera
    mask_camera: Camera
    gains: tuple[float, ...]
    info: dict = field(default_factory=dict)


def _sensor_plane_scene(scene, shape: tuple[int, int], fill: float) -> np.ndarray:
    """``scene`` resized to ``fill`` of the sensor's width (aspect kept), centred on a black
    sensor-sized grid and inverted (the pinhole geometry, Eq. 2)."""
    s = as_scene(scene)
    ny, nx = shape
    h, w = s.shape[:2]
    wx = max(1, int(round(fill * nx)))
    hy = max(1, min(ny, int(round(wx * h / w))))
    img = resize(s, (hy, wx) + s.shape[2:], order=1, anti_aliasing=hy < h,
                 preserve_range=True)
    out = np.zeros(tuple(shape) + s.shape[2:])
    y0, x0 = (ny - hy) // 2, (nx - wx) // 2
    out[y0:y0 + hy, x0:x0 + wx] = np.clip(img, 0.0, None)[::-1, ::-1]
    return out


def _linear_conv_crop(obj: np.ndarray, psf: np.ndarray) -> np.ndarray:
    """``crop(obj (*) psf)``: the linear convolution on a grid where nothing wraps, cropped
    to ``obj``'s grid with the PSF's centre (index ``P // 2``) on the object's pixel."""
    sy, sx = obj.shape[:2]
    py, px = psf.shape[:2]
    fshape = tuple(scipy.fft.next_fast_len(n, real=True) for n in (sy + py - 1, sx + px - 1))
    ph = scipy.fft.rfft2(psf, s=fshape)
    oy, ox = py // 2, px // 2

    def one(ch: np.ndarray) -> np.ndarray:
        return scipy.fft.irfft2(scipy.fft.rfft2(ch, s=fshape) * ph, s=fshape)[oy:oy + sy,
                                                                             ox:ox + sx]

    if obj.ndim == 2:
        return one(obj)
    return np.stack([one(obj[..., c]) for c in range(obj.shape[2])], axis=-1)


def simulate_psf_capture(scene, *, shape: tuple[int, int] = (128, 128),
                         pitch: float = 0.0066, psf_factor: float = 1.6,
                         psf_z1: float = 400.0, scene_z1: float = 40.0, z2: float = 8.0,
                         r1: float | None = None, R: float | None = None,
                         mask: str = "gzp", gains: tuple[float, ...] = (1.0, 0.8, 0.6),
                         fill: float = 0.7, noise: Noise | None = CAPTURE_NOISE,
                         psf_noise: Noise | None = CAPTURE_NOISE) -> PSFCapture:
    """Simulate a measured-PSF camera as real captures arise: a point source photographed
    at ``psf_z1`` (the PSF), a scene photographed at ``scene_z1``, both through the same
    finite-aperture zone-plate mask on one 8-bit sensor.

    A point at depth ``z`` casts the mask's shadow magnified by ``1 + z2/z`` (the paper's
    Methods, Eq. 2), so the PSF that fits the scene is the captured one magnified by
    ``true_scale = (1 + z2/scene_z1) / (1 + z2/psf_z1)``. The scene frame is the linear
    convolution of the sensor-plane object with the *exact* shadow at ``scene_z1`` (not a
    resampled capture: no inverse crime), cropped to the sensor; both captures then go
    through the sensor (:class:`Noise`: photon and read noise, 8-bit quantisation).

    Parameters
    ----------
    scene : array (H, W) or (H, W, 3)
        The scene (float in [0, 1] or an integer image); RGB gives RGB captures.
    shape : (int, int)
        The frame's grid (rows, cols); the PSF capture is ``psf_factor`` times larger (a
        full-aperture mask's shadow reaches past the frame).
    pitch : float
        Pixel pitch in mm.
    psf_factor : float
        Side of the PSF capture relative to the frame's.
    psf_z1, scene_z1, z2 : float
        Depth of the point source, of the scene, and the mask-to-sensor distance (mm).
    r1, R : float, optional
        The mask's innermost zone radius and aperture radius (mm). Defaults: ``r1`` puts the
        scene's shadow at half the critical frequency (``r1'^2 = 2 N p^2``: the captured
        PSF stays below Nyquist down to scale 0.7), ``R`` covers 1.2 times
        the frame's half-width (the shadow reaches past the frame).
    mask : {"gzp", "fza"}
        Sinusoidal or binary zone plate.
    gains : tuple of float
        Per-channel gain of both captures (three values for RGB; the first for grey).
    fill : float
        The scene's width as a fraction of the frame's.
    noise, psf_noise : Noise or None
        The sensor of the scene frame and of the PSF capture (None: noise-free, unquantised).

    Returns
    -------
    PSFCapture

    Examples
    --------
    >>> import numpy as np
    >>> cap = simulate_psf_capture(np.eye(32), shape=(64, 64))
    >>> cap.psf.shape, cap.frame.shape, round(cap.true_scale, 4)
    ((102, 102), (64, 64), 1.1765)
    """
    ny, nx = shape2 = tuple(int(v) for v in shape)
    if min(shape2) < 16:
        raise ClfzaError(f"shape must be at least 16x16, got {shape2}")
    pitch = positive("pitch", pitch)
    factor = in_range("psf_factor", psf_factor, 0.5, 4.0)
    psf_z1, scene_z1, z2 = (positive(k, v) for k, v in
                            (("psf_z1", psf_z1), ("scene_z1", scene_z1), ("z2", z2)))
    s = as_scene(scene)
    chans = 1 if s.ndim == 2 else 3
    g = tuple(float(positive("gain", v)) for v in gains)[:chans]
    if len(g) < chans:
        raise ClfzaError(f"gains must give {chans} values for this scene, got {gains!r}")
    scale_scene = 1.0 + z2 / scene_z1
    if r1 is None:
        r1 = math.sqrt(2.0 * max(ny, nx)) * pitch / scale_scene
    if R is None:
        R = 1.2 * 0.5 * max(ny, nx) * pitch / scale_scene
    psf_shape = (int(round(factor * ny)), int(round(factor * nx)))
    mask_cam = Camera(pitch=pitch, shape=psf_shape, r1=r1, z1=psf_z1, z2=z2, R=R, mask=mask,
                      name="psf-capture mask")
    # the point source's shadow, and the scene's on a grid that covers every offset
    point = shadow_pattern(mask_cam, psf_shape)
    scene_shadow = shadow_pattern(mask_cam.at_depth(scene_z1), (2 * ny + 1, 2 * nx + 1))
    obj = _sensor_plane_scene(s, shape2, in_range("fill", fill, 0.05, 1.0))
    clean = _linear_conv_crop(obj, scene_shadow / scene_shadow.sum())
    if chans == 3:
        clean = clean * np.asarray(g)
        point = point[..., None] * np.asarray(g)
    else:
        clean, point = clean * g[0], point * g[0]
    rng = np.random.default_rng(None if noise is None else noise.seed)
    stats = {}
    frame, psf = clean, point
    if noise is not None:
        frame, _, st = _apply_sensor(clean, noise, rng)
        stats["frame_saturated_fraction"] = st["saturated_fraction"]
    if psf_noise is not None:
        rng_p = np.random.default_rng(None if psf_noise.seed is None else psf_noise.seed + 1)
        psf, _, st = _apply_sensor(point, psf_noise, rng_p)
        stats["psf_saturated_fraction"] = st["saturated_fraction"]
    true_scale = scale_scene / (1.0 + z2 / psf_z1)
    cam = Camera.measured_psf(pitch, shape2, z2=z2, psf_z1=psf_z1, name="measured-psf")
    info = {"psf_z1_mm": psf_z1, "scene_z1_mm": scene_z1, "z2_mm": z2, "r1_mm": r1,
            "R_mm": R, "mask": mask, "gains": list(g), "psf_shape": list(psf_shape),
            "noise": None if noise is None else noise.__dict__.copy(),
            "psf_noise": None if psf_noise is None else psf_noise.__dict__.copy(), **stats}
    y = frame - frame.mean(axis=(0, 1), keepdims=True)
    return PSFCapture(psf=psf, frame=frame, y=y, truth=obj, true_scale=true_scale,
                      camera=cam, mask_camera=mask_cam, gains=g, info=info)
