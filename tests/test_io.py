"""clfza.io: reading and validating frames, calibration, crop, the gain of y, writers."""

from __future__ import annotations

import struct
import zlib
from pathlib import Path

import imageio.v3 as iio
import numpy as np
import pytest
import tifffile

from clfza import Camera, ClfzaError, Noise, simulate
from clfza import io as fio


def small_camera(n: int = 128, R: float | None = None, mask: str = "fza") -> Camera:
    # near-critical sampling: r1'^2 = N p^2
    p, z1, z2 = 0.01, 20.0, 3.0
    return Camera(pitch=p, shape=(n, n), r1=np.sqrt(n) * p / (1 + z2 / z1), z1=z1, z2=z2,
                  R=R, mask=mask)


# ----------------------------------------------------------------------------------------
# reading
# ----------------------------------------------------------------------------------------
@pytest.mark.parametrize("shape", [(37, 53), (37, 53, 3)])
@pytest.mark.parametrize("dtype", [np.uint8, np.uint16])
def test_png_roundtrip(tmp_path, rng, shape, dtype):
    a = rng.integers(0, np.iinfo(dtype).max, size=shape, dtype=dtype)
    p = fio.write_array(tmp_path / "a.png", a)
    b, info = fio.read_frame(p)
    assert info.format == "png" and info.bit_depth == 8 * np.dtype(dtype).itemsize
    assert b.dtype == np.float64 and np.array_equal(b, a)
    if dtype == np.uint8 or len(shape) == 2:  # what Pillow can read back must agree
        assert np.array_equal(iio.imread(p), a)


def test_png_stream_is_zlib_with_or_without_libdeflate(tmp_path, rng, monkeypatch):
    """The IDAT stream (libdeflate via imagecodecs) is a zlib stream, and the zlib fallback
    writes the same image."""
    import sys
    import zlib

    from clfza.io import _write as io_write

    data = rng.integers(0, 255, size=50_000, dtype=np.uint8).tobytes()
    assert zlib.decompress(io_write._zlib_stream(data)) == data
    a = rng.integers(0, 65535, size=(33, 41), dtype=np.uint16)
    fast = fio.encode_png(a)
    monkeypatch.setitem(sys.modules, "imagecodecs", None)  # import fails: the zlib path
    slow = fio.encode_png(a)
    for i, png in enumerate((fast, slow)):
        (tmp_path / f"{i}.png").write_bytes(png)
        assert np.array_equal(fio.read_frame(tmp_path / f"{i}.png")[0], a)
        assert np.array_equal(iio.imread(tmp_path / f"{i}.png"), a)


def _filtered_png16(a: np.ndarray, filters: np.ndarray) -> bytes:
    """A 16-bit RGB PNG whose rows use the given filter types (0..4)."""
    h, w, ch = a.shape
    x = np.ascontiguousarray(a.astype(">u2")).view(np.uint8).reshape(h, w, 2 * ch)
    x = x.astype(np.int32)
    A = np.zeros_like(x)
    A[:, 1:] = x[:, :-1]
    B = np.zeros_like(x)
    B[1:] = x[:-1]
    C = np.zeros_like(x)
    C[1:, 1:] = x[:-1, :-1]
    p = A + B - C
    pa, pb, pc = abs(p - A), abs(p - B), abs(p - C)
    paeth = np.where((pa <= pb) & (pa <= pc), A, np.where(pb <= pc, B, C))
    preds = [0 * x, A, B, (A + B) >> 1, paeth]
    rows = np.stack([(x[r] - preds[filters[r]][r]) & 255 for r in range(h)]).astype(np.uint8)
    rows = np.concatenate([filters[:, None].astype(np.uint8), rows.reshape(h, -1)], axis=1)

    def chunk(k, pl):
        return struct.pack(">I", len(pl)) + k + pl + struct.pack(">I", zlib.crc32(k + pl))

    return (b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", struct.pack(">IIBBBBB", w, h, 16, 2, 0, 0, 0))
            + chunk(b"IDAT", zlib.compress(rows.tobytes())) + chunk(b"IEND", b""))


@pytest.mark.parametrize("filters", ["all", "simple"])
def test_png16_rgb_decoder_all_filters(tmp_path, rng, filters):
    """Pillow truncates 16-bit colour PNGs to 8 bits; clfza decodes them exactly."""
    a = rng.integers(0, 65535, size=(41, 29, 3), dtype=np.uint16)
    hi = 5 if filters == "all" else 3
    ft = rng.integers(0, hi, size=41)
    ft[:hi] = np.arange(hi)
    p = tmp_path / "f.png"
    p.write_bytes(_filtered_png16(a, ft))
    b, info = fio.read_frame(p)
    assert info.bit_depth == 16 and np.array_equal(b, a)


