"""Issue 14, as classes: resource limits before work, checks before expensive work, values that
are what they claim, answers with evidence, records generated from what ran, and files other
people can read. Each class is one parametrised test over every member clfza has (every
reader, entry point, output writer), so that a new member gets the same check.
"""

from __future__ import annotations

import json
import os
import stat
import struct
import warnings
import zlib
from pathlib import Path

import numpy as np
import pytest

from clfza import Camera, Noise, simulate
from clfza.errors import ClfzaError
from clfza.io._limits import ResourceError

HUGE = 60000  # a side no machine decodes in its memory at 8 bytes a sample, x 4 copies


def _cam() -> Camera:
    return Camera(pitch=0.01, shape=(64, 64), r1=0.07, z1=20.0, z2=3.0, R=0.6)


def _chunk(kind: bytes, payload: bytes) -> bytes:
    return (struct.pack(">I", len(payload)) + kind + payload
            + struct.pack(">I", zlib.crc32(kind + payload)))


def _png_header_only(path: Path, h: int, w: int, bits: int, ctype: int) -> None:
    """A valid PNG signature and IHDR declaring h x w, with almost no image data."""
    ihdr = struct.pack(">IIBBBBB", w, h, bits, ctype, 0, 0, 0)
    path.write_bytes(b"\x89PNG\r\n\x1a\n" + _chunk(b"IHDR", ihdr)
                     + _chunk(b"IDAT", zlib.compress(b"\x00" * 64)) + _chunk(b"IEND", b""))


def _npy_header_only(path: Path, shape, dtype="<u2") -> None:
    with open(path, "wb") as fh:
        np.lib.format.write_array_header_1_0(
            fh, {"descr": dtype, "fortran_order": False, "shape": tuple(shape)})
        fh.write(b"\x00" * 64)


def _tiff_header_only(path: Path, h: int, w: int) -> None:
    """A 4x4 16-bit TIFF whose ImageLength/ImageWidth tags are rewritten to declare h x w."""
    import tifffile

    tifffile.imwrite(path, np.zeros((4, 4), np.uint16))
    with tifffile.TiffFile(path) as tf:
        tags = tf.pages[0].tags
        spots = [(tags["ImageWidth"].valueoffset, tags["ImageWidth"].dtype, w),
                 (tags["ImageLength"].valueoffset, tags["ImageLength"].dtype, h)]
    data = bytearray(path.read_bytes())
    for off, dt, v in spots:
        fmt = "<H" if int(dt) == 3 else "<I"
        struct.pack_into(fmt, data, off, v)
    path.write_bytes(bytes(data))


# ---------------------------------------------------------------------------------------
# resource limits before work: every reader and entry point, one message
# ---------------------------------------------------------------------------------------
def _read_png16_rgb(d):
    p = d / "huge16.png"
    _png_header_only(p, HUGE, HUGE, 16, 2)  # clfza's own 16-bit colour decoder
    from clfza.io import read_frame
    read_frame(p)


def _read_png8(d):
    p = d / "huge8.png"
    _png_header_only(p, HUGE, HUGE, 8, 0)
    from clfza.io import read_frame
    read_frame(p)


def _read_tiff(d):
    p = d / "huge.tif"
    _tiff_header_only(p, HUGE, HUGE)
    from clfza.io import read_frame
    read_frame(p)


def _read_npy(d):
    p = d / "huge.npy"
    _npy_header_only(p, (HUGE, HUGE))
    from clfza.io import read_frame
    read_frame(p)


def _read_npy_stack(d):
    p = d / "stack.npy"
    _npy_header_only(p, (3, HUGE, HUGE))
    from clfza.io._stream import FrameRef, read_ref
    read_ref(FrameRef(str(p), 1))


def _read_npz_stack(d):
    import zipfile

    p = d / "stack.npz"
    with zipfile.ZipFile(p, "w") as zf, zf.open("y.npy", "w") as fh:
        np.lib.format.write_array_header_1_0(
            fh, {"descr": "<u2", "fortran_order": False, "shape": (3, HUGE, HUGE)})
    from clfza.io._stream import FrameRef, read_ref
    read_ref(FrameRef(str(p), 0, "y"))


