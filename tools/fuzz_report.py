"""Fuzz clfza's readers and command line (issue 35, item 6), and write the report.

Generators (each case is drawn from its own seeded ``numpy.random.Generator``, so a case
is reproduced from the run's seed and its number alone; no new dependency):

``png``
    valid PNGs (8/16-bit grey, RGB, RGBA, grey-alpha, palette; every row filter) with their
    IHDR fields, chunk lengths, chunk CRCs and image data mutated, extra chunks (zTXt/iCCP
    bombs, duplicate IHDR, chunks after IEND), inflating bombs that claim a large image,
    truncations and byte flips; read with :func:`clfza.io.read_frame`.
``tiff``
    single and multi-page TIFFs (8/16-bit, float, RGB contiguous and planar, compressed,
    tiled, big-endian) with their IFD entries (sizes, bits, samples, strips, compression,
    types and counts), IFD offsets (loops, past the end) and bytes mutated; read with
    :func:`clfza.io.read_frame`, as a stack (:func:`clfza.io.expand_frames` then
    :func:`clfza.io.read_ref`) and with :func:`clfza.io.tiff_pages`.
``npy``
    NPY arrays with their header's shape (huge, negative, empty, many axes), dtype
    (signed, complex, object, structured, strings), order, header length and version
    mutated; read as a frame and as a stack.
``npz``
    archives of frames and stacks whose members carry the NPY mutations, odd member names,
    many members, deflate bombs, and mutated zip bytes; read as stacks.
``toml``
    camera files with values of the wrong type or range, missing, unknown and duplicate
    keys, other table layouts, deep nesting, invalid UTF-8, truncations and byte flips;
    read with :meth:`clfza.Camera.load`, some of them used by ``clfza simulate``.
``video``
    GIFs (screen and frame sizes, LZW code size) and MP4s (imageio-ffmpeg, when it is
    installed), mutated and read as stacks.
``cli-reconstruct`` / ``cli-simulate``
    random combinations of ``clfza reconstruct`` / ``clfza simulate`` options, valid and
    invalid values and conflicting options, on valid, mis-shaped, stacked and mutated
    inputs, calibration frames and PSFs.

Each case runs in a worker process (the reader or ``clfza.cli.main([...])`` called in it, so
that the interpreter and the OpenCL context start once per worker, not per case), which the
driver kills and replaces when a case passes its time limit (30 s) or its memory: a hang or
a crash is contained and reported as one. A case passes when

* it returns or raises :class:`~clfza.errors.ClfzaError` (a reader), or exits with 0, 1 or
  2 with no traceback and no "unexpected" error (the command line);
* it leaves no partial output: no temporary file, every image/NPY/stack written is named by
  a JSON record, every file a record names exists;
* its peak resident memory grows by less than ``CLFZA_MAX_MEMORY`` (set, like
  ``CLFZA_MAX_PIXELS``, low for the run: 512M and 4M by default); the peak is read from
  ``VmHWM``, reset before each case (``/proc/self/clear_refs``);
* it ends within the time limit.

Usage::

    python tools/fuzz_report.py                   # 2400 cases -> bench/results/fuzz_<machine>.*
    python tools/fuzz_report.py --cases 240 --out /tmp/fuzz
    python tools/fuzz_report.py --seed 7 --case 123 --keep   # rerun one case, keep its files

``tests/test_fuzz.py`` runs a short pass in the default suite and the full one under
``-m "fuzz and slow"``.
"""

from __future__ import annotations

import argparse
import contextlib
import io
import json
import os
import select
import shutil
import signal
import struct
import subprocess
import sys
import tempfile
import time
import traceback
import warnings
import zipfile
import zlib
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve()
ROOT = HERE.parents[1]

GENERATORS = ("png", "tiff", "npy", "npz", "toml", "video", "cli-reconstruct", "cli-simulate")
#: share of the cases per generator (the full run's 2400 cases: 360 PNG, 300 TIFF, ...)
WEIGHTS = {"png": 0.15, "tiff": 0.125, "npy": 0.11, "npz": 0.09, "toml": 0.11, "video": 0.085,
           "cli-reconstruct": 0.2, "cli-simulate": 0.13}
TIMEOUT_S = 30.0
MAX_PIXELS = "4M"
MAX_MEMORY = "512M"
MEMORY_BYTES = 512 << 20
#: the driver kills a worker whose resident memory grows past this (the case fails)
HARD_RSS_BYTES = 3 * MEMORY_BYTES
#: a case's outcome: "ok" (the input was read / the command succeeded), "refused" (a clean
#: error), or a bug ("bug:...")
BUG_KINDS = ("exception", "traceback", "unexpected", "exit-code", "stderr", "partial-output",
             "missing-output", "rss", "hang", "crash")
#: bugs the fuzzer found while it was written, fixed with a regression test each
#: (tests/test_fuzz.py); the report lists them
FIXED: list[dict] = [
    {"where": "clfza/camera/_camera.py: Camera.from_toml",
     "bug": "a camera file with deeply nested arrays or inline tables raised tomllib's "
            "RecursionError (a traceback through the API, 'unexpected', exit 1 on the CLI).",
     "fix": "one-line ClfzaError ('nested too deeply to read').",
     "test": "test_toml_nested_too_deeply"},
    {"where": "clfza/camera/_camera.py: Camera.from_toml, Camera.from_dict",
     "bug": "`[[camera]]` (an array of tables) or `camera = 3` raised AttributeError "
            "('list' object has no attribute 'setdefault').",
     "fix": "one-line ClfzaError: 'camera' must be one [camera] table.",
     "test": "test_toml_camera_not_a_table"},
    {"where": "clfza/camera/_camera.py: plausibility",
     "bug": "lengths at float64's ends (pitch/r1_shadow = 1e-300, r1/z2/R = 1e300, z1 = 1e-300) "
            "passed the positivity checks, then raised OverflowError or ZeroDivisionError in "
            "the simulation and the measurement's gain ('unexpected', exit 1; each frame "
            "retried 3 times).",
     "fix": "a plausibility error for a length, or the shadow constant r1', outside "
            "LENGTH_RANGE = 1e-12..1e12 mm.",
     "test": "test_camera_lengths_outside_float_range"},
    {"where": "clfza/cli/_common.py: load_camera",
     "bug": "`--z1 1e-300` moved a plausible camera to a shadow constant that overflows "
            "(OverflowError in simulate and reconstruct).",
     "fix": "the plausibility errors apply to the camera moved by --z1.",
     "test": "test_cli_z1_outside_float_range"},
    {"where": "clfza/io/_headers.py: npy_header; clfza/io/_stream.py: _npz_members",
     "bug": "an NPZ member header numpy's tokenizer gives up on (tokenize.TokenError), or a "
            "corrupt deflate stream (zlib.error), escaped expand_frames.",
     "fix": "npy_header raises ValueError for anything its parser or stream raises; "
            "_npz_members names any failure as 'the archive is corrupt'.",
     "test": "test_npz_member_header_unparsable, test_npz_member_deflate_corrupt"},
    {"where": "clfza/io/_stream.py: refs_of_file",
     "bug": "a 100-byte NPZ member claiming shape (1e9, 8, 8) made a billion FrameRefs before "
            "any read (a hang, then out of memory); a 4 MB (1e6, 2, 2) NPY made a million "
            "references (8 s, 400 MB) to frames too small to read.",
     "fix": "a stack whose member declares more data than it holds or (NPZ: inflated whole) "
            "more than CLFZA_MAX_PIXELS, or whose frames are under 4 px a side, is one "
            "reference whose read names the problem.",
     "test": "test_npz_member_claiming_a_billion_frames, test_npy_stack_of_frames_too_small"},
    {"where": "clfza/io/_stream.py: frame_shapes",
     "bug": "the output preflight read every member header of an NPZ once per member "
            "(quadratic: 30 s for 566 members before any frame was solved; the fuzzer's "
            "30-s limit).",
     "fix": "an archive's member shapes are read once per frame_shapes call.",
     "test": "test_frame_shapes_reads_an_archive_once"},
    {"where": "clfza/io/_stream.py: video_length, refs_of_file, _read_raw "
              "(clfza/io/_headers.py: gif_header)",
     "bug": "a 100-byte GIF whose frame sits at (65535, 1999) made Pillow build a 131-Mpixel "
            "canvas (500 MB peak RSS under CLFZA_MAX_PIXELS=4M; Pillow's own limit is 179 "
            "Mpixel) before clfza's pixel check.",
     "fix": "gif_header walks the blocks and gives the canvas (the screen grown to every "
            "frame's extent); it is checked against CLFZA_MAX_PIXELS and the memory before "
            "Pillow decodes.",
     "test": "test_gif_frame_far_outside_its_screen"},
]


# ==========================================================================================
# small byte tools
# ==========================================================================================
def _pick(rng: np.random.Generator, seq):
    return seq[int(rng.integers(len(seq)))]


def flip_bytes(rng: np.random.Generator, data: bytes, lo: int = 0, hi: int | None = None,
               n: int | None = None) -> tuple[bytes, str]:
    """``n`` random bytes of ``data[lo:hi]`` replaced by random values."""
    b = bytearray(data)
    hi = len(b) if hi is None else min(hi, len(b))
    if hi <= lo:
        return bytes(b), "flip(none)"
    n = int(rng.integers(1, 9)) if n is None else n
    for _ in range(n):
        b[int(rng.integers(lo, hi))] = int(rng.integers(256))
    return bytes(b), f"flip({n} in {lo}..{hi})"


def truncate(rng: np.random.Generator, data: bytes) -> tuple[bytes, str]:
    """``data`` cut at a random length, often inside the first 64 bytes."""
    if rng.random() < 0.4:
        n = int(rng.integers(0, min(64, len(data)) + 1))
    else:
        n = int(rng.integers(0, len(data)))
    return data[:n], f"truncate({n}/{len(data)})"


def generic(rng: np.random.Generator, data: bytes) -> tuple[bytes, str]:
    """A format-blind mutation: truncation, flips, a duplicated or inserted block."""
    r = rng.random()
    if r < 0.35:
        return truncate(rng, data)
    if r < 0.8:
        hi = min(len(data), 256) if rng.random() < 0.5 else len(data)
        return flip_bytes(rng, data, 0, hi)
    i = int(rng.integers(0, len(data) + 1))
    if r < 0.9:
        blk = bytes(rng.integers(0, 256, int(rng.integers(1, 64)), dtype=np.uint8))
        return data[:i] + blk + data[i:], f"insert({len(blk)} at {i})"
    j = min(len(data), i + int(rng.integers(1, 256)))
    return data[:j] + data[i:j] * int(rng.integers(1, 8)) + data[j:], f"repeat({i}..{j})"


#: interesting integers for header fields
EDGE_U32 = (0, 1, 2, 3, 4, 5, 7, 8, 16, 63, 64, 65, 255, 256, 1999, 2001, 4095, 65535, 65536,
            2**24, 2**31 - 1, 2**31, 2**32 - 1)


def edge_int(rng: np.random.Generator, base: int = 16, bits: int = 32) -> int:
    """An edge value, a small neighbour of ``base`` or a random integer of ``bits`` bits."""
    r = rng.random()
    if r < 0.5:
        v = _pick(rng, EDGE_U32)
    elif r < 0.8:
        v = base + int(rng.integers(-3, 4))
    else:
        v = int(rng.integers(0, 2**min(bits, 62)))
    return int(v) % (2**bits)