@pytest.mark.parametrize("dtype", [np.uint8, np.uint16, np.float32])
@pytest.mark.parametrize("rgb", [False, True])
def test_tiff_roundtrip(tmp_path, rng, dtype, rgb):
    shape = (24, 31, 3) if rgb else (24, 31)
    a = (rng.random(shape) * 200).astype(dtype)
    p = fio.write_array(tmp_path / "a.tif", a)
    b, info = fio.read_frame(p)
    assert np.array_equal(b, a.astype(np.float64))
    assert info.bit_depth == (None if dtype == np.float32 else 8 * np.dtype(dtype).itemsize)


def test_tiff_planar_rgb(tmp_path):
    a = np.arange(3 * 20 * 30, dtype=np.uint16).reshape(3, 20, 30)
    tifffile.imwrite(tmp_path / "p.tif", a, photometric="rgb", planarconfig="separate")
    b, _ = fio.read_frame(tmp_path / "p.tif")
    assert b.shape == (20, 30, 3) and np.array_equal(b[..., 1], a[1])


@pytest.mark.parametrize("dtype", [np.uint8, np.uint16, np.float32, np.float64])
def test_npy(tmp_path, rng, dtype):
    a = (rng.random((16, 18)) * 100).astype(dtype)
    np.save(tmp_path / "a.npy", a)
    b, info = fio.read_frame(tmp_path / "a.npy")
    assert np.array_equal(b, a.astype(np.float64)) and info.format == "npy"


def test_rgba_constant_alpha_dropped_and_single_channel_squeezed(tmp_path, rng):
    a = rng.integers(0, 255, size=(10, 12, 4), dtype=np.uint8)
    a[..., 3] = 255
    iio.imwrite(tmp_path / "a.png", a)
    b, _ = fio.read_frame(tmp_path / "a.png")
    assert b.shape == (10, 12, 3)
    f, _ = fio.check_frame(np.ones((10, 12, 1), np.uint16))
    assert f.shape == (10, 12)


@pytest.mark.parametrize("arr, word", [
    (np.zeros((8, 8), bool), "1-bit"),
    (np.zeros((8, 8), np.int32), "bit depth"),
    (np.zeros((8, 8), np.uint32), "bit depth"),
    (np.zeros((8, 8), np.complex64), "data type"),
    (np.zeros((0, 8), np.uint16), "empty"),
    (np.zeros((8,), np.uint16), "shape"),
    (np.zeros((2, 8, 8, 3), np.uint16), "shape"),
    (np.zeros((8, 8, 5), np.uint16), "shape"),
    (np.zeros((3, 8), np.uint16), "too small"),
    (np.array([[np.nan] * 8] * 8), "NaN"),
    (np.array([[np.inf] * 8] * 8, np.float32), "Inf"),
])
def test_check_frame_rejects(arr, word):
    with pytest.raises(ClfzaError, match=word):
        fio.check_frame(arr)


