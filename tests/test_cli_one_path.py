"""One ``clfza reconstruct`` path (issue 32, item 4): a single frame is a batch of one, every
input goes through :func:`clfza.distributed.reconstruct_many`, and every option works on
every kind of input. Also the names with one meaning (``--center`` / ``--object-offset``,
``kind``) and ``images, infos = reconstruct_many(...)``.

The commands run in this process (``clfza.cli.main``) on 64 x 64 frames with the numpy
backend, to stay fast.
"""

from __future__ import annotations

import json
import pickle
from pathlib import Path

import numpy as np
import pytest

import clfza
from clfza import Camera, ClfzaError
from clfza.cli import main
from clfza.distributed import KINDS, BatchResult, Job, reconstruct_many
from clfza.io import write_array
from clfza.models import load_psf
from clfza.models._exact import shadow_kernel

NAMES = ("f0", "f1", "f2")


pytestmark = pytest.mark.usefixtures("cli_logging")


@pytest.fixture(scope="module")
def work(tmp_path_factory) -> Path:
    """cam.toml (the 64 x 64 test camera, with an aperture), a folder of 3 simulated 12-bit
    frames, and the camera's own shadow as a "measured" PSF."""
    d = tmp_path_factory.mktemp("one_path")
    (d / "cam.toml").write_text("[camera]\npitch = 0.01\nshape = [64, 64]\nr1 = 0.07\n"
                                "z1 = 20.0\nz2 = 3.0\nR = 0.6\n")
    cam = Camera.load(d / "cam.toml")
    rng = np.random.default_rng(7)
    (d / "frames").mkdir()
    for name in NAMES:
        f = clfza.simulate(rng.random((24, 24)), cam, object_width=1.5).frame
        write_array(d / "frames" / f"{name}.tif", np.round(f / f.max() * 4000).astype(np.uint16))
    np.save(d / "psf.npy", shadow_kernel(cam))
    return d


def _run(work: Path, out: str, *extra: str, inputs: tuple[str, ...] = ("frames",)) -> int:
    return main(["reconstruct", *(str(work / i) for i in inputs), "--camera",
                 str(work / "cam.toml"), "--backend", "numpy", "--out", str(work / out),
                 *extra])


def _records(d: Path) -> list[dict]:
    """The JSON record of each frame of the folder; each frame has its image and NPY."""
    recs = []
    for name in NAMES:
        assert (d / f"{name}.png").is_file() and (d / f"{name}.npy").is_file(), name
        recs.append(json.loads((d / f"{name}.json").read_text()))
    return recs


# ----------------------------------------------------------------------------------------
# every option on a folder
# ----------------------------------------------------------------------------------------
def test_folder_with_measured_psf(work, capsys):
    rc = _run(work, "psf", "--method", "admm", "--iters", "10", "--tau", "1e-3", "--psf",
              str(work / "psf.npy"), "--roi", "8,8,48,48", "--orient", "upright")
    assert rc == 0, capsys.readouterr().err
    for rec in _records(work / "psf"):
        assert rec["psf"]["file"] == str(work / "psf.npy")
        assert rec["parameters"]["model"] == "exact"
        assert rec["output_geometry"] == {"orient": "upright", "roi": [8, 8, 48, 48]}
        assert np.load(rec["outputs"]["npy"]).shape == (48, 48)
    summary = json.loads((work / "psf" / "batch-001.json").read_text())
    assert summary["frames"] == summary["succeeded"] == 3


def test_folder_with_plan_and_explain(work, capsys):
    rc = _run(work, "plan", "--method", "fista", "--iters", "5", "--plan", "--explain")
    text = capsys.readouterr()
    assert rc == 0, text.err
    for name, rec in zip(NAMES, _records(work / "plan"), strict=True):
        assert rec["parameters"]["plan"]["bin"] == rec["bin_plan"]
        assert rec["iterations"] <= 5 and rec["stop_rule_fired"]
        assert f"plan for '{work / 'frames' / name}.tif'" in text.out
    assert text.out.count("  ran: ") == 3


