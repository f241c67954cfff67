"""Writing images and arrays (re-exported by :mod:`clfza.io`).

:func:`write_image` (16-bit PNG, 16-bit or float32 TIFF, float NPY) and :func:`write_array`
go through :mod:`clfza.io._outputs`: atomic, and never over an existing file unless ``force``.
The ``encode_*`` functions give the bytes without writing them; PNGs are encoded here
(:func:`encode_png`), since Pillow cannot store 16-bit colour.
"""

from __future__ import annotations

import io as _io
import struct
import zlib
from pathlib import Path

import numpy as np
import tifffile

from ..errors import ClfzaError
from ._outputs import atomic_write_bytes
from ._read import FRAME_SUFFIXES

SCALINGS = ("percentile", "minmax", "unit")


def _encode_png(arr: np.ndarray) -> bytes:
    """A PNG of an 8/16-bit grey or RGB array (no filtering, deflate level 6).

    Written here rather than with Pillow, which cannot store 16-bit colour. The zlib stream is
    made by libdeflate (imagecodecs) where available: faster than zlib for a slightly larger
    file, which matters in a stream (issue 15; measured: docs/measurements.md,
    clfza.io._write).
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
            + chunk(b"IDAT", _zlib_stream(rows.tobytes())) + chunk(b"IEND", b""))


def _zlib_stream(data: bytes, level: int = 6) -> bytes:
    """A zlib (RFC 1950) stream of ``data``: libdeflate through imagecodecs, else zlib."""
    try:
        # lazy: only compressed TIFFs need imagecodecs; without it zlib serves
        from imagecodecs import deflate_encode
    except ImportError:  # imagecodecs is a dependency; a build without libdeflate falls back
        return zlib.compress(data, level)
    return bytes(deflate_encode(data, level=level))


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
    scaling record; nothing is written (see :func:`clfza.io._outputs.atomic_write_many`)."""
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