def _read_psf(d):
    p = d / "psf.npy"
    _npy_header_only(p, (HUGE, HUGE))
    from clfza.models._psf import load_psf
    load_psf(p, max_pixels=1 << 40)


def _read_psf_stack(d):
    p = d / "psfs.npy"
    _npy_header_only(p, (4, HUGE, HUGE), "<f8")
    from clfza.models._psf import load_psf_stack
    load_psf_stack(p, [1, 2, 3, 4], max_pixels=1 << 40)


def _simulate_huge_camera(d):
    cam = Camera(pitch=0.01, shape=(100000, 100000), r1=3.0, z1=20.0, z2=3.0)
    simulate(np.ones((8, 8)), cam)


def _reconstruct_cli_huge_camera(d):
    from clfza.cli import main

    camera = (d / "cam.toml").read_text()  # the test camera (written by the test)
    (d / "big.toml").write_text(camera.replace("[64, 64]", "[100000, 100000]"))
    np.save(d / "f.npy", np.ones((8, 8)))
    rc = main(["reconstruct", str(d / "f.npy"), "--camera", str(d / "big.toml"),
               "--backend", "numpy", "--out", str(d / "o")])
    assert rc == 2 and not (d / "o").exists()
    raise ResourceError("reported by the CLI (exit 2, nothing written)")


READERS = [_read_png16_rgb, _read_png8, _read_tiff, _read_npy, _read_npy_stack, _read_npz_stack,
           _read_psf, _read_psf_stack, _simulate_huge_camera, _reconstruct_cli_huge_camera]


@pytest.mark.parametrize("case", READERS, ids=[f.__name__[1:] for f in READERS])
def test_memory_is_estimated_before_decoding_or_allocating(case, tmp_path, capsys,
                                                           camera_toml):
    """Each reader and entry point refuses a declared size it cannot hold, from the header or
    the shape (the files hold ~100 bytes of data: a decode would fail later, and slower)."""
    (tmp_path / "cam.toml").write_text(camera_toml)
    with pytest.raises(ResourceError) as exc:
        case(tmp_path)
    msg = str(exc.value) + capsys.readouterr().err
    assert "more than the limit" in msg or "reported by the CLI" in msg


SMALL_ENTRY_POINTS = ["read_frame", "read_ref", "simulate", "reconstruct", "autofocus", "cli"]


@pytest.mark.parametrize("entry", SMALL_ENTRY_POINTS)
def test_memory_limit_is_configurable_with_one_message(entry, tmp_path, monkeypatch, capsys,
                                                       camera_toml):
    """CLFZA_MAX_MEMORY bounds every entry point with the same message shape."""
    import clfza
    from clfza.focus import autofocus
    from clfza.io import read_frame
    from clfza.io._stream import FrameRef, read_ref

    frame = np.random.default_rng(0).random((64, 64))
    np.save(tmp_path / "f.npy", frame)
    np.save(tmp_path / "s.npy", np.stack([frame] * 3))
    (tmp_path / "cam.toml").write_text(camera_toml)
    monkeypatch.setenv("CLFZA_MAX_MEMORY", "20K")
    calls = {
        "read_frame": lambda: read_frame(tmp_path / "f.npy"),
        "read_ref": lambda: read_ref(FrameRef(str(tmp_path / "s.npy"), 1)),
        "simulate": lambda: simulate(frame, _cam()),
        "reconstruct": lambda: clfza.reconstruct(frame, _cam(), "bp", backend="numpy"),
        "autofocus": lambda: autofocus(frame, _cam(), (10, 40)),
    }
    if entry == "cli":
        from clfza.cli import main

        assert main(["reconstruct", str(tmp_path / "f.npy"), "--camera",
                     str(tmp_path / "cam.toml"), "--backend", "numpy", "--out",
                     str(tmp_path / "o")]) == 2
        msg = capsys.readouterr().err
    else:
        with pytest.raises(ResourceError) as exc:
            calls[entry]()
        msg = str(exc.value)
    assert "of memory" in msg and "more than the limit" in msg and "CLFZA_MAX_MEMORY" in msg


