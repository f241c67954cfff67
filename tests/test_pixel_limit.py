"""Bounded decoding (issue 35, item 5): ``CLFZA_MAX_PIXELS`` (default Pillow's 179 Mpixel
error limit) is checked from the header before anything is decoded -- PNG, TIFF (pages x
pixels where every page is decoded), NPY, GIF and video frames -- with one line naming the
variable. Crafted headers: tiny files that claim huge images."""

from __future__ import annotations

import struct
import zlib

import numpy as np
import pytest
import tifffile

from clfza import ClfzaError
from clfza.cli import main
from clfza.io import PIXELS_ENV, FrameRef, pixel_limit, read_frame, read_ref, tiff_pages

pytestmark = pytest.mark.usefixtures("cli_logging")

HUGE = 20000  # 20000 x 20000 = 400 Mpx > 179 Mpx


def _chunk(kind: bytes, data: bytes) -> bytes:
    return struct.pack(">I", len(data)) + kind + data + struct.pack(
        ">I", zlib.crc32(kind + data) & 0xFFFFFFFF)


def png_claiming(w: int, h: int, bits: int = 8, ctype: int = 0) -> bytes:
    """A PNG whose IHDR claims w x h pixels, with a few bytes of image data."""
    ihdr = struct.pack(">IIBBBBB", w, h, bits, ctype, 0, 0, 0)
    return (b"\x89PNG\r\n\x1a\n" + _chunk(b"IHDR", ihdr)
            + _chunk(b"IDAT", zlib.compress(b"\0" * 64)) + _chunk(b"IEND", b""))


def tiff_claiming(w: int, h: int) -> bytes:
    """A little-endian baseline TIFF whose one IFD claims a w x h 8-bit grey image."""
    entries = [(256, 4, 1, w), (257, 4, 1, h), (258, 3, 1, 8), (259, 3, 1, 1),
               (262, 3, 1, 1), (273, 4, 1, 8), (277, 3, 1, 1), (278, 4, 1, h),
               (279, 4, 1, 16)]
    ifd = struct.pack("<H", len(entries))
    for tag, typ, count, value in entries:
        val = struct.pack("<HH", value, 0) if typ == 3 else struct.pack("<I", value)
        ifd += struct.pack("<HHI", tag, typ, count) + val
    ifd += struct.pack("<I", 0)
    return b"II*\x00" + struct.pack("<I", 24) + b"\0" * 16 + ifd


def npy_claiming(shape, dtype="<u2") -> bytes:
    head = {"descr": dtype, "fortran_order": False, "shape": tuple(shape)}
    import io

    buf = io.BytesIO()
    np.lib.format.write_array_header_1_0(buf, head)
    return buf.getvalue() + b"\0" * 32


@pytest.fixture(autouse=True)
def _no_env(monkeypatch):
    monkeypatch.delenv(PIXELS_ENV, raising=False)


def test_default_is_pillows_error_limit():
    assert pixel_limit()[0] == 178956970


@pytest.mark.parametrize("name, data", [
    ("bomb.png", png_claiming(HUGE, HUGE)),
    ("bomb16.png", png_claiming(HUGE, HUGE, bits=16, ctype=2)),  # clfza's own decoder
    ("bomb.tif", tiff_claiming(HUGE, HUGE)),
    ("bomb.npy", npy_claiming((HUGE, HUGE))),
])
def test_crafted_header_refused_before_decoding(tmp_path, name, data):
    p = tmp_path / name
    p.write_bytes(data)
    assert p.stat().st_size < 1000
    with pytest.raises(ClfzaError) as e:
        read_frame(p)
    msg = str(e.value)
    assert "\n" not in msg and PIXELS_ENV in msg and f"{HUGE}x{HUGE}" in msg, msg


def test_npy_stack_counts_every_frame(tmp_path):
    p = tmp_path / "stack.npy"
    p.write_bytes(npy_claiming((400, 1000, 1000)))  # 400 frames of 1 Mpx, loaded whole
    with pytest.raises(ClfzaError, match=r"400 x 1000x1000 = 400000000 pixels"):
        read_frame(p)


def test_limit_is_configurable(tmp_path, monkeypatch):
    p = tmp_path / "f.npy"
    np.save(p, np.ones((64, 64), np.uint16))
    read_frame(p)
    monkeypatch.setenv(PIXELS_ENV, "1000")
    with pytest.raises(ClfzaError, match=rf"limit of 1000 pixels \({PIXELS_ENV}=1000\)"):
        read_frame(p)
    monkeypatch.setenv(PIXELS_ENV, "1M")
    read_frame(p)
    monkeypatch.setenv(PIXELS_ENV, "lots")
    with pytest.raises(ClfzaError, match=PIXELS_ENV):
        read_frame(p)


def test_tiff_pages_times_pixels(tmp_path, monkeypatch):
    p = tmp_path / "stack.tif"
    tifffile.imwrite(p, np.zeros((5, 16, 16), np.uint16))
    assert len(tiff_pages(p)) == 5
    monkeypatch.setenv(PIXELS_ENV, str(4 * 256))  # four pages fit, five do not
    with pytest.raises(ClfzaError, match=r"5 x 16x16 = 1280 pixels"):
        tiff_pages(p)
    read_ref(FrameRef(str(p), 3))  # a page of a stack read alone: 256 pixels


def test_gif_and_video_frames(tmp_path, monkeypatch):
    import imageio.v3 as iio

    frames = (np.random.default_rng(0).random((3, 32, 32)) * 255).astype(np.uint8)
    gif = tmp_path / "a.gif"
    iio.imwrite(gif, frames, extension=".gif")
    read_ref(FrameRef(str(gif), 1))
    monkeypatch.setenv(PIXELS_ENV, "500")
    with pytest.raises(ClfzaError, match=rf"32x32 = 1024 pixels.*{PIXELS_ENV}"):
        read_ref(FrameRef(str(gif), 1))
    pytest.importorskip("imageio_ffmpeg")
    mp4 = tmp_path / "a.mp4"
    iio.imwrite(mp4, np.repeat(frames[..., None], 3, axis=3), extension=".mp4", fps=5)
    with pytest.raises(ClfzaError, match=rf"32x32 = 1024 pixels.*{PIXELS_ENV}"):
        read_ref(FrameRef(str(mp4), 0))
    monkeypatch.delenv(PIXELS_ENV)
    assert read_ref(FrameRef(str(mp4), 0))[0].shape[:2] == (32, 32)


def test_cli_one_line(tmp_path, capsys):
    (tmp_path / "bomb.png").write_bytes(png_claiming(HUGE, HUGE))
    rc = main(["reconstruct", str(tmp_path / "bomb.png"), "--camera", "simulation",
               "--backend", "numpy", "--out", str(tmp_path / "rec"), "-q"])
    err = capsys.readouterr().err
    assert rc == 2 and err.count("\n") == 1 and PIXELS_ENV in err, err