# ==========================================================================================
# PNG
# ==========================================================================================
def png_chunk(kind: bytes, data: bytes, crc_ok: bool = True) -> bytes:
    crc = zlib.crc32(kind + data) & 0xFFFFFFFF
    return struct.pack(">I", len(data)) + kind + data + struct.pack(
        ">I", crc if crc_ok else crc ^ 0x5A5A5A5A)


def _png_filter(line: np.ndarray, prev: np.ndarray, f: int, bpp: int) -> np.ndarray:
    a = np.concatenate([np.zeros(bpp, np.int32), line[:-bpp]])
    b = prev
    c = np.concatenate([np.zeros(bpp, np.int32), prev[:-bpp]])
    if f == 1:
        pred = a
    elif f == 2:
        pred = b
    elif f == 3:
        pred = (a + b) >> 1
    elif f == 4:
        p = a + b - c
        pa, pb, pc = np.abs(p - a), np.abs(p - b), np.abs(p - c)
        pred = np.where((pa <= pb) & (pa <= pc), a, np.where(pb <= pc, b, c))
    else:
        pred = 0
    return ((line - pred) & 255).astype(np.uint8)


#: PNG variants: (bit depth, colour type, channels)
PNG_VARIANTS = {"grey8": (8, 0, 1), "grey16": (16, 0, 1), "rgb8": (8, 2, 3),
                "rgb16": (16, 2, 3), "rgba8": (8, 6, 4), "rgba16": (16, 6, 4),
                "greyalpha16": (16, 4, 2), "palette8": (8, 3, 1)}


def png_bytes(rng: np.random.Generator, variant: str, h: int, w: int,
              chunks_before_idat: list[bytes] | None = None) -> tuple[bytes, dict]:
    """A valid PNG of ``variant`` with random pixels and a random filter on every row; the
    parts (IHDR fields, raw rows) come back for the mutations."""
    bits, ctype, ch = PNG_VARIANTS[variant]
    hi = 255 if bits == 8 else 65535
    a = rng.integers(0, hi + 1, (h, w, ch))
    if ctype in (4, 6):
        a[..., -1] = hi  # a constant alpha: read as grey/RGB
    if ctype == 3:
        a = rng.integers(0, 16, (h, w, 1))
    px = a.astype(">u2" if bits == 16 else np.uint8).reshape(h, -1).view(np.uint8)
    bpp = ch * bits // 8
    rows, prev = [], np.zeros(px.shape[1], np.int32)
    for r in range(h):
        f = int(rng.integers(0, 5))
        line = px[r].astype(np.int32)
        rows.append(bytes([f]) + _png_filter(line, prev, f, bpp).tobytes())
        prev = line
    raw = b"".join(rows)
    ihdr = struct.pack(">IIBBBBB", w, h, bits, ctype, 0, 0, 0)
    out = b"\x89PNG\r\n\x1a\n" + png_chunk(b"IHDR", ihdr)
    if ctype == 3:
        out += png_chunk(b"PLTE", bytes(rng.integers(0, 256, 48, dtype=np.uint8)))
    for c in chunks_before_idat or []:
        out += c
    comp = zlib.compress(raw, int(rng.integers(0, 10)))
    if rng.random() < 0.3 and len(comp) > 8:  # image data split over several IDAT chunks
        cut = int(rng.integers(1, len(comp)))
        out += png_chunk(b"IDAT", comp[:cut]) + png_chunk(b"IDAT", comp[cut:])
    else:
        out += png_chunk(b"IDAT", comp)
    out += png_chunk(b"IEND", b"")
    return out, {"bits": bits, "ctype": ctype, "h": h, "w": w, "raw": raw}


def png_chunks(data: bytes) -> list[tuple[int, int, bytes]]:
    """(offset, length, type) of each chunk as far as the lengths lead."""
    out, pos = [], 8
    while pos + 8 <= len(data) and len(out) < 64:
        (n,) = struct.unpack(">I", data[pos:pos + 4])
        out.append((pos, n, data[pos + 4:pos + 8]))
        pos += 12 + n
    return out


def png_case(rng: np.random.Generator) -> tuple[dict[str, bytes], str, dict]:
    variant = _pick(rng, tuple(PNG_VARIANTS))
    h, w = int(rng.integers(1, 40)), int(rng.integers(1, 40))
    if rng.random() < 0.8:
        h, w = max(h, 4), max(w, 4)
    extra = []
    kind = _pick(rng, ("ihdr", "ihdr", "length", "crc", "truncate", "flip", "flip", "bomb",
                       "idat", "chunks", "generic", "valid"))
    if kind == "chunks":
        extra_kind = _pick(rng, ("ztxt-bomb", "iccp-bomb", "text-big", "unknown-critical",
                                 "unknown-ancillary", "dup-ihdr", "zero-idat", "plte-grey"))
        if extra_kind == "ztxt-bomb":
            extra.append(png_chunk(b"zTXt", b"k\0\0" + zlib.compress(b"A" * (64 << 20), 9)))
        elif extra_kind == "iccp-bomb":
            extra.append(png_chunk(b"iCCP", b"p\0\0" + zlib.compress(b"\0" * (64 << 20), 9)))
        elif extra_kind == "text-big":
            extra.append(png_chunk(b"tEXt", b"k\0" + b"x" * (1 << 20)))
        elif extra_kind == "unknown-critical":
            extra.append(png_chunk(b"ABCD", b"data"))
        elif extra_kind == "unknown-ancillary":
            extra.append(png_chunk(b"abCd", bytes(100)))
        elif extra_kind == "dup-ihdr":
            extra.append(png_chunk(b"IHDR", struct.pack(">IIBBBBB", 9999, 9999, 16, 2, 0, 0, 0)))
        elif extra_kind == "zero-idat":
            extra.append(png_chunk(b"IDAT", b""))
        else:
            extra.append(png_chunk(b"PLTE", bytes(768)))
        data, parts = png_bytes(rng, variant, h, w, extra)
        desc = f"{variant} {h}x{w} +{extra_kind}"
        if rng.random() < 0.3:
            data += png_chunk(b"IDAT", zlib.compress(b"\0" * 100))  # after IEND
            desc += " +after-iend"
        return {"frame.png": data}, desc, {}
    data, parts = png_bytes(rng, variant, h, w)
    desc = f"{variant} {h}x{w}"
    if kind == "ihdr":
        fields = {"width": (16, 4), "height": (20, 4), "bits": (24, 1), "ctype": (25, 1),
                  "compression": (26, 1), "filter": (27, 1), "interlace": (28, 1)}
        name = _pick(rng, tuple(fields))
        off, size = fields[name]
        if size == 4:
            v = edge_int(rng, w if name == "width" else h)
            if rng.random() < 0.3:  # a huge claim over the pixel limit
                v = int(rng.integers(2100, 70000))
        else:
            v = _pick(rng, (0, 1, 2, 3, 4, 5, 6, 7, 8, 16, 32, 255))
        b = bytearray(data)
        b[off:off + size] = v.to_bytes(size, "big")
        crc_ok = rng.random() < 0.85
        b[29:33] = struct.pack(">I", (zlib.crc32(bytes(b[12:29])) & 0xFFFFFFFF)
                               ^ (0 if crc_ok else 1))
        return {"frame.png": bytes(b)}, f"{desc} ihdr.{name}={v}{'' if crc_ok else ' bad-crc'}", {}
    if kind == "length":
        chunks = png_chunks(data)
        pos, n, k = _pick(rng, chunks)
        v = _pick(rng, (0, max(0, n - 1), n + 1, n + 100, 2**31 - 1, 2**32 - 1,
                        int(rng.integers(0, 2**32))))
        b = bytearray(data)
        b[pos:pos + 4] = struct.pack(">I", v)
        return {"frame.png": bytes(b)}, f"{desc} {k.decode('latin1')}.length={v}", {}
    if kind == "crc":
        chunks = png_chunks(data)
        pos, n, k = _pick(rng, chunks)
        b = bytearray(data)
        b[pos + 8 + n] ^= 0xFF
        return {"frame.png": bytes(b)}, f"{desc} {k.decode('latin1')}.crc", {}
    if kind == "truncate":
        d, m = truncate(rng, data)
        return {"frame.png": d}, f"{desc} {m}", {}
    if kind == "flip":
        hi = 41 if rng.random() < 0.5 else None
        d, m = flip_bytes(rng, data, 8, hi)
        return {"frame.png": d}, f"{desc} {m}", {}
    if kind == "bomb":
        bits, ctype, ch = PNG_VARIANTS[variant]
        if ctype == 3:
            ch = 1
        side_h, side_w = int(rng.integers(500, 4000)), int(rng.integers(500, 4000))
        if rng.random() < 0.2:
            side_h, side_w = int(rng.integers(20000, 70000)), int(rng.integers(20000, 70000))
        row = 1 + side_w * ch * bits // 8
        full = rng.random() < 0.5 and side_h * row < (64 << 20)
        body = zlib.compress(b"\0" * (side_h * row if full else min(side_h * row, 4096)), 9)
        ihdr = struct.pack(">IIBBBBB", side_w, side_h, bits, ctype, 0, 0, 0)
        d = (b"\x89PNG\r\n\x1a\n" + png_chunk(b"IHDR", ihdr)
             + (png_chunk(b"PLTE", bytes(48)) if ctype == 3 else b"")
             + png_chunk(b"IDAT", body) + png_chunk(b"IEND", b""))
        return ({"frame.png": d},
                f"{variant} bomb {side_h}x{side_w} {'inflating' if full else 'short'}", {})
    if kind == "idat":
        raw = bytearray(parts["raw"])
        m = _pick(rng, ("filter-type", "short", "long", "garbage", "raw-zlib-noise"))
        if m == "filter-type" and raw:
            raw[0] = int(rng.integers(5, 256))
            body = zlib.compress(bytes(raw))
        elif m == "short":
            body = zlib.compress(bytes(raw[:int(rng.integers(0, max(1, len(raw))))]))
        elif m == "long":
            body = zlib.compress(bytes(raw) + bytes(int(rng.integers(1, 5000))))
        elif m == "garbage":
            body = bytes(rng.integers(0, 256, int(rng.integers(1, 200)), dtype=np.uint8))
        else:
            body = zlib.compress(bytes(rng.integers(0, 256, len(raw), dtype=np.uint8)))
        chunks = png_chunks(data)
        idat = [c for c in chunks if c[2] == b"IDAT"]
        start, end = idat[0][0], idat[-1][0] + 12 + idat[-1][1]
        d = data[:start] + png_chunk(b"IDAT", body) + data[end:]
        return {"frame.png": d}, f"{desc} idat.{m}", {}
    if kind == "generic":
        d, m = generic(rng, data)
        return {"frame.png": d}, f"{desc} {m}", {}
    return {"frame.png": data}, f"{desc} valid", {}


# ==========================================================================================
# TIFF
# ==========================================================================================
TIFF_TAGS = {256: "width", 257: "length", 258: "bits", 259: "compression", 262: "photometric",
             273: "strip_offsets", 277: "samples", 278: "rows_per_strip",
             279: "strip_bytes", 284: "planar", 322: "tile_width", 323: "tile_length",
             324: "tile_offsets", 325: "tile_bytes", 339: "sample_format"}