def test_png16_truncation_is_found_before_inflating(tmp_path, monkeypatch):
    """A 16-bit colour PNG that declares 6000^2 in 200 bytes is refused at once (deflate
    cannot expand 1032:1), not after gigabytes and seconds of decoding: nothing is inflated."""
    import zlib

    from clfza.io import read_frame

    def no_inflate(*args, **kwargs):
        raise AssertionError("the PNG data was inflated before the size check")

    monkeypatch.setattr(zlib, "decompress", no_inflate)
    monkeypatch.setattr(zlib, "decompressobj", no_inflate)
    p = tmp_path / "t.png"
    _png_header_only(p, 6000, 6000, 16, 2)
    with pytest.raises(ClfzaError, match="truncated|more than the limit"):
        read_frame(p)


# ---------------------------------------------------------------------------------------
# checks before expensive work; whole records or nothing
# ---------------------------------------------------------------------------------------
@pytest.fixture
def work(tmp_path, camera_toml):
    (tmp_path / "cam.toml").write_text(camera_toml)
    m = simulate(np.random.default_rng(0).random((32, 32)), _cam())
    from clfza.io import write_array

    write_array(tmp_path / "good.tif", np.round(m.frame / m.frame.max() * 4000)
                .astype(np.uint16))
    return tmp_path


BAD_COMBOS = [
    (["--percentiles", "99,1"], "percentiles"),
    (["--roi", "0,0,65,10"], "roi"),
    (["--plan", "--margin", "3", "--method", "admm"], "--plan"),
    (["--psf", "good.tif", "--model", "tf", "--method", "admm"], "exact"),
    (["--bin", "two"], "--bin"),
]


@pytest.mark.parametrize("extra,word", BAD_COMBOS, ids=[c[1] for c in BAD_COMBOS])
def test_option_combinations_fail_before_any_fft_or_read(work, extra, word, monkeypatch,
                                                         capsys):
    import scipy.fft

    import clfza.io
    from clfza.cli import main

    def boom(*a, **k):
        raise AssertionError("work started before the options were validated")

    for name in ("rfft2", "irfft2", "fft2", "ifft2", "rfftn", "fftn"):
        monkeypatch.setattr(scipy.fft, name, boom)
    monkeypatch.setattr(clfza.io, "read_frame", boom)
    monkeypatch.chdir(work)
    rc = main(["reconstruct", "good.tif", "--camera", "cam.toml", "--backend", "numpy",
               "--out", "o", *extra])
    err = capsys.readouterr().err
    assert rc == 2 and word.lower() in err.lower() and "AssertionError" not in err, err
    assert not (work / "o").exists() or not any((work / "o").iterdir())


def _fail_json(monkeypatch):
    import clfza.cli._simulate
    import clfza.distributed._batch
    import clfza.distributed._sweep
    import clfza.io._outputs

    def boom(obj):
        raise OSError("disk full (injected)")

    # every module that encodes a record binds encode_json at import (reconstruct's records
    # are written by clfza.distributed's frame task)
    for module in (clfza.io._outputs, clfza.distributed._batch, clfza.cli._simulate,
                   clfza.distributed._sweep):
        monkeypatch.setattr(module, "encode_json", boom)


WRITERS = ["reconstruct", "simulate", "sweep", "write_many"]


