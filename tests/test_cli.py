"""The clfza command line, every command run as a subprocess (``python -m clfza``)."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from clfza import Camera, simulate
from clfza.io import read_frame, write_array

CAMERA_TOML = """\
# a small near-critical camera for fast tests
[camera]
name = "tiny"
pitch = 0.01
shape = [128, 128]
r1 = 0.0984
z1 = 20.0
z2 = 3.0
R = 1.0
"""


def clfza(*args, cwd=None, env=None, timeout=240) -> subprocess.CompletedProcess:
    e = dict(os.environ)
    e.update(env or {})
    return subprocess.run([sys.executable, "-m", "clfza", *map(str, args)], cwd=cwd, env=e,
                          capture_output=True, text=True, timeout=timeout)


def assert_ok(res: subprocess.CompletedProcess) -> None:
    assert res.returncode == 0, res.stdout + res.stderr
    assert "Traceback" not in res.stderr


@pytest.fixture(scope="module")
def work(tmp_path_factory) -> Path:
    """A folder with tiny.toml, a raw frame (12-bit TIFF), an RGB PNG and a Bayer mosaic."""
    from skimage import data

    d = tmp_path_factory.mktemp("cli")
    (d / "tiny.toml").write_text(CAMERA_TOML)
    cam = Camera.load(d / "tiny.toml")
    width = 0.9 * 128 * 0.01 / cam.magnification
    m = simulate(data.camera(), cam, object_width=width)
    dn = np.round(m.frame / m.frame.max() * 4000).astype(np.uint16)
    write_array(d / "frame.tif", dn)
    write_array(d / "frame2.png", dn)
    np.save(d / "truth.npy", m.truth)
    big = cam.with_shape((150, 140))
    rgb = simulate(data.astronaut(), big, object_width=width).frame
    write_array(d / "rgb.png", np.round(rgb / rgb.max() * 60000).astype(np.uint16))
    # a Bayer mosaic from a simulation at half the pitch
    cam2 = Camera(pitch=0.005, shape=(272, 260), r1=cam.r1, z1=20.0, z2=3.0, R=1.0)
    f = simulate(data.astronaut(), cam2, object_width=width).frame
    f = f / f.max()
    mos = np.empty(f.shape[:2])
    mos[0::2, 0::2], mos[0::2, 1::2] = f[0::2, 0::2, 0], f[0::2, 1::2, 1]
    mos[1::2, 0::2], mos[1::2, 1::2] = f[1::2, 0::2, 1], f[1::2, 1::2, 2]
    write_array(d / "bayer.tif", (np.round(mos * 50000) + 200).astype(np.uint16))
    write_array(d / "dark.tif", np.full(mos.shape, 200, np.uint16))
    np.save(d / "flat.npy", np.ones(mos.shape, np.float32))
    (d / "half.toml").write_text(CAMERA_TOML.replace("0.01", "0.005").replace(
        "[128, 128]", "[256, 256]"))
    return d


# ----------------------------------------------------------------------------------------
def test_version_and_help():
    res = clfza("--version")
    assert_ok(res)
    assert res.stdout.startswith("clfza ")
    res = clfza("--help")
    assert_ok(res)
    for cmd in ("demo", "info", "reconstruct", "simulate", "focus", "bench"):
        assert cmd in res.stdout
    for cmd in ("demo", "bench", "simulate"):
        r = clfza(cmd, "--help")
        assert_ok(r)
        assert "usage: clfza " + cmd in r.stdout


def test_info_devices_and_camera(work):
    res = clfza("info", "--camera", work / "tiny.toml")
    assert_ok(res)
    out = res.stdout
    assert "OpenCL devices" in out and "fp64" in out and "MiB" in out and "FFT" in out
    for word in ("sampling regime", "resolution (sensor)", "resolution (object)",
                 "field of view", "band limit", "suggested bin factor"):
        assert word in out, out
    res = clfza("info", "--camera", "experiment")
    assert_ok(res)
    assert "2400x2400" in res.stdout


def test_simulate_then_reconstruct_opencl(work, tmp_path):
    res = clfza("simulate", "camera", "--camera", work / "tiny.toml", "--noise",
                "photons=2e4,bits=12,seed=3", "--out", tmp_path / "sim", cwd=tmp_path)
    assert_ok(res)
    raw = tmp_path / "sim" / "camera-raw.tif"
    frame, info = read_frame(raw)
    assert info.dtype == "uint16" and frame.max() <= 4095 and frame.shape == (128, 128)
    truth = np.load(tmp_path / "sim" / "truth" / "camera-truth.npy")
    assert truth.shape == (128, 128)
    rec = json.loads((tmp_path / "sim" / "camera.json").read_text())
    assert rec["noise"]["bit_depth"] == 12 and 0 < rec["object_mean"] < 1
    assert (tmp_path / "sim" / "truth" / "camera-truth.png").exists()
    # the simulated frame reconstructs with the default (OpenCL) backend
    res = clfza("reconstruct", raw, "--camera", work / "tiny.toml", "--out", tmp_path / "rec")
    assert_ok(res)
    js = json.loads((tmp_path / "rec" / "camera-raw.json").read_text())
    assert js["backend"] == "opencl" and js["stop_reason"]
    img = np.load(tmp_path / "rec" / "camera-raw.npy")
    assert img.shape == (128, 128) and np.isfinite(img).all()


def test_reconstruct_outputs_and_record(work, tmp_path):
    out = tmp_path / "o"
    res = clfza("reconstruct", work / "frame.tif", "--camera", work / "tiny.toml",
                "--backend", "numpy", "--out", out, "--scaling", "percentile",
                "--percentiles", "1,99")
    assert_ok(res)
    assert res.stderr == ""
    names = sorted(p.name for p in out.iterdir())
    assert names == ["frame.json", "frame.npy", "frame.png"]
    png, info = read_frame(out / "frame.png")
    assert info.bit_depth == 16 and png.max() == 65535
    rec = json.loads((out / "frame.json").read_text())
    for key in ("clfza_version", "input", "camera", "method", "parameters", "device",
                "timings_s", "stop_reason", "outputs", "scaling", "input_file"):
        assert key in rec, key
    # the default route: ADMM with tau from the frame, and the record says so
    assert rec["method"] == "admm" and rec["parameters"]["method_asked"] == "auto"
    assert rec["notes"][0].startswith("method: auto, the default route")
    assert rec["scaling"]["percentiles"] == [1.0, 99.0]
    assert rec["camera"]["shape"] == [128, 128]
    assert rec["outputs"]["image"].endswith("frame.png")
    # the reconstruction correlates with the truth
    img = np.load(out / "frame.npy")
    truth = np.load(work / "truth.npy")
    c = np.corrcoef(img.ravel(), truth.ravel())[0, 1]
    assert c > 0.3, c


def test_no_overwrite_then_force(work, tmp_path):
    args = ("reconstruct", work / "frame.tif", "--camera", work / "tiny.toml", "--backend",
            "numpy", "--out", tmp_path, "--format", "tiff")
    assert_ok(clfza(*args))
    target = tmp_path / "frame.tif"
    before = target.read_bytes()
    mtime = target.stat().st_mtime_ns
    res = clfza(*args, "--scaling", "minmax")
    assert res.returncode != 0
    assert "exists" in res.stderr and "--force" in res.stderr
    assert len(res.stderr.strip().splitlines()) == 1 and "Traceback" not in res.stderr
    assert target.read_bytes() == before and target.stat().st_mtime_ns == mtime
    res = clfza(*args, "--scaling", "minmax", "--force")
    assert_ok(res)
    assert target.read_bytes() != before
    assert not [p for p in tmp_path.iterdir() if p.name.startswith(".")]  # no temp files


def test_batch_with_corrupt_file(work, tmp_path):
    src = tmp_path / "in"
    src.mkdir()
    for name in ("a.tif", "b.tif"):
        (src / name).write_bytes((work / "frame.tif").read_bytes())
    (src / "c_corrupt.tif").write_bytes((work / "frame.tif").read_bytes()[:300])
    (src / "d.png").write_bytes((work / "frame2.png").read_bytes())
    res = clfza("reconstruct", str(src / "*.tif"), src / "d.png", "--camera",
                work / "tiny.toml", "--backend", "numpy", "--out", tmp_path / "out")
    assert res.returncode == 1, res.stdout + res.stderr
    assert "Traceback" not in res.stderr
    err = res.stderr.strip().splitlines()
    assert len(err) == 1 and "c_corrupt.tif" in err[0] and "corrupt" in err[0]
    assert "reconstructed 3 of 4" in res.stdout and "c_corrupt.tif" in res.stdout
    outs = sorted(p.name for p in (tmp_path / "out").iterdir())
    for stem in ("a", "b", "d"):
        assert {f"{stem}.png", f"{stem}.npy", f"{stem}.json"} <= set(outs)
    assert not any(n.startswith("c_corrupt") for n in outs)
    summary = json.loads((tmp_path / "out" / "batch-001.json").read_text())
    # one summary for every batch (clfza.distributed.BatchResult.summary): counts, then the
    # outputs and the failures by input label ('path')
    assert summary["succeeded"] == 3 and len(summary["outputs"]) == 3
    assert [Path(f["input"].strip("'")).name for f in summary["failures"]] == ["c_corrupt.tif"]


def test_rgb_crop_center_and_quiet(work, tmp_path):
    res = clfza("reconstruct", work / "rgb.png", "--camera", work / "tiny.toml", "--backend",
                "numpy", "--out", tmp_path, "--center", "70,75", "--format", "tiff-float",
                "--quiet")
    assert_ok(res)
    assert res.stdout == "" and res.stderr == ""
    img, info = read_frame(tmp_path / "rgb.tif")
    assert img.shape == (128, 128, 3) and info.bit_depth is None
    rec = json.loads((tmp_path / "rgb.json").read_text())
    assert rec["crop_origin"] == [6, 11] and rec["scaling"]["mode"] == "none"


def test_bayer_dark_flat_bin_verbose(work, tmp_path):
    res = clfza("reconstruct", work / "bayer.tif", "--camera", work / "half.toml", "--bayer",
                "RGGB", "--dark", work / "dark.tif", "--flat", work / "flat.npy", "--bin", "2",
                "--backend", "numpy", "--out", tmp_path, "--verbose")
    assert_ok(res)
    assert "clfza:" in res.stderr  # the verbose log line
    rec = json.loads((tmp_path / "bayer.json").read_text())
    assert rec["camera"]["shape"] == [64, 64]
    assert abs(rec["camera"]["pitch_mm"] - 0.02) < 1e-12  # 0.005 x 2 (Bayer) x 2 (bin)
    assert rec["preparation"][:2] == ["dark", "flat"]
    assert any("demosaic" in s for s in rec["preparation"])
    assert np.load(tmp_path / "bayer.npy").shape == (64, 64, 3)


def test_iterative_method_when_available(work, tmp_path):
    from clfza.solvers import METHODS

    method = next((m for m in ("admm", "fista", "twist") if m in METHODS), None)
    if method is None:
        pytest.skip("no iterative solver in this build yet")
    res = clfza("reconstruct", work / "frame.tif", "--camera", work / "tiny.toml", "--method",
                method, "--iters", "5", "--tau", "0.005", "--backend", "numpy", "--out",
                tmp_path)
    assert_ok(res)
    rec = json.loads((tmp_path / "frame.json").read_text())
    assert rec["method"] == method and rec["parameters"]["iters"] == 5
    assert rec["stop_reason"]


def test_focus(work, tmp_path):
    res = clfza("focus", work / "frame.tif", "--camera", work / "tiny.toml", "--z-range",
                "10,60", "--coarse", "9", "--out", tmp_path)
    if res.returncode != 0 and "not available" in res.stderr:
        pytest.skip("autofocus is not in this build")
    # the curve and its best depth are recorded whether or not the focus is confident; the
    # frame was simulated at the camera's z1 = 20 mm
    rec = json.loads((tmp_path / "frame-focus.json").read_text())
    assert abs(rec["focus"]["z1_best"] - 20.0) <= 1.0, rec["focus"]["z1_best"]
    assert res.returncode in (0, 1), res.stderr
    if res.returncode == 1:  # an honest refusal is one line naming the record
        assert "no reliable focus" in res.stderr and "frame-focus.json" in res.stderr
        assert len(res.stderr.strip().splitlines()) == 1
    else:
        assert "best z1" in res.stdout and rec["focus"]["confident"]


@pytest.mark.xfail(strict=True, reason=(
    "issue 34, open: the calibrated isolation rule (MIN_ISOLATION 0.65) refuses this noise-free "
    "128^2 frame's right answer (20.3 mm for 20): a second hump of the 'mix' curve at 37 mm "
    "scores within 58 % of the peak's prominence"))
def test_focus_confident_on_a_clean_frame(work, tmp_path):
    res = clfza("focus", work / "frame.tif", "--camera", work / "tiny.toml", "--z-range",
                "10,60", "--coarse", "9", "--out", tmp_path)
    assert_ok(res)


def test_bench_dispatch(tmp_path, monkeypatch, capsys):
    """``clfza bench`` hands the profile and folder to clfza.benchmarks.run (in-process: the
    real suite takes minutes), or fails with one clear line when it is missing."""
    import clfza.benchmarks as b
    from clfza.cli import main

    calls = []
    monkeypatch.setattr(b, "run", lambda profile, out, first_run=None:
                        calls.append((profile, out)), raising=False)
    assert main(["bench", "--full", "--out", str(tmp_path)]) == 0
    assert calls == [("full", tmp_path)]
    monkeypatch.delattr(b, "run")
    assert main(["bench", "--quick"]) == 2
    assert "benchmarks are not available" in capsys.readouterr().err


def test_report_exception_one_line():
    from clfza.cli import report_exception
    from clfza.errors import DeviceError

    msg, code = report_exception(DeviceError("no OpenCL device\nmatches"))
    assert code == 2 and msg == "clfza: error: no OpenCL device matches"
    msg, code = report_exception(MemoryError("cannot allocate"))
    assert code == 2 and "out of memory" in msg
    fake = type("MemoryError", (Exception,), {"__module__": "pyopencl._cl"})
    msg, code = report_exception(fake("CL_MEM_OBJECT_ALLOCATION_FAILURE"))
    assert code == 2 and "out of memory" in msg
    msg, code = report_exception(RuntimeError("boom"))
    assert code == 1 and "--debug" in msg and "\n" not in msg


def test_debug_shows_traceback(tmp_path):
    res = clfza("--debug", "reconstruct", tmp_path / "missing.png", "--camera", "simulation")
    assert res.returncode != 0
    assert "Traceback" in res.stderr and "does not exist" in res.stderr


def test_reconstruct_explain_prints_the_plan(work, tmp_path):
    out = tmp_path / "p"
    res = clfza("reconstruct", work / "frame.tif", "--camera", work / "tiny.toml",
                "--backend", "numpy", "--out", out, "--explain", "--plan")
    assert_ok(res)
    for word in ("plan for", "bin", "noise", "dtype", "fov"):
        assert word in res.stdout, (word, res.stdout)
    assert (out / "frame.npy").exists()
