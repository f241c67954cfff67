"""Measured point-spread functions (PSFs) for any mask-based lensless camera.

A PSF *file* (the picture of a point source taken through the mask) becomes the kernel of a
linear-convolution forward model: ``frame = crop(object (*) psf)``, the linear convolution of
the object with the PSF on a padded FFT grid, cropped to the sensor. The :class:`PSF` record
and the reading and processing steps that :func:`load_psf` chains are here, with depth stacks;
which PSF of a stack fits a frame is :func:`clfza.focus.select_psf_depth`.

The PSF contract
----------------
:func:`load_psf` returns a :class:`PSF` whose ``array`` is

* float64, shape ``(H, W)`` for grey or ``(H, W, 3)`` for RGB (one PSF per channel);
* finite and non-negative: after dark and background subtraction, the small negative values
  that noise leaves are clipped to 0 (``info["clipped"]`` counts them); never all zero, and no
  channel is all zero;
* sampled at the *frame's* pitch, after the frame's own binning (``bin`` block-sums the PSF,
  ``psf_pitch``/``frame_pitch`` resample it with anti-aliasing, preserving the sum);
* centred: the point source sits at index ``(H // 2, W // 2)`` -- by ``center="centroid"`` or
  ``"peak"``, or, with ``center="none"``, because the caller keeps the capture geometry (the
  capture was cropped around the point, or the geometry is wanted as is);
* normalised: by default each channel sums to 1 (``normalise="sum"``; ``"max"``: each
  channel's maximum is 1; ``"none"``: the sensor's units);
* read-only (``array.flags.writeable`` is False; copy it to modify it).

A PSF may be larger than the frame: with a full-aperture mask a point's shadow extends beyond
the sensor, and published captures use a PSF about 1.6 times the frame. That is valid.

``info`` records what was done: source, dark subtracted, background value, clipped count,
binning (and the rows/columns it cropped), resample factor, centring shift, normalisation,
original and final shape.

Depth stacks
------------
A PSF changes with the distance of the point (the shadow of a mask scales as ``1 + z2/z1``).
:func:`load_psf_stack` reads one PSF per depth (a 3-D NPY, a multi-page TIFF or a list of
files) and :func:`clfza.focus.select_psf_depth` picks the depth at which the back-propagated
measurement is sharpest (:func:`clfza.focus.sharpness`).
"""

from __future__ import annotations

import math
import struct
import warnings
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import scipy.fft
import tifffile
from scipy.ndimage import center_of_mass, fourier_shift, gaussian_filter
from skimage.transform import rescale

from .. import io as fio
from ..errors import ClfzaError, finite_image, positive, positive_int

NORMALISATIONS = ("sum", "max", "none")
CENTERINGS = ("none", "centroid", "peak")
#: Largest PSF accepted, in pixels per channel (``H * W``); clfza.io's limit if it has one.
MAX_PSF_PIXELS = int(getattr(fio, "MAX_PIXELS", 1 << 26))
#: Width of the border ring used by ``background="border"``, as a fraction of the short side.
BORDER_FRACTION = 0.05
#: Clipped negative mass (relative to the positive mass) above which a warning is raised:
#: zero-mean noise on a dark surround clips a few percent; more means an offset too large.
CLIP_WARN_FRACTION = 0.1

Source = str | Path | np.ndarray


@dataclass(frozen=True)
class PSF:
    """A PSF that satisfies the contract in :mod:`clfza.models._psf`'s docstring.

    Attributes
    ----------
    array : ndarray
        float64 ``(H, W)`` or ``(H, W, 3)``, non-negative, normalised, read-only.
    pitch : float or None
        Sample spacing of ``array`` in mm (the frame's pitch), None when not given.
    info : dict
        What was done to the file (source, dark, background, clipped, bin, resample factor,
        centring shift, normalisation, original shape, ...).
    """

    array: np.ndarray
    pitch: float | None
    info: dict = field(default_factory=dict)

    @property
    def shape(self) -> tuple[int, ...]:
        return tuple(self.array.shape)

    @property
    def channels(self) -> int:
        return 1 if self.array.ndim == 2 else int(self.array.shape[2])


# ----------------------------------------------------------------------------------------
# validation before decoding
# ----------------------------------------------------------------------------------------
def _png_layout(p: Path) -> tuple[tuple[int, ...], np.dtype]:
    with open(p, "rb") as fh:
        head = fh.read(33)
    if head[:8] != b"\x89PNG\r\n\x1a\n" or head[12:16] != b"IHDR":
        raise ClfzaError(f"{str(p)!r} is not a readable PNG file (bad signature or header)")
    w, h, bits, ctype = struct.unpack(">IIBB", head[16:26])
    chans = {0: 1, 2: 3, 3: 3, 4: 2, 6: 4}.get(ctype, 1)
    shape = (h, w) if chans == 1 else (h, w, chans)
    return shape, np.dtype(np.uint16 if bits == 16 else np.uint8)