@pytest.mark.parametrize("writer", WRITERS)
def test_no_file_under_an_output_name_unless_the_record_is_whole(writer, work, monkeypatch):
    """A failure while writing the record (here: the JSON, written last) leaves no output
    file and no temporary behind, so the corrected rerun is not blocked."""
    from clfza.cli import main

    out = work / "o"
    monkeypatch.chdir(work)
    if writer == "write_many":
        import clfza.io._outputs as o

        def bad():
            yield out / "a.npy", b"1"
            raise OSError("injected")

        out.mkdir()
        with pytest.raises(OSError):
            o.atomic_write_many(list(bad()))
        assert not list(out.iterdir())
        return
    _fail_json(monkeypatch)
    if writer == "reconstruct":
        rc = main(["reconstruct", "good.tif", "--camera", "cam.toml", "--backend", "numpy",
                   "--out", str(out)])
    elif writer == "simulate":
        rc = main(["simulate", "checkerboard", "--camera", "cam.toml", "--out", str(out)])
    else:
        from clfza.distributed._sweep import write_sweep

        out.mkdir()
        pts = [{"tau": 0.1, "z1": 20.0, "image": np.zeros((8, 8)), "thumb": np.zeros((8, 8)),
                "metrics": {"tau": 0.1, "z1": 20.0, "focus": 1.0}}]
        try:
            write_sweep(out, pts, [0.1], [20.0], {})
            rc = 0
        except OSError:
            rc = 2
        except Exception as exc:  # the contact sheet's own needs
            pytest.skip(f"sweep contact sheet unavailable here: {exc}")
    assert rc != 0
    left = [p.name for p in out.rglob("*")] if out.exists() else []
    assert not left, left


# ---------------------------------------------------------------------------------------
# values that are what they claim
# ---------------------------------------------------------------------------------------
@pytest.mark.parametrize("shape", [[64.5, 64], [64, "64"], [True, 64], [64], [64, 64, 3]])
def test_fractional_or_mistyped_shapes_are_errors(shape, tmp_path, camera_toml):
    with pytest.raises(ClfzaError, match="shape"):
        Camera(pitch=0.01, shape=shape, r1=0.07, z1=20.0, z2=3.0)
    text = camera_toml.replace("[64, 64]", json.dumps(shape))
    (tmp_path / "c.toml").write_text(text)
    with pytest.raises(ClfzaError, match="shape"):
        Camera.load(tmp_path / "c.toml")
    assert Camera(pitch=0.01, shape=(64.0, 64), r1=0.07, z1=20.0, z2=3.0).shape == (64, 64)


@pytest.mark.parametrize("key,value", [("pitch", "0.01"), ("r1", True), ("z2", None),
                                       ("mask_center", "0,0")])
def test_camera_numbers_are_numbers(key, value):
    kw = dict(pitch=0.01, shape=(64, 64), r1=0.07, z1=20.0, z2=3.0)
    kw[key] = value
    with pytest.raises(ClfzaError, match=key):
        Camera(**kw)


def test_folder_as_camera_says_folder(tmp_path):
    with pytest.raises(ClfzaError, match="is a folder"):
        Camera.load(tmp_path)


@pytest.mark.parametrize("backend", ["numpy", "opencl"])
@pytest.mark.parametrize("method", ["bp", "admm", "fista", "twist"])
def test_unknown_model_names_the_valid_models(backend, method):
    import clfza

    with pytest.raises(ClfzaError) as exc:
        clfza.reconstruct(np.zeros((64, 64)), _cam(), method, backend=backend,
                          model="exactt")
    msg = str(exc.value)
    assert "'exactt'" in msg and "exact" in msg.replace("'exactt'", "") and "tf" in msg


IGNORED = [
    (["--center", "32,32"], "--center"),
    (["--device", "cpu"], "--device"),
    (["--scaling", "minmax", "--percentiles", "1,99"], "--percentiles"),
    (["--psf-pitch", "0.01"], "--psf-pitch"),
    (["--format", "tiff-float", "--scaling", "minmax"], "--scaling"),
]


@pytest.mark.parametrize("extra,opt", IGNORED, ids=[c[1] for c in IGNORED])
def test_every_ignored_option_is_warned_and_recorded(work, extra, opt, capsys):
    from clfza.cli import main

    rc = main(["reconstruct", str(work / "good.tif"), "--camera", str(work / "cam.toml"),
               "--backend", "numpy", "--out", str(work / "o"), *extra])
    err = capsys.readouterr().err
    assert rc == 0, err
    assert f"warning: {opt} is ignored" in err or f"{opt}" in err and "ignored" in err, err
    rec = json.loads((work / "o" / "good.json").read_text())
    assert any(opt in m for m in rec["ignored_options"])


