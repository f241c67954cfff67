"""What a frame file holds, from its header (re-exported by :mod:`clfza.io`).

:func:`npy_header`, :func:`tiff_header` and :func:`gif_header` read an array's layout without
decoding a pixel, so that a caller can refuse an oversized or wrongly shaped file before it is
read;
:func:`tiff_pages` decodes every page of a TIFF stack; :func:`one_line` folds the message of
the exception a reader caught into the one sentence of a :class:`~clfza.errors.ClfzaError`.
"""

from __future__ import annotations

from pathlib import Path
from typing import BinaryIO

import numpy as np
import tifffile

from ..errors import ClfzaError
from ._limits import check_pixels


def one_line(exc: BaseException) -> str:
    """An exception's message on one line of at most 160 characters, for error messages.

    White space runs fold to one space; an empty message gives the exception's type name; a
    longer one is cut and ends in ``...``.

    Examples
    --------
    >>> from clfza.io import one_line
    >>> one_line(ValueError("bad\\n  header"))
    'bad header'
    >>> one_line(KeyError())
    'KeyError'
    """
    s = " ".join(str(exc).split()) or type(exc).__name__
    return s if len(s) <= 160 else s[:157] + "..."


def npy_header(source: str | Path | BinaryIO) -> tuple[tuple[int, ...], np.dtype, bool, int]:
    """The layout of an NPY array from its header, with numpy's own header reader.

    Parameters
    ----------
    source : str, Path or binary file object
        An ``.npy`` file, or an open binary stream at the start of one (a member of an
        ``.npz`` archive opened with ``zipfile.ZipFile.open``); a stream is left just past
        the header.

    Returns
    -------
    (shape, dtype, fortran_order, data_offset)
        The array's shape, its numpy dtype, whether it is stored in Fortran (column-major)
        order, and where its data begin, in bytes from the start of the NPY data.

    Raises
    ------
    ValueError
        No NPY magic string, or a malformed header (numpy's messages; anything else the
        header's parser or the stream raises becomes a ValueError too).
    OSError
        The file cannot be opened or read.

    Examples
    --------
    >>> import io
    >>> from clfza.io import npy_header
    >>> buf = io.BytesIO()
    >>> np.save(buf, np.zeros((2, 3), np.float32))
    >>> _ = buf.seek(0)
    >>> npy_header(buf)
    ((2, 3), dtype('float32'), False, 128)
    """
    if isinstance(source, (str, Path)):
        with open(source, "rb") as fh:
            return npy_header(fh)
    start = source.tell()
    try:
        version = np.lib.format.read_magic(source)
        read = (np.lib.format.read_array_header_1_0 if version == (1, 0)
                else np.lib.format.read_array_header_2_0)
        shape, fortran_order, dtype = read(source)
    except (ValueError, OSError):
        raise
    except Exception as exc:  # numpy's header parser (tokenize), a corrupt zip member (zlib)
        raise ValueError(f"malformed NPY header ({one_line(exc)})") from None
    return tuple(int(v) for v in shape), np.dtype(dtype), bool(fortran_order), \
        source.tell() - start


def tiff_header(path: str | Path) -> tuple[int, tuple[int, ...], np.dtype]:
    """How many pages a TIFF file holds, and its first page's shape and dtype (as stored).

    Only the headers are read (counting pages walks the chain of directories). A planar RGB
    page has the shape ``(3, H, W)`` here.

    Parameters
    ----------
    path : str or Path
        A ``.tif``/``.tiff`` file.

    Returns
    -------
    (pages, shape, dtype)

    Raises
    ------
    Exception
        Whatever tifffile raises for a file that is not a readable TIFF.

    Examples
    --------
    >>> from clfza.io import tiff_header
    >>> tifffile.imwrite("stack.tif", np.zeros((5, 8, 8), np.uint16))
    >>> tiff_header("stack.tif")
    (5, (8, 8), dtype('uint16'))
    """
    with tifffile.TiffFile(path) as tf:
        first = tf.pages[0]
        if first.dtype is None:
            raise ValueError("the first page's sample format is not supported")
        return len(tf.pages), tuple(int(v) for v in first.shape), np.dtype(first.dtype)