def tiff_bytes(rng: np.random.Generator) -> tuple[bytes, str, int]:
    """A valid TIFF (tifffile) of a random layout; its description and page count."""
    import tifffile  # lazy: the driver's generators only

    kind = _pick(rng, ("grey8", "grey16", "rgb8", "rgb16", "planar", "float32", "float64",
                       "zlib", "lzw", "tiled", "bigendian", "stack", "stack", "stack-rgb",
                       "bigtiff"))
    h, w = int(rng.integers(4, 40)), int(rng.integers(4, 40))
    pages = 1
    kw: dict = {}
    if kind in ("grey8", "zlib", "lzw"):
        a = rng.integers(0, 256, (h, w), dtype=np.uint8)
        if kind != "grey8":
            kw["compression"] = "zlib" if kind == "zlib" else "lzw"
    elif kind in ("grey16", "bigendian", "bigtiff"):
        a = rng.integers(0, 65536, (h, w), dtype=np.uint16)
        if kind == "bigendian":
            kw["byteorder"] = ">"
        if kind == "bigtiff":
            kw["bigtiff"] = True
    elif kind in ("rgb8", "rgb16"):
        a = rng.integers(0, 256, (h, w, 3)).astype(np.uint8 if kind == "rgb8" else np.uint16)
        kw["photometric"] = "rgb"
    elif kind == "planar":
        a = rng.integers(0, 65536, (3, h, w), dtype=np.uint16)
        kw.update(photometric="rgb", planarconfig="separate")
    elif kind in ("float32", "float64"):
        a = rng.random((h, w)).astype(kind)
    elif kind == "tiled":
        a = rng.integers(0, 65536, (32, 48), dtype=np.uint16)
        kw["tile"] = (16, 16)
    elif kind == "stack":
        pages = int(rng.integers(2, 6))
        a = rng.integers(0, 65536, (pages, h, w), dtype=np.uint16)
        kw["photometric"] = "minisblack"
    else:
        pages = int(rng.integers(2, 4))
        a = rng.integers(0, 256, (pages, h, w, 3), dtype=np.uint8)
        kw["photometric"] = "rgb"
    buf = io.BytesIO()
    tifffile.imwrite(buf, a, **kw)
    return buf.getvalue(), f"{kind} {'x'.join(map(str, a.shape))}", pages


def tiff_ifds(data: bytes) -> tuple[str, list[int], list[tuple[int, int, int, int]]]:
    """Byte order, the IFD offsets and (entry offset, tag, type, count) of a classic TIFF."""
    if data[:2] not in (b"II", b"MM") or len(data) < 8:
        return "<", [], []
    bo = "<" if data[:2] == b"II" else ">"
    if struct.unpack(bo + "H", data[2:4])[0] != 42:
        return bo, [], []
    (off,) = struct.unpack(bo + "I", data[4:8])
    ifds, entries = [], []
    while off and off + 2 <= len(data) and off not in ifds and len(ifds) < 32:
        ifds.append(off)
        (n,) = struct.unpack(bo + "H", data[off:off + 2])
        for k in range(n):
            pos = off + 2 + 12 * k
            if pos + 12 > len(data):
                break
            tag, typ, count = struct.unpack(bo + "HHI", data[pos:pos + 8])
            entries.append((pos, tag, typ, count))
        nxt = off + 2 + 12 * n
        if nxt + 4 > len(data):
            break
        (off,) = struct.unpack(bo + "I", data[nxt:nxt + 4])
    return bo, ifds, entries


def tiff_case(rng: np.random.Generator) -> tuple[dict[str, bytes], str, dict]:
    data, desc, pages = tiff_bytes(rng)
    bo, ifds, entries = tiff_ifds(data)
    kind = _pick(rng, ("tag", "tag", "tag", "entry", "ifd", "truncate", "flip", "generic",
                       "valid"))
    if kind in ("tag", "entry") and not entries:
        kind = "flip"
    b = bytearray(data)
    if kind == "tag":
        cands = [e for e in entries if e[1] in TIFF_TAGS] or entries
        pos, tag, typ, count = _pick(rng, cands)
        name = TIFF_TAGS.get(tag, str(tag))
        v = edge_int(rng, 16)
        if name in ("bits",):
            v = _pick(rng, (0, 1, 2, 4, 7, 8, 12, 16, 24, 32, 64, 128, 65535))
        elif name in ("compression",):
            v = _pick(rng, (0, 1, 2, 5, 6, 7, 8, 32773, 34712, 50000, 65535))
        elif name in ("samples", "planar", "photometric", "sample_format"):
            v = _pick(rng, (0, 1, 2, 3, 4, 5, 6, 8, 255, 65535))
        # one value in the entry itself, as SHORT or LONG
        if typ == 3 and v < 65536:
            b[pos + 2:pos + 8] = struct.pack(bo + "HI", 3, 1)
            b[pos + 8:pos + 12] = struct.pack(bo + "HH", v, 0)
        else:
            b[pos + 2:pos + 8] = struct.pack(bo + "HI", 4, 1)
            b[pos + 8:pos + 12] = struct.pack(bo + "I", v % 2**32)
        return {"frame.tif": bytes(b)}, f"{desc} {name}={v}", {"pages": pages}
    if kind == "entry":
        pos, tag, typ, count = _pick(rng, entries)
        m = _pick(rng, ("type", "count", "tag"))
        if m == "type":
            v = int(rng.integers(0, 20))
            b[pos + 2:pos + 4] = struct.pack(bo + "H", v)
        elif m == "count":
            v = edge_int(rng, count)
            b[pos + 4:pos + 8] = struct.pack(bo + "I", v)
        else:
            v = int(rng.integers(0, 65536))
            b[pos:pos + 2] = struct.pack(bo + "H", v)
        return ({"frame.tif": bytes(b)}, f"{desc} entry({TIFF_TAGS.get(tag, tag)}).{m}={v}",
                {"pages": pages})
    if kind == "ifd" and ifds:
        m = _pick(rng, ("first", "count", "next-loop", "next-far"))
        off = _pick(rng, ifds)
        if m == "first":
            v = edge_int(rng, 8)
            b[4:8] = struct.pack(bo + "I", v)
        elif m == "count":
            v = _pick(rng, (0, 1, 2, 255, 4096, 65535))
            b[off:off + 2] = struct.pack(bo + "H", v)
        else:
            (n,) = struct.unpack(bo + "H", data[off:off + 2])
            nxt = off + 2 + 12 * n
            v = off if m == "next-loop" else edge_int(rng, len(data))
            if nxt + 4 <= len(b):
                b[nxt:nxt + 4] = struct.pack(bo + "I", v)
        return {"frame.tif": bytes(b)}, f"{desc} ifd.{m}={v}", {"pages": pages}
    if kind == "truncate":
        d, m = truncate(rng, data)
    elif kind == "flip":
        d, m = flip_bytes(rng, data, 0, 16 + (max(ifds) + 400 if ifds else 256))
    elif kind == "generic":
        d, m = generic(rng, data)
    else:
        d, m = data, "valid"
    return {"frame.tif": d}, f"{desc} {m}", {"pages": pages}


# ==========================================================================================
# NPY / NPZ
# ==========================================================================================
def npy_raw(header: str, body: bytes, version: tuple[int, int] = (1, 0),
            hlen: int | None = None) -> bytes:
    """An NPY file from header text (padded as numpy does) and data bytes."""
    text = header.encode("latin1", "replace")
    pre = 10 if version[0] == 1 else 12
    pad = (-(pre + len(text) + 1)) % 64
    text = text + b" " * pad + b"\n"
    n = len(text) if hlen is None else hlen
    size = struct.pack("<H", n % 65536) if version[0] == 1 else struct.pack("<I", n % 2**32)
    return b"\x93NUMPY" + bytes(version) + size + text + body


NPY_DESCRS = ("'<u1'", "'|u1'", "'<u2'", "'>u2'", "'<f2'", "'<f4'", "'<f8'", "'>f8'",
              "'|b1'", "'<i2'", "'<i4'", "'<u4'", "'<u8'", "'<c8'", "'<c16'", "'|O'",
              "'|V16'", "'<U4'", "'|S8'", "'<M8[s]'", "[('a', '<f4'), ('b', '<u2')]",
              "'<u3'", "'garbage'", "0", "None", "'<f16'")
NPY_SHAPES = ("()", "(0,)", "(16,)", "(0, 16)", "(16, 0)", "(3, 3)", "(16, 16)", "(16, 16, 1)",
              "(16, 16, 2)", "(16, 16, 3)", "(16, 16, 4)", "(16, 16, 5)", "(2, 16, 16)",
              "(200, 16, 16)", "(3, 16, 16, 3)", "(2, 2, 16, 16, 3)", "(-1, 16)",
              "(16, -16)", "(2000, 2000)", "(2001, 2000)", "(100000, 100000)",
              "(1000000000, 8, 8)", "(100000, 4, 4)", "(3000000000, 4, 4)",
              "(2**40, 2**40)", "(9223372036854775807, 2)", "(16.5, 16)", "('a', 16)",
              "(" + "1, " * 40 + ")", "(65536, 65536, 3)", "(4, 1000000000)")


def npy_variant(rng: np.random.Generator) -> tuple[np.ndarray, str]:
    kind = _pick(rng, ("u1", "u2", "f4", "f8", "f2", ">u2", "rgb-u2", "rgba-f4", "stack",
                       "stack-rgb", "i2", "bool", "c8", "fortran", "nan"))
    h, w = int(rng.integers(4, 24)), int(rng.integers(4, 24))
    if kind in ("u1", "u2", ">u2", "i2"):
        a = rng.integers(0, 200, (h, w)).astype(kind)
    elif kind in ("f4", "f8", "f2"):
        a = rng.random((h, w)).astype(kind)
    elif kind == "rgb-u2":
        a = rng.integers(0, 65536, (h, w, 3)).astype(np.uint16)
    elif kind == "rgba-f4":
        a = rng.random((h, w, 4)).astype(np.float32)
    elif kind == "stack":
        a = rng.random((int(rng.integers(2, 5)), h, w))
    elif kind == "stack-rgb":
        a = rng.integers(0, 256, (int(rng.integers(2, 4)), h, w, 3)).astype(np.uint8)
    elif kind == "bool":
        a = rng.random((h, w)) > 0.5
    elif kind == "c8":
        a = (rng.random((h, w)) + 1j).astype(np.complex64)
    elif kind == "fortran":
        a = np.asfortranarray(rng.random((h, w)))
    else:
        a = rng.random((h, w))
        a[0, 0] = np.nan
    return a, kind


def npy_mutate(rng: np.random.Generator, a: np.ndarray) -> tuple[bytes, str]:
    """A valid NPY of ``a``, or one with its header, length, version or bytes mutated."""
    buf = io.BytesIO()
    np.save(buf, a, allow_pickle=False)
    data = buf.getvalue()
    body = data[len(data) - a.nbytes:] if a.nbytes else b""
    descr = repr(np.lib.format.dtype_to_descr(a.dtype))
    fortran = a.flags.f_contiguous and not a.flags.c_contiguous
    shape = repr(tuple(a.shape))
    version = (1, 0)
    kind = _pick(rng, ("shape", "shape", "descr", "fortran", "header", "hlen", "version",
                       "body", "truncate", "flip", "valid"))
    hlen = None
    if kind == "shape":
        shape = _pick(rng, NPY_SHAPES)
    elif kind == "descr":
        descr = _pick(rng, NPY_DESCRS)
    elif kind == "fortran":
        fortran = _pick(rng, (True, False, 1, "'x'", None))
    elif kind == "hlen":
        hlen = edge_int(rng, 118, 16)
    elif kind == "version":
        version = _pick(rng, ((1, 0), (2, 0), (3, 0), (0, 0), (9, 9), (255, 255)))
    elif kind == "body":
        body = body[:int(rng.integers(0, len(body) + 1))] if rng.random() < 0.6 else \
            body + bytes(int(rng.integers(1, 500)))
    if kind == "header":
        header = _pick(rng, ("{}", "garbage", "{'descr': '<f8'}", "[1, 2, 3]",
                             "{'descr': '<f8', 'fortran_order': False, 'shape': (4, 4), "
                             "'extra': 1}",
                             "{'descr': '<f8', 'fortran_order': False, 'shape': " + "(" * 200
                             + ")" * 200 + "}",
                             "{'descr': '" + "x" * 5000 + "', 'fortran_order': False, "
                             "'shape': (4, 4)}",
                             "__import__('os').system('true')", "{'descr': '<f8',"))
        desc = f"header={header[:40]!r}"
    else:
        header = f"{{'descr': {descr}, 'fortran_order': {fortran}, 'shape': {shape}, }}"
        desc = {"shape": f"shape={shape[:40]}", "descr": f"descr={descr}",
                "fortran": f"fortran={fortran}", "hlen": f"hlen={hlen}",
                "version": f"version={version}", "body": f"body={len(body)}/{a.nbytes}"
                }.get(kind, kind)
    d = npy_raw(header, body, version, hlen)
    if kind == "truncate":
        d, desc = truncate(rng, data)
    elif kind == "flip":
        d, desc = flip_bytes(rng, data, 0, 128 if rng.random() < 0.7 else None)
    elif kind == "valid":
        d = data
    return d, desc