def _pages_agree(p: Path, shape: tuple[int, ...]) -> bool:
    """Whether every page of TIFF ``p`` has ``shape`` (from the headers: nothing decoded)."""
    with tifffile.TiffFile(p) as tf:
        return all(tuple(int(v) for v in pg.shape) == shape for pg in tf.pages)


def _tiff_layout(p: Path, stack: bool) -> tuple[tuple[int, ...], np.dtype]:
    try:
        pages, shape, dtype = fio.tiff_header(p)
        if pages > 1 and not stack:
            raise ClfzaError(f"TIFF {str(p)!r} holds {pages} pages (a stack); read it "
                             "with load_psf_stack or save one PSF per file")
        if stack and pages > 1 and not _pages_agree(p, shape):
            raise ClfzaError(f"the pages of TIFF {str(p)!r} differ in shape; a PSF stack "
                             "needs one shape for every depth")
    except ClfzaError:
        raise
    except Exception as exc:
        raise ClfzaError(f"cannot read TIFF {str(p)!r}: the file is corrupt or truncated "
                         f"({fio.one_line(exc)})") from None
    if len(shape) == 3 and shape[0] in (3, 4) and shape[-1] not in (3, 4):
        shape = (*shape[1:], shape[0])  # planar RGB -> (H, W, C)
    return ((pages, *shape) if stack else shape), dtype


def _npy_layout(p: Path) -> tuple[tuple[int, ...], np.dtype]:
    try:
        shape, dtype, _, _ = fio.npy_header(p)
    except Exception as exc:
        raise ClfzaError(f"{str(p)!r} is not a readable NPY file ({fio.one_line(exc)})") \
            from None
    return shape, dtype


def _file_layout(path: Path, stack: bool = False) -> tuple[tuple[int, ...], np.dtype]:
    """Shape and dtype of an image file from its header alone (nothing is decoded)."""
    if not path.is_file():
        raise ClfzaError(f"{str(path)!r} does not exist or is not a file")
    kind = fio.FRAME_SUFFIXES.get(path.suffix.lower())
    if kind is None:
        raise ClfzaError(f"{str(path)!r} has unsupported suffix {path.suffix or '(none)'!r}; "
                         "a PSF is read from .png, .tif/.tiff or .npy")
    if path.stat().st_size == 0:
        raise ClfzaError(f"{str(path)!r} is an empty file (0 bytes)")
    if kind == "png":
        return _png_layout(path)
    if kind == "tiff":
        return _tiff_layout(path, stack)
    return _npy_layout(path)


def _check_dtype(dtype: np.dtype, name: str) -> None:
    kind = dtype.kind
    if kind == "c":
        raise ClfzaError(f"{name} is complex ({dtype}); a PSF is a real intensity: pass "
                         "abs(field)**2 or the real part")
    if kind == "b":
        raise ClfzaError(f"{name} is boolean; a PSF is a measured intensity (convert a "
                         "binary mask to float if you mean to use it as a PSF)")
    if kind not in "iuf":
        raise ClfzaError(f"{name} has unsupported data type {dtype}; a PSF must be integer "
                         "or floating point")


def _check_layout(shape: tuple[int, ...], dtype: np.dtype, name: str, max_pixels: int) -> None:
    """Reject a PSF by its dtype, rank, channel count and size (cheap: no pixel is read)."""
    _check_dtype(dtype, name)
    if len(shape) not in (2, 3):
        hint = "; a depth stack goes to load_psf_stack" if len(shape) == 4 else ""
        raise ClfzaError(f"{name} must be (H, W) or (H, W, 3), got {len(shape)} dimensions "
                         f"{tuple(shape)}{hint}")
    if len(shape) == 3 and shape[2] not in (1, 3):
        c = shape[2]
        if c == 4:
            raise ClfzaError(f"{name} has 4 channels (RGBA? drop the alpha channel), shape "
                             f"{tuple(shape)}")
        hint = " (grey + alpha? keep the grey channel)" if c == 2 else ""
        if c > 4 and shape[0] < shape[2]:
            hint = " (a depth stack (D, H, W)? read it with load_psf_stack)"
        raise ClfzaError(f"{name} has {c} channels{hint}; a PSF is grey (H, W) or RGB "
                         f"(H, W, 3), got shape {tuple(shape)}")
    h, w = int(shape[0]), int(shape[1])
    if min(h, w) < fio.MIN_SIDE:
        raise ClfzaError(f"{name} is too small ({h}x{w}; at least "
                         f"{fio.MIN_SIDE}x{fio.MIN_SIDE} pixels)")
    if h * w > max_pixels:
        raise ClfzaError(f"{name} has {h}x{w} = {h * w} pixels, more than the limit "
                         f"max_pixels = {max_pixels}")


