"""Every check before the first frame is solved (issue 35, item 1): ``--stack-out`` against
the frames' channels (from headers only), its suffix and an existing target; ``--out`` and the
stacks' folders and permissions; the outputs' disk space (estimated); errors under ``-q``;
Ctrl-C said once, leaving only complete outputs.

Runs in this process (``clfza.cli.main``) on 64 x 64 frames with the numpy backend.
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
import pytest
import tifffile

import clfza
import clfza.distributed._batch as batch_mod
from clfza import Camera
from clfza.cli import _preflight, main
from clfza.io import FrameRef, frame_channels, frame_shapes, write_array

pytestmark = pytest.mark.usefixtures("cli_logging")

CAM = "[camera]\npitch = 0.01\nshape = [64, 64]\nr1 = 0.07\nz1 = 20.0\nz2 = 3.0\nR = 0.6\n"


@pytest.fixture
def work(tmp_path) -> Path:
    """cam.toml; frames/g0.tif, g1.tif (grey) and c0.tif (RGB), 12-bit."""
    (tmp_path / "cam.toml").write_text(CAM)
    cam = Camera.load(tmp_path / "cam.toml")
    rng = np.random.default_rng(3)
    d = tmp_path / "frames"
    d.mkdir()
    for name in ("g0", "g1"):
        f = clfza.simulate(rng.random((24, 24)), cam, object_width=1.5).frame
        write_array(d / f"{name}.tif", np.round(f / f.max() * 4000).astype(np.uint16))
    f = clfza.simulate(rng.random((24, 24, 3)), cam, object_width=1.5).frame
    write_array(d / "c0.tif", np.round(f / f.max() * 4000).astype(np.uint16))
    return tmp_path


def _reconstruct(work: Path, *extra: str, inputs=("frames",)) -> int:
    return main(["reconstruct", *(str(work / i) for i in inputs), "--camera",
                 str(work / "cam.toml"), "--backend", "numpy", "--out", str(work / "rec"),
                 *extra])


@pytest.fixture
def no_solve(monkeypatch):
    """Fail the test if any frame reaches the solver."""
    calls = []

    def solve(*a, **k):
        calls.append(1)
        raise AssertionError("a frame was solved before the checks failed")

    monkeypatch.setattr(batch_mod, "_solve", solve)
    return calls


def test_frame_shapes_from_headers(work, tmp_path):
    d = work / "frames"
    np.save(tmp_path / "stack.npy", np.zeros((5, 16, 16, 3), np.uint16))
    tifffile.imwrite(tmp_path / "planar.tif", np.zeros((3, 16, 16), np.uint16),
                     photometric="rgb", planarconfig="separate")
    refs = [FrameRef(str(d / "g0.tif")), FrameRef(str(d / "c0.tif")),
            FrameRef(str(tmp_path / "stack.npy"), 2), FrameRef(str(tmp_path / "planar.tif")),
            FrameRef(str(tmp_path / "missing.png"))]
    shapes = frame_shapes(refs)
    assert shapes == [(64, 64), (64, 64, 3), (16, 16, 3), (16, 16, 3), None]
    assert [frame_channels(s) for s in shapes] == [1, 3, 3, 3, None]


def test_stack_of_grey_and_rgb_refused_before_any_solve(work, capsys, no_solve):
    rc = _reconstruct(work, "--stack-out", str(work / "all.tif"), "-q")
    err = capsys.readouterr().err
    assert rc == 2 and not no_solve
    assert err.count("clfza: error:") == 1 and "mix grey and colour" in err
    assert "2 grey" in err and "1 RGB" in err and "c0.tif" in err
    assert not (work / "rec").exists() or not any((work / "rec").iterdir())


@pytest.mark.parametrize("target, words", [("all.png", "use .tif, .gif or .mp4"),
                                           ("exists.tif", "exists; pass --force")])
def test_stack_target_checked_before_any_solve(work, capsys, no_solve, target, words):
    (work / "exists.tif").write_bytes(b"x")
    rc = _reconstruct(work, "--stack-out", str(work / target), "-q",
                      inputs=("frames/g0.tif", "frames/g1.tif"))
    err = capsys.readouterr().err
    assert rc == 2 and not no_solve and words in err, err


def test_grey_stack_written(work, capsys):
    rc = _reconstruct(work, "--stack-out", str(work / "grey.tif"), "-q",
                      inputs=("frames/g0.tif", "frames/g1.tif"))
    assert rc == 0, capsys.readouterr().err
    assert tifffile.imread(work / "grey.tif").shape == (2, 64, 64)


@pytest.mark.skipif(os.geteuid() == 0, reason="root writes anywhere")
def test_unwritable_out_refused_before_any_solve(work, capsys, no_solve):
    ro = work / "ro"
    ro.mkdir()
    ro.chmod(0o500)
    try:
        rc = main(["reconstruct", str(work / "frames" / "g0.tif"), "--camera",
                   str(work / "cam.toml"), "--backend", "numpy", "--out", str(ro / "sub"),
                   "-q"])
    finally:
        ro.chmod(0o700)
    err = capsys.readouterr().err
    assert rc == 2 and not no_solve and "no permission to write" in err, err


def test_out_under_a_file_refused(work, capsys, no_solve):
    (work / "afile").write_text("x")
    rc = main(["reconstruct", str(work / "frames" / "g0.tif"), "--camera",
               str(work / "cam.toml"), "--backend", "numpy", "--out",
               str(work / "afile" / "sub"), "-q"])
    err = capsys.readouterr().err
    assert rc == 2 and not no_solve and "is a file" in err, err


def test_disk_space_estimated_before_any_solve(work, capsys, no_solve, monkeypatch):
    class Usage:
        free = 10_000  # bytes: less than three frames' image, NPY and JSON

    monkeypatch.setattr(_preflight.shutil, "disk_usage", lambda p: Usage())
    rc = _reconstruct(work, "-q")
    err = capsys.readouterr().err
    assert rc == 2 and not no_solve
    assert "need about" in err and "of disk" in err and "9.77 KiB free" in err, err


def test_output_bytes_estimate():
    frames, stacks = _preflight.output_bytes(2, (100, 100), [1, 3], "png", ["a.tif", "b.gif"])
    assert frames == 40_000 * 10 + 2 * _preflight.JSON_BYTES
    assert stacks == 40_000 * 2 + 40_000 * 1


def test_stack_error_printed_under_quiet(work, capsys, monkeypatch):
    """A stack that fails at the end (here: made to) is an error line even with -q."""
    def fail(*a, **k):
        raise clfza.ClfzaError("disk full")

    monkeypatch.setattr("clfza.cli._batch.write_stack", fail)
    rc = _reconstruct(work, "--stack-out", str(work / "grey.tif"), "-q",
                      inputs=("frames/g0.tif", "frames/g1.tif"))
    err = capsys.readouterr().err
    assert rc == 1 and "clfza: error: stack" in err and "disk full" in err, err


def test_ctrl_c_said_once_and_only_complete_outputs(work, capsys, monkeypatch):
    real = batch_mod._solve
    seen = []

    def solve(*a, **k):
        seen.append(1)
        if len(seen) == 2:
            raise KeyboardInterrupt
        return real(*a, **k)

    monkeypatch.setattr(batch_mod, "_solve", solve)
    rc = _reconstruct(work, "-q", inputs=("frames/g0.tif", "frames/g1.tif"))
    err = capsys.readouterr().err
    assert rc == 130 and err.count("interrupted") == 1, err
    assert sorted(p.name for p in (work / "rec").iterdir()) == ["g0.json", "g0.npy", "g0.png"]


def test_focus_without_answer_is_an_error_under_quiet(work, capsys):
    """Exit 1 with a reason shown under -q (a failure is never silent)."""
    np.save(work / "noise.npy", 1000 + np.random.default_rng(1).normal(0, 5, (80, 80)))
    rc = main(["focus", str(work / "noise.npy"), "--camera", str(work / "cam.toml"),
               "--z-range", "10,40", "--crop", "64", "--backend", "numpy", "--out",
               str(work / "o"), "-q"])
    err = capsys.readouterr().err
    assert rc == 1 and err.startswith("clfza: error: no reliable focus"), err