def npy_case(rng: np.random.Generator) -> tuple[dict[str, bytes], str, dict]:
    a, kind = npy_variant(rng)
    d, desc = npy_mutate(rng, a)
    return {"frame.npy": d}, f"{kind} {'x'.join(map(str, a.shape))} {desc}", {}


def npz_case(rng: np.random.Generator) -> tuple[dict[str, bytes], str, dict]:
    members: list[tuple[str, bytes]] = []
    descs = []
    for i in range(int(rng.integers(1, 4))):
        a, kind = npy_variant(rng)
        if rng.random() < 0.5:
            d, desc = npy_mutate(rng, a)
        else:
            buf = io.BytesIO()
            np.save(buf, a)
            d, desc = buf.getvalue(), "valid"
        name = f"arr_{i}.npy"
        if rng.random() < 0.15:
            name = _pick(rng, ("../up.npy", "a/b.npy", ".npy", "noext", "x" * 200 + ".npy",
                               "sp ace.npy", "\u00e9t\u00e9.npy", "arr_0.npy"))
        members.append((name, d))
        descs.append(f"{name[:20]}:{kind}:{desc}")
    extra = ""
    r = rng.random()
    if r < 0.08:  # many tiny members
        n = int(rng.integers(100, 600))
        tiny = io.BytesIO()
        np.save(tiny, np.zeros((4, 4), np.uint8))
        members += [(f"m{i}.npy", tiny.getvalue()) for i in range(n)]
        extra = f" +{n} members"
    elif r < 0.16:  # a deflate bomb: a large declared array of zeros
        side = int(_pick(rng, (1500, 2000, 2500, 4000)))
        bomb = npy_raw(f"{{'descr': '<f8', 'fortran_order': False, 'shape': ({side}, {side}), }}",
                       bytes(8 * side * side))
        members.append(("bomb.npy", bomb))
        extra = f" +bomb {side}^2 f8"
    elif r < 0.22:  # a big stack of tiny frames, declared and stored
        n = int(rng.integers(1000, 20000))
        members.append(("many.npy", npy_raw(
            f"{{'descr': '|u1', 'fortran_order': False, 'shape': ({n}, 4, 4), }}",
            bytes(16 * n))))
        extra = f" +stack of {n}"
    buf = io.BytesIO()
    method = zipfile.ZIP_DEFLATED if rng.random() < 0.6 else zipfile.ZIP_STORED
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # duplicate names
        with zipfile.ZipFile(buf, "w", method) as zf:
            for name, d in members:
                zf.writestr(name, d)
    data = buf.getvalue()
    desc = " ".join(descs)[:200] + extra
    r = rng.random()
    if r < 0.3:
        data, m = generic(rng, data)
        desc += f" zip:{m}"
    elif r < 0.4:
        data, m = flip_bytes(rng, data, max(0, len(data) - 120))  # the central directory
        desc += f" cd:{m}"
    return {"frames.npz": data}, desc, {}


# ==========================================================================================
# camera TOML
# ==========================================================================================
def toml_value(v) -> str:
    """TOML text for a value (floats nan/inf as TOML spells them)."""
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, int):
        return str(v)
    if isinstance(v, float):
        if v != v:
            return "nan"
        if v in (float("inf"), float("-inf")):
            return "inf" if v > 0 else "-inf"
        return repr(v)
    if isinstance(v, str):
        return json.dumps(v)
    if isinstance(v, (list, tuple)):
        return "[" + ", ".join(toml_value(x) for x in v) + "]"
    if isinstance(v, dict):
        return "{" + ", ".join(f"{k} = {toml_value(x)}" for k, x in v.items()) + "}"
    return str(v)


BASE_CAMERA = {"pitch": 0.01, "shape": [64, 64], "r1": 0.07, "z1": 20.0, "z2": 3.0, "R": 0.6}
CAMERA_KEYS = ("pitch", "shape", "r1", "z1", "z2", "R", "mask", "phase", "r1_shadow",
               "wavelength", "mask_center", "name", "r1_shadow_squared")
ODD_VALUES = (0, -1, 1, 0.0, -0.0, 1e-300, 1e300, float("nan"), float("inf"), float("-inf"),
              2**63 - 1, -(2**63), "0.01", "", "inf", True, False, [], [1], [1, 2], [1, 2, 3],
              ["a", "b"], [64.5, 64], [0, 0], [-64, 64], [100000, 100000],
              [2000, 2000], [3, 2**40], {"a": 1}, [[1, 2], [3, 4]], "fza", "gzp", "FZA",
              "none", 3.0, 1e-6, 0.5, 1e-3)


def toml_case(rng: np.random.Generator) -> tuple[dict[str, bytes], str, dict]:
    cam = dict(BASE_CAMERA)
    if rng.random() < 0.3:
        cam.update(mask=_pick(rng, ("fza", "gzp")), phase=float(rng.uniform(-3, 3)))
    if rng.random() < 0.2:
        cam["wavelength"] = 5.5e-4
    descs = []
    layout = "table"
    text_mut = None
    for _ in range(int(rng.integers(1, 4))):
        kind = _pick(rng, ("value", "value", "value", "drop", "unknown", "layout", "text",
                           "deep", "utf8", "valid"))
        if kind == "value":
            k = _pick(rng, CAMERA_KEYS)
            v = _pick(rng, ODD_VALUES)
            if rng.random() < 0.3 and k != "shape":  # plausible but scaled (a unit slip)
                v = float(BASE_CAMERA.get(k, 1.0) if isinstance(BASE_CAMERA.get(k), float)
                          else 1.0) * float(_pick(rng, (1e-3, 1e3, 10, 0.1)))
            cam[k] = v
            descs.append(f"{k}={toml_value(v)[:30]}")
        elif kind == "drop":
            k = _pick(rng, tuple(cam))
            cam.pop(k, None)
            descs.append(f"drop {k}")
        elif kind == "unknown":
            k = _pick(rng, ("pitch_um", "Pitch", "shape2", "x", "camera"))
            cam[k] = 1
            descs.append(f"unknown {k}")
        elif kind == "layout":
            layout = _pick(rng, ("top", "table", "sub", "array", "dup-table", "two"))
            descs.append(f"layout {layout}")
        else:
            text_mut = kind
            descs.append(kind)
    body = "".join(f"{k} = {toml_value(v)}\n" for k, v in cam.items())
    if layout == "top":
        text = body
    elif layout == "sub":
        text = "[camera.optics]\n" + body
    elif layout == "array":
        text = "[[camera]]\n" + body
    elif layout == "dup-table":
        text = "[camera]\n" + body + "[camera]\npitch = 0.01\n"
    elif layout == "two":
        text = "name = 'x'\n[camera]\n" + body
    else:
        text = "[camera]\n" + body
    data = text.encode("utf-8")
    if text_mut == "text":
        data, m = generic(rng, data)
        descs.append(m)
    elif text_mut == "deep":
        n = int(_pick(rng, (100, 1000, 5000, 50000)))
        which = _pick(rng, ("array", "table"))
        if which == "array":
            data += b"deep = " + b"[" * n + b"]" * n + b"\n"
        else:
            data += b"deep = " + b"{a = " * n + b"1" + b"}" * n + b"\n"
        descs.append(f"deep {which} {n}")
    elif text_mut == "utf8":
        i = int(rng.integers(0, len(data)))
        data = data[:i] + _pick(rng, (b"\xff\xfe", b"\xc3", b"\x00", b"\xef\xbb\xbf",
                                      b"\xed\xa0\x80")) + data[i:]
        descs.append(f"bytes at {i}")
    elif text_mut == "dup":
        data += b"pitch = 0.02\n"
    return {"cam.toml": data}, "; ".join(descs), {}


# ==========================================================================================
# GIF and video
# ==========================================================================================
def gif_bytes(rng: np.random.Generator) -> bytes:
    import imageio.v3 as iio  # lazy: the driver's generators only

    n, h, w = int(rng.integers(1, 4)), int(rng.integers(4, 24)), int(rng.integers(4, 24))
    grey = rng.random() < 0.5
    a = rng.integers(0, 256, (n, h, w) if grey else (n, h, w, 3), dtype=np.uint8)
    return iio.imwrite("<bytes>", a if n > 1 else a[0], extension=".gif")


def gif_blocks(data: bytes) -> tuple[list[int], list[int]]:
    """Offsets of each image descriptor and each LZW minimum code size byte of a GIF."""
    desc, lzw = [], []
    if len(data) < 13:
        return desc, lzw
    flags = data[10]
    pos = 13 + (3 * 2 ** ((flags & 7) + 1) if flags & 0x80 else 0)
    while pos < len(data) and len(desc) < 64:
        t = data[pos]
        if t == 0x21:  # extension: label, sub-blocks
            pos += 2
            while pos < len(data) and data[pos]:
                pos += data[pos] + 1
            pos += 1
        elif t == 0x2C:
            desc.append(pos)
            if pos + 10 > len(data):
                break
            f = data[pos + 9]
            pos += 10 + (3 * 2 ** ((f & 7) + 1) if f & 0x80 else 0)
            lzw.append(pos)
            pos += 1
            while pos < len(data) and data[pos]:
                pos += data[pos] + 1
            pos += 1
        else:
            break
    return desc, lzw


_MP4_CACHE: dict[tuple[int, int, int], bytes] = {}


def mp4_bytes(rng: np.random.Generator) -> bytes | None:
    """A tiny MP4 through imageio-ffmpeg (a few cached layouts), None without it."""
    try:
        import imageio.v3 as iio  # lazy: the driver's generators only
        import imageio_ffmpeg  # noqa: F401  # lazy: optional (clfza[video])
    except ImportError:
        return None
    key = (int(rng.integers(1, 4)), int(_pick(rng, (16, 32))), int(rng.integers(0, 2)))
    if key not in _MP4_CACHE:
        n, s, grey = key
        g = np.random.default_rng(key)
        a = g.integers(0, 256, (n, s, s, 3), dtype=np.uint8)
        if grey:
            a[..., 1] = a[..., 2] = a[..., 0]
        _MP4_CACHE[key] = iio.imwrite("<bytes>", a, extension=".mp4", fps=5)
    return _MP4_CACHE[key]


