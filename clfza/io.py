"""Raw frames in, images out: reading, validation, calibration, cropping and writing.

Reading
    :func:`read_frame` reads PNG (imageio; 16-bit colour PNGs, which Pillow truncates to 8
    bits, with a small decoder here), TIFF (tifffile) and NPY files, 8/16-bit unsigned
    integer or floating point, grey ``(H, W)`` or colour ``(H, W, 3)``; anything else (a
    corrupt file, an unknown suffix, 1/32-bit or signed integers, NaN/Inf, an empty or
    wrongly shaped array) raises :class:`~clfza.errors.ClfzaError` with one sentence.
    Frames stay in the sensor's own units (digital numbers); nothing is rescaled, so dark and
    flat frames from the same sensor apply directly.

Calibration and geometry
    :func:`subtract_dark`, :func:`flat_field`, :func:`demosaic` (2x2 superpixel binning of a
    Bayer mosaic) and :func:`center_crop` (the paper crops the 4656 x 3522 frame to 2048^2
    around its centre).

The observation
    :func:`frame_to_measurement` turns a raw frame into the DC-free observation ``y`` in the
    units of the operator ``K`` (see its docstring for the gain calibration).

Writing
    :func:`write_image` (16-bit PNG, 16-bit or float32 TIFF, float NPY) through
    :mod:`clfza.outputs`: atomic, and never over an existing file unless ``force``.
"""

from __future__ import annotations

import io as _io
import logging
import math
import struct
import zlib
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from . import limits
from .camera import Camera
from .errors import ClfzaError, in_range, positive
from .outputs import atomic_write_bytes

log = logging.getLogger(__name__)

FRAME_SUFFIXES = {".png": "png", ".tif": "tiff", ".tiff": "tiff", ".npy": "npy"}
BAYER_PATTERNS = ("RGGB", "BGGR", "GRBG", "GBRG")
SCALINGS = ("percentile", "minmax", "unit")
MIN_SIDE = 4  # smallest frame side accepted
HUGE_VALUE = 1e150  # largest |value| whose square (and sums of squares) float64 holds


@dataclass(frozen=True)
class FrameInfo:
    """Where a frame came from and what it was stored as."""

    path: str
    format: str
    dtype: str
    shape: tuple[int, ...]
    bit_depth: int | None  # 8 or 16 for integer frames, None for floating point

    def to_dict(self) -> dict:
        d = dict(self.__dict__)
        d["shape"] = list(self.shape)
        return d


# ----------------------------------------------------------------------------------------
# reading
# ----------------------------------------------------------------------------------------
def _png_ihdr(head: bytes) -> tuple[int, int, int, int, int] | None:
    """(width, height, bit depth, colour type, interlace) from a PNG's first 33 bytes."""
    if len(head) < 33 or head[12:16] != b"IHDR":
        return None
    w, h, bits, ctype, _, _, interlace = struct.unpack(">IIBBBBB", head[16:29])
    return w, h, bits, ctype, interlace


def _read_png(p: Path) -> np.ndarray:
    """PNG via imageio (Pillow), except 16-bit colour PNGs, which Pillow truncates to 8 bits:
    those are decoded here (:func:`_decode_png16`)."""
    import imageio.v3 as iio

    with open(p, "rb") as fh:
        head = fh.read(33)
    if head[:8] != b"\x89PNG\r\n\x1a\n":
        raise ClfzaError(f"{str(p)!r} is not a PNG file (bad signature); the file is corrupt "
                         "or has the wrong suffix")
    ihdr = _png_ihdr(head)
    if ihdr is None:
        raise ClfzaError(f"cannot read PNG {str(p)!r}: the header is corrupt")
    if ihdr[2] == 16 and ihdr[3] in (2, 4, 6):
        return _decode_png16(p, ihdr)
    try:
        return np.asarray(iio.imread(p, extension=".png"))
    except Exception as exc:  # imageio/Pillow raise many kinds
        raise ClfzaError(f"cannot read PNG {str(p)!r}: the file is corrupt or truncated "
                         f"({_one_line(exc)})") from None


_PNG_CHANNELS = {0: 1, 2: 3, 4: 2, 6: 4}
ZLIB_MAX_RATIO = 1032  # deflate's largest expansion (258-byte matches in ~2-bit codes)
#: working bytes per stored sample of clfza's 16-bit colour PNG decoder (inflated rows, two
#: int32 planes for the filters, the byte-swapped copy)
PNG16_DECODER_BYTES = 22.0


