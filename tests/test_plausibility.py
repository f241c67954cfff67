"""Plausibility (issue 35, item 3): camera values outside physical ranges get one line naming
the likely unit slip; a crop forced by ``--bin`` is warned about; a sweep says when its best
point sits at the edge of its grid. The shipped presets stay silent."""

from __future__ import annotations

import json
import logging
import warnings
from importlib import resources

import numpy as np
import pytest

import clfza
from clfza import Camera, ClfzaError
from clfza.camera import CameraWarning, plausibility
from clfza.cli import main
from clfza.distributed import edge_warning
from clfza.distributed._sweep import best
from clfza.io import bin_crop_note, write_array

pytestmark = pytest.mark.usefixtures("cli_logging")


def _cam(**kw) -> dict:
    d = {"pitch": 0.01, "shape": [512, 512], "r1": 0.23, "z1": 20.0, "z2": 3.0}
    d.update(kw)
    return {"camera": d}


def test_presets_are_plausible():
    names = [p.name[:-5] for p in resources.files("clfza.camera.presets").iterdir()
             if p.name.endswith(".toml")]
    assert {"simulation", "experiment"} <= set(names)
    with warnings.catch_warnings():
        warnings.simplefilter("error", CameraWarning)
        for n in names:
            assert plausibility(Camera.preset(n)) == ([], [])


def test_pitch_in_micrometres_is_an_error():
    with pytest.raises(ClfzaError, match=r"pitch = 10 mm .* 10 um is pitch = 0\.01$"):
        Camera.from_dict(_cam(pitch=10))


@pytest.mark.parametrize("kw, words", [
    ({"pitch": 0.2}, "0.2 um is pitch = 0.0002"),
    ({"pitch": 3.75e-6}, "3.75e-06 m is pitch = 0.00375"),
    ({"z1": 3.0, "z2": 20.0}, "swapped?"),
    ({"r1": 230.0}, "micrometres written as millimetres (r1 = 0.23)"),
])
def test_implausible_values_warn_with_the_slip(kw, words):
    with pytest.warns(CameraWarning) as rec:
        Camera.from_dict(_cam(**kw))
    assert len(rec) == 1 and words in str(rec[0].message)
    assert "\n" not in str(rec[0].message)


def test_cli_says_the_slip_in_one_line(tmp_path, capsys):
    (tmp_path / "um.toml").write_text("[camera]\npitch = 10\nshape = [512, 512]\nr1 = 0.23\n"
                                      "z1 = 20.0\nz2 = 3.0\n")
    (tmp_path / "swap.toml").write_text("[camera]\npitch = 0.01\nshape = [512, 512]\n"
                                        "r1 = 0.23\nz1 = 3.0\nz2 = 20.0\n")
    assert main(["info", "--camera", str(tmp_path / "um.toml")]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and err.startswith("clfza: error:") and "10 um" in err
    # an earlier test's main() may have left logging believing it still captures warnings
    # while pytest restored warnings.showwarning: start from a clean state, as a process does
    logging.captureWarnings(False)
    assert main(["info", "--camera", str(tmp_path / "swap.toml")]) == 0
    err = capsys.readouterr().err
    lines = [ln for ln in err.splitlines() if "warning" in ln]
    assert len(lines) == 1 and lines[0].startswith("clfza: warning: ") and "swapped" in lines[0]
    assert ".py:" not in lines[0]  # the message, not the warning's file and source line


def test_bin_crop_note():
    assert bin_crop_note((512, 512), 7) == (
        "--bin 7 crops the 512x512 frame to 511x511 (sides must be multiples of 7: the last 1 "
        "row(s) and 1 column(s) are dropped); choose a bin factor that divides the crop, or "
        "--crop 511,511 to say so")
    assert bin_crop_note((512, 512), 4) is None and bin_crop_note((5, 5), 1) is None


def test_bin_forced_crop_warned_once(tmp_path, capsys):
    (tmp_path / "cam.toml").write_text("[camera]\npitch = 0.01\nshape = [64, 64]\nr1 = 0.07\n"
                                       "z1 = 20.0\nz2 = 3.0\nR = 0.6\n")
    cam = Camera.load(tmp_path / "cam.toml")
    f = clfza.simulate(np.random.default_rng(0).random((24, 24)), cam, object_width=1.5).frame
    for n in ("a", "b"):
        write_array(tmp_path / f"{n}.npy", f)
    rc = main(["reconstruct", str(tmp_path / "a.npy"), str(tmp_path / "b.npy"), "--camera",
               str(tmp_path / "cam.toml"), "--backend", "numpy", "--bin", "5", "--out",
               str(tmp_path / "rec")])
    err = capsys.readouterr().err
    assert rc == 0, err
    assert err.count("--bin 5 crops the 64x64 frame to 60x60") == 1, err
    rec = json.loads((tmp_path / "rec" / "a.json").read_text())
    assert rec["preparation"] == ["bin 5x5 (cropped to 60x60 first)"]


def _points(taus, z1s, score):
    return [{"metrics": {"z1": z, "tau": t, "focus": score(z, t)}} for z in z1s for t in taus]


def test_sweep_best_at_the_edge_is_said(caplog):
    taus, z1s = [1e-3, 1e-2, 1e-1], [15.0, 20.0, 25.0]
    inside = best(_points(taus, z1s, lambda z, t: -abs(t - 1e-2) - abs(z - 20)), taus, z1s)
    assert inside["at_edge"] == [] and edge_warning(inside, taus, z1s) is None
    edge = best(_points(taus, z1s, lambda z, t: t - abs(z - 20)), taus, z1s)
    assert edge["at_edge"] == ["tau"] and edge["tau"] == 0.1
    msg = edge_warning(edge, taus, z1s)
    assert "tau = 0.1 is the largest of its grid (0.001..0.1; extend --tau)" in msg
    assert "the optimum may lie beyond it" in msg
    two = best(_points([1e-3, 1e-2], [20.0], lambda z, t: t), [1e-3, 1e-2], [20.0])
    assert two["at_edge"] == []  # two points have no inside


def test_sweep_cli_warns_at_the_edge(tmp_path, capsys, monkeypatch):
    (tmp_path / "cam.toml").write_text("[camera]\npitch = 0.01\nshape = [64, 64]\nr1 = 0.07\n"
                                       "z1 = 20.0\nz2 = 3.0\nR = 0.6\n")
    cam = Camera.load(tmp_path / "cam.toml")
    f = clfza.simulate(np.random.default_rng(0).random((24, 24)), cam, object_width=1.5).frame
    write_array(tmp_path / "a.npy", f)
    monkeypatch.setattr("clfza.cli._sweep.sweep", lambda *a, **k: [
        {"metrics": {"z1": 20.0, "tau": t, "focus": t}, "thumb": np.zeros((4, 4), np.float32)}
        for t in (1e-3, 1e-2, 1e-1)])
    rc = main(["sweep", str(tmp_path / "a.npy"), "--camera", str(tmp_path / "cam.toml"),
               "--method", "admm", "--tau", "1e-3:1e-1:3", "--backend", "numpy",
               "--out", str(tmp_path / "o")])
    err = capsys.readouterr().err
    assert rc == 0 and err.count("edge of the sweep") == 1, err
    js = json.loads(next((tmp_path / "o").glob("sweep-*/sweep.json")).read_text())
    assert js["suggested"]["at_edge"] == ["tau"]