def _read_array(source: Source, name: str, max_pixels: int) -> tuple[np.ndarray, str]:
    """Validate and return ``source`` (path or array) as float64 ``(H, W)`` / ``(H, W, 3)``."""
    if isinstance(source, (str, Path)):
        p = Path(source)
        shape, dtype = _file_layout(p)
        _check_layout(shape, dtype, f"{name} {str(p)!r}", max_pixels)
        a, _ = fio.read_frame(p, name=f"{name} {str(p)!r}")
        return a, str(p)
    if isinstance(source, PSF):
        source = source.array
    a = np.asarray(source)
    _check_layout(a.shape, a.dtype, name, max_pixels)
    if a.ndim == 3 and a.shape[2] == 1:
        a = a[..., 0]
    return finite_image(name, a), f"array {a.dtype} {a.shape}"


# ----------------------------------------------------------------------------------------
# the processing steps
# ----------------------------------------------------------------------------------------
def _subtract_dark(a: np.ndarray, dark, max_pixels: int) -> tuple[np.ndarray, str | None]:
    if dark is None:
        return a, None
    d, label = _read_array(dark, "dark frame", max_pixels)
    if d.shape == a.shape or (d.ndim == 2 and a.ndim == 3 and d.shape == a.shape[:2]):
        return a - (d[..., None] if d.ndim < a.ndim else d), label
    raise ClfzaError(f"the dark frame has shape {d.shape} but the PSF {a.shape}; take the "
                     "dark frame in the same sensor mode (size, binning, colour)")


def border_background(a: np.ndarray, fraction: float = BORDER_FRACTION) -> np.ndarray:
    """Per-channel median of the outermost ring of ``a`` (width ``fraction`` of the short side).

    Valid only when the point's image leaves the border dark: for a PSF that fills the frame
    (the shadow of a full-aperture mask) the ring holds signal and this over-subtracts; give
    a number or a dark frame then.
    """
    h, w = a.shape[:2]
    k = max(1, int(round(fraction * min(h, w))))
    ring = np.ones((h, w), dtype=bool)
    ring[k:h - k, k:w - k] = False
    return np.median(a[ring], axis=0)


def _subtract_background(a: np.ndarray, background) -> tuple[np.ndarray, object]:
    if background is None:
        return a, None
    if isinstance(background, str):
        if background != "border":
            raise ClfzaError(f"background must be a number, 'border' or None, got "
                             f"{background!r}")
        b = border_background(a)
        value = b.tolist() if np.ndim(b) else float(b)
        return a - b, value
    try:
        b = float(background)
    except (TypeError, ValueError):
        raise ClfzaError(f"background must be a number, 'border' or None, got "
                         f"{background!r}") from None
    if not math.isfinite(b):
        raise ClfzaError(f"background must be finite, got {background!r}")
    return a - b, b


def _check_nonzero(a: np.ndarray, when: str) -> None:
    peak = a.max(axis=(0, 1))
    if np.any(peak <= 0):
        which = "" if a.ndim == 2 else f" (channel {int(np.argmin(peak))})"
        when = f" {when}" if when else ""
        raise ClfzaError(f"the PSF is all zero or negative{which}{when}; check the dark "
                         "frame, the background level and the exposure")


def _clip_negatives(a: np.ndarray) -> tuple[np.ndarray, int]:
    """Clip noise's negative values to 0; warn when they carry more than 10 % of the mass."""
    neg = a < 0
    n = int(np.count_nonzero(neg))
    if n:
        lost = float(-a[neg].sum())
        pos = float(a[a > 0].sum())
        if lost > CLIP_WARN_FRACTION * pos:
            warnings.warn(f"clipping {n} negative PSF pixels removes {lost / pos:.1%} of its "
                          "mass: is the dark frame or the background too high?", stacklevel=3)
        a = np.where(neg, 0.0, a)
    return a, n


def _to_channels(a: np.ndarray, channels: int | None) -> tuple[np.ndarray, str | None]:
    if channels is None:
        return a, None
    if channels not in (1, 3):
        raise ClfzaError(f"channels must be None, 1 or 3, got {channels!r}")
    if channels == 1 and a.ndim == 3:
        return a.mean(axis=2), "RGB averaged to grey"
    if channels == 3 and a.ndim == 2:
        return np.repeat(a[..., None], 3, axis=2), "grey repeated for 3 channels"
    return a, None


def bin_sum(a: np.ndarray, factor: int) -> tuple[np.ndarray, tuple[int, int]]:
    """Block-sum ``factor x factor`` pixels; returns the result and the (rows, cols) of the
    remainder cropped from the bottom and right edges."""
    h, w = a.shape[:2]
    hb, wb = h // factor, w // factor
    if min(hb, wb) < fio.MIN_SIDE:
        raise ClfzaError(f"binning a {h}x{w} PSF by {factor} leaves {hb}x{wb} pixels (at least "
                         f"{fio.MIN_SIDE}x{fio.MIN_SIDE})")
    c = a[:hb * factor, :wb * factor]
    s = c.reshape(hb, factor, wb, factor, *a.shape[2:]).sum(axis=(1, 3))
    return s, (h - hb * factor, w - wb * factor)