def test_read_frame_file_errors(tmp_path):
    with pytest.raises(ClfzaError, match="does not exist"):
        fio.read_frame(tmp_path / "nope.png")
    with pytest.raises(ClfzaError, match="folder"):
        fio.read_frame(tmp_path)
    (tmp_path / "a.jpg").write_bytes(b"\xff\xd8")
    with pytest.raises(ClfzaError, match="unsupported suffix"):
        fio.read_frame(tmp_path / "a.jpg")
    (tmp_path / "e.png").write_bytes(b"")
    with pytest.raises(ClfzaError, match="empty file"):
        fio.read_frame(tmp_path / "e.png")
    good = fio.encode_png(np.zeros((16, 16), np.uint16))
    (tmp_path / "t.png").write_bytes(good[: len(good) // 2])
    with pytest.raises(ClfzaError, match="corrupt|truncated"):
        fio.read_frame(tmp_path / "t.png")


# ----------------------------------------------------------------------------------------
# calibration, Bayer, crop
# ----------------------------------------------------------------------------------------
def test_dark_and_flat(rng):
    f = rng.random((8, 10)) + 2
    dark = np.full((8, 10), 0.5)
    np.testing.assert_allclose(fio.subtract_dark(f, dark), f - 0.5)
    flat = np.full((8, 10), 3.0)
    flat[0, 0] = 6.0
    out = fio.flat_field(f, flat)
    norm = flat / flat.mean()
    np.testing.assert_allclose(out, f / norm)
    rgb = np.stack([f] * 3, -1)
    assert fio.subtract_dark(rgb, dark).shape == (8, 10, 3)
    with pytest.raises(ClfzaError, match="shape"):
        fio.subtract_dark(f, np.zeros((4, 4)))
    with pytest.raises(ClfzaError, match="positive"):
        fio.flat_field(f, np.zeros((8, 10)))


@pytest.mark.parametrize("pattern", fio.BAYER_PATTERNS)
def test_demosaic_superpixel(pattern):
    h, w = 12, 16
    val = {"R": 10.0, "G": 20.0, "B": 30.0}
    mos = np.zeros((h, w))
    for k, (dy, dx) in enumerate(((0, 0), (0, 1), (1, 0), (1, 1))):
        mos[dy::2, dx::2] = val[pattern[k]]
    # make the two greens differ to check they are averaged
    g = [i for i, c in enumerate(pattern) if c == "G"]
    dy, dx = divmod(g[1], 2)
    mos[dy::2, dx::2] = 24.0
    rgb = fio.demosaic(mos, pattern.lower())
    assert rgb.shape == (6, 8, 3)
    np.testing.assert_allclose(rgb[..., 0], 10.0)
    np.testing.assert_allclose(rgb[..., 1], 22.0)
    np.testing.assert_allclose(rgb[..., 2], 30.0)


def test_demosaic_errors():
    with pytest.raises(ClfzaError, match="Bayer pattern"):
        fio.demosaic(np.zeros((16, 16)), "RGBG")
    with pytest.raises(ClfzaError, match="single-channel"):
        fio.demosaic(np.zeros((16, 16, 3)), "RGGB")


def test_center_crop():
    f = np.arange(20 * 30, dtype=float).reshape(20, 30)
    c, origin = fio.center_crop(f, (10, 10))
    assert origin == (5, 10) and c.shape == (10, 10)
    c, origin = fio.center_crop(f, (4, 6), center=(3, 4))
    assert origin == (1, 1)
    c, origin = fio.center_crop(f, (4, 6), center=(4, 5), align=2)
    assert origin[0] % 2 == 0 and origin[1] % 2 == 0
    for shape, center, word in [((30, 10), None, "larger"), ((10, 10), (1, 1), "extends past"),
                                ((10, 10), (50, 5), "outside"), ((2, 2), None, "too small")]:
        with pytest.raises(ClfzaError, match=word):
            fio.center_crop(f, shape, center)


def test_parse_pair():
    assert fio.parse_pair("64", "crop") == (64, 64)
    assert fio.parse_pair("64,32", "crop") == (64, 32)
    assert fio.parse_pair("64x32", "crop") == (64, 32)
    assert fio.parse_pair("1.5,2", "c", integer=False) == (1.5, 2.0)
    for bad in ("", "1,2,3", "a,b", "1,"):
        with pytest.raises(ClfzaError):
            fio.parse_pair(bad, "crop")


# ----------------------------------------------------------------------------------------
# the observation y
# ----------------------------------------------------------------------------------------
def _scene(n: int, rng) -> np.ndarray:
    from scipy.ndimage import gaussian_filter

    return np.clip(gaussian_filter(rng.random((n, n)), 2) * 2 - 0.5, 0, 1)


@pytest.mark.parametrize("R", [None, 0.64])
@pytest.mark.parametrize("noise", [Noise(), Noise(photons=2e4, bit_depth=12)])
def test_frame_to_measurement_reproduces_simulation(rng, R, noise):
    """A scene filling the sensor: y from the raw frame (gain unknown, object mean known)
    matches Measurement.y to within a few percent, with and without a finite aperture."""
    cam = small_camera(128, R=R)
    m = simulate(_scene(128, rng), cam, sensor_plane=True, noise=noise)
    y = fio.frame_to_measurement(m.frame, cam, object_mean=float(m.truth.mean()))
    rel = np.linalg.norm(y - m.y) / np.linalg.norm(m.y)
    assert rel < 0.04, rel
    # the gain does not matter
    y2 = fio.frame_to_measurement(7.5 * m.frame, cam, object_mean=float(m.truth.mean()))
    np.testing.assert_allclose(y2, y, rtol=1e-10, atol=1e-12)


def test_frame_to_measurement_projected_scene(rng):
    """A projected scene exactly as wide as the sensor, noise-free."""
    cam = small_camera(128)
    width = cam.shape[1] * cam.pitch / cam.magnification
    m = simulate(_scene(128, rng), cam, object_width=width)
    y = fio.frame_to_measurement(m.frame, cam, object_mean=float(m.truth.mean()))
    assert np.linalg.norm(y - m.y) / np.linalg.norm(m.y) < 0.04


def test_frame_to_measurement_rgb_and_errors(rng):
    cam = small_camera(64)
    f = rng.random((64, 64, 3)) + 1.0
    f[..., 2] *= 10
    y = fio.frame_to_measurement(f, cam)
    assert y.shape == (64, 64, 3)
    np.testing.assert_allclose(y.mean(axis=(0, 1)), 0, atol=1e-12)
    # each channel is normalised by its own mean: the 10x channel gives the same y
    y1 = fio.frame_to_measurement(f[..., 2] / 10, cam)
    np.testing.assert_allclose(y[..., 2], y1, rtol=1e-10)
    with pytest.raises(ClfzaError, match="camera grid"):
        fio.frame_to_measurement(f[:32], cam)
    with pytest.raises(ClfzaError, match="mean is <= 0"):
        fio.frame_to_measurement(np.zeros((64, 64)), cam)
    with pytest.raises(ClfzaError, match="flat"):
        fio.frame_to_measurement(np.ones((64, 64)), cam)
    with pytest.raises(ClfzaError, match="object_mean"):
        fio.frame_to_measurement(f, cam, object_mean=0)


def test_effective_pixels():
    assert fio.effective_pixels(small_camera(64)) == 64 * 64
    big = fio.effective_pixels(small_camera(64, R=10.0))
    assert big == 64 * 64
    small = fio.effective_pixels(small_camera(64, R=0.1))
    assert 0 < small < 0.5 * 64 * 64


# ----------------------------------------------------------------------------------------
# writing
# ----------------------------------------------------------------------------------------
def test_scale_to_uint16_modes(rng):
    a = rng.normal(size=(50, 50))
    a[0, 0] = 100.0  # a hot pixel
    u, info = fio.scale_to_uint16(a, "percentile", (1, 99))
    assert u.dtype == np.uint16 and info["mode"] == "percentile" and info["hi"] < 100
    assert u.max() == 65535 and u.min() == 0 and info["clipped_fraction"] > 0
    u, info = fio.scale_to_uint16(a, "minmax")
    assert info["hi"] == 100.0 and u[0, 0] == 65535
    u, info = fio.scale_to_uint16(np.full((4, 4), 0.5), "unit")
    assert np.all(u == 32768)
    u, info = fio.scale_to_uint16(np.ones((4, 4)), "minmax")
    assert np.all(u == 0) and info["note"] == "flat image"
    with pytest.raises(ClfzaError, match="scaling"):
        fio.scale_to_uint16(a, "log")
    with pytest.raises(ClfzaError, match="percentiles"):
        fio.scale_to_uint16(a, "percentile", (90, 10))


@pytest.mark.parametrize("name, float_tiff", [("x.png", False), ("x.tif", False),
                                              ("x.tif", True), ("x.npy", False)])
def test_write_image_no_overwrite_then_force(tmp_path, rng, name, float_tiff):
    img = rng.random((20, 24, 3))
    p, info = fio.write_image(tmp_path / name, img, tiff_float=float_tiff)
    back, binfo = fio.read_frame(p)
    if name.endswith(".npy") or float_tiff:
        np.testing.assert_allclose(back, img, rtol=1e-6)
        assert info["mode"] == "none"
    else:
        assert binfo.bit_depth == 16 and info["dtype"] == "uint16"
    before = p.read_bytes()
    with pytest.raises(ClfzaError, match="exists"):
        fio.write_image(p, img * 0 + 0.25)
    assert p.read_bytes() == before
    fio.write_image(p, img[::-1].copy(), force=True, tiff_float=float_tiff)
    assert p.read_bytes() != before
    # atomic: no temporary files left behind
    assert sorted(x.name for x in Path(tmp_path).iterdir()) == [name]


def test_write_array_rejects():
    with pytest.raises(ClfzaError, match="use .png"):
        fio.write_array("x.bmp", np.zeros((4, 4), np.uint8))
    with pytest.raises(ClfzaError, match="8- or 16-bit"):
        fio.write_array("x.png", np.zeros((4, 4), np.float32))
