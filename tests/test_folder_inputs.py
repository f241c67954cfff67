"""Inputs that cannot be confused (issue 35, item 2): ``clfza simulate`` writes its ground
truth to ``OUT/truth/``, a folder read skips clfza's own outputs (by their records, or a
simulation's ``-truth`` files beside its raw frame) and says in one log line what it took
and what it skipped.

Runs in this process (``clfza.cli.main``) on 64 x 64 frames with the numpy backend.
"""

from __future__ import annotations

import json
import logging
from pathlib import Path

import numpy as np
import pytest

from clfza.cli import main
from clfza.io import expand_frames, folder_frames

pytestmark = pytest.mark.usefixtures("cli_logging")

CAM = "[camera]\npitch = 0.01\nshape = [64, 64]\nr1 = 0.07\nz1 = 20.0\nz2 = 3.0\nR = 0.6\n"


@pytest.fixture
def cam(tmp_path) -> Path:
    p = tmp_path / "cam.toml"
    p.write_text(CAM)
    return p


def _simulate(cam: Path, out: Path, names=("f01", "f02", "f03")) -> None:
    for n in names:
        rc = main(["simulate", "checkerboard", "--camera", str(cam), "--out", str(out),
                   "--name", n, "--object-width", "2", "-q"])
        assert rc == 0


def test_simulate_writes_truth_in_a_subfolder(cam, tmp_path):
    _simulate(cam, tmp_path / "sim", ("f01",))
    sim = tmp_path / "sim"
    assert sorted(p.name for p in sim.iterdir()) == ["f01-raw.tif", "f01.json", "truth"]
    assert sorted(p.name for p in (sim / "truth").iterdir()) == ["f01-truth.npy",
                                                                "f01-truth.png"]
    rec = json.loads((sim / "f01.json").read_text())
    assert Path(rec["outputs"]["truth_npy"]).parent.name == "truth"


def test_folder_of_simulated_frames_reconstructs_only_the_frames(cam, tmp_path, caplog):
    _simulate(cam, tmp_path / "sim")
    with caplog.at_level(logging.INFO, logger="clfza"):
        rc = main(["reconstruct", str(tmp_path / "sim"), "--camera", str(cam), "--backend",
                   "numpy", "--out", str(tmp_path / "rec"), "-q"])
    assert rc == 0
    summary = json.loads((tmp_path / "rec" / "batch-001.json").read_text())
    assert summary["frames"] == 3
    assert [Path(o["input"].strip("'")).name for o in summary["outputs"]] == \
        ["f01-raw.tif", "f02-raw.tif", "f03-raw.tif"]
    lines = [r.getMessage() for r in caplog.records if "took" in r.getMessage()]
    assert len(lines) == 1 and "took 3 file(s)" in lines[0] and "skipped" not in lines[0]


def test_folder_skips_old_layout_truth_and_reconstructions(cam, tmp_path, caplog):
    """Outputs beside the frames (simulate before issue 35; reconstruct --out into the input
    folder) are skipped, named in one warning line."""
    d = tmp_path / "mixed"
    _simulate(cam, d)
    for n in ("f01", "f02", "f03"):  # the old layout: truth beside the raw frame
        for suf in ("npy", "png"):
            (d / "truth" / f"{n}-truth.{suf}").rename(d / f"{n}-truth.{suf}")
    rc = main(["reconstruct", str(d / "f01-raw.tif"), "--camera", str(cam), "--backend",
               "numpy", "--out", str(d), "-q"])
    assert rc == 0 and (d / "f01-raw.png").is_file()
    (d / "user-frame.npy").write_bytes((d / "f01-raw.npy").read_bytes())  # not recorded
    caplog.clear()
    with caplog.at_level(logging.INFO, logger="clfza"):
        taken, skipped = folder_frames(d)
    assert [f.name for f in taken] == ["f01-raw.tif", "f02-raw.tif", "f03-raw.tif",
                                       "user-frame.npy"]
    assert sorted(f.name for f, _ in skipped) == sorted(
        ["f01-raw.png", "f01-raw.npy"] + [f"{n}-truth.{s}" for n in ("f01", "f02", "f03")
                                          for s in ("npy", "png")])
    why = dict((f.name, w) for f, w in skipped)
    assert why["f01-raw.png"] == "an output of f01-raw.json"
    assert why["f02-truth.npy"] in ("an output of f02.json", "a simulation's ground truth")
    warn = [r for r in caplog.records if r.levelno == logging.WARNING]
    assert len(warn) == 1 and "took 4 file(s)" in warn[0].getMessage() \
        and "skipped 8" in warn[0].getMessage()


def test_truth_name_without_raw_frame_is_a_frame(tmp_path):
    """A user's own ``x-truth.npy`` with no simulation beside it is read as a frame."""
    np.save(tmp_path / "x-truth.npy", np.ones((8, 8)))
    refs, missing = expand_frames([tmp_path])
    assert [Path(r.path).name for r in refs] == ["x-truth.npy"] and not missing


def test_folder_of_only_outputs_says_so(cam, tmp_path):
    d = tmp_path / "sim"
    _simulate(cam, d, ("f01",))
    (d / "f01-raw.tif").unlink()
    (d / "truth" / "f01-truth.npy").rename(d / "f01-truth.npy")
    refs, missing = expand_frames([d])
    assert not refs and "only clfza's own outputs" in missing[0][1]
