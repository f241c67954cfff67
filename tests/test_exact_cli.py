"""``clfza reconstruct`` with the exact model and measured PSFs, as a user runs it."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from skimage import data

from clfza import Camera
from clfza.models._exact import shadow_kernel
from clfza.simulation import simulate

CAMERA = """[camera]
pitch = 0.01
shape = [128, 128]
r1 = 0.25
z1 = 300.0
z2 = 3.0
R = 1.0
mask = "fza"
"""


def run(*args, cwd) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "clfza", *map(str, args)], cwd=cwd,
                          env=dict(os.environ), capture_output=True, text=True, timeout=240)


@pytest.fixture(scope="module")
def work(tmp_path_factory) -> Path:
    d = tmp_path_factory.mktemp("exact_cli")
    (d / "cam.toml").write_text(CAMERA)
    cam = Camera.load(d / "cam.toml")
    m = simulate(data.camera(), cam, object_width=0.4 * 1.28 / cam.magnification)
    np.save(d / "frame.npy", m.frame)
    np.save(d / "truth.npy", m.truth)
    psf = shadow_kernel(cam)  # 1.6x the frame: a point's shadow reaches past the sensor
    assert psf.shape[0] > 1.5 * 128
    np.save(d / "psf.npy", psf)
    np.save(d / "zeros.npy", np.zeros((64, 64)))
    np.save(d / "nan.npy", np.full((64, 64), np.nan))
    np.save(d / "four.npy", np.ones((64, 64, 4)))
    np.save(d / "complex.npy", np.ones((64, 64), complex))
    return d


def test_exact_model_and_psf_from_the_command_line(work):
    res = run("reconstruct", "frame.npy", "--camera", "cam.toml", "--method", "admm",
              "--iters", "40", "--out", "a", cwd=work)
    assert res.returncode == 0, res.stderr
    rec = json.loads((work / "a" / "frame.json").read_text())
    assert rec["parameters"]["model"] == "exact"
    assert any("finite aperture" in n for n in rec["notes"])
    # the end choice of the exact ADMM (mean of the iterates or the last) is recorded
    r = rec["returned"]
    assert r["image"] in ("mean", "last")
    assert r["objective_" + r["image"]] == min(r["objective_mean"], r["objective_last"])
    res = run("reconstruct", "frame.npy", "--camera", "cam.toml", "--method", "admm",
              "--iters", "60", "--tau", "1e-4", "--psf", "psf.npy", "--orient", "upright",
              "--roi",
              "32,32,64,64", "--out", "b", cwd=work)
    assert res.returncode == 0, res.stderr
    rec = json.loads((work / "b" / "frame.json").read_text())
    assert rec["psf"]["file"] == "psf.npy" and rec["output_geometry"]["roi"] == [32, 32, 64, 64]
    a, b = np.load(work / "a" / "frame.npy"), np.load(work / "b" / "frame.npy")
    assert b.shape == (64, 64)
    # both recover the scene: the camera model, and the camera's own shadow as a "measured"
    # PSF (cropped to the ROI and rotated by 180 degrees)
    t = np.load(work / "truth.npy")
    assert np.corrcoef(a.ravel(), t.ravel())[0, 1] > 0.8
    assert np.corrcoef(t[32:96, 32:96][::-1, ::-1].ravel(), b.ravel())[0, 1] > 0.6


@pytest.mark.parametrize("bad,why", [("zeros.npy", "zero"), ("nan.npy", "NaN"),
                                     ("four.npy", "alpha"), ("complex.npy", "complex")])
def test_bad_psf_is_one_line(work, bad, why):
    res = run("reconstruct", "frame.npy", "--camera", "cam.toml", "--method", "admm",
              "--psf", bad, "--out", f"bad-{bad}", cwd=work)
    lines = [ln for ln in res.stderr.splitlines() if ln.strip()]
    assert res.returncode == 2 and len(lines) == 1, res.stderr
    assert "Traceback" not in res.stderr and why.lower() in lines[0].lower()
    assert not (work / f"bad-{bad}").exists() or not any((work / f"bad-{bad}").iterdir())


def test_plan_bins_the_exact_model(work, tmp_path):
    """--plan on a finite-aperture camera: the frame is binned and the exact model's binned
    kernel runs (said in the notes)."""
    cam = Camera.preset("experiment").with_shape((600, 600))  # a 600^2 crop: bins 8x
    assert cam.suggested_bin > 1
    m = simulate(data.camera(), cam, object_width=150.0)
    np.save(tmp_path / "f.npy", m.frame)
    (tmp_path / "c.toml").write_text(
        "[camera]\npitch = 0.00375\nshape = [600, 600]\nr1 = 0.32\nz1 = 300.0\nz2 = 3.0\n"
        "R = 4.56\nmask = \"fza\"\nr1_shadow_squared = 0.10559975306184179\n")
    res = run("reconstruct", "f.npy", "--camera", "c.toml", "--method", "admm", "--iters",
              "30", "--plan", "--out", "p", cwd=tmp_path)
    assert res.returncode == 0, res.stderr
    rec = json.loads((tmp_path / "p" / "f.json").read_text())
    notes = " ".join(rec["notes"])
    assert "binned" in notes and "exact model" in notes
    assert np.load(tmp_path / "p" / "f.npy").shape == (600, 600)
