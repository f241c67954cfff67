"""``clfza reconstruct --opt reg=dncnn`` (issue 38) on a simulated frame, as a subprocess: the
plug-and-play ADMM runs and records its denoiser; the methods and models that refuse the
prior say why in one line, with no traceback."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest


def clfza(*args, cwd=None) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "clfza", *map(str, args)], cwd=cwd,
                          env=dict(os.environ), capture_output=True, text=True, timeout=240)


@pytest.fixture(scope="module")
def frame(tmp_path_factory, camera_toml) -> tuple[Path, Path]:
    """A 64^2 grey frame simulated by ``clfza simulate`` (camera scene, Gaussian noise)."""
    d = tmp_path_factory.mktemp("pnp_cli")
    (d / "tiny.toml").write_text(camera_toml)  # the 64x64 test camera (conftest)
    res = clfza("simulate", "camera", "--camera", d / "tiny.toml", "--noise", "0.001",
                "--out", d / "sim", "-q")
    assert res.returncode == 0, res.stderr
    (raw,) = (d / "sim").glob("camera-raw.*")
    return d, raw


def test_cli_reg_dncnn_runs_and_records_the_denoiser(frame):
    """On the default OpenCL device (the test run's --cl-device through PYOPENCL_CTX)."""
    d, raw = frame
    res = clfza("reconstruct", raw, "--camera", d / "tiny.toml", "--method", "admm", "--opt",
                "reg=dncnn", "--tau", "0.01", "--model", "tf", "--out",
                d / "rec", "-q")
    assert res.returncode == 0 and "Traceback" not in res.stderr, res.stderr
    rec = json.loads((d / "rec" / f"{raw.stem}.json").read_text())
    # the frame's record: the options, and the notes naming the variant and its schedule
    assert rec["method"] == "admm" and rec["parameters"]["reg"] == "dncnn"
    assert rec["parameters"]["model"] == "tf" and rec["iterations"] >= 1
    assert any(n.startswith("prior: DnCNN 6N, sigma from") for n in rec["notes"])


@pytest.mark.parametrize("args, words", [
    (("--method", "fista", "--opt", "reg=dncnn", "--tau", "0.01"),
     ("prior for method 'admm'", "docs/measurements.md", "--method admm --opt reg=dncnn")),
    (("--method", "twist", "--opt", "reg=dncnn", "--tau", "0.01"),
     ("prior for method 'admm'", "docs/measurements.md")),
    # the camera's own model here is the exact model of the mask's shadow: refused
    (("--method", "admm", "--opt", "reg=dncnn", "--tau", "0.01", "--model", "exact"),
     ("measured PSF only", "--model tf", "bench/results/dncnn_quality_experiment")),
])
def test_cli_refusals_are_one_line(frame, args, words):
    d, raw = frame
    res = clfza("reconstruct", raw, "--camera", d / "tiny.toml", *args, "--out",
                d / "refused", "-q")
    assert res.returncode != 0 and "Traceback" not in res.stderr, res.stderr
    lines = [ln for ln in res.stderr.splitlines() if ln.strip()]
    assert len(lines) == 1 and lines[0].startswith("clfza: error:"), res.stderr
    for w in words:
        assert w in lines[0], lines[0]
