"""``clfza focus --psf`` and ``clfza reconstruct --psf --psf-scale`` (issue 34): the scale
search from the command line, its record (schema-checked) and curve, and psf.scale in the
frame record."""

from __future__ import annotations

import json

import numpy as np
import pytest
from skimage import data

from clfza.cli import main
from clfza.io import validate_record
from clfza.simulation import simulate_psf_capture


@pytest.fixture(scope="module")
def files(tmp_path_factory):
    d = tmp_path_factory.mktemp("psfcli")
    cap = simulate_psf_capture(data.coffee(), shape=(160, 160), scene_z1=40.0)
    np.save(d / "frame.npy", cap.frame.mean(axis=2).round().astype(np.uint8))
    np.save(d / "psf.npy", cap.psf.mean(axis=2))
    (d / "cam.toml").write_text("[camera]\npitch = 0.0066\nshape = [160, 160]\nz2 = 8.0\n"
                                "psf_z1 = 400.0\n")
    return d, cap


def test_focus_psf_finds_scale_and_depth(files):
    d, cap = files
    rc = main(["focus", str(d / "frame.npy"), "--camera", str(d / "cam.toml"), "--psf",
               str(d / "psf.npy"), "--out", str(d / "f")])
    rec = json.loads((d / "f" / "frame-focus.json").read_text())
    validate_record(rec, "focus")
    res = rec["psf_scale"]
    assert rc == (0 if res["confident"] else 1)
    assert res["scale"] == pytest.approx(cap.true_scale, rel=0.02)
    assert res["depth_mm"] == pytest.approx(40.0, rel=0.15)
    assert (d / "f" / "frame-focus.png").stat().st_size > 1000


def test_focus_psf_refuses_z_options(files, capsys):
    d, _ = files
    assert main(["focus", str(d / "frame.npy"), "--camera", str(d / "cam.toml"), "--psf",
                 str(d / "psf.npy"), "--z-range", "10,40", "--out", str(d / "g")]) != 0
    assert "do not go with --psf" in capsys.readouterr().err
    assert main(["focus", str(d / "frame.npy"), "--camera", str(d / "cam.toml"),
                 "--out", str(d / "g")]) != 0
    assert "--z-range" in capsys.readouterr().err
    assert not (d / "g").exists()


@pytest.mark.parametrize("scale", ["1.2", "auto"])
def test_reconstruct_psf_scale_recorded(files, scale):
    d, cap = files
    out = d / f"r{scale}"
    rc = main(["reconstruct", str(d / "frame.npy"), "--camera", str(d / "cam.toml"), "--psf",
               str(d / "psf.npy"), "--psf-scale", scale, "--method", "admm", "--iters", "3",
               "--backend", "numpy", "--out", str(out)])
    assert rc == 0
    rec = json.loads((out / "frame.json").read_text())
    validate_record(rec, "frame")
    if scale == "auto":
        assert rec["psf"]["scale"] == pytest.approx(cap.true_scale, rel=0.02)
        assert rec["psf"]["scale_search"]["scale"] == rec["psf"]["scale"]
    else:
        assert rec["psf"]["scale"] == 1.2 and "scale_search" not in rec["psf"]