# ---------------------------------------------------------------------------------------
# answers with evidence
# ---------------------------------------------------------------------------------------
def test_autofocus_refuses_an_all_zero_measurement():
    from clfza.focus import autofocus

    with pytest.raises(ClfzaError, match="all zeros"):
        autofocus(np.zeros((64, 64)), _cam(), (10, 40))


def test_autofocus_on_noise_warns_with_evidence():
    from clfza.focus import FocusWarning, autofocus

    y = np.random.default_rng(3).normal(size=(64, 64))
    with pytest.warns(FocusWarning, match="no reliable depth"):
        fr = autofocus(y, _cam(), (10, 40))
    assert not fr.confident and fr.to_dict()["evidence"]["reason"]


def test_focus_cli_flat_curve_has_no_answer_and_next_command_keeps_crop(work, capsys):
    from argparse import Namespace

    from clfza.cli import main
    from clfza.cli._focus import next_command

    np.save(work / "noise.npy", 1000 + np.random.default_rng(1).normal(0, 5, (80, 80)))
    rc = main(["focus", str(work / "noise.npy"), "--camera", str(work / "cam.toml"),
               "--z-range", "10,40", "--crop", "64", "--out", str(work / "o")])
    out = capsys.readouterr()
    assert rc == 1 and "no reliable focus" in out.err and "best z1" not in out.out
    rec = json.loads((work / "o" / "noise-focus.json").read_text())
    assert rec["focus"]["confident"] is False
    args = Namespace(raw="a b.tif", camera="cam.toml", dark=None, flat="f.tif", bayer=None,
                     crop=(64, 64), center=(40.0, 41.5), bin="2", object_mean=0.5)
    cmd = next_command(args, 21.5)
    for part in ("--crop 64,64", "--center 40,41.5", "--bin 2", "--flat f.tif", "--z1 21.5",
                 "'a b.tif'"):
        assert part in cmd, cmd


def test_plan_keeps_a_photon_limited_12_bit_frame_and_says_why():
    """The flat verdict needs the noise model to explain the frame (an equivalence test at
    99 %); a photon-limited 12-bit frame holds a scene and is solved."""
    from skimage import data

    from clfza.reconstruction._plan import make_plan

    cam = Camera.preset("simulation").with_shape((256, 256))
    m = simulate(data.camera() / 255.0, cam, noise=Noise(photons=100, bit_depth=12, seed=1))
    plan = make_plan(m.frame.astype(np.uint16), cam, method="admm")
    assert plan.frame_state == "ok"
    frame_d = [d for d in plan.decisions if d.name == "frame"][0]
    assert "confidence" in frame_d.reason
    fb = Camera(pitch=0.01, shape=(128, 128), r1=np.sqrt(128) * 0.01 / 1.15, z1=20.0,
                z2=3.0, R=0.64 / 1.15, mask="gzp")  # tests/test_plan.py's full-band camera
    noise = np.random.default_rng(0).normal(0, 0.01, fb.shape)
    flat = make_plan(noise, fb, method="admm", kind="y")
    assert flat.frame_state == "flat"
    assert "confidence" in [d for d in flat.decisions if d.name == "frame"][0].reason


@pytest.mark.parametrize("value", [1e200, 1e300, np.finfo(np.float64).max / 4])
def test_huge_scene_values_are_a_clear_error_not_inf(value):
    scene = np.full((16, 16), value)
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # no RuntimeWarning may escape
        with pytest.raises(ClfzaError, match="overflow"):
            simulate(scene, _cam())


def test_huge_measurement_values_are_a_clear_error():
    import clfza

    with warnings.catch_warnings():
        warnings.simplefilter("error")
        with pytest.raises(ClfzaError, match="overflow"):
            clfza.reconstruct(np.full((64, 64), 1e200), _cam(), "bp", backend="numpy")


# ---------------------------------------------------------------------------------------
# records generated from what ran
# ---------------------------------------------------------------------------------------
@pytest.mark.parametrize("noise", [Noise(gaussian_var=0.01), Noise(photons=500),
                                   Noise(photons=500, bit_depth=12, gaussian_var=0.01),
                                   Noise(gaussian_var=0.01, bit_depth=16)])