def frame_layout(p: Path) -> tuple[tuple[int, ...], int, float] | None:
    """``(shape, bytes per sample, decoder bytes per sample)`` of a frame file from its
    header alone (nothing is decoded); None when the header cannot be read (the reader then
    names the problem). A multi-page TIFF gives its first page."""
    fmt = FRAME_SUFFIXES.get(p.suffix.lower())
    try:
        if fmt == "png":
            with open(p, "rb") as fh:
                ihdr = _png_ihdr(fh.read(33))
            if ihdr is None:
                return None
            w, h, bits, ctype, _ = ihdr
            chans = {0: 1, 2: 3, 3: 3, 4: 2, 6: 4}.get(ctype, 1)
            item = 2 if bits == 16 else 1
            dec = PNG16_DECODER_BYTES if (bits == 16 and ctype in (2, 4, 6)) else 2.0 * item
            return ((h, w) if chans == 1 else (h, w, chans)), item, dec
        if fmt == "tiff":
            import tifffile

            with tifffile.TiffFile(p) as tf:
                page = tf.pages[0]
                return tuple(int(v) for v in page.shape), int(page.dtype.itemsize), \
                    float(page.dtype.itemsize)
        if fmt == "npy":
            with open(p, "rb") as fh:
                version = np.lib.format.read_magic(fh)
                read = (np.lib.format.read_array_header_1_0 if version == (1, 0)
                        else np.lib.format.read_array_header_2_0)
                shape, _, dtype = read(fh)
            return tuple(int(v) for v in shape), int(np.dtype(dtype).itemsize), 0.0
    except Exception:  # a corrupt header: the reader names the problem
        return None
    return None


def check_layout_memory(label: str, shape: tuple[int, ...], itemsize: int,
                        decoder: float = 0.0) -> None:
    """Refuse a frame by its declared size before it is decoded (:mod:`clfza.limits`)."""
    if len(shape) < 2:
        return
    if len(shape) == 2 or (len(shape) == 3 and shape[2] in (1, 2, 3, 4)):
        hw = shape[:2]
    else:  # planar (C, H, W) or a stack (N, H, W[, C])
        hw = shape[1:3]
    limits.check_pixels(label, hw)
    dims = "x".join(str(int(v)) for v in shape)
    limits.check_memory(f"reading {label}", limits.frame_bytes(
        shape, itemsize, decoder_bytes_per_sample=decoder),
        f"{dims} samples of {itemsize} byte(s), decoded and converted to float64",
        f"crop the frame before reading it with clfza, or raise the limit with {limits.ENV}")


