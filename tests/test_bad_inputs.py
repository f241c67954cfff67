"""A corpus of bad inputs -- files, camera files and parameters -- for every command.

Each case runs ``python -m clfza ...`` as a subprocess and must end with a non-zero exit
status, exactly one line on stderr that starts with ``clfza: error:`` and contains a useful
word, and no traceback. The subprocesses of the whole corpus are launched together by a
module fixture (a small thread pool: each one is mostly interpreter start-up), and every case
is checked as its own parametrised test.
"""

from __future__ import annotations

import os
import subprocess
import sys
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import numpy as np
import pytest
import tifffile

from clfza.io import encode_png, write_array

OK = ("--camera", "cam.toml", "--backend", "numpy")

# (id, argv, word expected in the message (case-insensitive), extra environment)
CASES: list[tuple[str, list[str], str, dict]] = [
    # ---- frame files ------------------------------------------------------------------
    ("missing-file", ["reconstruct", "nope.png", *OK], "does not exist", {}),
    ("folder-as-frame", ["reconstruct", "adir", *OK], "folder", {}),
    ("empty-file", ["reconstruct", "empty.png", *OK], "empty file", {}),
    ("truncated-png", ["reconstruct", "truncated.png", *OK], "corrupt", {}),
    ("garbage-png", ["reconstruct", "garbage.png", *OK], "not a PNG", {}),
    ("png-bad-crc", ["reconstruct", "badcrc.png", *OK], "corrupt", {}),
    ("garbage-tiff", ["reconstruct", "garbage.tif", *OK], "corrupt", {}),
    ("truncated-tiff", ["reconstruct", "truncated.tif", *OK], "corrupt", {}),
    # a multi-page TIFF is a frame stack (issue 15): its 16x16 pages do not fit the camera
    ("tiff-stack", ["reconstruct", "stack.tif", *OK], "larger than the frame", {}),
    ("garbage-npy", ["reconstruct", "garbage.npy", *OK], "not an NPY", {}),
    ("npy-objects", ["reconstruct", "objects.npy", *OK], "objects", {}),
    ("npz-as-npy", ["reconstruct", "archive.npy", *OK], "npz", {}),
    ("jpeg-suffix", ["reconstruct", "photo.jpg", *OK], "unsupported suffix", {}),
    ("nan-values", ["reconstruct", "nan.npy", *OK], "NaN", {}),
    ("inf-values", ["reconstruct", "inf.tif", *OK], "Inf", {}),
    ("empty-array", ["reconstruct", "empty.npy", *OK], "empty", {}),
    # (2, 64, 64, 3) is a stack of two RGB frames (issue 15); these are constant
    ("rank-4", ["reconstruct", "rank4.npy", *OK], "flat", {}),
    ("five-channels", ["reconstruct", "five.npy", *OK], "RGB", {}),
    ("int32-depth", ["reconstruct", "int32.npy", *OK], "bit depth", {}),
    ("uint32-tiff", ["reconstruct", "uint32.tif", *OK], "bit depth", {}),
    ("one-bit-png", ["reconstruct", "onebit.png", *OK], "1-bit", {}),
    ("complex", ["reconstruct", "complex.npy", *OK], "data type", {}),
    ("rgba-alpha", ["reconstruct", "rgba.png", *OK], "alpha", {}),
    ("flat-frame", ["reconstruct", "flat_frame.npy", *OK], "flat", {}),
    ("black-frame", ["reconstruct", "black.npy", *OK], "mean is <= 0", {}),
    ("frame-too-small", ["reconstruct", "small.npy", *OK], "larger than the frame", {}),
    ("glob-no-match", ["reconstruct", "nothing*.tif", *OK], "matches no file", {}),
    # ---- calibration frames and preparation -------------------------------------------
    ("dark-wrong-shape", ["reconstruct", "good.tif", "--dark", "small.npy", *OK],
     "same sensor", {}),
    ("dark-missing", ["reconstruct", "good.tif", "--dark", "nodark.tif", *OK],
     "does not exist", {}),
    ("flat-with-zeros", ["reconstruct", "good.tif", "--flat", "black.npy", *OK],
     "flat field", {}),
    ("bayer-on-rgb", ["reconstruct", "rgb.tif", "--bayer", "RGGB", *OK], "single-channel", {}),
    ("bayer-bad-pattern", ["reconstruct", "good.tif", "--bayer", "RGBX", *OK], "bayer", {}),
    ("crop-three-values", ["reconstruct", "good.tif", "--crop", "10,10,10", *OK], "crop", {}),
    ("crop-too-large", ["reconstruct", "good.tif", "--crop", "500", *OK], "larger", {}),
    ("center-outside", ["reconstruct", "big.tif", "--crop", "64", "--center", "900,3", *OK],
     "outside", {}),
    ("bin-zero", ["reconstruct", "good.tif", "--bin", "0", *OK], "bin", {}),
    ("object-mean-negative", ["reconstruct", "good.tif", "--object-mean", "-1", *OK],
     "object-mean", {}),
    # ---- solver and output parameters -------------------------------------------------
    ("tau-negative", ["reconstruct", "good.tif", "--tau", "-1", *OK], "tau", {}),
    ("iters-zero", ["reconstruct", "good.tif", "--iters", "0", *OK], "iters", {}),
    ("unknown-method", ["reconstruct", "good.tif", "--method", "magic", *OK], "method", {}),
    ("bp-with-tau", ["reconstruct", "good.tif", "--method", "bp", "--tau", "0.01", *OK],
     "takes no options", {}),
    ("bad-opt", ["reconstruct", "good.tif", "--opt", "novalue", *OK], "KEY=VALUE", {}),
    ("percentiles-reversed", ["reconstruct", "good.tif", "--percentiles", "99,1", *OK],
     "percentiles", {}),
    ("out-is-a-file", ["reconstruct", "good.tif", "--camera", "cam.toml", "--out", "good.tif"],
     "not a folder", {}),
    ("no-such-device", ["reconstruct", "good.tif", "--camera", "cam.toml", "--device",
                        "no-such-device-xyz"], "no OpenCL device", {}),
    ("no-device-env", ["reconstruct", "good.tif", "--camera", "cam.toml"],
     "no OpenCL device", {"PYOPENCL_CTX": "no-such-device-xyz"}),
    # ---- camera files -----------------------------------------------------------------
    ("camera-missing", ["reconstruct", "good.tif", "--camera", "nocam.toml"],
     "does not exist", {}),
    ("camera-bad-toml", ["reconstruct", "good.tif", "--camera", "syntax.toml"], "TOML", {}),
    ("camera-missing-key", ["reconstruct", "good.tif", "--camera", "nopitch.toml"],
     "missing", {}),
    ("camera-negative-pitch", ["reconstruct", "good.tif", "--camera", "negpitch.toml"],
     "pitch", {}),
    ("camera-zero-shape", ["reconstruct", "good.tif", "--camera", "zeroshape.toml"],
     "shape", {}),
    ("camera-unknown-key", ["reconstruct", "good.tif", "--camera", "unknown.toml"],
     "unknown", {}),
    ("camera-bad-mask", ["reconstruct", "good.tif", "--camera", "badmask.toml"], "mask", {}),
    ("camera-not-a-preset", ["info", "--camera", "simulashun"], "does not exist", {}),
    # issue 14: what is wrong, named
    ("camera-is-a-folder", ["reconstruct", "good.tif", "--camera", "adir"], "is a folder", {}),
    ("camera-fractional-shape", ["reconstruct", "good.tif", "--camera", "fracshape.toml"],
     "fractional", {}),
    ("huge-declared-png16", ["reconstruct", "huge16.png", *OK], "more than the limit", {}),
    # ---- simulate, focus, bench, usage ------------------------------------------------
    ("simulate-missing-scene", ["simulate", "noscene.png", "--camera", "cam.toml"],
     "does not exist", {}),
    ("simulate-nan-scene", ["simulate", "nan.npy", "--camera", "cam.toml"], "NaN", {}),
    ("simulate-bad-noise-key", ["simulate", "camera", "--camera", "cam.toml", "--noise",
                                "loud=3"], "noise", {}),
    ("simulate-negative-noise", ["simulate", "camera", "--camera", "cam.toml", "--noise",
                                 "-0.5"], "gaussian_var", {}),
    ("simulate-exists", ["simulate", "camera", "--camera", "cam.toml", "--out", "simdone"],
     "exists", {}),
    ("focus-reversed-range", ["focus", "good.tif", "--camera", "cam.toml", "--z-range",
                              "40,10"], "z-range", {}),
    ("focus-no-range", ["focus", "good.tif", "--camera", "cam.toml"], "z-range", {}),
    # one API (issue 32): --search is the strategy, numbers are parsed then validated, and a
    # tau grid with the default method (bp) names an iterative one
    ("focus-bad-search", ["focus", "good.tif", "--camera", "cam.toml", "--z-range", "10,40",
                          "--search", "bisect"], "search", {}),
    ("z1-not-a-number", ["reconstruct", "good.tif", "--z1", "abc", *OK], "number", {}),
    ("sweep-tau-with-bp", ["sweep", "good.tif", "--camera", "cam.toml", "--tau", "1e-3"],
     "--method", {}),
    ("bench-both-profiles", ["bench", "--quick", "--full"], "not allowed", {}),
    ("unknown-command", ["explode"], "invalid choice", {}),
]