def video_case(rng: np.random.Generator) -> tuple[dict[str, bytes], str, dict]:
    if rng.random() < 0.3:
        data = mp4_bytes(rng)
        if data is not None:
            kind = _pick(rng, ("flip", "flip-head", "truncate", "valid"))
            if kind == "flip":
                d, m = flip_bytes(rng, data)
            elif kind == "flip-head":
                d, m = flip_bytes(rng, data, 0, 1024)
            elif kind == "truncate":
                d, m = truncate(rng, data)
            else:
                d, m = data, "valid"
            return {"movie.mp4": d}, f"mp4 {m}", {}
    data = gif_bytes(rng)
    desc, lzw = gif_blocks(data)
    b = bytearray(data)
    kind = _pick(rng, ("screen", "frame-size", "frame-pos", "lzw", "truncate", "flip",
                       "generic", "valid"))
    if kind == "screen":
        w, h = edge_int(rng, 16, 16), edge_int(rng, 16, 16)
        b[6:10] = struct.pack("<HH", w, h)
        m = f"screen={w}x{h}"
    elif kind in ("frame-size", "frame-pos") and desc:
        pos = _pick(rng, desc)
        w, h = edge_int(rng, 16, 16), edge_int(rng, 16, 16)
        off = pos + (5 if kind == "frame-size" else 1)
        b[off:off + 4] = struct.pack("<HH", w, h)
        m = f"{kind}={w}x{h}"
    elif kind == "lzw" and lzw:
        pos = _pick(rng, lzw)
        v = _pick(rng, (0, 1, 2, 9, 11, 12, 13, 255))
        if pos < len(b):
            b[pos] = v
        m = f"lzw={v}"
    elif kind == "truncate":
        d, m = truncate(rng, data)
        b = bytearray(d)
    elif kind == "generic":
        d, m = generic(rng, data)
        b = bytearray(d)
    elif kind == "valid":
        m = "valid"
    else:
        d, m = flip_bytes(rng, data, 0, 64 if rng.random() < 0.5 else None)
        b = bytearray(d)
    return {"anim.gif": bytes(b)}, f"gif {m}", {}


# ==========================================================================================
# the command line
# ==========================================================================================
CAMERA_64 = "[camera]\npitch = 0.01\nshape = [64, 64]\nr1 = 0.07\nz1 = 20.0\nz2 = 3.0\nR = 0.6\n"


def _npy(a: np.ndarray) -> bytes:
    buf = io.BytesIO()
    np.save(buf, a)
    return buf.getvalue()


def frame_file(rng: np.random.Generator, shape=(64, 64), suffix: str | None = None,
               dtype: str | None = None) -> tuple[str, bytes]:
    """A valid frame file (suffix, bytes) of ``shape``."""
    import imageio.v3 as iio  # lazy: the driver's generators only
    import tifffile  # lazy: the driver's generators only

    suffix = suffix or _pick(rng, (".npy", ".png", ".tif"))
    dtype = dtype or _pick(rng, ("uint8", "uint16", "float32"))
    if suffix == ".png" and dtype == "float32":
        dtype = "uint16"
    a = rng.random(shape)
    if dtype != "float32":
        a = (a * np.iinfo(dtype).max).astype(dtype)
    else:
        a = a.astype(np.float32)
    if suffix == ".npy":
        return suffix, _npy(a)
    if suffix == ".tif":
        buf = io.BytesIO()
        tifffile.imwrite(buf, a, photometric="rgb" if a.ndim == 3 else "minisblack")
        return suffix, buf.getvalue()
    if a.dtype == np.uint16 and a.ndim == 3:  # Pillow writes no 16-bit colour PNG
        return suffix, png_bytes(rng, "rgb16", shape[0], shape[1])[0]
    return suffix, iio.imwrite("<bytes>", a, extension=".png")


READER_CASES = {}  # filled below: generator name -> function


def mutated_input(rng: np.random.Generator) -> tuple[str, bytes, str]:
    """A file from one of the reader generators: (name, bytes, description)."""
    gen = _pick(rng, ("png", "tiff", "npy", "npz", "video"))
    files, desc, _ = READER_CASES[gen](rng)
    name, data = next(iter(files.items()))
    return name, data, f"{gen}:{desc}"


def _vals(rng: np.random.Generator, good: tuple, bad: tuple, p_bad: float = 0.25) -> str:
    return str(_pick(rng, bad if (rng.random() < p_bad or not good) else good))


#: ``clfza reconstruct`` options: name -> (valid values, invalid values); None: a flag
RECONSTRUCT_OPTIONS: dict = {
    "--method": (("bp", "twist", "fista", "admm"), ("BP", "", "tv", "admm ", "nope")),
    "--tau": (("0.01", "0.001", "auto", "0", "1e3"), ("-1", "nan", "inf", "x", "1e400",
                                                     "AUTO ")),
    "--iters": (("1", "3", "10", "30"), ("0", "-3", "2.5", "x", "")),
    "--opt": (("mode=paper", "mode=efficient", "reg=tv", "reg=l1", "nonneg=true",
               "nonneg=false", "stop=none", "tol=1e-3", "rho=1.0", "min_iters=2",
               "tv_iters=5", "relax=1.5", "mu=0.5", "adapt=false", "average=true"),
              ("mode=xyz", "reg=abc", "nonneg=maybe", "tol=-1", "rho=0", "unknown=1",
               "=1", "noequals", "tau=-1", "iters=0", "relax=nan", "min_iters=x",
               "callback=1", "x0=1", "truth=1", "checkpoints=5", "colour=2", "weight=x",
               "highpass=-1", "support=2", "stop=maybe", "tv_tol=inf", "lambda1=0")),
    "--backend": (("opencl", "numpy"), ("cuda",)),
    "--model": (("auto", "tf", "exact"), ("paper", "")),
    "--psf-pitch": (("0.01", "0.005", "0.02"), ("0", "-1", "nan", "inf", "x")),
    "--margin": (("0", "2", "8"), ("-1", "x", "1.5", "100000")),
    "--explain": None,
    "--plan": None,
    "--format": (("png", "tiff", "tiff-float"), ("jpg", "npy")),
    "--scaling": (("percentile", "minmax", "unit"), ("log",)),
    "--percentiles": (("0.1,99.9", "1,99", "0,100", "5"), ("99,1", "50,50", "-5,50",
                                                           "nan,1", "a,b", "0,101",
                                                           "1,2,3", "inf,inf")),
    "--force": None,
    "--orient": (("sensor", "upright"), ("left",)),
    "--roi": (("0,0,32,32", "10,20,16,8", "0,0,64,64"), ("60,60,10,10", "0,0,0,5", "1,2,3",
                                                       "-1,0,4,4", "0,0,100000,100000",
                                                       "a,b,c,d")),
    "--resume": None,
    "--retries": (("0", "1", "2"), ("-1", "x")),
    "--fps": (("10", "2.5", "30"), ("0", "-1", "nan", "inf", "1e-300", "x")),
    "--frames-per-solve": (("auto", "1", "2", "4"), ("0", "-2", "x", "1.5")),
    "--bayer": (("RGGB", "bggr", "GRBG", "GBRG"), ("XXXX", "rgb")),
    "--crop": (("32", "64", "48,40", "60,64"), ("0", "-4", "64,64,64", "100000", "x",
                                               "1", "3,3")),
    "--center": (("32,32", "30,34", "33.5,30"), ("-10,5", "1e9,0", "nan,0", "inf,1",
                                                 "1", "x,y")),
    "--bin": (("1", "2", "3", "auto", "4"), ("0", "-1", "x", "1000", "2.5", "7")),
    "--z1": (("20", "30", "1e6"), ("0", "-5", "x", "inf", "nan", "1e-300")),
    "--object-mean": (("0.5", "0.1", "2"), ("0", "-1", "nan", "1e300", "inf")),
    # only invalid devices: another valid device compiles the kernels again (seconds)
    "--device": ((), ("gpu", "99:99", "nothing-like-this", "0:99")),
}


def _write_files(files: dict[str, bytes], rel: str, data: bytes) -> str:
    files[rel] = data
    return rel


