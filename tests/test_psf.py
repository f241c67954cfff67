"""clfza.models._psf: measured PSFs -- reading, validation, calibration, resampling, depth
stacks."""

from __future__ import annotations

import json
import warnings

import numpy as np
import pytest
import tifffile
from scipy.signal import fftconvolve

from clfza import ClfzaError
from clfza import io as fio
from clfza.camera._masks import zone_plate
from clfza.focus import PSFDepthWarning, back_project, select_psf_depth
from clfza.models import PSF, load_psf, load_psf_stack


def blob(shape=(64, 64), center=None, sigma=3.0, amp=1000.0) -> np.ndarray:
    """A Gaussian blob (float64)."""
    h, w = shape
    cy, cx = (h // 2, w // 2) if center is None else center
    yy, xx = np.mgrid[:h, :w]
    return amp * np.exp(-((yy - cy) ** 2 + (xx - cx) ** 2) / (2 * sigma**2))


def moments(a: np.ndarray) -> tuple[float, float, float]:
    """Centroid (row, col) and RMS width (per axis, averaged) of a 2-D intensity."""
    yy, xx = np.mgrid[: a.shape[0], : a.shape[1]]
    s = a.sum()
    cy, cx = (a * yy).sum() / s, (a * xx).sum() / s
    var = ((a * (yy - cy) ** 2).sum() + (a * (xx - cx) ** 2).sum()) / (2 * s)
    return float(cy), float(cx), float(np.sqrt(var))


# ----------------------------------------------------------------------------------------
# bad inputs: one ClfzaError line each
# ----------------------------------------------------------------------------------------
GOOD = blob((16, 16))
BAD_ARRAYS = {
    "complex": (GOOD.astype(complex), "complex"),
    "bool": (GOOD > 1, "boolean"),
    "object": (np.array([[object()] * 8] * 8), "data type object"),
    "nan": (np.where(GOOD > 500, np.nan, GOOD), "NaN"),
    "inf": (np.where(GOOD > 500, np.inf, GOOD), "NaN or Inf"),
    "all-zero": (np.zeros((16, 16)), "all zero"),
    "two channels": (np.zeros((16, 16, 2)), "2 channels (grey + alpha"),
    "rgba": (np.ones((16, 16, 4)), "RGBA? drop the alpha channel"),
    "five channels": (np.ones((16, 16, 5)), "5 channels"),
    "1-d": (np.ones(16), "1 dimensions"),
    "4-d": (np.ones((2, 16, 16, 3)), "load_psf_stack"),
    "3-d stack": (np.ones((5, 16, 16)), "load_psf_stack"),
    "tiny": (np.ones((2, 16)), "too small"),
}


@pytest.mark.parametrize("case", list(BAD_ARRAYS))
def test_bad_arrays(case):
    arr, words = BAD_ARRAYS[case]
    with pytest.raises(ClfzaError, match=None) as ei:
        load_psf(arr)
    msg = str(ei.value)
    assert words in msg and "\n" not in msg


@pytest.mark.parametrize(("kwargs", "words"), [
    ({"background": 2000.0}, "after subtracting the background 2000"),
    ({"dark": np.ones((8, 8))}, "dark frame has shape (8, 8) but the PSF (16, 16)"),
    ({"dark": GOOD * 2}, "after dark subtraction"),
    ({"background": "edges"}, "background must be"),
    ({"center": "middle"}, "center must be one of"),
    ({"normalise": "l2"}, "normalise must be one of"),
    ({"bin": 0}, "bin must be an integer >= 1"),
    ({"bin": 5}, "leaves 3x3 pixels"),
    ({"channels": 2}, "channels must be"),
    ({"psf_pitch": -1.0}, "psf_pitch must be"),
    ({"frame_pitch": 0.01}, "frame_pitch needs psf_pitch"),
    ({"max_pixels": 100}, "more than the limit max_pixels = 100"),
    ({"psf_pitch": 0.01, "frame_pitch": 0.001, "max_pixels": 10000}, "more than max_pixels"),
])
def test_bad_options(kwargs, words):
    with pytest.raises(ClfzaError) as ei:
        load_psf(GOOD, **kwargs)
    assert words in str(ei.value)


def test_rgb_channel_all_zero_named():
    a = np.stack([GOOD, GOOD, np.zeros_like(GOOD)], axis=-1)
    with pytest.raises(ClfzaError, match=r"\(channel 2\)"):
        load_psf(a)


def test_pixel_limit_is_checked_before_decoding(tmp_path, monkeypatch):
    p = tmp_path / "big.npy"
    np.save(p, np.ones((64, 64)))

    def no_decoding(*args, **kwargs):
        raise AssertionError("the file was decoded before its size was checked")

    monkeypatch.setattr(fio, "read_frame", no_decoding)
    with pytest.raises(ClfzaError, match="64x64 = 4096 pixels, more than the limit"):
        load_psf(p, max_pixels=1000)


@pytest.mark.parametrize(("name", "writer", "words"), [
    ("rgba.png", lambda p: p.write_bytes(fio.encode_png(np.ones((8, 8, 4), np.uint8))),
     "RGBA? drop the alpha channel"),
    ("stack.tif", lambda p: tifffile.imwrite(p, np.ones((3, 8, 8), np.uint16),
                                             photometric="minisblack"), "load_psf_stack"),
    ("c.npy", lambda p: np.save(p, np.ones((8, 8), complex)), "complex"),
    ("nan.npy", lambda p: np.save(p, np.full((8, 8), np.nan)), "NaN"),
    ("empty.png", lambda p: p.write_bytes(b""), "empty file"),
    ("psf.jpg", lambda p: p.write_bytes(b"\xff\xd8"), "unsupported suffix"),
])
def test_bad_files(tmp_path, name, writer, words):
    p = tmp_path / name
    writer(p)
    with pytest.raises(ClfzaError) as ei:
        load_psf(p)
    assert words in str(ei.value) and "\n" not in str(ei.value)


# ----------------------------------------------------------------------------------------
# files
# ----------------------------------------------------------------------------------------
def _write(tmp_path, kind: str, a: np.ndarray):
    p = tmp_path / {"lzw": "a.tif", "zlib": "a.tif", "png": "a.png", "npy": "a.npy",
                    "tif": "a.tif"}[kind]
    if kind in ("lzw", "zlib"):
        tifffile.imwrite(p, a, compression=kind,
                         photometric="rgb" if a.ndim == 3 else "minisblack")
    elif kind == "png":
        p.write_bytes(fio.encode_png(a))
    elif kind == "tif":
        tifffile.imwrite(p, a)
    else:
        np.save(p, a)
    return p


@pytest.mark.parametrize(("kind", "dtype", "rgb"), [
    ("lzw", np.uint16, False), ("zlib", np.uint16, False), ("lzw", np.uint8, True),
    ("zlib", np.float32, False), ("png", np.uint8, False), ("png", np.uint16, False),
    ("png", np.uint16, True), ("npy", np.float64, False), ("npy", np.uint16, True),
])
def test_files_load(tmp_path, kind, dtype, rgb):
    a = blob((24, 20), amp=200.0 if dtype == np.uint8 else 60000.0) + 1.0
    if rgb:
        a = np.stack([a, 0.5 * a, 0.25 * a], axis=-1)
    a = a.astype(dtype)
    psf = load_psf(_write(tmp_path, kind, a), normalise="none")
    assert psf.array.dtype == np.float64 and psf.shape == a.shape
    np.testing.assert_array_equal(psf.array, a.astype(np.float64))
    assert psf.info["source"].endswith(("a.tif", "a.png", "a.npy"))


def test_psf_contract_defaults():
    psf = load_psf(blob((40, 30)).astype(np.float32), psf_pitch=0.005)
    a = psf.array
    assert a.dtype == np.float64 and a.shape == (40, 30) and a.min() >= 0
    assert np.isclose(a.sum(), 1.0) and psf.pitch == 0.005 and not a.flags.writeable
    for key in ("source", "dark", "background", "clipped", "resample_factor", "bin",
                "bin_cropped", "centring_shift", "normalisation", "original_shape"):
        assert key in psf.info
    assert isinstance(load_psf(psf), PSF)
    json.dumps(psf.info)  # goes into JSON records as is


def test_psf_larger_than_frame_is_valid():
    big = zone_plate((330, 330), 0.01, 0.3, R=1.5)
    psf = load_psf(big)
    assert psf.shape == (330, 330) and np.isclose(psf.array.sum(), 1.0)


# ----------------------------------------------------------------------------------------
# channels, normalisation, dark and background
# ----------------------------------------------------------------------------------------
def test_rgb_kept_per_channel_and_averaged_to_grey():
    a = np.stack([blob(sigma=2), 3 * blob(sigma=4), 0.1 * blob(sigma=6)], axis=-1)
    psf = load_psf(a)
    assert psf.channels == 3
    np.testing.assert_allclose(psf.array.sum(axis=(0, 1)), 1.0)
    for c in range(3):
        np.testing.assert_allclose(psf.array[..., c], a[..., c] / a[..., c].sum())
    grey = load_psf(a, channels=1, normalise="none")
    np.testing.assert_allclose(grey.array, a.mean(axis=2))
    assert grey.info["channels"] == "RGB averaged to grey"
    assert load_psf(a[..., 0], channels=3).shape == (64, 64, 3)


def test_normalisations():
    a = np.stack([blob(), 2 * blob()], axis=-1)[..., [0, 1, 1]]
    np.testing.assert_allclose(load_psf(a, normalise="max").array.max(axis=(0, 1)), 1.0)
    np.testing.assert_allclose(load_psf(a, normalise="sum").array.sum(axis=(0, 1)), 1.0)
    np.testing.assert_allclose(load_psf(a, normalise="none").array, a)


def test_dark_subtraction_and_clipping(rng):
    truth = blob()
    dark = 100.0 + 5.0 * rng.standard_normal(truth.shape)
    raw = truth + dark + rng.standard_normal(truth.shape)  # noise leaves small negatives
    psf = load_psf(raw, dark=dark, normalise="none")
    assert psf.info["dark"].startswith("array") and psf.info["clipped"] > 0
    assert psf.array.min() == 0.0
    assert np.abs(psf.array - truth).max() < 6.0
    rgb = load_psf(np.stack([raw] * 3, axis=-1), dark=dark, normalise="none")  # grey dark
    np.testing.assert_allclose(rgb.array[..., 1], psf.array)


def test_large_clipping_warns():
    with pytest.warns(UserWarning, match="too high?"):
        load_psf(blob() - 50.0)


def test_background_border_and_constant(tmp_path):
    truth = blob(sigma=2.0)
    psf = load_psf(truth + 40.0, background="border", normalise="none")
    assert psf.info["background"] == pytest.approx(40.0)
    np.testing.assert_allclose(psf.array, truth, atol=1e-9)
    const = load_psf(truth + 40.0, background=40.0, normalise="none")
    np.testing.assert_allclose(const.array, truth, atol=1e-9)
    dark_file = _write(tmp_path, "npy", np.full(truth.shape, 40.0))
    from_file = load_psf(truth + 40.0, dark=dark_file, normalise="none")
    np.testing.assert_allclose(from_file.array, truth, atol=1e-9)
    assert from_file.info["dark"] == str(dark_file)


# ----------------------------------------------------------------------------------------
# binning, resampling, centring
# ----------------------------------------------------------------------------------------
def test_binning_preserves_sum_and_reports_crop():
    a = blob((67, 64), sigma=5.0)
    psf = load_psf(a, bin=3, normalise="none", psf_pitch=0.002)
    assert psf.shape == (22, 21) and psf.info["bin_cropped"] == [1, 1]
    assert psf.pitch == pytest.approx(0.006)
    assert psf.array.sum() == pytest.approx(a[:66, :63].sum(), rel=1e-12)
    np.testing.assert_allclose(psf.array[0, 0], a[:3, :3].sum())


@pytest.mark.parametrize(("psf_pitch", "frame_pitch", "ratio"), [(0.01, 0.02, 0.5),
                                                                 (0.02, 0.01, 2.0)])
def test_resampling_preserves_sum_and_scales_width(psf_pitch, frame_pitch, ratio):
    sigma = 6.0 if ratio < 1 else 3.0
    a = blob((128, 128), sigma=sigma)
    psf = load_psf(a, psf_pitch=psf_pitch, frame_pitch=frame_pitch, normalise="none")
    assert psf.shape == (int(128 * ratio),) * 2 and psf.pitch == frame_pitch
    assert psf.info["resample_factor"] == pytest.approx(ratio)
    assert psf.array.sum() == pytest.approx(a.sum(), rel=1e-12)
    width = moments(psf.array)[2]
    assert width == pytest.approx(sigma * ratio, rel=0.05)


def test_bin_then_resample_to_frame_pitch():
    a = blob((120, 120), sigma=8.0)
    psf = load_psf(a, bin=2, psf_pitch=0.005, frame_pitch=0.015, normalise="none")
    assert psf.info["resample_factor"] == pytest.approx(2 / 3)
    assert psf.shape == (40, 40) and psf.array.sum() == pytest.approx(a.sum(), rel=1e-12)


@pytest.mark.parametrize("shape", [(64, 64), (63, 70)])
def test_centroid_centring_within_a_tenth_of_a_pixel(shape):
    a = blob(shape, center=(20.3, 41.7), sigma=3.0)
    psf = load_psf(a, center="centroid")
    cy, cx, width = moments(psf.array)
    assert abs(cy - shape[0] // 2) < 0.1 and abs(cx - shape[1] // 2) < 0.1
    assert width == pytest.approx(3.0, rel=0.02)
    assert psf.info["centring_shift"] == pytest.approx([shape[0] // 2 - 20.3,
                                                       shape[1] // 2 - 41.7], abs=1e-3)


def test_peak_centring_rgb_moves_channels_together():
    a = np.stack([blob(center=(10, 50), sigma=2.0), blob(center=(10, 50), sigma=2.0),
                  blob(center=(11, 51), sigma=2.0, amp=300.0)], axis=-1)  # lateral colour
    a[5, 40, 0] = 5000.0  # a hot pixel is not the peak
    psf = load_psf(a, center="peak", normalise="none")
    assert psf.info["centring_shift"] == [22.0, -18.0]
    np.testing.assert_allclose(psf.array, np.roll(a, (22, -18), axis=(0, 1)), atol=1e-6)


# ----------------------------------------------------------------------------------------
# stacks and depth selection
# ----------------------------------------------------------------------------------------
R1S = (0.20, 0.22, 0.24, 0.26, 0.28)  # shadow constants r1' (mm): one per depth
DEPTHS = (12.0, 20.0, 35.0, 60.0, 150.0)


@pytest.fixture(scope="module")
def fza_stack() -> np.ndarray:
    """Five FZA-like PSFs (GZP shadows, aperture 0.9 mm, pitch 10 um), 200^2: larger than
    the 128^2 frame."""
    return np.stack([zone_plate((200, 200), 0.01, r, kind="gzp", R=0.9) for r in R1S])


def measure(psf: np.ndarray, shape=(128, 128)) -> np.ndarray:
    """Linear convolution of a simple object (bars and points) with ``psf``, cropped to the
    sensor, DC removed."""
    obj = np.zeros(shape)
    obj[40:90, 60:64] = 1.0
    obj[60:64, 20:50] = 1.0
    obj[30, 30], obj[100, 90] = 3.0, 2.0
    c0, c1 = psf.shape[0] // 2, psf.shape[1] // 2
    y = fftconvolve(obj, psf)[c0:c0 + shape[0], c1:c1 + shape[1]]
    return y - y.mean()


@pytest.mark.parametrize("true", [1, 2, 3])
def test_select_depth_picks_the_true_psf(fza_stack, true):
    stack = load_psf_stack(fza_stack, DEPTHS)
    y = measure(stack.arrays[true])
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        warnings.filterwarnings("ignore", message=".*not reliable")  # confidence: elsewhere
        k, scores = select_psf_depth(y, stack)
    assert k == true and scores.shape == (5,)
    assert scores[true] - np.delete(scores, true).max() > 0.05


@pytest.mark.parametrize("metric", ["mix", "tamura"])
def test_select_depth_binary_fza_with_noise(metric):
    rng = np.random.default_rng(7)
    stack = np.stack([zone_plate((200, 200), 0.01, r, kind="fza") for r in R1S])
    y = measure(stack[1] / stack[1].sum())
    y += 0.5 * y.std() * rng.standard_normal(y.shape)
    k, scores = select_psf_depth(y, stack, DEPTHS, metric=metric)
    assert k == 1, scores


def test_select_depth_warns_at_an_end(fza_stack):
    y = measure(fza_stack[0] / fza_stack[0].sum())
    with pytest.warns(PSFDepthWarning, match="first depth"):
        k, _ = select_psf_depth(y, fza_stack, DEPTHS)
    assert k == 0
    with pytest.warns(PSFDepthWarning, match=r"first depth of the stack \(PSF 0\)"):
        select_psf_depth(y, fza_stack)


def test_select_depth_flat_curve(fza_stack):
    same = np.stack([fza_stack[2]] * 4)
    y = measure(same[0])
    with pytest.warns(PSFDepthWarning, match=r"flat .*scores 1 mm"):
        select_psf_depth(y, same, [1, 2, 3, 4])
    with pytest.raises(ClfzaError, match="flat"):
        select_psf_depth(y, same, [1, 2, 3, 4], flat="error")
    with pytest.raises(ClfzaError, match="4 PSFs but 3 depths"):
        select_psf_depth(y, same, [1, 2, 3])
    with pytest.raises(ClfzaError, match="metric must be"):
        select_psf_depth(y, same, metric="entropy")


def test_back_project_is_the_adjoint_of_linear_convolution(rng):
    obj, psf = rng.standard_normal((9, 11)), rng.standard_normal((14, 7))
    y = rng.standard_normal((9, 11))
    forward = fftconvolve(obj, psf)[7:16, 3:14]  # crop to the sensor, PSF centre (7, 3)
    assert np.vdot(forward, y) == pytest.approx(np.vdot(obj, back_project(y, psf)),
                                                rel=1e-12)


def test_stack_from_npy_tiff_and_list(tmp_path, fza_stack):
    raw = (fza_stack[:, ::4, ::4] * 60000).astype(np.uint16)  # 5 x 50 x 50
    npy = tmp_path / "stack.npy"
    np.save(npy, raw)
    tif = tmp_path / "stack.tif"
    tifffile.imwrite(tif, raw, compression="zlib", photometric="minisblack")
    files = []
    for k, a in enumerate(raw):
        files.append(tmp_path / f"psf{k}.png")
        files[-1].write_bytes(fio.encode_png(a))
    ref = raw / raw.sum(axis=(1, 2), keepdims=True)
    for src in (npy, tif, files, raw):
        st = load_psf_stack(src, DEPTHS)
        assert len(st) == 5 and st.depths == DEPTHS and st.arrays.shape == (5, 50, 50)
        np.testing.assert_allclose(st.arrays, ref, rtol=1e-12)
    binned = load_psf_stack(npy, DEPTHS, bin=2, psf_pitch=0.01)
    assert binned.arrays.shape == (5, 25, 25) and binned.pitch == pytest.approx(0.02)
    assert binned.psf(3).info["bin"] == 2
    with pytest.raises(ClfzaError, match="5 PSFs but 4 depths"):
        load_psf_stack(npy, DEPTHS[:4])
    with pytest.raises(ClfzaError, match="more than max_pixels"):
        load_psf_stack(tif, DEPTHS, max_pixels=1000)
    with pytest.raises(ClfzaError, match="distinct"):
        load_psf_stack(raw, [1, 1, 2, 3, 4])
