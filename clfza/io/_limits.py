"""Resource limits, checked before the work: memory estimated from headers and shapes.

Every reader (:func:`clfza.io.read_frame` for PNG -- clfza's own 16-bit colour decoder
included --, TIFF and NPY; the stacks of :mod:`clfza.io._stream`; PSF files and stacks) and every
entry point that allocates in proportion to a grid (:func:`clfza.simulate`,
:func:`clfza.reconstruct`, :func:`clfza.focus.autofocus`) first estimates the bytes it will
hold at its peak from the header or the camera's shape, and calls :func:`check_memory`, which
raises :class:`ResourceError` -- one message shape for all of them -- when the estimate exceeds
the limit. Nothing is decoded or allocated before that check.

Before the memory, the pixels: :func:`check_pixels` refuses a decode of more than
``CLFZA_MAX_PIXELS`` pixels (default :data:`MAX_PIXELS`, Pillow's decompression-bomb limit),
read from the header -- a PNG's IHDR, a TIFF's pages x pixels when all are decoded at once, an
NPY header, a video's or GIF's frame size.

The memory limit is ``CLFZA_MAX_MEMORY`` (bytes, or with a suffix ``K``, ``M``, ``G``, ``T``:
``CLFZA_MAX_MEMORY=8G``) when set, otherwise the memory the operating system reports as
available (``MemAvailable`` on Linux, else the physical memory).
"""

from __future__ import annotations

import math
import os

import numpy as np

from ..errors import ClfzaError

ENV = "CLFZA_MAX_MEMORY"
PIXELS_ENV = "CLFZA_MAX_PIXELS"
#: Most pixels one decode may produce (a frame, or every page of a TIFF decoded at once, or
#: an archived stack inflated whole), whatever the memory, unless ``CLFZA_MAX_PIXELS`` says
#: otherwise: Pillow's decompression-bomb error limit (2 x 89478485, about 179 Mpx), far
#: above any FZA sensor crop clfza reconstructs (the paper's 4656 x 3522 frame is 16.4 Mpx).
MAX_PIXELS = 178956970


class ResourceError(ClfzaError):
    """The work would need more memory (or pixels) than the limit allows."""


def _parse_size(text: str) -> int:
    s = str(text).strip().upper().removesuffix("B").removesuffix("I")
    mult = 1
    for suf, m in (("K", 1 << 10), ("M", 1 << 20), ("G", 1 << 30), ("T", 1 << 40)):
        if s.endswith(suf):
            s, mult = s[:-1], m
            break
    try:
        v = float(s) * mult
    except ValueError:
        raise ClfzaError(f"{ENV} must be a size such as 4000000000 or 4G, got {text!r}") from None
    if not math.isfinite(v) or v <= 0:
        raise ClfzaError(f"{ENV} must be a positive size, got {text!r}")
    return int(v)