def reconstruct_case(rng: np.random.Generator) -> tuple[dict[str, bytes], str, dict]:
    files: dict[str, bytes] = {}
    # half the cases draw valid values only (they reach the solve and the writers), the
    # others mix in invalid values, inputs and files
    valid = rng.random() < 0.5
    p_bad = 0.0 if valid else 0.3
    descs: list[str] = ["valid options" if valid else "mixed options"]
    # the camera
    r = rng.random()
    if r < 0.8 or (valid and r >= 0.9):
        camera = _write_files(files, "cam.toml", CAMERA_64.encode())
    elif r < 0.9:
        camera = "simulation"
    else:
        tfiles, tdesc, _ = toml_case(rng)
        camera = _write_files(files, "cam.toml", tfiles["cam.toml"])
        descs.append(f"camera:{tdesc}")
    grey = rng.random() < 0.75
    shape = (64, 64) if grey else (64, 64, 3)
    if camera == "simulation":
        shape = (512, 512) if grey else (512, 512, 3)
    # the inputs
    inputs = []
    for i in range(int(rng.integers(1, 4))):
        k = _pick(rng, ("frame", "frame", "frame", "stack", "folder", "glob", "truth-folder")
                  if valid else ("frame", "frame", "other-shape", "stack", "folder", "glob",
                                 "missing", "mutated", "empty-folder", "truth-folder"))
        if k == "frame":
            suf, d = frame_file(rng, shape)
            inputs.append(_write_files(files, f"in/f{i}{suf}", d))
        elif k == "other-shape":
            s = _pick(rng, ((48, 80), (128, 128), (4, 4), (3, 64), (64, 64, 4), (64, 64, 2)))
            suf, d = frame_file(rng, s, suffix=".npy")
            inputs.append(_write_files(files, f"in/o{i}{suf}", d))
        elif k == "stack":
            n = int(rng.integers(2, 4))
            a = rng.random((n, *shape)).astype(np.float32)
            inputs.append(_write_files(files, f"in/s{i}.npy", _npy(a)))
        elif k == "folder":
            for j in range(int(rng.integers(1, 3))):
                suf, d = frame_file(rng, shape)
                _write_files(files, f"dir{i}/f{j}{suf}", d)
            inputs.append(f"dir{i}")
        elif k == "truth-folder":  # a simulation's outputs: raw frame, record, truth
            suf, d = frame_file(rng, shape, suffix=".tif", dtype="float32")
            _write_files(files, f"sim{i}/x-raw.tif", d)
            _write_files(files, f"sim{i}/x-truth.npy", _npy(rng.random(shape)))
            _write_files(files, f"sim{i}/x.json", json.dumps(
                {"clfza_version": "0", "outputs": {"raw": f"sim{i}/x-raw.tif",
                                                   "truth_npy": f"sim{i}/x-truth.npy"}}
            ).encode())
            inputs.append(f"sim{i}")
        elif k == "glob":
            suf, d = frame_file(rng, shape, suffix=".npy")
            _write_files(files, f"g{i}/a{suf}", d)
            inputs.append(f"g{i}/*.npy" if valid else
                          _pick(rng, (f"g{i}/*.npy", f"g{i}/*.nomatch", f"g{i}/[")))
        elif k == "missing":
            inputs.append(f"in/missing{i}.png")
        elif k == "empty-folder":
            _write_files(files, f"empty{i}/.keep", b"")
            inputs.append(f"empty{i}")
        else:
            name, d, desc = mutated_input(rng)
            inputs.append(_write_files(files, f"in/m{i}{Path(name).suffix}", d))
            descs.append(f"input:{desc}")
    argv = ["reconstruct", *inputs, "--camera", camera]
    out = _pick(rng, ("out", "out", "out", "deep/new/out", "default") if valid else
                ("out", "out", "deep/new/out", "file-out", "default"))
    if out == "file-out":
        _write_files(files, "file-out", b"not a folder")
    if out != "default":
        argv += ["--out", out]
    out_dir = "clfza-out" if out == "default" else out
    if rng.random() < 0.15 and not valid and out != "file-out":  # earlier outputs there
        stem = Path(inputs[0]).stem
        _write_files(files, f"{out_dir}/{stem}.{_pick(rng, ('png', 'npy', 'json'))}",
                     b"stale")
        descs.append("stale output")
    # options, drawn
    names = list(RECONSTRUCT_OPTIONS)
    if valid:
        names = [n for n in names if RECONSTRUCT_OPTIONS[n] is None or RECONSTRUCT_OPTIONS[n][0]]
    drawn = [str(n) for n in rng.choice(names, int(rng.integers(0, 7)), replace=False)]
    if "--method" not in drawn and rng.random() < 0.5:
        drawn.insert(0, "--method")
    method_iterative = False
    for name in drawn:
        spec = RECONSTRUCT_OPTIONS[str(name)]
        if spec is None:
            argv.append(str(name))
            continue
        v = _vals(rng, *spec, p_bad=p_bad)
        if name == "--method" and camera == "simulation":
            v = "bp"  # the 512^2 preset: keep a case's solve short
        argv += [f"{name}={v}"] if (v.startswith("-") or not v) else [str(name), v]
        if name == "--method" and v in ("twist", "fista", "admm"):
            method_iterative = True
    if method_iterative and "--iters" not in " ".join(argv):
        argv += ["--iters", str(int(rng.integers(1, 30)))]
    if camera == "simulation" and "--method" not in argv:
        argv += ["--method", "bp"]
    if rng.random() < 0.15:
        r = rng.random()
        if r < 0.6 or valid:
            suf, d = frame_file(rng, shape[:2] if rng.random() < 0.7 else (48, 48),
                                suffix=".npy", dtype="float32")
            argv += ["--psf", _write_files(files, f"psf{suf}", d)]
        elif r < 0.8:
            name, d, desc = mutated_input(rng)
            argv += ["--psf", _write_files(files, f"psf{Path(name).suffix}", d)]
            descs.append(f"psf:{desc}")
        else:
            argv += ["--psf", "nope.npy"]
    for cal in ("--dark", "--flat"):
        if rng.random() < 0.12:
            r = rng.random()
            if r < 0.4 or valid:
                suf, d = frame_file(rng, shape, suffix=".npy", dtype="float32")
            elif r < 0.55:
                suf, d = ".npy", _npy(np.zeros(shape))
            elif r < 0.7:
                suf, d = ".npy", _npy(np.full(shape, np.nan))
            elif r < 0.85:
                suf, d = frame_file(rng, (32, 32), suffix=".npy")
            else:
                name, d, desc = mutated_input(rng)
                suf = Path(name).suffix
                descs.append(f"{cal}:{desc}")
            argv += [cal, _write_files(files, f"cal{cal[2:]}{suf}", d)]
    for _ in range(int(rng.random() < 0.15) + int(rng.random() < 0.05)):
        target = _pick(rng, ("stack.tif", "stack.gif", "stack.mp4", "sub/dir/stack.tif")
                       if valid else ("stack.tif", "stack.gif", "stack.mp4", "stack.png",
                                      "exists.tif", "out", "sub/dir/stack.tif"))
        if target == "exists.tif":
            _write_files(files, "exists.tif", b"old")
        argv += ["--stack-out", target]
    if rng.random() < 0.3:
        argv.append(_pick(rng, ("-q", "-v")))
    if rng.random() < 0.01:
        argv.append("--help")
    return files, " ".join(descs), {"argv": argv}


SIMULATE_OPTIONS: dict = {
    "--noise": (("0.01", "0", "photons=1000,read=2,bits=12,seed=1", "bits=8", "gaussian=0.001",
                 "photons=50,seed=3", "exposure=2,bits=16", "none"),
                ("bits=20", "bits=0", "bits=2.5", "gaussian=-1", "photons=0", "photons=-5",
                 "exposure=1e300", "x=1", "nan", "inf", "-1", "=", ",", "bits=", "seed=1e30",
                 "read=nan", "photons=inf")),
    "--object-width": (("1", "0.3", "5"), ("0", "-1", "nan", "1e-12", "1e12", "x")),
    "--object-offset": (("0,0", "0.1,-0.2", "1,1"), ("1e9,0", "nan,0", "1", "x,y",
                                                     "inf,0")),
    "--sensor-plane": None,
    "--diffraction": None,
    "--z1": (("20", "50", "inf"), ("0", "-5", "x", "nan", "1e-300")),
    "--format": (("png", "tiff", "npy"), ("bmp", "")),
    "--name": (("scene", "a-b", "x.y"), ("", "a/b", "..", ".", "x" * 300, "\u00e9t\u00e9",
                                        "-x", "a\\b")),
    "--force": None,
}


def simulate_case(rng: np.random.Generator) -> tuple[dict[str, bytes], str, dict]:
    files: dict[str, bytes] = {}
    valid = rng.random() < 0.5
    p_bad = 0.0 if valid else 0.3
    descs: list[str] = ["valid options" if valid else "mixed options"]
    r = rng.random()
    if r < 0.75 or (valid and r >= 0.85):
        camera = _write_files(files, "cam.toml", CAMERA_64.encode())
    elif r < 0.85:
        camera = "simulation" if valid else _pick(rng, ("simulation", "experiment", "nope"))
    else:
        tfiles, tdesc, _ = toml_case(rng)
        camera = _write_files(files, "cam.toml", tfiles["cam.toml"])
        descs.append(f"camera:{tdesc}")
    r = rng.random() * (0.7 if valid else 1.0)
    if r < 0.35:
        scene = _pick(rng, ("camera", "checkerboard", "coins", "astronaut", "moon")
                      + (() if valid else ("nope",)))
    elif r < 0.7:
        s = _pick(rng, ((64, 64), (32, 48), (100, 80), (64, 64, 3), (4, 4))
                  + (() if valid else ((3, 3), (64, 64, 4))))
        suf, d = frame_file(rng, s)
        scene = _write_files(files, f"scene{suf}", d)
    elif r < 0.8:
        a = rng.normal(size=(32, 32))  # negative float intensities
        scene = _write_files(files, "scene.npy", _npy(a))
    else:
        name, d, desc = mutated_input(rng)
        scene = _write_files(files, f"scene{Path(name).suffix}", d)
        descs.append(f"scene:{desc}")
    argv = ["simulate", scene, "--camera", camera]
    out = _pick(rng, ("out", "out", "deep/new/out", "default") if valid else
                ("out", "out", "deep/new/out", "file-out", "truth-file", "default"))
    if out == "file-out":
        _write_files(files, "file-out", b"x")
    if out == "truth-file":
        out = "out"
        _write_files(files, "out/truth", b"x")
        descs.append("truth is a file")
    if out != "default":
        argv += ["--out", out]
    if rng.random() < 0.1 and not valid and out != "file-out":
        _write_files(files, f"{'clfza-out' if out == 'default' else out}/scene-raw.tif", b"old")
        descs.append("stale output")
    for name in rng.choice(list(SIMULATE_OPTIONS), int(rng.integers(0, 5)), replace=False):
        spec = SIMULATE_OPTIONS[str(name)]
        if spec is None:
            argv.append(str(name))
            continue
        v = _vals(rng, *spec, p_bad=p_bad)
        argv += [f"{name}={v}"] if (v.startswith("-") or not v) else [str(name), v]
    if rng.random() < 0.25:
        argv.append(_pick(rng, ("-q", "-v")))
    return files, " ".join(descs), {"argv": argv}


READER_CASES.update(png=png_case, tiff=tiff_case, npy=npy_case, npz=npz_case,
                    toml=toml_case, video=video_case)
CASE_MAKERS = {**READER_CASES, "cli-reconstruct": reconstruct_case,
               "cli-simulate": simulate_case}


# ==========================================================================================
# cases
# ==========================================================================================
@dataclass
class Case:
    """One generated case: its number, generator, files and what to run."""

    index: int
    gen: str
    desc: str
    files: dict[str, bytes]
    action: dict

    def spec(self) -> dict:
        """What the worker needs (the files are already on disk)."""
        return {"index": self.index, "gen": self.gen, "action": self.action}


def schedule(n: int, seed: int) -> list[str]:
    """The generator of each of ``n`` cases: shares by :data:`WEIGHTS`, interleaved."""
    counts = {g: int(round(WEIGHTS[g] * n)) for g in GENERATORS}
    diff = n - sum(counts.values())
    counts["cli-reconstruct"] += diff
    order = [g for g in GENERATORS for _ in range(counts[g])]
    rng = np.random.default_rng([seed, 2**31])
    rng.shuffle(order)
    return order


def make_case(index: int, gen: str, seed: int) -> Case:
    """Case ``index`` of the run with ``seed`` (reproducible from these alone)."""
    rng = np.random.default_rng([seed, index])
    files, desc, extra = CASE_MAKERS[gen](rng)
    if gen in READER_CASES:
        name = next(iter(files))
        how = {"png": ("frame",), "tiff": ("frame", "refs", "pages"), "npy": ("frame", "refs"),
               "npz": ("refs",), "toml": ("camera", "camera", "camera", "simulate"),
               "video": ("refs",)}[gen]
        h = _pick(rng, how)
        if gen == "tiff" and extra.get("pages", 1) > 1 and h == "frame":
            h = "refs"
        action = {"op": "read", "how": h, "path": name}
        if h == "simulate":
            action = {"op": "cli", "argv": ["simulate", "checkerboard", "--camera", name,
                                            "--out", "out", "-q"]}
        elif rng.random() < 0.12:  # the same file through the command line
            action = {"op": "cli", "argv": ["reconstruct", name, "--camera", "cam64.toml",
                                            "--out", "out", "-q"]}
            files["cam64.toml"] = CAMERA_64.encode()
        return Case(index, gen, desc, files, action)
    return Case(index, gen, desc, files, {"op": "cli", "argv": extra["argv"]})


# ==========================================================================================
# the worker: runs cases in one process (clfza imported once)
# ==========================================================================================
def _status_kb(key: str, pid: str = "self") -> int:
    try:
        with open(f"/proc/{pid}/status", encoding="ascii") as fh:
            for line in fh:
                if line.startswith(key):
                    return int(line.split()[1])
    except (OSError, ValueError, IndexError):
        pass
    return -1


def _reset_peak() -> bool:
    try:
        with open("/proc/self/clear_refs", "w", encoding="ascii") as fh:
            fh.write("5")
        return True
    except OSError:
        return False


UNEXPECTED = "(rerun with --debug for the traceback)"


def run_read(how: str, path: str) -> tuple[str, str]:
    """Run one reader; ("ok" | "refused" | "bug:exception", message)."""
    from clfza import Camera, ClfzaError  # lazy: the worker imports clfza once, at start
    from clfza.io import expand_frames, read_frame, read_ref, tiff_pages  # lazy: as above

    try:
        if how == "frame":
            read_frame(path)
        elif how == "pages":
            tiff_pages(path)
        elif how == "camera":
            Camera.load(path)
        else:
            refs, missing = expand_frames([path])
            pick = list(range(min(3, len(refs))))
            if len(refs) > 3:
                pick.append(len(refs) - 1)
            for i in pick:
                try:
                    read_ref(refs[i])
                except ClfzaError:
                    if i == pick[-1]:
                        raise
            if not refs:
                return "refused", f"no frames ({missing})"
        return "ok", ""
    except ClfzaError as exc:
        return "refused", " ".join(str(exc).split())[:300]
    except Exception as exc:
        tb = traceback.format_exc()
        return "bug:exception", f"{type(exc).__name__}: {exc}"[:300] + "\n" + tb[-3000:]


