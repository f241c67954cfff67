"""Reading and validating raw frames (re-exported by :mod:`clfza.io`).

:func:`read_frame` reads PNG (imageio; 16-bit colour PNGs, which Pillow truncates to 8 bits,
with a small decoder here), TIFF (tifffile) and NPY files, 8/16-bit unsigned integer or
floating point, grey ``(H, W)`` or colour ``(H, W, 3)``; anything else (a corrupt file, an
unknown suffix, 1/32-bit or signed integers, NaN/Inf, an empty or wrongly shaped array) raises
:class:`~clfza.errors.ClfzaError` with one sentence. Frames stay in the sensor's own units
(digital numbers); nothing is rescaled, so dark and flat frames from the same sensor apply
directly. :func:`frame_layout` and :func:`check_layout_memory` refuse an oversized frame from
its header, before it is decoded.
"""

from __future__ import annotations

import logging
import struct
import zlib
from dataclasses import dataclass
from pathlib import Path

import imageio.v3 as iio
import numpy as np
import tifffile

from ..errors import ClfzaError
from . import _limits as limits
from ._headers import npy_header, one_line, tiff_header

log = logging.getLogger("clfza.io")  # the name the reader has always logged under

FRAME_SUFFIXES = {".png": "png", ".tif": "tiff", ".tiff": "tiff", ".npy": "npy"}
MIN_SIDE = 4  # smallest frame side accepted


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


def _png_ihdr(head: bytes) -> tuple[int, int, int, int, int] | None:
    """(width, height, bit depth, colour type, interlace) from a PNG's first 33 bytes."""
    if len(head) < 33 or head[12:16] != b"IHDR":
        return None
    w, h, bits, ctype, _, _, interlace = struct.unpack(">IIBBBBB", head[16:29])
    return w, h, bits, ctype, interlace


def _read_png(p: Path) -> np.ndarray:
    """PNG via imageio (Pillow), except 16-bit colour PNGs, which Pillow truncates to 8 bits:
    those are decoded here (:func:`_decode_png16`)."""

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
                         f"({one_line(exc)})") from None


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
            _, shape, dtype = tiff_header(p)
            return shape, int(dtype.itemsize), float(dtype.itemsize)
        if fmt == "npy":
            shape, dtype, _, _ = npy_header(p)
            return shape, int(dtype.itemsize), 0.0
    except Exception:  # a corrupt header: the reader names the problem
        return None
    return None


def check_layout_memory(label: str, shape: tuple[int, ...], itemsize: int,
                        decoder: float = 0.0) -> None:
    """Refuse a frame by its declared size before it is decoded (:mod:`clfza.io._limits`)."""
    if len(shape) < 2:
        return
    count = 1
    if len(shape) == 2 or (len(shape) == 3 and shape[2] in (1, 2, 3, 4)):
        hw = shape[:2]
    else:  # planar (C, H, W) or a stack (N, H, W[, C]), decoded whole
        hw = shape[1:3]
        if not (len(shape) == 3 and shape[0] in (3, 4)):
            count = int(shape[0])
    limits.check_pixels(label, hw, count=count)
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


def _read_tiff(p: Path) -> np.ndarray:

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
                         f"an unsupported encoding ({one_line(exc)})") from None
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
        msg = one_line(exc)
        if "pickle" in msg.lower():
            raise ClfzaError(f"NPY {str(p)!r} holds Python objects, not a numeric array") \
                from None
        raise ClfzaError(f"cannot read NPY {str(p)!r}: the file is corrupt or not a .npy "
                         f"array ({msg})") from None
    except Exception as exc:
        raise ClfzaError(f"cannot read NPY {str(p)!r}: the file is corrupt or truncated "
                         f"({one_line(exc)})") from None
    if not isinstance(arr, np.ndarray):  # np.load returns an NpzFile for .npz content
        raise ClfzaError(f"{str(p)!r} is an .npz archive; save one array with numpy.save")
    return arr


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
        raise ClfzaError(f"cannot read {label}: {one_line(exc)}") from None
    layout = frame_layout(p)
    if layout is not None:
        check_layout_memory(label, *layout)
    try:
        raw = {"png": _read_png, "tiff": _read_tiff, "npy": _read_npy}[fmt](p)
    except PermissionError:
        raise ClfzaError(f"cannot read {label}: permission denied") from None
    except OSError as exc:
        raise ClfzaError(f"cannot read {label}: {one_line(exc)}") from None
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