def _decode_png16(p: Path, ihdr: tuple[int, int, int, int, int]) -> np.ndarray:
    """Decode a non-interlaced 16-bit grey-alpha, RGB or RGBA PNG (all five row filters)."""
    w, h, bits, ctype, interlace = ihdr
    label = repr(str(p))
    if interlace:
        raise ClfzaError(f"PNG {label} is an interlaced 16-bit colour image, which clfza does "
                         "not decode; save it without interlacing or as TIFF")
    data = p.read_bytes()
    pos, idat = 8, []
    while pos + 8 <= len(data):
        (n,) = struct.unpack(">I", data[pos:pos + 4])
        kind = data[pos + 4:pos + 8]
        chunk = data[pos + 8:pos + 8 + n]
        if len(chunk) != n or pos + 12 + n > len(data):
            raise ClfzaError(f"cannot read PNG {label}: the file is truncated")
        if zlib.crc32(kind + chunk) != struct.unpack(">I", data[pos + 8 + n:pos + 12 + n])[0]:
            raise ClfzaError(f"cannot read PNG {label}: CRC error in a {kind!r} chunk (corrupt)")
        if kind == b"IDAT":
            idat.append(chunk)
        if kind == b"IEND":
            break
        pos += 12 + n
    bpp = 2 * _PNG_CHANNELS[ctype]
    expected = h * (1 + w * bpp)
    packed = sum(len(c) for c in idat)
    if h == 0 or w == 0 or packed * ZLIB_MAX_RATIO + 64 < expected:
        # deflate cannot expand more than ~1032:1: the data cannot hold the declared image
        raise ClfzaError(f"cannot read PNG {label}: the image data is truncated ({packed} "
                         f"compressed bytes cannot hold the declared {w}x{h} image)")
    try:
        dec = zlib.decompressobj()
        raw = dec.decompress(b"".join(idat), expected + 1)
    except zlib.error as exc:
        raise ClfzaError(f"cannot read PNG {label}: corrupt image data ({exc})") from None
    if len(raw) != expected:
        raise ClfzaError(f"cannot read PNG {label}: the image data is truncated")
    rows = np.frombuffer(raw, np.uint8).reshape(h, 1 + w * bpp)
    ft = rows[:, 0]
    if ft.max() > 4:
        raise ClfzaError(f"cannot read PNG {label}: invalid row filter (corrupt)")
    filt = rows[:, 1:].reshape(h, w, bpp).astype(np.int32)
    out = _png_unfilter(filt, ft)
    px = np.ascontiguousarray(out.astype(np.uint8)).view(">u2").reshape(h, w, bpp // 2)
    return px.astype(np.uint16)


def _png_unfilter(filt: np.ndarray, ft: np.ndarray) -> np.ndarray:
    """Undo PNG row filters on (h, w, bytes per pixel) int32 data.

    Rows that use only None/Sub/Up are undone row by row (Sub as a cumulative sum mod 256);
    Average and Paeth depend on the left and upper neighbours, so those images are undone along
    anti-diagonals (h + w vectorised steps).
    """
    h, w, _ = filt.shape
    out = np.zeros((h + 1, w + 1, filt.shape[2]), np.int32)  # zero row/column of padding
    if ft.max() <= 2:
        for r in range(h):
            f = int(ft[r])
            x = filt[r]
            if f == 1:
                x = np.cumsum(x, axis=0)
            elif f == 2:
                x = x + out[r, 1:]
            out[r + 1, 1:] = x & 255
        return out[1:, 1:]
    for t in range(h + w - 1):
        rs = np.arange(max(0, t - w + 1), min(h - 1, t) + 1)
        js = t - rs
        x = filt[rs, js]
        a, b, c = out[rs + 1, js], out[rs, js + 1], out[rs, js]
        f = ft[rs][:, None]
        pp = a + b - c
        pa, pb, pc = np.abs(pp - a), np.abs(pp - b), np.abs(pp - c)
        paeth = np.where((pa <= pb) & (pa <= pc), a, np.where(pb <= pc, b, c))
        pred = np.select([f == 1, f == 2, f == 3, f == 4], [a, b, (a + b) >> 1, paeth], 0)
        out[rs + 1, js + 1] = (x + pred) & 255
    return out[1:, 1:]


def _encode_png(arr: np.ndarray) -> bytes:
    """A PNG of an 8/16-bit grey or RGB array (no filtering, zlib level 6).

    Written here rather than with Pillow, which cannot store 16-bit colour.
    """
    a = np.asarray(arr)
    if a.dtype not in (np.uint8, np.uint16):
        raise ClfzaError("PNG holds 8- or 16-bit unsigned integers only")
    if a.ndim == 3 and a.shape[2] == 1:
        a = a[..., 0]
    if a.ndim == 2:
        ctype: int | None = 0
    else:
        ctype = {3: 2, 4: 6, 2: 4}.get(a.shape[2]) if a.ndim == 3 else None
    if ctype is None:
        raise ClfzaError(f"PNG holds grey or RGB images, got shape {a.shape}")
    h, w = a.shape[:2]
    bits = 8 * a.dtype.itemsize
    body = np.ascontiguousarray(a.astype(a.dtype.newbyteorder(">"))).view(np.uint8)
    body = body.reshape(h, -1)
    rows = np.concatenate([np.zeros((h, 1), np.uint8), body], axis=1)

    def chunk(kind: bytes, payload: bytes) -> bytes:
        return (struct.pack(">I", len(payload)) + kind + payload
                + struct.pack(">I", zlib.crc32(kind + payload)))

    ihdr = struct.pack(">IIBBBBB", w, h, bits, ctype, 0, 0, 0)
    return (b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", ihdr)
            + chunk(b"IDAT", zlib.compress(rows.tobytes(), 6)) + chunk(b"IEND", b""))


def _read_tiff(p: Path) -> np.ndarray:
    import tifffile

    try:
        with tifffile.TiffFile(p) as tf:
            if len(tf.series) == 0:
                raise ClfzaError(f"TIFF {str(p)!r} contains no readable image (the file is "
                                 "corrupt or truncated)")
            series = tf.series[0]
            pages = len(tf.pages)
            if pages > 1:
                raise ClfzaError(f"TIFF {str(p)!r} holds {pages} pages (a stack); clfza reads "
                                 "one frame per file")
            arr = series.asarray()
            planar = getattr(tf.pages[0], "planarconfig", None)
    except ClfzaError:
        raise
    except Exception as exc:
        raise ClfzaError(f"cannot read TIFF {str(p)!r}: the file is corrupt, truncated or uses "
                         f"an unsupported encoding ({_one_line(exc)})") from None
    arr = np.asarray(arr)
    # planar RGB (3, H, W) -> (H, W, 3)
    if arr.ndim == 3 and arr.shape[0] in (3, 4) and arr.shape[-1] not in (3, 4):
        if planar is None or int(planar) == 2:
            arr = np.moveaxis(arr, 0, -1)
    return arr


def _read_npy(p: Path) -> np.ndarray:
    with open(p, "rb") as fh:
        magic = fh.read(6)
    if magic[:4] == b"PK\x03\x04":
        raise ClfzaError(f"{str(p)!r} is an .npz archive; save one array with numpy.save")
    if magic != b"\x93NUMPY":
        raise ClfzaError(f"{str(p)!r} is not an NPY file (bad signature); the file is corrupt "
                         "or has the wrong suffix")
    try:
        arr = np.load(p, allow_pickle=False)
    except ValueError as exc:
        msg = _one_line(exc)
        if "pickle" in msg.lower():
            raise ClfzaError(f"NPY {str(p)!r} holds Python objects, not a numeric array") \
                from None
        raise ClfzaError(f"cannot read NPY {str(p)!r}: the file is corrupt or not a .npy "
                         f"array ({msg})") from None
    except Exception as exc:
        raise ClfzaError(f"cannot read NPY {str(p)!r}: the file is corrupt or truncated "
                         f"({_one_line(exc)})") from None
    if not isinstance(arr, np.ndarray):  # np.load returns an NpzFile for .npz content
        raise ClfzaError(f"{str(p)!r} is an .npz archive; save one array with numpy.save")
    return arr


def _one_line(exc: BaseException) -> str:
    s = " ".join(str(exc).split())
    s = s or type(exc).__name__
    return s if len(s) <= 160 else s[:157] + "..."


def check_frame(arr, name: str = "frame") -> tuple[np.ndarray, int | None]:
    """Validate a raw frame and return it as float64 with its integer bit depth.

    Accepted: ``uint8`` and ``uint16`` (8/16-bit; 10-14-bit sensors store into ``uint16``),
    ``float16/32/64``; shapes ``(H, W)``, ``(H, W, 1)``, ``(H, W, 3)`` and ``(H, W, 4)`` with
    a constant alpha channel (dropped). Both sides must be at least 4 pixels.

    Raises
    ------
    ClfzaError
        Booleans (1-bit), signed or 32/64-bit integers, complex or object data, the wrong
        rank or channel count, an empty array, NaN or Inf.
    """
    a = np.asarray(arr)
    kind, size = a.dtype.kind, a.dtype.itemsize
    if kind == "b":
        raise ClfzaError(f"{name} is 1-bit (boolean); clfza reads 8- or 16-bit sensor frames")
    if kind == "u" and size in (1, 2):
        bits: int | None = 8 * size
    elif kind == "f":
        bits = None
    elif kind in "iu":
        raise ClfzaError(f"{name} has an unsupported bit depth / sample type ({a.dtype}: "
                         f"{'signed ' if kind == 'i' else ''}{8 * size}-bit integer); use "
                         "8- or 16-bit unsigned integers or floating point")
    else:
        raise ClfzaError(f"{name} has unsupported data type {a.dtype}; use 8- or 16-bit "
                         "unsigned integers or floating point")
    if a.size == 0:
        raise ClfzaError(f"{name} is empty (shape {a.shape})")
    if a.ndim == 3 and a.shape[2] == 4:
        alpha = a[..., 3]
        if alpha.min() != alpha.max():
            raise ClfzaError(f"{name} is RGBA with a varying alpha channel; save it as grey "
                             "or RGB")
        a = a[..., :3]
    if a.ndim == 3 and a.shape[2] == 1:
        a = a[..., 0]
    if a.ndim not in (2, 3) or (a.ndim == 3 and a.shape[2] != 3):
        raise ClfzaError(f"{name} must be grey (H, W) or RGB (H, W, 3), got shape {a.shape}")
    if min(a.shape[:2]) < MIN_SIDE:
        raise ClfzaError(f"{name} is too small ({a.shape[0]}x{a.shape[1]} pixels; at least "
                         f"{MIN_SIDE}x{MIN_SIDE})")
    f = a.astype(np.float64)
    if kind == "f":
        finite = np.isfinite(f)
        if not finite.all():
            bad = int(f.size - np.count_nonzero(finite))
            raise ClfzaError(f"{name} contains {bad} NaN or Inf value(s)")
    return f, bits


def read_frame(path: str | Path, name: str | None = None) -> tuple[np.ndarray, FrameInfo]:
    """Read and validate one frame file.

    Parameters
    ----------
    path : str or Path
        A ``.png`` (8/16-bit, grey or RGB), ``.tif``/``.tiff`` (8/16-bit or float) or ``.npy``
        (uint8/uint16/float) file.
    name : str, optional
        How to call the frame in messages (default: the path).

    Returns
    -------
    (frame, info)
        ``frame``: float64 ``(H, W)`` or ``(H, W, 3)`` in the file's own units (digital
        numbers); ``info``: :class:`FrameInfo`.
    """
    p = Path(path)
    label = name or repr(str(p))
    if not p.exists():
        raise ClfzaError(f"{label} does not exist")
    if p.is_dir():
        raise ClfzaError(f"{label} is a folder, not a frame file")
    fmt = FRAME_SUFFIXES.get(p.suffix.lower())
    if fmt is None:
        raise ClfzaError(f"{label} has unsupported suffix {p.suffix or '(none)'!r}; clfza reads "
                         ".png, .tif/.tiff and .npy (lossy formats such as JPEG destroy the "
                         "zone pattern)")
    try:
        if p.stat().st_size == 0:
            raise ClfzaError(f"{label} is an empty file (0 bytes)")
    except OSError as exc:
        raise ClfzaError(f"cannot read {label}: {_one_line(exc)}") from None
    layout = frame_layout(p)
    if layout is not None:
        check_layout_memory(label, *layout)
    try:
        raw = {"png": _read_png, "tiff": _read_tiff, "npy": _read_npy}[fmt](p)
    except PermissionError:
        raise ClfzaError(f"cannot read {label}: permission denied") from None
    except OSError as exc:
        raise ClfzaError(f"cannot read {label}: {_one_line(exc)}") from None
    frame, bits = check_frame(raw, name=label)
    info = FrameInfo(path=str(p), format=fmt, dtype=str(raw.dtype), shape=tuple(raw.shape),
                     bit_depth=bits)
    log.debug("read %s: %s %s", p, raw.dtype, raw.shape)
    return frame, info


def read_scene(path: str | Path) -> np.ndarray:
    """Read a scene image for simulation, scaled to [0, 1] (integer images by their dtype's
    maximum; float images as stored, and they must not be negative)."""
    frame, info = read_frame(path)
    if info.bit_depth is not None:
        frame = frame / (2**info.bit_depth - 1)
    elif frame.min() < 0:
        raise ClfzaError(f"scene {str(path)!r} has negative intensities (min "
                         f"{frame.min():.3g})")
    return frame


# ----------------------------------------------------------------------------------------
# calibration
# ----------------------------------------------------------------------------------------
def _same_shape(frame: np.ndarray, other: np.ndarray, what: str) -> np.ndarray:
    if other.shape == frame.shape:
        return other
    if other.ndim == 2 and frame.ndim == 3 and other.shape == frame.shape[:2]:
        return other[..., None]
    raise ClfzaError(f"the {what} has shape {other.shape}, the frame {frame.shape}; they must "
                     "come from the same sensor mode")


def subtract_dark(frame: np.ndarray, dark: np.ndarray) -> np.ndarray:
    """``frame - dark`` (same shape; a grey dark frame applies to every colour channel).

    Negative results (read noise around a black level) are kept: clipping them would bias
    the mean that :func:`frame_to_measurement` divides by.
    """
    return frame - _same_shape(frame, np.asarray(dark, dtype=np.float64), "dark frame")


def flat_field(frame: np.ndarray, flat: np.ndarray) -> np.ndarray:
    """Divide by the flat field normalised to mean 1 (per channel for an RGB flat).

    The flat should already be dark-subtracted (or be bright enough that its dark level does
    not matter). Every flat pixel must be positive.
    """
    f = _same_shape(frame, np.asarray(flat, dtype=np.float64), "flat field")
    if f.min() <= 0:
        raise ClfzaError(f"the flat field has {int(np.count_nonzero(f <= 0))} pixel(s) <= 0; "
                         "a flat field must be positive everywhere")
    norm = f / f.mean(axis=(0, 1), keepdims=True)
    return frame / norm


def demosaic(raw: np.ndarray, pattern: str) -> np.ndarray:
    """Turn a Bayer mosaic into an RGB frame by 2x2 superpixel binning.

    Each 2x2 cell (one red, two green, one blue photosite) becomes one RGB pixel: red and
    blue as measured, green the mean of the two greens. The result has half the rows and
    columns, and its pixel pitch is twice the sensor's (the CLI doubles the camera's pitch).

    Why binning rather than bilinear interpolation: every output value is a measurement, not
    an interpolation, so no demosaicing pattern (zipper, false colour) is imprinted on the
    fine zones of the FZA shadow, and the channels stay co-sited. What it gives up -- half the
    sampling rate -- is usually not there to lose: the system's band limit
    ``rho_c = R' / r1'^2`` lies below the pixel Nyquist frequency in typical FZA setups
    (``Camera.suggested_bin`` >= 2 for the paper's experiment), and the binned grid is closer to
    critical sampling of ``H_T``.

    Parameters
    ----------
    raw : array (H, W)
        The mosaic (odd trailing rows/columns are dropped).
    pattern : {"RGGB", "BGGR", "GRBG", "GBRG"}
        Colour of the 2x2 cell read row by row from the top-left photosite.
    """
    pat = str(pattern).upper()
    if pat not in BAYER_PATTERNS:
        raise ClfzaError(f"Bayer pattern must be one of {BAYER_PATTERNS}, got {pattern!r}")
    a = np.asarray(raw, dtype=np.float64)
    if a.ndim != 2:
        raise ClfzaError(f"a Bayer mosaic is a single-channel (H, W) frame, got shape {a.shape}")
    h, w = (a.shape[0] // 2) * 2, (a.shape[1] // 2) * 2
    if h < 2 * MIN_SIDE or w < 2 * MIN_SIDE:
        raise ClfzaError(f"the Bayer mosaic is too small ({a.shape[0]}x{a.shape[1]})")
    a = a[:h, :w]
    cells = {(0, 0): a[0::2, 0::2], (0, 1): a[0::2, 1::2], (1, 0): a[1::2, 0::2],
             (1, 1): a[1::2, 1::2]}
    where = {(0, 0): pat[0], (0, 1): pat[1], (1, 0): pat[2], (1, 1): pat[3]}
    r = next(cells[k] for k, c in where.items() if c == "R")
    b = next(cells[k] for k, c in where.items() if c == "B")
    g1, g2 = (cells[k] for k, c in where.items() if c == "G")
    return np.stack([r, 0.5 * (g1 + g2), b], axis=-1)


def parse_pair(text: str, what: str, *, integer: bool = True) -> tuple:
    """Parse ``"N"`` or ``"A,B"`` (also ``AxB``) into a pair; a single value repeats."""
    parts = [s for s in str(text).replace("x", ",").replace("X", ",").split(",")]
    if len(parts) not in (1, 2) or any(not s.strip() for s in parts):
        raise ClfzaError(f"{what} must be 'N' or 'A,B', got {text!r}")
    try:
        vals = [int(s) if integer else float(s) for s in parts]
    except ValueError:
        kind = "integers" if integer else "numbers"
        raise ClfzaError(f"{what} must be {kind} ('N' or 'A,B'), got {text!r}") from None
    if not integer and not all(math.isfinite(v) for v in vals):
        raise ClfzaError(f"{what} must be finite, got {text!r}")
    if len(vals) == 1:
        vals = vals * 2
    return tuple(vals)


def center_crop(frame: np.ndarray, shape: tuple[int, int],
                center: tuple[float, float] | None = None, align: int = 1
                ) -> tuple[np.ndarray, tuple[int, int]]:
    """Crop ``shape`` pixels around ``center`` (row, col; default the frame's centre).

    ``align`` rounds the crop's origin down to a multiple (2 keeps a Bayer mosaic's phase).

    The paper crops the sensor's 4656 x 3522 frame to 2048^2 around the centre of the FZA
    shadow; ``center`` lets the shadow's centre, when it is off the frame's, be given.

    Returns
    -------
    (crop, origin)
        The crop (a view) and the (row, col) of its top-left pixel in the frame.
    """
    H, W = frame.shape[:2]
    try:
        h, w = (int(s) for s in shape)
    except (TypeError, ValueError):
        raise ClfzaError(f"crop must be two integers (rows, cols), got {shape!r}") from None
    if h < MIN_SIDE or w < MIN_SIDE:
        raise ClfzaError(f"crop {h}x{w} is too small (at least {MIN_SIDE}x{MIN_SIDE})")
    if h > H or w > W:
        raise ClfzaError(f"crop {h}x{w} is larger than the frame ({H}x{W}); use a smaller "
                         "--crop or a camera file whose shape fits the frame")
    cy, cx = (H / 2, W / 2) if center is None else (float(center[0]), float(center[1]))
    if not (0 <= cy <= H and 0 <= cx <= W):
        raise ClfzaError(f"centre ({cy:g}, {cx:g}) lies outside the {H}x{W} frame")
    y0 = int(round(cy - h / 2))
    x0 = int(round(cx - w / 2))
    if align > 1:
        y0, x0 = max(0, y0 - y0 % align), max(0, x0 - x0 % align)
    if y0 < 0 or x0 < 0 or y0 + h > H or x0 + w > W:
        raise ClfzaError(f"a {h}x{w} crop centred at ({cy:g}, {cx:g}) extends past the "
                         f"{H}x{W} frame; move the centre or crop less")
    return frame[y0:y0 + h, x0:x0 + w], (y0, x0)


# ----------------------------------------------------------------------------------------
# the observation y
# ----------------------------------------------------------------------------------------
def effective_pixels(camera: Camera, samples: int = 40) -> float:
    """``N_eff``: the mean number of sensor pixels that see one object point through the
    aperture (an object point at sensor position q reaches the pixels within ``R'`` of q).

    Equal to ``H W`` for a mask whose shadow covers the whole sensor from every point;
    computed on a ``samples x samples`` grid of object and sensor positions otherwise.
    """
    ny, nx = camera.shape
    Rs = camera.R_shadow
    if Rs is None or Rs >= math.hypot(*camera.sensor_size):
        return float(ny * nx)
    hy, hx = camera.sensor_size
    ys = (np.arange(samples) + 0.5) / samples * hy
    xs = (np.arange(samples) + 0.5) / samples * hx
    yy, xx = np.meshgrid(ys, xs, indexing="ij")
    pts = np.stack([yy.ravel(), xx.ravel()], axis=1)
    d2 = ((pts[:, None, :] - pts[None, :, :]) ** 2).sum(axis=-1)
    frac = float(np.mean(d2 <= Rs * Rs))
    return frac * ny * nx


def frame_to_measurement(frame, camera: Camera, *, object_mean: float = 0.5,
                         n_eff: float | None = None) -> np.ndarray:
    """The DC-free observation ``y`` (units of ``K``) of a raw frame with an unknown gain.

    Derivation. The frame is ``F = g conv(O, T)``: the sensor-plane object ``O`` convolved
    with the mask's shadow ``T = 1/2 + 1/2 c(r)`` (``c`` the zone pattern, mean zero), times
    an unknown gain ``g`` (exposure, quantum efficiency, ADC). Two of its parts matter:

    * the DC: ``mean(F) ~ g (1/2) N_eff mean(O)`` -- each object pixel lights, through the
      mask's mean transmittance 1/2, the ``N_eff`` sensor pixels that see it within the
      aperture's shadow (:func:`effective_pixels`; ``H W`` for an unbounded mask);
    * the AC: ``F - mean(F) = g (r1'^2 / (2 p^2)) K O``, because the Fourier transform of
      ``cos(pi r^2 / r1'^2)`` is ``r1'^2 sin(pi r1'^2 rho^2)`` and a discrete convolution
      carries a factor ``1 / p^2`` (:mod:`clfza.simulate` uses the same scale).

    Eliminating ``g`` with an assumed object mean ``m = mean(O)``::

        y = K O = (F - mean(F)) / mean(F) * (N_eff p^2 / r1'^2) * m

    so reconstructions of real frames are scaled such that the object's mean is ``m``. Only
    the scale rests on the assumption; the image's shape does not. ``m`` is the mean over the
    part of the scene whose light reaches the sensor: for a scene filling the sensor this
    reproduces :attr:`clfza.simulate.Measurement.y` to within a few percent (tested), while
    light from a scene larger than the view raises ``mean(F)`` and lowers the recovered scale.
    Colour frames are handled per channel (each with its own mean).

    Parameters
    ----------
    frame : array (H, W) or (H, W, 3)
        Dark-subtracted (and flat-fielded) frame on the camera's grid.
    camera : Camera
        The camera; ``frame`` must have its shape.
    object_mean : float
        Assumed mean ``m`` of the sensor-plane object, in (0, 1]; 0.5 by default.
    n_eff : float, optional
        Override ``N_eff`` (e.g. from a calibration shot).

    Returns
    -------
    ndarray
        ``y`` with the frame's shape, float64.
    """
    f = np.asarray(frame, dtype=np.float64)
    if f.ndim not in (2, 3) or f.size == 0:
        raise ClfzaError(f"frame must be (H, W) or (H, W, 3), got shape {f.shape}")
    if f.shape[:2] != tuple(camera.shape):
        raise ClfzaError(f"frame is {f.shape[0]}x{f.shape[1]} but the camera grid is "
                         f"{camera.shape[0]}x{camera.shape[1]}; crop it (--crop) or fix the "
                         "camera's shape")
    m = in_range("object_mean", object_mean, 1e-6, 1e6)
    ne = effective_pixels(camera) if n_eff is None else positive("n_eff", n_eff)
    big = float(np.max(np.abs(f)))
    if big > HUGE_VALUE:
        raise ClfzaError(f"frame values reach {big:.3g}: their squares overflow float64 "
                         f"(limit {HUGE_VALUE:.0e}); rescale the frame to sensor units")
    mean = f.mean(axis=(0, 1), keepdims=True)
    if np.any(mean <= 0):
        raise ClfzaError("the frame's mean is <= 0 (after dark subtraction): it is black or "
                         "over-corrected; check the exposure and the dark frame")
    ac = f - mean
    spread = np.sqrt(np.mean(ac**2, axis=(0, 1)))
    if np.any(spread <= 1e-12 * np.abs(mean.reshape(spread.shape))):
        raise ClfzaError("the frame is flat (no modulation): there is no zone pattern to "
                         "reconstruct from")
    return ac / mean * (ne * camera.pitch**2 / camera.r1p**2) * m


# ----------------------------------------------------------------------------------------
# writing
# ----------------------------------------------------------------------------------------
def scale_to_uint16(img: np.ndarray, scaling: str = "percentile",
                    percentiles: tuple[float, float] = (0.1, 99.9)) -> tuple[np.ndarray, dict]:
    """Map an image to 16 bits and say how.

    ``"percentile"`` (default): the ``percentiles`` (lo, hi) of the image map to 0 and 65535,
    values outside are clipped (a few hot or twin-image pixels do not squash the contrast);
    ``"minmax"``: the image's min and max map to 0 and 65535; ``"unit"``: the range [0, 1]
    maps to 0..65535, clipped (reconstructions are scaled so that the object's mean is the
    assumed ``object_mean``; see :func:`frame_to_measurement`). Colour images use one range for
    all channels. The returned dict (mode, lo, hi) goes into the JSON record.
    """
    a = np.asarray(img, dtype=np.float64)
    if scaling == "percentile":
        plo, phi = (float(v) for v in percentiles)
        if not 0 <= plo < phi <= 100:
            raise ClfzaError(f"percentiles must satisfy 0 <= lo < hi <= 100, got {percentiles}")
        lo, hi = (float(v) for v in np.percentile(a, [plo, phi]))
    elif scaling == "minmax":
        lo, hi = float(a.min()), float(a.max())
    elif scaling == "unit":
        lo, hi = 0.0, 1.0
    else:
        raise ClfzaError(f"scaling must be one of {SCALINGS}, got {scaling!r}")
    info = {"mode": scaling, "lo": lo, "hi": hi, "out_range": [0, 65535]}
    if scaling == "percentile":
        info["percentiles"] = [plo, phi]
    if hi <= lo:
        return np.zeros(a.shape, np.uint16), {**info, "note": "flat image"}
    u = np.clip((a - lo) / (hi - lo), 0.0, 1.0)
    info["clipped_fraction"] = float(np.mean((a < lo) | (a > hi)))
    return np.round(u * 65535).astype(np.uint16), info


def encode_png(arr: np.ndarray) -> bytes:
    """PNG bytes of a uint8/uint16 grey or RGB array (16-bit colour included)."""
    return _encode_png(arr)


def encode_tiff(arr: np.ndarray) -> bytes:
    """TIFF bytes of an array (tifffile; RGB as contiguous samples)."""
    import tifffile

    buf = _io.BytesIO()
    a = np.ascontiguousarray(arr)
    photometric = "rgb" if a.ndim == 3 and a.shape[2] == 3 else "minisblack"
    tifffile.imwrite(buf, a, photometric=photometric)
    return buf.getvalue()


def encode_npy(arr: np.ndarray) -> bytes:
    buf = _io.BytesIO()
    np.save(buf, np.asarray(arr), allow_pickle=False)
    return buf.getvalue()


def write_array(path: str | Path, arr: np.ndarray, force: bool = False) -> Path:
    """Write an array exactly (PNG/TIFF at its dtype, NPY as is); atomic, no overwrite."""
    return atomic_write_bytes(Path(path), encode_array(path, arr), force)


def check_output_options(path: str | Path, scaling: str = "percentile",
                         percentiles: tuple[float, float] = (0.1, 99.9)) -> None:
    """Validate an image output's suffix, scaling and percentiles -- before any work."""
    p = Path(path)
    if FRAME_SUFFIXES.get(p.suffix.lower()) is None:
        raise ClfzaError(f"cannot write {str(p)!r}: use .png, .tif/.tiff or .npy")
    if scaling not in SCALINGS:
        raise ClfzaError(f"scaling must be one of {SCALINGS}, got {scaling!r}")
    try:
        plo, phi = (float(v) for v in percentiles)
    except (TypeError, ValueError):
        raise ClfzaError(f"percentiles must be two numbers LO,HI, got {percentiles!r}") \
            from None
    if not 0 <= plo < phi <= 100:
        raise ClfzaError(f"percentiles must satisfy 0 <= lo < hi <= 100, got "
                         f"{plo:g},{phi:g}")


def encode_image(path: str | Path, img: np.ndarray, *, scaling: str = "percentile",
                 percentiles: tuple[float, float] = (0.1, 99.9),
                 tiff_float: bool = False) -> tuple[bytes, dict]:
    """The bytes :func:`write_image` writes to ``path`` (format from its suffix) and the
    scaling record; nothing is written (see :func:`clfza.outputs.atomic_write_many`)."""
    p = Path(path)
    fmt = FRAME_SUFFIXES.get(p.suffix.lower())
    a = np.asarray(img, dtype=np.float64)
    if fmt == "npy":
        return encode_npy(a), {"mode": "none", "dtype": "float64"}
    if fmt == "tiff" and tiff_float:
        return encode_tiff(a.astype(np.float32)), {"mode": "none", "dtype": "float32"}
    if fmt not in ("png", "tiff"):
        raise ClfzaError(f"cannot write {str(p)!r}: use .png, .tif/.tiff or .npy")
    u, info = scale_to_uint16(a, scaling, percentiles)
    data = encode_png(u) if fmt == "png" else encode_tiff(u)
    return data, {**info, "dtype": "uint16"}


def encode_array(path: str | Path, arr: np.ndarray) -> bytes:
    """The bytes :func:`write_array` writes to ``path``."""
    p = Path(path)
    fmt = FRAME_SUFFIXES.get(p.suffix.lower())
    if fmt is None:
        raise ClfzaError(f"cannot write {str(p)!r}: use .png, .tif/.tiff or .npy")
    a = np.asarray(arr)
    if fmt == "png":
        if a.dtype not in (np.uint8, np.uint16):
            raise ClfzaError("PNG holds 8- or 16-bit unsigned integers only")
        return encode_png(a)
    return encode_tiff(a) if fmt == "tiff" else encode_npy(a)


def write_image(path: str | Path, img: np.ndarray, *, force: bool = False,
                scaling: str = "percentile", percentiles: tuple[float, float] = (0.1, 99.9),
                tiff_float: bool = False) -> tuple[Path, dict]:
    """Write a reconstruction: ``.png`` 16-bit, ``.tif`` 16-bit (or float32 with
    ``tiff_float``), ``.npy`` float64; atomic and never over an existing file unless
    ``force``.

    Returns
    -------
    (path, scaling_info)
        ``scaling_info`` describes the 16-bit mapping (see :func:`scale_to_uint16`); for the
        float outputs it is ``{"mode": "none"}``.
    """
    p = Path(path)
    data, info = encode_image(p, img, scaling=scaling, percentiles=percentiles,
                              tiff_float=tiff_float)
    return atomic_write_bytes(p, data, force), info