def run_cli(argv: list[str]) -> tuple[str, str, int]:
    """Run ``clfza ARGV`` in this process; (outcome, message, exit status)."""
    from clfza.cli import main  # lazy: the worker imports clfza once, at start

    out, err = io.StringIO(), io.StringIO()
    rc: int
    try:
        with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
            try:
                rc = main(list(argv))
            except SystemExit as exc:
                rc = exc.code if isinstance(exc.code, int) else (0 if exc.code is None else 2)
    except Exception as exc:  # main() must catch everything (without --debug)
        return ("bug:exception", f"{type(exc).__name__}: {exc}"[:300] + "\n"
                + traceback.format_exc()[-3000:], -1)
    so, se = out.getvalue(), err.getvalue()
    text = so + se
    lines = [ln for ln in se.splitlines() if ln.strip()]
    first = next((ln for ln in lines if "error" in ln), lines[0] if lines else "")
    if "Traceback (most recent call last)" in text:
        return "bug:traceback", text[-3000:], rc
    if UNEXPECTED in text:
        bad = next(ln for ln in text.splitlines() if UNEXPECTED in ln)
        return "bug:unexpected", bad[:500], rc
    if rc not in (0, 1, 2):
        return "bug:exit-code", f"exit {rc}: {first}"[:300], rc
    stray = [ln for ln in lines if not ln.startswith("clfza")]
    if stray:
        return "bug:stderr", f"stderr line not clfza's: {stray[0][:200]}", rc
    return ("ok" if rc == 0 else "refused"), first[:300], rc


def warm_up() -> None:
    """Run a small reconstruction (BP and ADMM) and a simulation once, so that the OpenCL
    context, the kernels and the imports are in place before the first case: a case's time
    and memory are its own."""
    from clfza.cli import main  # lazy: the worker imports clfza once, at start

    with tempfile.TemporaryDirectory(prefix="clfza-fuzz-warm-") as d:
        cam, frame = Path(d) / "cam.toml", Path(d) / "f.npy"
        cam.write_text(CAMERA_64)
        np.save(frame, np.random.default_rng(0).random((64, 64)) + 1.0)
        with contextlib.redirect_stdout(io.StringIO()), \
                contextlib.redirect_stderr(io.StringIO()), warnings.catch_warnings():
            warnings.simplefilter("ignore")
            for extra in (["--method", "bp"], ["--method", "admm", "--iters", "2"]):
                main(["reconstruct", str(frame), "--camera", str(cam), "--out",
                      str(Path(d) / "out"), "--force", "-q", *extra])
            main(["simulate", "checkerboard", "--camera", str(cam), "--out",
                  str(Path(d) / "sim"), "-q"])


def worker_main(fd: int) -> None:
    """Serve cases: one JSON line in on stdin, one JSON line out on ``fd``."""
    import faulthandler

    import clfza.cli  # noqa: F401  # lazy: loaded once per worker
    import clfza.io  # noqa: F401  # lazy: loaded once per worker

    faulthandler.enable()
    warm_up()
    outf = os.fdopen(fd, "w", buffering=1)
    outf.write(json.dumps({"ready": True}) + "\n")
    for line in sys.stdin:
        spec = json.loads(line)
        os.chdir(spec["dir"])
        faulthandler.dump_traceback_later(TIMEOUT_S - 2, exit=False)
        peak_ok = _reset_peak()
        rss0 = _status_kb("VmRSS:")
        t0 = time.perf_counter()
        act = spec["action"]
        with warnings.catch_warnings(record=True) as ws:
            warnings.simplefilter("always")
            if act["op"] == "read":
                outcome, msg = run_read(act["how"], act["path"])
                rc = None
            else:
                outcome, msg, rc = run_cli(act["argv"])
        dt = time.perf_counter() - t0
        faulthandler.cancel_dump_traceback_later()
        hwm = _status_kb("VmHWM:")
        grow = (hwm - rss0) * 1024 if peak_ok and hwm >= 0 and rss0 >= 0 else -1
        os.chdir("/")
        outf.write(json.dumps({"index": spec["index"], "outcome": outcome, "message": msg,
                               "rc": rc, "time_s": dt, "rss_growth": grow,
                               "warnings": len(ws)}) + "\n")


# ==========================================================================================
# the driver
# ==========================================================================================
class Worker:
    """A worker process and the case it runs."""

    def __init__(self, env: dict, log_dir: Path, n: int):
        r, w = os.pipe()
        self.log = open(log_dir / f"worker-{n}.log", "ab")  # noqa: SIM115
        self.proc = subprocess.Popen([sys.executable, str(HERE), "--worker", str(w)],
                                     stdin=subprocess.PIPE, stdout=self.log, stderr=self.log,
                                     pass_fds=(w,), env=env, text=True,
                                     start_new_session=True)
        os.close(w)
        self.fd = r
        self.buf = b""
        self.case: Case | None = None
        self.started = 0.0
        self.ready = False
        self.eof = False
        self.born = time.monotonic()

    def send(self, case: Case, case_dir: Path) -> None:
        self.case = case
        self.started = time.monotonic()
        spec = case.spec()
        spec["dir"] = str(case_dir)
        self.proc.stdin.write(json.dumps(spec) + "\n")
        self.proc.stdin.flush()

    def lines(self) -> list[dict]:
        """Whole lines read so far ([] at the end of the stream: check ``alive``)."""
        try:
            chunk = os.read(self.fd, 65536)
        except OSError:
            chunk = b""
        if not chunk:
            self.eof = True
            return []
        self.buf += chunk
        *full, self.buf = self.buf.split(b"\n")
        return [json.loads(x) for x in full if x.strip()]

    def kill(self) -> None:
        try:
            os.killpg(self.proc.pid, signal.SIGKILL)
        except (ProcessLookupError, PermissionError):
            pass
        self.proc.wait()
        self.close()

    def close(self) -> None:
        for f in (self.proc.stdin,):
            try:
                f.close()
            except OSError:
                pass
        try:
            os.close(self.fd)
        except OSError:
            pass
        self.log.close()


def _snapshot(d: Path) -> set[str]:
    return {str(p.relative_to(d)) for p in d.rglob("*") if p.is_file()}


OUTPUT_SUFFIXES = (".png", ".tif", ".tiff", ".npy", ".gif", ".mp4", ".json")


def check_outputs(d: Path, before: set[str]) -> tuple[str, str] | None:
    """A partial output a case left in ``d`` (files in ``before`` were there already): a
    temporary file, an image, NPY or stack that no JSON record names, or a file that a new
    record names and that does not exist; None when there is none."""
    new = sorted(_snapshot(d) - before)
    tmp = [f for f in new if Path(f).name.startswith(".") and f.endswith(".tmp")]
    if tmp:
        return "bug:partial-output", f"temporary file(s) left: {tmp[:3]}"
    named: set[str] = set()
    missing: list[str] = []
    for f in sorted(set(new) | before):
        if not f.endswith(".json"):
            continue
        try:
            rec = json.loads((d / f).read_text(encoding="utf-8"))
        except (OSError, ValueError, UnicodeDecodeError):
            continue
        if not isinstance(rec, dict) or "clfza_version" not in rec:
            continue
        paths: list[str] = []
        o = rec.get("outputs")
        if isinstance(o, dict):
            paths += [v for v in o.values() if isinstance(v, str)]
        elif isinstance(o, list):  # a batch summary
            paths += [v for x in o if isinstance(x, dict) for k, v in x.items()
                      if isinstance(v, str) and k != "input"]
        paths += [v for v in rec.get("stacks", []) or [] if isinstance(v, str)]
        for v in paths:
            q = d / v  # relative to the case folder, the command's working folder
            try:
                rel = str(q.resolve().relative_to(d.resolve()))
            except (ValueError, OSError):
                continue
            named.add(rel)
            if f in new and not q.exists():
                missing.append(rel)
    if missing:
        return "bug:missing-output", f"a record names missing file(s): {missing[:3]}"
    orphans = [f for f in new if Path(f).suffix.lower() in OUTPUT_SUFFIXES
               and not f.endswith(".json") and f not in named]
    if orphans:
        return "bug:partial-output", f"output(s) no record names: {orphans[:3]}"
    return None


@dataclass
class Result:
    """One case's outcome as the report keeps it."""

    index: int
    gen: str
    desc: str
    action: str
    outcome: str
    message: str
    time_s: float
    rss_growth: int
    rc: int | None = None
    warnings: int = 0
    extra: dict = field(default_factory=dict)


def _action_text(action: dict) -> str:
    if action["op"] == "read":
        return f"read:{action['how']} {action['path']}"
    return "clfza " + " ".join(action["argv"])