def resample(a: np.ndarray, factor: float, max_pixels: int = MAX_PSF_PIXELS) -> np.ndarray:
    """Resample by ``factor`` (output pixels per input pixel along each axis), preserving
    each channel's sum.

    Bilinear interpolation (it keeps the PSF non-negative) with scikit-image's Gaussian
    anti-aliasing when shrinking (``sigma = (1/factor - 1) / 2`` input pixels); the image's
    outer edges stay aligned, as the sensor area is the same at both pitches.
    """

    h, w = a.shape[:2]
    hn, wn = int(round(h * factor)), int(round(w * factor))
    if min(hn, wn) < fio.MIN_SIDE:
        raise ClfzaError(f"resampling a {h}x{w} PSF by {factor:.4g} leaves {hn}x{wn} pixels")
    if hn * wn > max_pixels:
        raise ClfzaError(f"resampling a {h}x{w} PSF by {factor:.4g} gives {hn}x{wn} pixels, "
                         f"more than max_pixels = {max_pixels}")
    out = rescale(a, factor, order=1, mode="edge", anti_aliasing=factor < 1,
                  preserve_range=True, channel_axis=2 if a.ndim == 3 else None)
    out = np.maximum(out, 0.0)
    s_in, s_out = a.sum(axis=(0, 1)), out.sum(axis=(0, 1))
    return out * (s_in / np.where(s_out > 0, s_out, 1.0))


def shift_image(a: np.ndarray, dy: float, dx: float) -> np.ndarray:
    """Shift by ``(dy, dx)`` pixels without wrapping: the integer part exactly (zero fill), the
    fractional part (|d| <= 1/2) by a Fourier phase ramp, which keeps the sum and the
    band-limited detail (a bilinear shift would blur the finest zones)."""
    iy, ix = int(round(dy)), int(round(dx))
    fy, fx = dy - iy, dx - ix
    out = np.zeros_like(a)
    h, w = a.shape[:2]
    ys, yd = (slice(0, h - iy), slice(iy, h)) if iy >= 0 else (slice(-iy, h), slice(0, h + iy))
    xs, xd = (slice(0, w - ix), slice(ix, w)) if ix >= 0 else (slice(-ix, w), slice(0, w + ix))
    out[yd, xd] = a[ys, xs]
    if abs(fy) < 1e-9 and abs(fx) < 1e-9:
        return out
    planes = out[..., None] if out.ndim == 2 else out
    res = np.empty_like(planes)
    for c in range(planes.shape[2]):
        spec = fourier_shift(scipy.fft.fft2(planes[..., c]), (fy, fx))
        res[..., c] = scipy.fft.ifft2(spec).real
    return res[..., 0] if a.ndim == 2 else res