def _make_files(d: Path, camera: str) -> None:
    """The inputs of every case in ``d``; ``camera``: the test camera's file text."""
    from clfza import Camera, simulate

    (d / "cam.toml").write_text(camera)
    cam = Camera.load(d / "cam.toml")
    rng = np.random.default_rng(0)
    frame = simulate(rng.random((32, 32)), cam).frame
    good = np.round(frame / frame.max() * 4000).astype(np.uint16)
    write_array(d / "good.tif", good)
    write_array(d / "rgb.tif", np.stack([good] * 3, -1))
    write_array(d / "big.tif", np.tile(good, (2, 2)))
    (d / "adir").mkdir()
    (d / "empty.png").write_bytes(b"")
    png = encode_png(good)
    (d / "truncated.png").write_bytes(png[: len(png) // 2])
    (d / "garbage.png").write_bytes(rng.bytes(500))
    bad = bytearray(png)
    bad[-20] ^= 0xFF  # inside the IDAT payload: breaks its CRC
    (d / "badcrc.png").write_bytes(bytes(bad))
    tif = (d / "good.tif").read_bytes()
    (d / "garbage.tif").write_bytes(b"II*\x00" + rng.bytes(400))
    (d / "truncated.tif").write_bytes(tif[:200])
    tifffile.imwrite(d / "stack.tif", np.zeros((5, 16, 16), np.uint16))
    (d / "garbage.npy").write_bytes(rng.bytes(300))
    np.save(d / "objects.npy", np.array([{"a": 1}], dtype=object), allow_pickle=True)
    with open(d / "archive.npy", "wb") as fh:
        np.savez(fh, a=good)
    (d / "photo.jpg").write_bytes(b"\xff\xd8\xff\xe0" + rng.bytes(100))
    nan = good.astype(np.float64)
    nan[3, 4] = np.nan
    np.save(d / "nan.npy", nan)
    inf = good.astype(np.float32)
    inf[5, 5] = np.inf
    tifffile.imwrite(d / "inf.tif", inf)
    np.save(d / "empty.npy", np.zeros((0, 64)))
    np.save(d / "rank4.npy", np.ones((2, 64, 64, 3)))
    np.save(d / "five.npy", np.ones((64, 64, 5)))
    np.save(d / "int32.npy", good.astype(np.int32))
    tifffile.imwrite(d / "uint32.tif", good.astype(np.uint32))
    import imageio.v3 as iio

    iio.imwrite(d / "onebit.png", good > 2000)
    np.save(d / "complex.npy", good.astype(np.complex64))
    rgba = np.zeros((64, 64, 4), np.uint8)
    rgba[..., 3] = rng.integers(0, 255, (64, 64))
    iio.imwrite(d / "rgba.png", rgba)
    np.save(d / "flat_frame.npy", np.full((64, 64), 1000.0))
    np.save(d / "black.npy", np.zeros((64, 64)))
    np.save(d / "small.npy", good[:32, :32])
    cams = {
        "syntax.toml": "[camera\npitch = 0.01",
        "nopitch.toml": camera.replace("pitch = 0.01\n", ""),
        "negpitch.toml": camera.replace("pitch = 0.01", "pitch = -0.01"),
        "zeroshape.toml": camera.replace("[64, 64]", "[0, 64]"),
        "unknown.toml": camera + "focal_length = 3\n",
        "badmask.toml": camera + 'mask = "square"\n',
        "fracshape.toml": camera.replace("[64, 64]", "[64.5, 64]"),
    }
    for name, text in cams.items():
        (d / name).write_text(text)
    import struct
    import zlib

    def chunk(kind: bytes, payload: bytes) -> bytes:
        return (struct.pack(">I", len(payload)) + kind + payload
                + struct.pack(">I", zlib.crc32(kind + payload)))

    ihdr = struct.pack(">IIBBBBB", 60000, 60000, 16, 2, 0, 0, 0)  # 16-bit RGB, 60000^2
    (d / "huge16.png").write_bytes(b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", ihdr)
                                   + chunk(b"IDAT", zlib.compress(b"\0" * 99))
                                   + chunk(b"IEND", b""))
    (d / "simdone").mkdir()
    (d / "simdone" / "camera.json").write_text("{}")


@pytest.fixture(scope="module")
def results(tmp_path_factory, camera_toml) -> dict[str, subprocess.CompletedProcess]:
    d = tmp_path_factory.mktemp("bad")
    _make_files(d, camera_toml)

    def run(case):
        cid, argv, _, env = case
        e = dict(os.environ)
        e.pop("PYOPENCL_CTX", None)
        e.update(env)
        if argv[0] in ("reconstruct", "simulate", "focus") and "--out" not in argv:
            argv = [*argv, "--out", f"out-{cid}"]  # cases run concurrently
        return cid, subprocess.run([sys.executable, "-m", "clfza", *argv], cwd=d, env=e,
                                   capture_output=True, text=True, timeout=300)

    workers = max(2, min(4, (os.cpu_count() or 2) + 1))
    with ThreadPoolExecutor(workers) as pool:
        return dict(pool.map(run, CASES))


def test_corpus_is_large_enough():
    assert len(CASES) >= 30
    assert len({c[0] for c in CASES}) == len(CASES)


@pytest.mark.parametrize("case", CASES, ids=[c[0] for c in CASES])
def test_bad_input(results, case):
    cid, argv, word, _ = case
    res = results[cid]
    where = f"{argv}\nstdout: {res.stdout}\nstderr: {res.stderr}"
    assert res.returncode != 0, where
    assert "Traceback" not in res.stderr, where
    lines = res.stderr.strip().splitlines()
    assert len(lines) == 1, where
    assert lines[0].startswith("clfza: error: "), where
    assert word.lower() in lines[0].lower(), where
    assert len(lines[0]) < 600, where