def run(cases: int, seed: int, workers: int = 2, work: Path | None = None,
        only: list[int] | None = None, keep: bool = False, progress=None) -> dict:
    """Generate and run ``cases`` cases; the report's content (see :func:`write_report`).

    Parameters
    ----------
    cases : int
        Number of cases (the schedule's length; ``only`` runs a subset of it).
    seed : int
        The run's seed: case ``i`` is drawn from ``default_rng([seed, i])``.
    workers : int
        Worker processes running cases side by side.
    work : Path, optional
        Where case folders go (default: a temporary folder, removed at the end).
    only : list of int, optional
        Run only these case numbers.
    keep : bool
        Keep every case folder (failing ones are kept under ``work`` whenever ``work`` is
        given).
    progress : callable, optional
        Called with each :class:`Result`.

    Returns
    -------
    dict
        ``results`` (list of :class:`Result`), ``wall_s``, ``config``.
    """
    sched = schedule(cases, seed)
    todo = list(range(cases)) if only is None else [i for i in only if 0 <= i < cases]
    own_work = work is None
    root = Path(tempfile.mkdtemp(prefix="clfza-fuzz-")) if own_work else Path(work)
    root.mkdir(parents=True, exist_ok=True)
    env = dict(os.environ, CLFZA_MAX_PIXELS=MAX_PIXELS, CLFZA_MAX_MEMORY=MAX_MEMORY,
               PYTHONFAULTHANDLER="1", PYTHONPATH=str(ROOT) + os.pathsep
               + os.environ.get("PYTHONPATH", ""))
    env.pop("CLFZA_TEST_DEVICE", None)
    results: list[Result] = []
    befores: dict[int, set[str]] = {}
    pool: list[Worker] = []
    nworker = 0
    t_start = time.perf_counter()
    pending = list(todo)

    def new_worker() -> Worker:
        nonlocal nworker
        nworker += 1
        return Worker(env, root, nworker)

    def finish(w: Worker, outcome: str, msg: str, dt: float, grow: int, rc=None, nw=0):
        case = w.case
        assert case is not None
        d = root / f"case-{case.index:05d}"
        if not outcome.startswith("bug:hang") and not outcome.startswith("bug:crash") \
                and not outcome.startswith("bug:rss"):
            part = check_outputs(d, befores.pop(case.index))
            if part is not None and not outcome.startswith("bug"):
                outcome, msg = part
        if grow > MEMORY_BYTES and not outcome.startswith("bug"):
            outcome, msg = "bug:rss", f"peak RSS grew by {grow >> 20} MiB; {msg}"
        res = Result(case.index, case.gen, case.desc, _action_text(case.action), outcome, msg,
                     round(dt, 4), grow, rc, nw)
        results.append(res)
        if progress is not None:
            progress(res)
        if outcome.startswith("bug"):
            (d / "CASE.json").write_text(json.dumps(
                {"seed": seed, "cases": cases, "index": case.index, "gen": case.gen,
                 "desc": case.desc, "action": case.action, "outcome": outcome,
                 "message": msg}, indent=2))
        elif not keep:
            shutil.rmtree(d, ignore_errors=True)
        w.case = None

    try:
        pool = [new_worker() for _ in range(max(1, workers))]
        while pending or any(w.case is not None for w in pool):
            # hand out cases
            for w in pool:
                if w.ready and w.case is None and pending:
                    i = pending.pop(0)
                    case = make_case(i, sched[i], seed)
                    d = root / f"case-{i:05d}"
                    shutil.rmtree(d, ignore_errors=True)
                    for rel, data in case.files.items():
                        p = d / rel
                        try:
                            p.parent.mkdir(parents=True, exist_ok=True)
                            p.write_bytes(data)
                        except OSError:  # a file where a folder was drawn: the first wins
                            pass
                    d.mkdir(parents=True, exist_ok=True)
                    befores[i] = _snapshot(d)
                    w.send(case, d)
            fds = {w.fd: w for w in pool}
            ready, _, _ = select.select(list(fds), [], [], 0.05)
            for fd in ready:
                w = fds[fd]
                w.eof = False
                for msg in w.lines():
                    if msg.get("ready"):
                        w.ready = True
                        continue
                    finish(w, msg["outcome"], msg["message"], msg["time_s"],
                           msg["rss_growth"], msg.get("rc"), msg.get("warnings", 0))
                if w.eof:  # the worker died
                    code = w.proc.wait()
                    if w.case is not None:
                        finish(w, "bug:crash", f"the worker died (exit {code}) running the "
                               f"case; see its log", time.monotonic() - w.started, -1)
                    elif not w.ready:
                        raise RuntimeError(f"a fuzz worker failed to start (exit {code}); "
                                           f"see {root}/worker-*.log")
                    w.close()
                    pool[pool.index(w)] = new_worker()
            now = time.monotonic()
            for k, w in enumerate(pool):
                if not w.ready and now - w.born > 300:
                    raise RuntimeError(f"a fuzz worker did not start in 300 s; see {root}")
                if w.case is None:
                    continue
                rss = _status_kb("VmRSS:", str(w.proc.pid)) * 1024
                if now - w.started > TIMEOUT_S:
                    w.kill()
                    finish(w, "bug:hang", f"no answer in {TIMEOUT_S:.0f} s (the worker's log "
                           "has its stack)", now - w.started, -1)
                    pool[k] = new_worker()
                elif rss > HARD_RSS_BYTES:
                    w.kill()
                    finish(w, "bug:rss", f"the worker's RSS reached {rss >> 20} MiB",
                           now - w.started, rss)
                    pool[k] = new_worker()
    finally:
        for w in pool:
            if w.proc.poll() is None:
                try:
                    w.proc.stdin.close()
                except OSError:
                    pass
                try:
                    w.proc.wait(timeout=5)
                except subprocess.TimeoutExpired:
                    w.kill()
            w.close()
        if own_work and not any(r.outcome.startswith("bug") for r in results) and not keep:
            shutil.rmtree(root, ignore_errors=True)
    wall = time.perf_counter() - t_start
    results.sort(key=lambda r: r.index)
    return {"results": results, "wall_s": wall, "work": str(root),
            "config": {"cases": cases, "ran": len(todo), "seed": seed, "workers": workers,
                       "timeout_s": TIMEOUT_S, "CLFZA_MAX_PIXELS": MAX_PIXELS,
                       "CLFZA_MAX_MEMORY": MAX_MEMORY}}


def bugs(run_result: dict) -> list[Result]:
    """The failing cases of a run."""
    return [r for r in run_result["results"] if r.outcome.startswith("bug")]


def summarise(run_result: dict) -> dict:
    """Counts per generator and outcome, times and memory: the report's JSON."""
    res: list[Result] = run_result["results"]
    per: dict = {}
    for g in GENERATORS:
        rs = [r for r in res if r.gen == g]
        if not rs:
            continue
        outcomes: dict[str, int] = {}
        for r in rs:
            outcomes[r.outcome] = outcomes.get(r.outcome, 0) + 1
        per[g] = {"cases": len(rs), "outcomes": dict(sorted(outcomes.items())),
                  "cli_cases": sum(r.action.startswith("clfza") for r in rs),
                  "time_s": round(sum(r.time_s for r in rs), 2),
                  "max_case_s": round(max(r.time_s for r in rs), 3),
                  "max_rss_growth_mib": round(max(r.rss_growth for r in rs) / 2**20, 1)}
    slow = sorted(res, key=lambda r: -r.time_s)[:8]
    big = sorted(res, key=lambda r: -r.rss_growth)[:8]
    return {
        "config": run_result["config"],
        "wall_s": round(run_result["wall_s"], 1),
        "cases": len(res),
        "bugs": len(bugs(run_result)),
        "generators": per,
        "max_case_s": round(max((r.time_s for r in res), default=0.0), 3),
        "max_rss_growth_mib": round(max((r.rss_growth for r in res), default=0) / 2**20, 1),
        "slowest": [{"index": r.index, "gen": r.gen, "time_s": r.time_s, "outcome": r.outcome,
                     "desc": r.desc[:120], "action": r.action[:200]} for r in slow],
        "largest_rss": [{"index": r.index, "gen": r.gen,
                         "rss_growth_mib": round(r.rss_growth / 2**20, 1),
                         "outcome": r.outcome, "desc": r.desc[:120],
                         "action": r.action[:200]} for r in big],
        "failures": [{"index": r.index, "gen": r.gen, "outcome": r.outcome,
                      "message": r.message[:600], "desc": r.desc[:200],
                      "action": r.action[:300]} for r in bugs(run_result)],
        "fixed": FIXED,
    }


def markdown(s: dict, machine: str) -> str:
    """The report's Markdown."""
    c = s["config"]
    lines = [
        f"# Fuzz report: readers and command line ({machine})",
        "",
        f"{s['cases']} cases (seed {c['seed']}, {c['workers']} worker processes), "
        f"{s['wall_s']} s wall; CLFZA_MAX_PIXELS={c['CLFZA_MAX_PIXELS']}, "
        f"CLFZA_MAX_MEMORY={c['CLFZA_MAX_MEMORY']}, {c['timeout_s']:.0f} s per case. "
        f"Failing cases: **{s['bugs']}**. Longest case {s['max_case_s']} s; largest peak "
        f"RSS growth {s['max_rss_growth_mib']} MiB.",
        "",
        "Generated by `python tools/fuzz_report.py` (see its docstring for the generators "
        "and the checks).",
        "",
        "| generator | cases | through the CLI | outcomes | time (s) | longest (s) | "
        "max RSS growth (MiB) |",
        "|---|---:|---:|---|---:|---:|---:|",
    ]
    for g, v in s["generators"].items():
        oc = ", ".join(f"{k} {n}" for k, n in v["outcomes"].items())
        lines.append(f"| {g} | {v['cases']} | {v['cli_cases']} | {oc} | {v['time_s']} | "
                     f"{v['max_case_s']} | {v['max_rss_growth_mib']} |")
    lines += ["", "## Failing cases", ""]
    if not s["failures"]:
        lines.append("None.")
    for f in s["failures"]:
        lines.append(f"- case {f['index']} ({f['gen']}, {f['outcome']}): {f['desc']} -- "
                     f"`{f['action']}` -- {f['message'].splitlines()[0] if f['message'] else ''}")
    lines += ["", "## Bugs found by the fuzzer and fixed", ""]
    if not s["fixed"]:
        lines.append("None.")
    for b in s["fixed"]:
        lines.append(f"- **{b['where']}**: {b['bug']} Fix: {b['fix']} "
                     f"(regression test: `{b['test']}`)")
    lines += ["", "## Slowest cases", "", "| case | generator | s | outcome | what |",
              "|---:|---|---:|---|---|"]
    for r in s["slowest"]:
        lines.append(f"| {r['index']} | {r['gen']} | {r['time_s']} | {r['outcome']} | "
                     f"{r['desc'][:60]} `{r['action'][:90]}` |")
    lines += ["", "## Largest peak RSS growth", "", "| case | generator | MiB | outcome | what |",
              "|---:|---|---:|---|---|"]
    for r in s["largest_rss"]:
        lines.append(f"| {r['index']} | {r['gen']} | {r['rss_growth_mib']} | {r['outcome']} | "
                     f"{r['desc'][:60]} `{r['action'][:90]}` |")
    return "\n".join(lines).replace("\x00", "") + "\n"


def write_report(run_result: dict, out: Path, machine: str | None = None) -> tuple[Path, Path]:
    """Write ``fuzz_<machine>.json`` and ``.md`` into ``out``."""
    from clfza.benchmarks import machine_record, machine_slug  # lazy: the report only

    rec = machine_record()
    machine = machine or machine_slug(rec)
    s = summarise(run_result)
    s["machine"] = {k: rec[k] for k in ("cpu_model", "cores_usable", "memory_gib", "python",
                                        "platform", "date")}
    out.mkdir(parents=True, exist_ok=True)
    js = out / f"fuzz_{machine}.json"
    md = out / f"fuzz_{machine}.md"
    js.write_text(json.dumps(s, indent=2, default=str) + "\n", encoding="utf-8")
    md.write_text(markdown(s, machine), encoding="utf-8")
    return js, md


def main(argv: list[str] | None = None) -> int:
    """The command line (see the module docstring)."""
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--worker", type=int, help=argparse.SUPPRESS)
    ap.add_argument("--cases", type=int, default=2400)
    ap.add_argument("--seed", type=int, default=35)
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--case", type=int, action="append", help="run only this case number")
    ap.add_argument("--work", type=Path, help="case folders (failing ones are kept)")
    ap.add_argument("--keep", action="store_true", help="keep every case folder")
    ap.add_argument("--out", type=Path, default=ROOT / "bench" / "results")
    ap.add_argument("--machine", help="label in the file names (default: the CPU's)")
    ap.add_argument("--no-report", action="store_true")
    a = ap.parse_args(argv)
    if a.worker is not None:
        worker_main(a.worker)
        return 0

    def show(r: Result) -> None:
        if r.outcome.startswith("bug"):
            print(f"case {r.index} {r.gen}: {r.outcome}: {r.desc[:100]} | {r.action[:160]} | "
                  f"{r.message.splitlines()[0] if r.message else ''}", flush=True)

    work = a.work or (Path(tempfile.gettempdir()) / "clfza-fuzz" if a.case or a.keep else None)
    res = run(a.cases, a.seed, a.workers, work, a.case, a.keep, progress=show)
    s = summarise(res)
    print(f"{s['cases']} cases in {s['wall_s']} s, {s['bugs']} failing; max case "
          f"{s['max_case_s']} s, max RSS growth {s['max_rss_growth_mib']} MiB")
    for g, v in s["generators"].items():
        print(f"  {g:16s} {v['cases']:5d}  {v['outcomes']}")
    if s["bugs"]:
        print(f"failing case folders: {res['work']}")
    if not a.no_report and not a.case:
        js, md = write_report(res, a.out, a.machine)
        print(f"wrote {js} and {md}")
    return 1 if s["bugs"] else 0


if __name__ == "__main__":
    sys.exit(main())