def _available() -> int:
    try:
        with open("/proc/meminfo", encoding="ascii") as fh:
            for line in fh:
                if line.startswith("MemAvailable:"):
                    return int(line.split()[1]) * 1024
    except (OSError, ValueError, IndexError):
        pass
    try:
        return int(os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES"))
    except (ValueError, OSError, AttributeError):  # pragma: no cover - not POSIX
        return 16 << 30


def memory_limit() -> tuple[int, str]:
    """The limit in bytes and where it comes from."""
    env = os.environ.get(ENV)
    if env:
        return _parse_size(env), f"{ENV}={env}"
    return _available(), "the memory available on this machine"


def fmt_bytes(n: float) -> str:
    for unit, m in (("TiB", 1 << 40), ("GiB", 1 << 30), ("MiB", 1 << 20), ("KiB", 1 << 10)):
        if n >= m:
            return f"{n / m:.3g} {unit}"
    return f"{int(n)} B"


def check_memory(what: str, nbytes: float, detail: str = "", hint: str = "") -> float:
    """Raise :class:`ResourceError` when ``nbytes`` exceeds :func:`memory_limit`.

    The message (shared by every reader and entry point) is::

        WHAT needs about X of memory (DETAIL), more than the limit of Y (SOURCE); HINT
    """
    limit, source = memory_limit()
    if nbytes > limit:
        d = f" ({detail})" if detail else ""
        h = hint or (f"crop or bin the data, or raise the limit with {ENV}")
        raise ResourceError(f"{what} needs about {fmt_bytes(nbytes)} of memory{d}, more than "
                            f"the limit of {fmt_bytes(limit)} ({source}); {h}")
    return float(nbytes)


def pixel_limit() -> tuple[int, str]:
    """The most pixels one decode may produce, and where the number comes from:
    ``CLFZA_MAX_PIXELS`` (an integer, ``5e8`` or with a suffix ``K``/``M``/``G``, powers of
    1000) when set, else :data:`MAX_PIXELS`."""
    env = os.environ.get(PIXELS_ENV)
    if not env:
        return MAX_PIXELS, f"the default; set {PIXELS_ENV} to change it"
    s = env.strip().upper()
    mult = {"K": 1e3, "M": 1e6, "G": 1e9}.get(s[-1:], 1.0)
    try:
        v = float(s[:-1] if mult != 1.0 else s) * mult
    except ValueError:
        v = float("nan")
    if not math.isfinite(v) or v < 1:
        raise ClfzaError(f"{PIXELS_ENV} must be a positive pixel count such as 500000000 or "
                         f"500M, got {env!r}")
    return int(v), f"{PIXELS_ENV}={env}"


def check_pixels(what: str, shape, hint: str = "", count: int = 1) -> None:
    """Refuse a decode of ``count`` images of ``shape`` (H, W, ...) pixels above
    :func:`pixel_limit` before anything is decoded; one line naming ``CLFZA_MAX_PIXELS``."""
    h, w = int(shape[0]), int(shape[1])
    n = h * w * max(1, int(count))
    limit, source = pixel_limit()
    if n > limit:
        pages = f"{int(count)} x " if count > 1 else ""
        raise ResourceError(f"{what} declares {pages}{h}x{w} = {n} pixels, more than the limit "
                            f"of {limit} pixels ({source}); "
                            f"{hint or 'crop the frame before reading it with clfza'}, or "
                            f"raise the limit with {PIXELS_ENV}")


def frame_bytes(shape, itemsize: int, *, decoder_bytes_per_sample: float = 0.0) -> float:
    """Peak bytes of reading one frame of ``shape`` stored with ``itemsize`` bytes per sample:
    the stored array, the decoder's working arrays, and the validated float64 copy plus the
    preparation's working copies (dark, flat, crop, ``y``: about four float64 arrays)."""
    n = 1.0
    for s in shape:
        n *= int(s)
    return n * (itemsize + decoder_bytes_per_sample + 4 * 8)


def grid_bytes(shape, channels: int = 1, itemsize: int = 8, arrays: float = 1.0) -> float:
    """Bytes of ``arrays`` arrays of ``shape`` x ``channels`` at ``itemsize`` bytes."""
    n = float(channels)
    for s in shape:
        n *= int(s)
    return n * itemsize * arrays


#: float64-array equivalents a solve holds per channel plane (iterates, duals, spectra and
#: the FFT's scratch), by method; the exact model works on a padded grid (see estimate)
SOLVE_ARRAYS = {"bp": 4, "twist": 14, "fista": 12, "admm": 14}


def check_reconstruct(shape, channels: int, method: str, *, model: str = "auto",
                      itemsize: int = 8) -> float:
    """Check the memory of one reconstruction on a grid of ``shape`` (before any set-up)."""
    k = SOLVE_ARRAYS.get(method, 14)
    pad = {"exact": 4.0, "padded": 4.0, "auto": 2.5}.get(model, 1.0)  # linear-convolution grid
    est = grid_bytes(shape, channels, max(itemsize, 8), k * (pad if method != "bp" else 1.0))
    return check_memory(f"reconstructing a {int(shape[0])}x{int(shape[1])} grid with "
                        f"{method!r}", est, f"about {k} working arrays per channel",
                        "use a smaller crop (--crop), bin the frame (--bin), or raise the "
                        f"limit with {ENV}")


#: largest magnitude a measurement may hold: its squares (norms, objectives) must fit float64
MAX_VALUE = 1e150


#: the same for float32 arithmetic (OpenCL): N |y|^2 must stay below 3.4e38
MAX_VALUE32 = 1e15


def check_values(name: str, a, dtype="float64") -> None:
    """Refuse data whose magnitude overflows the squares every solver takes (one line, not
    Inf/NaN with a RuntimeWarning)."""

    f32 = np.dtype(dtype) == np.float32
    lim = MAX_VALUE32 if f32 else MAX_VALUE
    big = float(np.max(np.abs(a))) if np.size(a) else 0.0
    if big > lim:
        raise ClfzaError(f"{name} values reach {big:.3g}: their squares overflow "
                         f"{'float32' if f32 else 'float64'} (limit {lim:.0e}); rescale the "
                         "data" + ("" if not f32 else " or use backend='numpy' (float64)"))