def gif_header(path: str | Path) -> tuple[int, tuple[int, int]]:
    """How many frames a GIF holds and the canvas its decoder builds, from the headers.

    The canvas is the logical screen, grown to hold every frame's extent (left + width,
    top + height), as Pillow grows it: a frame placed far outside a small screen makes a
    large canvas. Only the block structure is walked (no image data is decompressed).

    Parameters
    ----------
    path : str or Path
        A ``.gif`` file.

    Returns
    -------
    (frames, (height, width))
        The number of image descriptors, and the canvas size in pixels.

    Raises
    ------
    ValueError
        No GIF signature, or the blocks end before the first frame.
    OSError
        The file cannot be read.

    Examples
    --------
    >>> import imageio.v3 as iio
    >>> from clfza.io import gif_header
    >>> iio.imwrite("a.gif", np.arange(240, dtype=np.uint8).reshape(3, 8, 10))
    >>> gif_header("a.gif")
    (3, (8, 10))
    """
    data = Path(path).read_bytes()
    if data[:6] not in (b"GIF87a", b"GIF89a") or len(data) < 13:
        raise ValueError("not a GIF file (bad signature)")
    w, h = int.from_bytes(data[6:8], "little"), int.from_bytes(data[8:10], "little")
    flags = data[10]
    pos = 13 + (3 << ((flags & 7) + 1) if flags & 0x80 else 0)
    frames = 0

    def skip_blocks(at: int) -> int:  # a chain of data sub-blocks, ended by a zero size
        while at < len(data) and data[at]:
            at += data[at] + 1
        return at + 1

    while pos < len(data):
        kind = data[pos]
        if kind == 0x21:  # extension: label, then data sub-blocks
            pos = skip_blocks(pos + 2)
        elif kind == 0x2C:  # image descriptor: left, top, width, height, flags
            if pos + 10 > len(data):
                break
            x0, y0, fw, fh = (int.from_bytes(data[pos + k:pos + k + 2], "little")
                              for k in (1, 3, 5, 7))
            w, h = max(w, x0 + fw), max(h, y0 + fh)
            frames += 1
            f = data[pos + 9]
            pos += 10 + (3 << ((f & 7) + 1) if f & 0x80 else 0)
            pos = skip_blocks(pos + 1)  # the LZW code size, then the image data
        else:  # the trailer (0x3B) or garbage: the decoder stops here too
            break
    if frames == 0:
        raise ValueError("the GIF holds no image")
    return frames, (h, w)


def tiff_pages(path: str | Path) -> list[np.ndarray]:
    """Every page of a TIFF file, decoded, channels last.

    A page stored planar, ``(3, H, W)`` or ``(4, H, W)``, becomes ``(H, W, 3)`` or
    ``(H, W, 4)``. Check the size from :func:`tiff_header` first: every page is decoded.

    Parameters
    ----------
    path : str or Path
        A ``.tif``/``.tiff`` file, one image per page (a depth stack, a time series).

    Returns
    -------
    list of ndarray
        One array per page, in the file's order, in the stored dtype.

    Raises
    ------
    ClfzaError
        The file is corrupt or uses an encoding tifffile cannot decode.

    Examples
    --------
    >>> from clfza.io import tiff_pages
    >>> tifffile.imwrite("stack.tif", np.zeros((5, 8, 8), np.uint16))
    >>> [a.shape for a in tiff_pages("stack.tif")][:2]
    [(8, 8), (8, 8)]
    """
    out = []
    try:
        with tifffile.TiffFile(path) as tf:
            first = tf.pages[0].shape
            hw = first[1:3] if (len(first) == 3 and first[0] in (3, 4)
                                and first[-1] not in (3, 4)) else first[:2]
            # every page is decoded: pages x pixels against CLFZA_MAX_PIXELS, before any
            check_pixels(f"TIFF stack {str(path)!r}", hw, count=len(tf.pages))
            for pg in tf.pages:
                a = np.asarray(pg.asarray())
                if a.ndim == 3 and a.shape[0] in (3, 4) and a.shape[-1] not in (3, 4):
                    a = np.moveaxis(a, 0, -1)
                out.append(a)
    except ClfzaError:
        raise
    except Exception as exc:
        raise ClfzaError(f"cannot read TIFF stack {str(path)!r}: the file is corrupt or uses an "
                         f"unsupported encoding ({one_line(exc)})") from None
    return out