def _center(a: np.ndarray, how: str) -> tuple[np.ndarray, dict]:
    """Move the centroid (sub-pixel) or the peak (whole pixels) to ``(H // 2, W // 2)``."""
    if how == "none":
        return a, {"centring": "none", "centring_shift": [0.0, 0.0]}
    grey = a if a.ndim == 2 else a.sum(axis=2)
    if how == "centroid":
        cy, cx = center_of_mass(grey)
    else:
        sm = gaussian_filter(grey, 1.0)  # one hot pixel is not the peak
        cy, cx = np.unravel_index(int(np.argmax(sm)), sm.shape)
    h, w = grey.shape
    dy, dx = float(h // 2 - cy), float(w // 2 - cx)
    out = shift_image(a, dy, dx)
    out, clipped = _clip_negatives(out)
    kept = float(out.sum()) / float(a.sum())
    return out, {"centring": how, "centring_shift": [dy, dx], "centring_clipped": clipped,
                 "centring_mass_kept": kept}


def _normalise(a: np.ndarray, how: str) -> np.ndarray:
    if how == "none":
        return a
    scale = a.sum(axis=(0, 1)) if how == "sum" else a.max(axis=(0, 1))
    return a / scale


@dataclass(frozen=True)
class PSFStack:
    """PSFs of one camera at several depths: ``arrays[k]`` belongs to ``depths[k]`` (mm)."""

    arrays: np.ndarray
    depths: tuple[float, ...]
    pitch: float | None
    infos: tuple[dict, ...] = ()

    def __len__(self) -> int:
        return len(self.depths)

    def psf(self, k: int) -> PSF:
        """The ``k``-th PSF as a :class:`PSF`."""
        info = self.infos[k] if self.infos else {}
        return PSF(self.arrays[k], self.pitch, dict(info))


# ----------------------------------------------------------------------------------------
# public: one PSF
# ----------------------------------------------------------------------------------------
def _calibrate(a: np.ndarray, dark, background, max_pixels: int, info: dict) -> np.ndarray:
    """Subtract the dark frame and the background, clip noise's negatives (recorded in
    ``info``); the PSF must keep some light after each step."""
    a, info["dark"] = _subtract_dark(a, dark, max_pixels)
    _check_nonzero(a, "after dark subtraction" if dark is not None else "")
    a, info["background"] = _subtract_background(a, background)
    if background is not None:
        _check_nonzero(a, f"after subtracting the background {info['background']}")
    a, info["clipped"] = _clip_negatives(a)
    return a


def _check_options(psf_pitch, frame_pitch, bin, center, normalise, channels,
                   max_pixels) -> tuple[float | None, float | None, int, int]:
    pp = None if psf_pitch is None else positive("psf_pitch", psf_pitch)
    fp = None if frame_pitch is None else positive("frame_pitch", frame_pitch)
    b = positive_int("bin", bin)
    mp = positive_int("max_pixels", max_pixels)
    if center not in CENTERINGS:
        raise ClfzaError(f"center must be one of {CENTERINGS}, got {center!r}")
    if normalise not in NORMALISATIONS:
        raise ClfzaError(f"normalise must be one of {NORMALISATIONS}, got {normalise!r}")
    if channels not in (None, 1, 3):
        raise ClfzaError(f"channels must be None, 1 or 3, got {channels!r}")
    if fp is not None and pp is None:
        raise ClfzaError("frame_pitch needs psf_pitch (the pitch of the PSF file's pixels) "
                         "to resample the PSF")
    return pp, fp, b, mp


def load_psf(source: Source | PSF, *, dark: Source | None = None,
             background: float | str | None = None, psf_pitch: float | None = None,
             frame_pitch: float | None = None, bin: int = 1, center: str = "none",
             normalise: str = "sum", channels: int | None = None,
             max_pixels: int = MAX_PSF_PIXELS) -> PSF:
    """Read a measured PSF and bring it to the module's contract.

    Steps, in order: validate (dtype, rank, channels and size from the file header, before
    decoding), read (:func:`clfza.io.read_frame`), subtract ``dark``, subtract
    ``background``, clip noise's negatives, convert ``channels``, block-sum by ``bin``,
    resample from ``psf_pitch * bin`` to ``frame_pitch``, centre, normalise.

    Parameters
    ----------
    source : path, ndarray or PSF
        8/16-bit PNG, TIFF (uncompressed, LZW or deflate; integer or float), NPY, or an
        array; grey ``(H, W)`` or RGB ``(H, W, 3)``.
    dark : path or ndarray, optional
        Dark frame with the PSF's shape (a grey dark frame applies to every channel).
    background : float or "border", optional
        A constant to subtract, or ``"border"``: the per-channel median of the outermost 5 %
        ring (:func:`border_background`). Wrong for a PSF that fills the frame (a
        full-aperture mask's shadow): the ring then holds signal.
    psf_pitch, frame_pitch : float, optional
        Pixel pitch (mm) of the PSF file and of the frame the PSF will be used with (after
        the frame's binning). When they differ (after ``bin``) the PSF is resampled with
        anti-aliasing, preserving its sum (:func:`resample`).
    bin : int
        Block-sum ``bin x bin`` pixels first; a remainder is cropped from the bottom and right
        (``info["bin_cropped"]``).
    center : {"none", "centroid", "peak"}
        ``"none"`` keeps the capture geometry; ``"centroid"`` moves the intensity centroid to
        ``(H // 2, W // 2)`` with sub-pixel accuracy; ``"peak"`` moves the brightest pixel of
        the lightly smoothed image there (whole pixels). Colour channels move together.
        The centroid is biased by light left in the surround (subtract the background first)
        and by a shadow cut off at the array's edges (it lands on the visible part's centre).
    normalise : {"sum", "max", "none"}
        Each channel sums to 1, has maximum 1, or keeps the sensor's units.
    channels : {None, 1, 3}
        None keeps the file's channels; 1 averages RGB to grey; 3 repeats a grey PSF.
    max_pixels : int
        Largest ``H * W`` accepted (checked before the file is decoded).

    Returns
    -------
    PSF

    Raises
    ------
    ClfzaError
        Complex, boolean or object data; NaN/Inf; rank other than 2 or 3; 2 or 4+ channels;
        too many pixels; an all-zero PSF (also after background subtraction); a dark frame
        of another shape; bad options.
    """
    pp, fp, b, mp = _check_options(psf_pitch, frame_pitch, bin, center, normalise, channels,
                                   max_pixels)
    a, label = _read_array(source, "PSF", mp)
    info: dict = {"source": label, "original_shape": list(a.shape)}
    a = _calibrate(a, dark, background, mp, info)
    a, info["channels"] = _to_channels(a, channels)
    info["bin"], info["bin_cropped"] = b, [0, 0]
    if b > 1:
        a, cropped = bin_sum(a, b)
        info["bin_cropped"] = list(cropped)
    pitch = None if pp is None else pp * b
    factor = 1.0 if fp is None else pitch / fp
    info["resample_factor"] = factor
    if abs(factor - 1.0) > 1e-9:
        a = resample(a, factor, mp)
    pitch = fp if fp is not None else pitch
    a, centring = _center(a, center)
    info.update(centring)
    _check_nonzero(a, "after centring (the shift moved it out of the array)")
    info["normalisation"] = normalise
    # the sums before normalising: a colour PSF's give the sensor's channel gains (white
    # balance, clfza.reconstruction's white_balance="psf")
    info["channel_sums"] = [float(v) for v in np.ravel(a.sum(axis=(0, 1)))]
    a = np.ascontiguousarray(_normalise(a, normalise), dtype=np.float64)
    info["shape"] = list(a.shape)
    a.flags.writeable = False
    return PSF(array=a, pitch=pitch, info=info)


# ----------------------------------------------------------------------------------------
# public: depth stacks
# ----------------------------------------------------------------------------------------
def check_depths(depths: Sequence[float], n: int | None) -> tuple[float, ...]:
    try:
        ds = tuple(positive("depth", d, allow_inf=True) for d in depths)
    except TypeError:  # not iterable
        raise ClfzaError(f"depths must be a sequence of numbers, got {depths!r}") from None
    if not ds:
        raise ClfzaError("a PSF stack needs at least one depth")
    if len(set(ds)) != len(ds):
        raise ClfzaError(f"depths must be distinct, got {list(ds)}")
    if n is not None and n != len(ds):
        raise ClfzaError(f"the stack holds {n} PSFs but {len(ds)} depths were given")
    return ds


def _stack_slices(source, max_pixels: int) -> list:
    """The stack's slices (arrays or paths) after checking its size from the header."""
    if isinstance(source, (list, tuple)):
        return list(source)
    if isinstance(source, (str, Path)):
        p = Path(source)
        shape, dtype = _file_layout(p, stack=True)
        if len(shape) not in (3, 4):
            raise ClfzaError(f"PSF stack {str(p)!r} must be (D, H, W) or (D, H, W, 3), got "
                             f"shape {tuple(shape)}")
        _check_dtype(dtype, f"PSF stack {str(p)!r}")
        total = int(np.prod(shape[:3]))
        if total > max_pixels:
            raise ClfzaError(f"PSF stack {str(p)!r} has {total} pixels, more than "
                             f"max_pixels = {max_pixels}")
        fio.check_layout_memory(f"PSF stack {str(p)!r}", shape, dtype.itemsize,
                                dtype.itemsize)
        if p.suffix.lower() == ".npy":
            return list(np.load(p, mmap_mode="r", allow_pickle=False))
        return fio.tiff_pages(p)
    a = np.asarray(source)
    if a.ndim not in (3, 4):
        raise ClfzaError(f"a PSF stack array must be (D, H, W) or (D, H, W, 3), got shape "
                         f"{a.shape}")
    return list(a)


def load_psf_stack(source: Source | Sequence[Source], depths: Sequence[float], *,
                   max_pixels: int = 4 * MAX_PSF_PIXELS, **options) -> PSFStack:
    """Read one PSF per depth into a :class:`PSFStack`.

    Parameters
    ----------
    source : path, ndarray or list
        A 3-D NPY ``(D, H, W)`` (or 4-D ``(D, H, W, 3)``), a multi-page TIFF (one page per
        depth), an array of those shapes, or a list of PSF files or arrays.
    depths : sequence of float
        Object distance (mm) of each PSF, in the stack's order; ``len(depths) == D``.
    max_pixels : int
        Largest total ``D * H * W`` accepted (checked from the header before decoding).
    **options
        Passed to :func:`load_psf` for every slice (``dark``, ``background``, ``bin``,
        ``psf_pitch``, ``frame_pitch``, ``center``, ``normalise``, ``channels``).

    Returns
    -------
    PSFStack
    """
    mp = positive_int("max_pixels", max_pixels)
    slices = _stack_slices(source, mp)
    if isinstance(options.get("dark"), (str, Path)):  # read the dark frame once
        options["dark"], _ = _read_array(options["dark"], "dark frame", mp)
    ds = check_depths(depths, len(slices))
    psfs = [load_psf(s, **options) for s in slices]
    shapes = {p.shape for p in psfs}
    if len(shapes) != 1:
        raise ClfzaError(f"the PSFs of a stack must share one shape, got {sorted(shapes)}")
    arr = np.stack([p.array for p in psfs])
    arr.flags.writeable = False
    return PSFStack(arrays=arr, depths=ds, pitch=psfs[0].pitch,
                    infos=tuple(p.info for p in psfs))


# ----------------------------------------------------------------------------------------
# public: a PSF magnified about its centre (a point at another depth)
# ----------------------------------------------------------------------------------------
def _area_matrix(n_in: int, scale: float, n_out: int, first: int):
    """Rows ``first .. first + n_out - 1`` of the 1-D resampling matrix of a magnification
    by ``scale`` about index ``n_in // 2`` (which lands on ``round(n_in * scale) // 2``):
    each output pixel is the integral of the linear interpolation of the input over its
    footprint (a tent convolved with a box), so the sum is kept and shrinking is
    anti-aliased. Returned as a sparse CSR matrix ``(n_out, n_in)``."""
    from scipy.sparse import csr_matrix  # lazy: only a rescale needs it (import time)

    c_in = n_in // 2
    c_out = int(round(n_in * scale)) // 2
    i = np.arange(first, first + n_out, dtype=np.float64)
    a = c_in + (i - c_out - 0.5) / scale  # footprint of output pixel i, input coordinates
    b = c_in + (i - c_out + 0.5) / scale
    j0 = np.floor(a).astype(np.int64) - 1
    span = int(math.ceil(1.0 / scale)) + 3
    cols = j0[:, None] + np.arange(span)[None, :]

    def tent_cdf(x: np.ndarray) -> np.ndarray:  # integral of max(0, 1 - |t|) up to x
        x = np.clip(x, -1.0, 1.0)
        return np.where(x < 0, 0.5 * (1 + x) ** 2, 1.0 - 0.5 * (1 - x) ** 2)

    w = tent_cdf(b[:, None] - cols) - tent_cdf(a[:, None] - cols)
    ok = (cols >= 0) & (cols < n_in) & (w > 0)
    rows = np.broadcast_to(np.arange(n_out)[:, None], cols.shape)
    return csr_matrix((w[ok], (rows[ok], cols[ok])), shape=(n_out, n_in))


def magnify(a: np.ndarray, scale: float, max_shape: tuple[int, int] | None = None
            ) -> np.ndarray:
    """``a`` (2-D, or ``(H, W, C)``) magnified by ``scale`` about its centre pixel
    ``(H // 2, W // 2)``, which stays the centre ``(H' // 2, W' // 2)`` of the result
    (``H' = round(H scale)``, or ``max_shape`` when smaller: the centred window of it).

    Each output pixel integrates the bilinear interpolation of ``a`` over its footprint:
    non-negative input stays non-negative, each channel's sum is kept (up to what
    ``max_shape`` cuts), and shrinking is anti-aliased (pixel integration).

    Examples
    --------
    >>> a = np.zeros((9, 9)); a[4, 4] = 1.0
    >>> b = magnify(a, 2.0)
    >>> b.shape, round(float(b.sum()), 12), np.unravel_index(int(b.argmax()), b.shape)
    ((18, 18), 1.0, (np.int64(9), np.int64(9)))
    """
    s = positive("scale", scale)
    h, w = a.shape[:2]
    hs, ws = int(round(h * s)), int(round(w * s))
    if min(hs, ws) < 1:
        raise ClfzaError(f"magnifying a {h}x{w} PSF by {s:.4g} leaves no pixel")
    ho, wo = (hs, ws) if max_shape is None else (min(hs, int(max_shape[0])),
                                                  min(ws, int(max_shape[1])))
    ry = _area_matrix(h, s, ho, hs // 2 - ho // 2)
    rx = _area_matrix(w, s, wo, ws // 2 - wo // 2)
    planes = a[..., None] if a.ndim == 2 else a
    out = np.empty((ho, wo, planes.shape[2]))
    for c in range(planes.shape[2]):
        out[..., c] = (rx @ (ry @ planes[..., c]).T).T
    return out[..., 0] if a.ndim == 2 else out


def scale_psf(psf: PSF | np.ndarray, scale: float,
              max_shape: tuple[int, int] | None = None) -> PSF:
    """The PSF of a point at another depth: ``psf`` magnified by ``scale`` about its centre
    (a point at depth ``z`` casts the mask's shadow magnified by ``1 + z2/z``, so the scale
    from a capture at ``z_psf`` to a scene at ``z`` is ``(1 + z2/z) / (1 + z2/z_psf)``).

    ``max_shape`` keeps the centred window of the result (a frame of ``N`` pixels needs
    ``2N - 1``: no object-to-sensor offset reaches further); what it cuts is recorded. Each
    channel is normalised as the input was (sum 1 stays sum 1 of the kept window); ``info``
    gains ``scale`` (the magnification applied after the PSF was resampled to the frame's
    pitch) and ``scale_cut_fraction`` (the light outside ``max_shape``).

    Examples
    --------
    >>> p = load_psf(np.outer(np.hanning(21), np.hanning(21)))
    >>> q = scale_psf(p, 1.5)
    >>> q.shape, q.info["scale"], round(float(q.array.sum()), 12)
    ((32, 32), 1.5, 1.0)
    """
    p = psf if isinstance(psf, PSF) else load_psf(psf)
    s = positive("scale", scale)
    a = np.asarray(p.array, dtype=np.float64)
    out = magnify(a, s, max_shape)
    total = a.sum(axis=(0, 1))
    kept = out.sum(axis=(0, 1))
    if np.any(kept <= 0):
        raise ClfzaError(f"the PSF magnified by {s:.4g} and cut to {max_shape} holds no light")
    out = out * (total / kept)  # the input's normalisation, on the kept window
    out = np.ascontiguousarray(np.maximum(out, 0.0))
    out.flags.writeable = False
    full = total * 1.0
    info = {**p.info, "scale": s, "scale_cut_fraction": float(np.max(1.0 - kept / full)),
            "shape": list(out.shape)}
    return PSF(array=out, pitch=p.pitch, info=info)


#: Light a PSF may lose when :func:`crop_to_support` cuts its dark tail (relative to its sum).
SUPPORT_CUT = 1e-4


def crop_to_support(psf: PSF | np.ndarray, cut: float = SUPPORT_CUT) -> PSF:
    """The PSF cut to the centred box that holds all but ``cut`` of its light: the padded
    grid of the linear-convolution model is sized by the kernel's array (the sensor plus half
    the kernel per axis), and a full-aperture mask's captured PSF is often larger than its
    shadow, its tail dark (or holding only the capture's clipped noise).

    Per axis the box's half-width is the smallest that leaves at most ``cut / 2`` of the
    light (all channels together) in the rows (columns) outside it, so the box loses at most
    ``cut``. The box is centred on ``(H // 2, W // 2)``, which stays the centre. Each channel
    is renormalised to its sum before the cut. ``info`` gains ``support_cut``: the shape
    before and after, and the light cut (the largest channel's fraction).

    Parameters
    ----------
    psf : PSF or ndarray (H, W) or (H, W, C)
    cut : float
        The largest fraction of the light cut, in ``[0, 0.1]`` (0: keep every lit row).

    Returns
    -------
    PSF

    Examples
    --------
    >>> a = np.zeros((41, 41)); a[15:26, 15:26] = 1.0
    >>> q = crop_to_support(a)
    >>> q.shape, q.info["support_cut"]["light_cut"]
    ((11, 11), 0.0)
    """
    p = psf if isinstance(psf, PSF) else load_psf(psf)
    c = float(cut)
    if not 0.0 <= c <= 0.1:
        raise ClfzaError(f"cut must be in [0, 0.1], got {cut!r}")
    a = np.asarray(p.array, dtype=np.float64)
    grey = a.sum(axis=2) if a.ndim == 3 else a
    total = float(grey.sum())
    if not np.isfinite(total) or total <= 0:
        raise ClfzaError(f"the PSF has no light (sum {total:.3g})")
    half = []
    for axis in (0, 1):
        m = grey.sum(axis=1 - axis) / total  # light per row (axis 0) or column
        n, cen = m.size, m.size // 2
        # light outside [cen - r, cen + r] for every r: both tails' cumulative sums
        left = np.concatenate([[0.0], np.cumsum(m[:cen])])  # left[i]: rows < i
        right = np.concatenate([[0.0], np.cumsum(m[::-1][:n - cen - 1])])  # rows >= n - i
        rs = np.arange(max(cen, n - cen - 1) + 1)
        out = left[np.clip(cen - rs, 0, cen)] + right[np.clip(n - cen - 1 - rs, 0, n - cen - 1)]
        ok = np.nonzero(out <= 0.5 * c + 1e-15)[0]
        half.append(int(ok[0]) if ok.size else int(rs[-1]))
    (ry, rx), (h, w) = half, grey.shape
    cy, cx = h // 2, w // 2
    y0, y1 = max(0, cy - ry), min(h, cy + ry + 1)
    x0, x1 = max(0, cx - rx), min(w, cx + rx + 1)
    # keep the centre at the new array's (H' // 2, W' // 2): odd sizes, symmetric
    out = np.ascontiguousarray(a[y0:y1, x0:x1])
    sums, kept = a.sum(axis=(0, 1)), out.sum(axis=(0, 1))
    if np.any(kept <= 0):
        raise ClfzaError("cutting the PSF's tail left a channel without light")
    lost = float(np.max(1.0 - kept / sums))
    out = out * (sums / kept)
    out.flags.writeable = False
    info = {**p.info, "support_cut": {"from": list(a.shape[:2]), "to": list(out.shape[:2]),
                                      "light_cut": lost, "cut": c},
            "shape": list(out.shape)}
    return PSF(array=out, pitch=p.pitch, info=info)