def test_simulated_frame_carries_every_noise_term(noise):
    m = simulate(np.random.default_rng(0).random((32, 32)), _cam(), noise=noise)
    assert np.allclose(m.frame_to_y(m.frame), m.y)
    if noise.gaussian_var:
        assert np.var(m.y - m.clean_y) > 0.5 * noise.gaussian_var


def test_simulate_cli_writes_the_noisy_frame(work):
    from clfza.cli import main

    rc = main(["simulate", "checkerboard", "--camera", str(work / "cam.toml"), "--noise",
               "0.01", "--format", "npy", "--out", str(work / "s")])
    assert rc == 0
    rec = json.loads((work / "s" / "checkerboard.json").read_text())
    frame = np.load(work / "s" / "checkerboard-raw.npy")
    clean = simulate(__import__("skimage.data", fromlist=["x"]).checkerboard(), _cam())
    y = (frame - frame.mean()) * rec["frame_scale"]
    assert np.var(y - clean.clean_y) == pytest.approx(0.01, rel=0.2)


def test_plan_record_and_explain_describe_what_ran(tmp_path, capsys):
    """The JSON's bin and iterations and --explain's iteration count come from the run."""
    from clfza.cli import main
    from clfza.io import write_array

    n, p = 240, 0.005
    r1p = np.sqrt(3 * n) * p
    (tmp_path / "bl.toml").write_text(
        f"[camera]\npitch = {p}\nshape = [{n}, {n}]\nr1 = {r1p / 1.15}\nz1 = 20.0\n"
        f"z2 = 3.0\nR = {0.95 * n * p / 2 / 1.15}\nmask = \"gzp\"\n")
    cam = Camera.load(tmp_path / "bl.toml")
    m = simulate(np.random.default_rng(0).random((60, 60)), cam,
                 noise=Noise(gaussian_var=1e-4))
    write_array(tmp_path / "f.npy", m.frame)
    rc = main(["reconstruct", str(tmp_path / "f.npy"), "--camera", str(tmp_path / "bl.toml"),
               "--backend", "numpy", "--method", "fista", "--iters", "7", "--plan",
               "--explain", "--out", str(tmp_path / "o")])
    out = capsys.readouterr().out
    assert rc == 0
    rec = json.loads((tmp_path / "o" / "f.json").read_text())
    assert rec["bin"] == rec["parameters"]["plan"]["bin"] == 3 and rec["bin_plan"] == 3
    assert rec["solve_shape"] == [80, 80]
    assert rec["iterations"] <= 7 and rec["stop_rule_fired"]
    assert "7 iterations" in out and "200 iterations" not in out
    assert f"ran: {rec['iterations']} iteration(s) on 80x80 (bin 3" in out


# ---------------------------------------------------------------------------------------
# files other people can read
# ---------------------------------------------------------------------------------------
def _writers(d: Path):
    from clfza.io import write_array, write_image
    from clfza.io._outputs import atomic_write_many, write_json
    from clfza.io._stream import write_stack

    img = np.random.default_rng(0).random((16, 16))
    yield "write_image", lambda: [write_image(d / "a.png", img)[0]]
    yield "write_array", lambda: [write_array(d / "b.npy", img)]
    yield "write_json", lambda: [write_json(d / "c.json", {"a": 1})]
    yield "write_many", lambda: atomic_write_many([(d / "d1", b"1"), (d / "d2", b"2")])
    yield "write_stack", lambda: [write_stack(d / "e.tif", [img, img])]


@pytest.mark.parametrize("mask", [0o022, 0o027, 0o002])
def test_outputs_respect_the_umask(tmp_path, mask):
    old = os.umask(mask)
    try:
        for name, write in _writers(tmp_path):
            for path in write():
                mode = stat.S_IMODE(os.stat(path).st_mode)
                assert mode == 0o666 & ~mask, (name, oct(mode))
    finally:
        os.umask(old)