def test_folder_with_exact_model_margin_and_solver_options(work, capsys):
    rc = _run(work, "exact", "--method", "admm", "--iters", "8", "--model", "exact",
              "--margin", "4", "--opt", "nonneg=true", "--format", "tiff-float")
    assert rc == 0, capsys.readouterr().err
    for name in NAMES:
        rec = json.loads((work / "exact" / f"{name}.json").read_text())
        assert rec["parameters"]["model"] == "exact" and rec["parameters"]["nonneg"] is True
        assert rec["parameters"]["margin"] == 4
        assert rec["outputs"]["image"].endswith(f"{name}.tif")
        assert rec["scaling"]["mode"] == "none"


def test_single_file_equals_the_same_file_in_a_folder(work, capsys):
    assert _run(work, "one", "--method", "admm", "--iters", "6",
                inputs=("frames/f1.tif",)) == 0
    single = capsys.readouterr().out
    assert single.startswith("wrote ") and not (work / "one" / "batch-001.json").exists()
    assert _run(work, "many", "--method", "admm", "--iters", "6") == 0
    np.testing.assert_array_equal(np.load(work / "one" / "f1.npy"),
                                  np.load(work / "many" / "f1.npy"))
    a = json.loads((work / "one" / "f1.json").read_text())
    b = json.loads((work / "many" / "f1.json").read_text())
    assert set(a) == set(b)  # one record, whatever the input
    assert a["input"] == b["input"] == str(work / "frames" / "f1.tif")
    assert a["camera_file"] == str(work / "cam.toml")


def test_existing_outputs_are_refused_before_any_solve(work, capsys, monkeypatch):
    import clfza.distributed._batch as batch

    assert _run(work, "again", inputs=("frames/f0.tif",)) == 0
    capsys.readouterr()

    def no_solve(*a, **k):
        raise AssertionError("solved although the outputs exist")

    monkeypatch.setattr(batch, "reconstruct", no_solve)
    assert _run(work, "again", inputs=("frames/f0.tif",)) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "exists" in err[0] and "--force" in err[0]


def test_debug_raises_a_batch_frames_error(work, tmp_path, capsys):
    (tmp_path / "bad.npy").write_bytes(b"not an array")
    argv = ["reconstruct", str(work / "frames" / "f0.tif"), str(tmp_path / "bad.npy"),
            "--camera", str(work / "cam.toml"), "--backend", "numpy", "--out",
            str(tmp_path / "o")]
    assert main(argv) == 1  # without --debug: named, and the other frame is done
    assert "bad.npy" in capsys.readouterr().err
    with pytest.raises(ClfzaError, match="bad.npy"):
        main(["--debug", *argv[:-1], str(tmp_path / "o2")])


# ----------------------------------------------------------------------------------------
# the library side: images, infos; the job travels; one vocabulary for kind
# ----------------------------------------------------------------------------------------
def test_images_infos_unpack(work, tmp_path):
    cam = Camera.load(work / "cam.toml")
    files = [work / "frames" / f"{n}.tif" for n in NAMES] + [tmp_path / "missing.tif"]
    images, infos = reconstruct_many(files, cam, "bp", backend="numpy")
    assert len(images) == len(infos) == 4
    for img, info, name in zip(images[:3], infos[:3], NAMES, strict=True):
        assert img.shape == (64, 64) and info["name"] == name and info["method"] == "bp"
    assert images[3] is None and "does not exist" in infos[3]["error"]
    # written to disk only: no images kept, the records name the files
    res = reconstruct_many(files[:2], cam, "bp", backend="numpy", out_dir=tmp_path / "o")
    assert isinstance(res, BatchResult)
    images, infos = res
    assert images == [None, None]
    np.testing.assert_array_equal(np.load(infos[0]["outputs"]["npy"]),
                                  reconstruct_many(files[:1], cam, "bp",
                                                   backend="numpy").images[0])
    # resume: the skipped frames' records come from disk, their images are not read back
    images, infos = reconstruct_many(files[:2], cam, "bp", backend="numpy",
                                     out_dir=tmp_path / "o", resume=True)
    assert images == [None, None] and [i["name"] for i in infos] == ["f0", "f1"]


