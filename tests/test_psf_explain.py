"""``clfza reconstruct --explain`` with a measured PSF (issue 34, item 3): the planner models
the zone plate (r1, z1, z2, R), which a measured PSF replaces, so neither the explanation
nor the JSON record shows an FZA quantity (r1', the band limit R'/r1'^2, rho_c) computed
from values the camera file does not have."""

from __future__ import annotations

import json

import numpy as np
import pytest

from clfza.cli import main
from clfza.io import validate_record, write_array
from clfza.simulation import simulate_psf_capture

pytestmark = pytest.mark.usefixtures("cli_logging")

FZA_WORDS = ("r1'", "rho_c", "R'/r1'", "band limit", "r1_mm", "R_mm", "r1_shadow")
FZA_KEYS = ("r1_mm", "r1_shadow_mm", "z1_mm", "R_mm", "mask", "magnification", "band_limit")


@pytest.fixture(scope="module")
def files(tmp_path_factory):
    d = tmp_path_factory.mktemp("psfexplain")
    cap = simulate_psf_capture(np.eye(48), shape=(64, 64), psf_z1=40.0, scene_z1=40.0)
    write_array(d / "f.png", cap.frame.round().astype(np.uint8))
    np.save(d / "p.npy", cap.psf)
    (d / "psf.toml").write_text("[camera]\npitch = 0.0066\nshape = [64, 64]\n")
    (d / "fza.toml").write_text("[camera]\npitch = 0.0066\nshape = [64, 64]\nr1 = 0.05\n"
                                "z1 = 40.0\nz2 = 8.0\nR = 0.2\n")
    return d


def _explain(d, camera: str, capsys, *extra) -> tuple[str, dict]:
    out = d / f"o-{camera}"
    assert main(["reconstruct", str(d / "f.png"), "--camera", str(d / camera), "--psf",
                 str(d / "p.npy"), "--method", "admm", "--iters", "5", "--backend", "numpy",
                 "--explain", "--out", str(out), "--force", *extra]) == 0
    text = capsys.readouterr().out
    rec = json.loads((out / "f.json").read_text())
    assert validate_record(rec, "frame") == []
    return text, rec


def test_measured_psf_camera_explains_no_fza_quantity(files, capsys):
    text, rec = _explain(files, "psf.toml", capsys)
    assert "measured PSF: no plan" in text and "ran: 5 iteration(s)" in text
    assert "advice only" not in text
    shown = text + json.dumps(rec["camera"]) + json.dumps(rec["parameters"]) \
        + " ".join(rec["notes"])
    for word in FZA_WORDS:
        assert word not in shown, word
    assert rec["camera"]["kind"] == "psf"
    assert not [k for k in rec["camera"] if any(k.startswith(f) for f in FZA_KEYS)]


def test_psf_on_fza_camera_file_makes_no_plan(files, capsys):
    """--psf with a camera file that has FZA keys: the PSF is the operator, so the plan's
    band limits (from the file's r1 and R) are not shown as if they applied."""
    text, _ = _explain(files, "fza.toml", capsys)
    assert "measured PSF: no plan" in text
    assert "rho_c" not in text and "R'/r1'" not in text
