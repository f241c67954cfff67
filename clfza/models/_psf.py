"""Measured point-spread functions (PSFs) for any mask-based lensless camera.

A PSF *file* (the picture of a point source taken through the mask) becomes the kernel of a
linear-convolution forward model: ``frame = crop(object (*) psf)``, the linear convolution of
the object with the PSF on a padded FFT grid, cropped to the sensor. The :class:`PSF` record
and the reading and processing steps live in :mod:`clfza.models._psf_steps` (re-exported here); this
module chains them (:func:`load_psf`) and handles depth stacks.

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
files) and :func:`select_psf_depth` picks the depth at which the back-propagated measurement
is sharpest (:func:`clfza.focus.sharpness`).
"""

from __future__ import annotations

import math
import warnings
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import scipy.fft
import tifffile
from scipy.ndimage import gaussian_filter
from scipy.signal.windows import tukey

from .. import io as fio
from ..errors import ClfzaError, finite_image, positive, positive_int
from ..focus import METRICS, central_mask, sharpness
from ._psf_steps import (  # noqa: F401  (re-exported: the PSF record, constants and steps)
    BORDER_FRACTION,
    CENTERINGS,
    CLIP_WARN_FRACTION,
    MAX_PSF_PIXELS,
    NORMALISATIONS,
    PSF,
    Source,
    _center,
    _check_dtype,
    _check_nonzero,
    _clip_negatives,
    _file_layout,
    _normalise,
    _read_array,
    _subtract_background,
    _subtract_dark,
    _to_channels,
    bin_sum,
    border_background,
    resample,
    shift_image,
)

#: Score spread (relative) below which a depth-score curve is called flat.
FLAT_TOLERANCE = 0.01


class PSFDepthWarning(UserWarning):
    """The depth-selection score curve is flat or peaks at an end of the stack."""


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
    a = np.ascontiguousarray(_normalise(a, normalise), dtype=np.float64)
    info["shape"] = list(a.shape)
    a.flags.writeable = False
    return PSF(array=a, pitch=pitch, info=info)


# ----------------------------------------------------------------------------------------
# public: depth stacks
# ----------------------------------------------------------------------------------------
def _check_depths(depths: Sequence[float], n: int | None) -> tuple[float, ...]:
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
        _check_dtype(np.dtype(dtype), f"PSF stack {str(p)!r}")
        total = int(np.prod(shape[:3]))
        if total > max_pixels:
            raise ClfzaError(f"PSF stack {str(p)!r} has {total} pixels, more than "
                             f"max_pixels = {max_pixels}")
        fio.check_layout_memory(f"PSF stack {str(p)!r}", tuple(int(v) for v in shape),
                                np.dtype(dtype).itemsize, np.dtype(dtype).itemsize)
        if p.suffix.lower() == ".npy":
            return list(np.load(p, mmap_mode="r", allow_pickle=False))
        return _tiff_pages(p)
    a = np.asarray(source)
    if a.ndim not in (3, 4):
        raise ClfzaError(f"a PSF stack array must be (D, H, W) or (D, H, W, 3), got shape "
                         f"{a.shape}")
    return list(a)


def _tiff_pages(p: Path) -> list[np.ndarray]:

    out = []
    try:
        with tifffile.TiffFile(p) as tf:
            for pg in tf.pages:
                a = np.asarray(pg.asarray())
                if a.ndim == 3 and a.shape[0] in (3, 4) and a.shape[-1] not in (3, 4):
                    a = np.moveaxis(a, 0, -1)
                out.append(a)
    except Exception as exc:
        raise ClfzaError(f"cannot read TIFF stack {str(p)!r}: the file is corrupt or uses an "
                         f"unsupported encoding ({' '.join(str(exc).split())[:160]})") from None
    return out


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
    ds = _check_depths(depths, len(slices))
    psfs = [load_psf(s, **options) for s in slices]
    shapes = {p.shape for p in psfs}
    if len(shapes) != 1:
        raise ClfzaError(f"the PSFs of a stack must share one shape, got {sorted(shapes)}")
    arr = np.stack([p.array for p in psfs])
    arr.flags.writeable = False
    return PSFStack(arrays=arr, depths=ds, pitch=psfs[0].pitch,
                    infos=tuple(p.info for p in psfs))


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


def _prepare_measurement(y: np.ndarray, highpass: float, taper: float) -> np.ndarray:
    a = finite_image("measurement", y)
    if a.ndim == 3:
        a = a.mean(axis=2)
    a = a - a.mean()
    if highpass > 0:
        a = a - gaussian_filter(a, float(highpass), mode="nearest")
    if taper > 0:
        a = a * np.outer(tukey(a.shape[0], taper), tukey(a.shape[1], taper))
    return a


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
                     highpass: float = 8.0, taper: float = 0.25, margin: float = 0.15,
                     flat: str = "warn") -> tuple[int, np.ndarray]:
    """Pick the PSF of a depth stack under which the measurement back-propagates sharpest.

    ``y`` (DC-free; its mean is removed again) is high-passed and tapered as in
    :class:`clfza.focus.FastBP`, correlated with each PSF (:func:`back_project`, the adjoint
    of the convolution model; channels of ``y`` and of the PSFs are averaged) and scored with
    :func:`clfza.focus.sharpness` on the central region (``margin`` cut on each side).

    Parameters
    ----------
    y : ndarray (H, W) or (H, W, 3)
        The measurement on the frame's grid (the PSFs' pitch).
    stack : PSFStack, ndarray (D, H, W[, 3]) or list of arrays/PSFs
    depths : sequence of float, optional
        Depth of each PSF (mm); taken from a PSFStack when omitted. Used in messages.
    metric : str
        One of :data:`clfza.focus.METRICS`. ``"mix"`` (default) and ``"tamura"`` are scale
        invariant enough to compare PSFs of different scale: on synthetic GZP and binary FZA
        stacks (five shadow scales 0.20-0.28 mm, with and without aperture, Gaussian noise
        of 0, 10 and 50 % of the measurement's spread) both picked the true PSF 60/60 times;
        ``"gradient"`` and ``"laplacian"`` favour the larger shadows (36/60 and 42/60).
    flat : {"warn", "error"}
        What to do when the scores are flat (max/min within 1 %): warn with the scores
        (:class:`PSFDepthWarning`) or raise :class:`ClfzaError`. A maximum at an end of the
        stack always warns.

    Returns
    -------
    (index, scores)
        Index of the sharpest PSF and the score of every PSF (larger = sharper).
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
        labels = [f"{d:g} mm" for d in _check_depths(depths, len(kernels))]
    a = _prepare_measurement(y, highpass, taper)
    mask = central_mask(a.shape, margin)
    scores = np.empty(len(kernels))
    for k, h in enumerate(kernels):
        h2 = finite_image(f"PSF {k}", h)
        h2 = h2.mean(axis=2) if h2.ndim == 3 else h2
        scores[k] = sharpness(back_project(a, h2), metric, mask)
    _flat_or_edge(scores, metric, labels, flat)
    return int(np.argmax(scores)), scores