def test_kind_vocabulary_and_raise_errors(work):
    cam = Camera.load(work / "cam.toml")
    assert KINDS == ("frame", "y")
    with pytest.raises(ClfzaError, match="'frame'"):
        reconstruct_many(work / "frames", cam, kind="raw", backend="numpy")
    with pytest.raises(ClfzaError, match="does not exist"):
        reconstruct_many([work / "nope.tif"], cam, backend="numpy", raise_errors=True)


def test_job_with_psf_pickles(work):
    """Dask pickles the job by module path; the PSF's array travels inside it."""
    cam = Camera.load(work / "cam.toml")
    psf = load_psf(work / "psf.npy", psf_pitch=cam.pitch, frame_pitch=cam.pitch,
                   center="centroid")
    job = Job(cam, "admm", {"iters": 3}, "numpy", psf=psf, roi=(0, 0, 8, 8))
    back = pickle.loads(pickle.dumps(job))
    np.testing.assert_array_equal(back.psf.array, psf.array)
    assert back.psf.info == psf.info and back.roi == job.roi and back.camera == cam


def test_psf_on_another_pitch_is_refused(work, capsys):
    """A PSF is loaded once for the pitch every prepared frame has (here --bin 2)."""
    rc = _run(work, "bin2", "--method", "admm", "--iters", "4", "--psf",
              str(work / "psf.npy"), "--bin", "2")
    assert rc == 0, capsys.readouterr().err
    rec = json.loads((work / "bin2" / "f0.json").read_text())
    assert rec["camera"]["shape"] == [32, 32] and rec["psf"]["resample_factor"] == 0.5
    cam = Camera.load(work / "cam.toml")
    psf = load_psf(work / "psf.npy", psf_pitch=cam.pitch, frame_pitch=cam.pitch)
    res = reconstruct_many(work / "frames", cam, "admm", backend="numpy", psf=psf,
                           prep=clfza.distributed.FramePrep(bin="2"), iters=4)
    assert not any(r.ok for r in res.results)
    assert "pitch" in res.results[0].error


# ----------------------------------------------------------------------------------------
# simulate --object-offset Y,X (mm), reconstruct --center Y,X (pixels)
# ----------------------------------------------------------------------------------------
@pytest.mark.parametrize("offset", [(0.3, 0.0), (0.0, -0.2)])
def test_simulate_object_offset_is_rows_then_columns(work, tmp_path, offset, capsys):
    cam = Camera.load(work / "cam.toml")
    rc = main(["simulate", "checkerboard", "--camera", str(work / "cam.toml"), "--out",
               str(tmp_path), "--object-width", "2", "--object-offset",
               f"{offset[0]},{offset[1]}", "--format", "npy"])
    assert rc == 0, capsys.readouterr().err
    from clfza.cli._simulate import load_scene

    scene, _ = load_scene("checkerboard")
    want = clfza.simulate(scene, cam, object_width=2.0, center=(offset[1], offset[0]))
    np.testing.assert_allclose(np.load(tmp_path / "truth" / "checkerboard-truth.npy"), want.truth)
    with pytest.raises(SystemExit):  # one name per meaning: --center is reconstruct's crop
        main(["simulate", "checkerboard", "--camera", str(work / "cam.toml"), "--center",
              "0,0"])


def test_z1_with_a_measured_psf_is_refused(work, capsys):
    """--z1 cannot move a measured PSF's depth: one line before any frame is read."""
    rc = _run(work, "z1psf", "--method", "admm", "--psf", str(work / "psf.npy"), "--z1", "30")
    err = capsys.readouterr().err
    assert rc == 2 and "--z1 does nothing with --psf" in err and err.count("\n") == 1, err
    assert not (work / "z1psf").exists()


def test_observations_given_as_raw_frames_are_named():
    """DC-free observations passed to reconstruct_many without kind='y' are named as such,
    not reported as a float32 overflow after the raw-frame preparation."""
    cam = clfza.Camera.preset("simulation").with_shape((64, 64))
    rng = np.random.default_rng(2)
    ys = np.stack([clfza.simulate(rng.random((64, 64)), cam).y for _ in range(2)])
    res = reconstruct_many(ys, cam, "admm", iters=5)
    assert all("pass kind='y'" in r.error for r in res.results)
    assert all(r.ok for r in reconstruct_many(ys, cam, "admm", kind="y", iters=5).results)
