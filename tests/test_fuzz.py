"""Fuzzed readers and options (issue 35, item 6): ``tools/fuzz_report.py`` mutates valid PNG,
TIFF, NPY, NPZ, camera TOML, GIF and MP4 files and draws ``clfza reconstruct`` / ``clfza
simulate`` option combinations; every case must end in a result or one clean error, leave no
partial output, keep its peak RSS growth under ``CLFZA_MAX_MEMORY`` and end within 30 s.

The default run has a short pass (:data:`SHORT_CASES` cases, ~30 s on two cores); the full
pass (>= 2000 cases, ~2 min on two cores) is marked ``fuzz`` and ``slow``::

    python -m pytest -q -m "fuzz and slow" tests/test_fuzz.py

Below the passes, a regression test for each bug the fuzzer found (the report lists them).
"""

from __future__ import annotations

import importlib.util
import io
import json
import os
import struct
import sys
import zipfile
from pathlib import Path

import numpy as np
import pytest

from clfza import Camera, ClfzaError
from clfza.cli import main
from clfza.io import PIXELS_ENV, expand_frames, frame_shapes, gif_header, read_ref

pytestmark = [pytest.mark.fuzz, pytest.mark.usefixtures("cli_logging")]

SHORT_CASES = int(os.environ.get("CLFZA_FUZZ_SHORT", "240"))
FULL_CASES = int(os.environ.get("CLFZA_FUZZ_CASES", "2400"))


@pytest.fixture(scope="module")
def fuzz():
    path = Path(__file__).resolve().parents[1] / "tools" / "fuzz_report.py"
    spec = importlib.util.spec_from_file_location("clfza_tools_fuzz_report", path)
    mod = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = mod
    spec.loader.exec_module(mod)
    return mod


def _failures(fuzz, res) -> str:
    return "\n".join(f"case {r.index} ({r.gen}) {r.outcome}: {r.desc[:120]} | {r.action[:200]} "
                     f"| {r.message[:400]}" for r in fuzz.bugs(res))


def _check_pass(fuzz, res, cases: int) -> None:
    assert not fuzz.bugs(res), (f"failing fuzz cases (rerun one with `python "
                                f"tools/fuzz_report.py --cases {cases} --seed "
                                f"{res['config']['seed']} --case N`):\n" + _failures(fuzz, res))
    s = fuzz.summarise(res)
    assert s["cases"] == cases
    assert set(s["generators"]) == set(fuzz.GENERATORS)  # every generator drew cases
    assert s["max_rss_growth_mib"] * 2**20 <= fuzz.MEMORY_BYTES
    # a case past fuzz.TIMEOUT_S is killed and counted a bug ("bug:hang") above


def test_fuzz_short_pass(fuzz, tmp_path):
    """A short pass in the default run (its own seed: not a part of the full pass)."""
    res = fuzz.run(SHORT_CASES, seed=135, workers=2, work=tmp_path)
    _check_pass(fuzz, res, SHORT_CASES)


@pytest.mark.slow
def test_fuzz_full_pass(fuzz, tmp_path):
    """The full pass: >= 2000 cases (``CLFZA_FUZZ_CASES``), its report in ``tmp_path``
    (``python tools/fuzz_report.py`` writes the committed one to ``bench/results``)."""
    assert FULL_CASES >= 2000 or "CLFZA_FUZZ_CASES" in os.environ
    res = fuzz.run(FULL_CASES, seed=35, workers=2, work=tmp_path / "cases")
    js, md = fuzz.write_report(res, tmp_path, "ci")
    assert json.loads(js.read_text())["bugs"] == 0 and md.exists()
    _check_pass(fuzz, res, FULL_CASES)


def test_generators_are_reproducible(fuzz):
    """A case is drawn from the run's seed and its number alone (``--case N`` reruns it)."""
    sched = fuzz.schedule(300, 7)
    for i in (0, 17, 123, 299):
        a, b = fuzz.make_case(i, sched[i], 7), fuzz.make_case(i, sched[i], 7)
        assert (a.gen, a.desc, a.files, a.action) == (b.gen, b.desc, b.files, b.action)
    counts = {g: sched.count(g) for g in fuzz.GENERATORS}
    assert sum(counts.values()) == 300 and min(counts.values()) > 0


def test_output_check_finds_partial_outputs(fuzz, tmp_path):
    """The checker the passes rely on: a temporary file, an image no record names and a
    record naming a missing file are each found; a whole record passes."""
    (tmp_path / "out").mkdir()
    before = fuzz._snapshot(tmp_path)
    rec = {"clfza_version": "x", "outputs": {"image": "out/a.png", "npy": "out/a.npy",
                                             "json": "out/a.json"}}
    for name in ("a.png", "a.npy"):
        (tmp_path / "out" / name).write_bytes(b"x")
    (tmp_path / "out" / "a.json").write_text(json.dumps(rec))
    assert fuzz.check_outputs(tmp_path, before) is None
    (tmp_path / "out" / "b.png").write_bytes(b"x")
    assert fuzz.check_outputs(tmp_path, before)[0] == "bug:partial-output"
    (tmp_path / "out" / "b.png").unlink()
    (tmp_path / "out" / ".a.png.x1.tmp").write_bytes(b"x")
    assert fuzz.check_outputs(tmp_path, before)[0] == "bug:partial-output"
    (tmp_path / "out" / ".a.png.x1.tmp").unlink()
    (tmp_path / "out" / "a.npy").unlink()
    assert fuzz.check_outputs(tmp_path, before)[0] == "bug:missing-output"


# ------------------------------------------------------------------------------------------
# regression tests: the bugs the fuzzer found
# ------------------------------------------------------------------------------------------
CAMERA = "pitch = 0.01\nshape = [64, 64]\nr1 = 0.07\nz1 = 20.0\nz2 = 3.0\nR = 0.6\n"


@pytest.mark.parametrize("nest", ["deep = " + "[" * 5000 + "]" * 5000,
                                  "deep = " + "{a = " * 5000 + "1" + "}" * 5000])
def test_toml_nested_too_deeply(tmp_path, nest):
    """tomllib recurses per nesting level: RecursionError was no ClfzaError."""
    p = tmp_path / "cam.toml"
    p.write_text("[camera]\n" + CAMERA + nest + "\n")
    with pytest.raises(ClfzaError, match="nested too deeply"):
        Camera.load(p)


@pytest.mark.parametrize("text, what", [("[[camera]]\n" + CAMERA, "an array of tables"),
                                        ("camera = 3\n", "the value 3")])
def test_toml_camera_not_a_table(tmp_path, text, what):
    """``[[camera]]`` (an array of tables) raised AttributeError ('list' has no setdefault)."""
    p = tmp_path / "cam.toml"
    p.write_text(text)
    with pytest.raises(ClfzaError, match=f"must be one \\[camera\\] table, got {what}"):
        Camera.load(p)
    with pytest.raises(ClfzaError, match="must be a table"):
        Camera.from_dict({"camera": [{"pitch": 0.01}]})


@pytest.mark.parametrize("key, value", [("z1", "1e-300"), ("pitch", "1e-300"), ("r1", "1e300"),
                                        ("z2", "1e300"), ("R", "1e300"),
                                        ("r1_shadow", "1e-300")])
def test_camera_lengths_outside_float_range(tmp_path, capsys, key, value):
    """Lengths whose squares overflow (or vanish) raised OverflowError/ZeroDivisionError in
    the simulation and the measurement's gain ("unexpected", exit 1)."""
    lines = [ln for ln in CAMERA.splitlines() if not ln.startswith(f"{key} ")]
    p = tmp_path / "cam.toml"
    p.write_text("[camera]\n" + "\n".join(lines) + f"\n{key} = {value}\n")
    with pytest.raises(ClfzaError, match="outside the lengths clfza computes with"):
        Camera.load(p)
    assert main(["simulate", "checkerboard", "--camera", str(p), "--out",
                 str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err
    assert "outside the lengths" in err and "unexpected" not in err
    assert not (tmp_path / "o").exists()


def test_cli_z1_outside_float_range(tmp_path, capsys):
    """``--z1 1e-300`` moved a plausible camera to a shadow constant that overflows."""
    p = tmp_path / "cam.toml"
    p.write_text("[camera]\n" + CAMERA)
    frame = tmp_path / "f.npy"
    np.save(frame, np.random.default_rng(0).random((64, 64)) + 1.0)
    for argv in (["simulate", "checkerboard"], ["reconstruct", str(frame), "--method", "bp"]):
        assert main([*argv, "--camera", str(p), "--z1", "1e-300", "--out",
                     str(tmp_path / "o")]) == 2
        err = capsys.readouterr().err
        assert "--z1 1e-300: z1 = 1e-300 mm is outside" in err and "unexpected" not in err
    assert not (tmp_path / "o").exists()


def _npy_bytes(header: str, body: bytes = b"") -> bytes:
    text = header.encode("latin1")
    text += b" " * ((-(10 + len(text) + 1)) % 64) + b"\n"
    return b"\x93NUMPY\x01\x00" + struct.pack("<H", len(text)) + text + body


def _npz(path: Path, members: dict[str, bytes], method=zipfile.ZIP_STORED) -> Path:
    with zipfile.ZipFile(path, "w", method) as zf:
        for name, data in members.items():
            zf.writestr(name, data)
    return path


def test_npz_member_header_unparsable(tmp_path):
    """A member header numpy's tokenizer gives up on raised tokenize.TokenError."""
    p = _npz(tmp_path / "a.npz", {"a.npy": _npy_bytes("{'descr': '<f8',")})
    with pytest.raises(ClfzaError, match="archive is corrupt"):
        expand_frames([p])


def test_npz_member_deflate_corrupt(tmp_path):
    """A member whose deflate stream is corrupt raised zlib.error while its header was read."""
    buf = io.BytesIO()
    np.save(buf, np.zeros((8, 8)))
    p = _npz(tmp_path / "a.npz", {"a.npy": buf.getvalue()}, zipfile.ZIP_DEFLATED)
    data = bytearray(p.read_bytes())
    start = 30 + len("a.npy")  # the local header, then the deflate stream
    data[start:start + 6] = b"\xff" * 6
    p.write_bytes(bytes(data))
    with pytest.raises(ClfzaError, match="archive is corrupt"):
        expand_frames([p])


def test_npz_member_claiming_a_billion_frames(tmp_path, monkeypatch):
    """A 100-byte member claiming (1e9, 8, 8) made a billion frame references (a hang, then
    out of memory) before any read: now one reference, whose read names the limit."""
    monkeypatch.setenv(PIXELS_ENV, "4M")
    head = "{'descr': '|u1', 'fortran_order': False, 'shape': (1000000000, 8, 8), }"
    p = _npz(tmp_path / "a.npz", {"a.npy": _npy_bytes(head, bytes(64))})
    refs, _ = expand_frames([p])
    assert len(refs) == 1
    with pytest.raises(ClfzaError, match="1000000000 x 8x8"):
        read_ref(refs[0])
    # a member that declares more data than it holds: one reference too
    head = "{'descr': '<f8', 'fortran_order': False, 'shape': (100000, 4, 4), }"
    p = _npz(tmp_path / "b.npz", {"b.npy": _npy_bytes(head, bytes(64))})
    refs, _ = expand_frames([p])
    assert len(refs) == 1
    with pytest.raises(ClfzaError):
        read_ref(refs[0])


def test_npy_stack_of_frames_too_small(tmp_path):
    """A 4 MB ``(1000000, 2, 2)`` array made a million references (8 s, 400 MB), each to a
    frame too small to read: now one, whose read names the shape."""
    p = tmp_path / "s.npy"
    np.save(p, np.zeros((1000000, 2, 2), np.uint8))
    refs, _ = expand_frames([p])
    assert len(refs) == 1
    with pytest.raises(ClfzaError, match="grey \\(H, W\\) or RGB"):
        read_ref(refs[0])


def test_frame_shapes_reads_an_archive_once(tmp_path, monkeypatch):
    """frame_shapes read every member header of an archive once per member (quadratic:
    30 s for 566 members, before any frame was solved)."""
    import clfza.io._stream as stream

    buf = io.BytesIO()
    np.save(buf, np.zeros((8, 8), np.uint8))
    p = _npz(tmp_path / "m.npz", {f"m{i}.npy": buf.getvalue() for i in range(300)})
    refs, _ = expand_frames([p])
    calls = []
    real = stream.npy_header
    monkeypatch.setattr(stream, "npy_header", lambda *a: calls.append(1) or real(*a))
    shapes = frame_shapes(refs)
    assert len(shapes) == 300 and set(shapes) == {(8, 8)}
    assert len(calls) <= 300


def _gif_with_frame_at(path: Path, left: int, top: int) -> Path:
    import imageio.v3 as iio

    data = bytearray(iio.imwrite("<bytes>", np.arange(64, dtype=np.uint8).reshape(8, 8),
                                 extension=".gif"))
    flags = data[10]
    pos = 13 + (3 << ((flags & 7) + 1) if flags & 0x80 else 0)  # after the colour table
    while data[pos] == 0x21:  # extensions: label, sub-blocks
        pos += 2
        while data[pos]:
            pos += data[pos] + 1
        pos += 1
    assert data[pos] == 0x2C  # the image descriptor: left, top, width, height
    data[pos + 1:pos + 5] = struct.pack("<HH", left, top)
    path.write_bytes(bytes(data))
    return path


def test_gif_frame_far_outside_its_screen(tmp_path, monkeypatch):
    """A 100-byte GIF whose frame sits at (65535, 1999) made Pillow build a 131-Mpixel canvas
    (500 MB) under CLFZA_MAX_PIXELS=4M (Pillow's own limit is 179 Mpixel): the canvas is now
    read from the headers and refused before anything is decoded."""
    monkeypatch.setenv(PIXELS_ENV, "4M")
    p = _gif_with_frame_at(tmp_path / "a.gif", 65535, 1999)
    assert gif_header(p) == (1, (1999 + 8, 65535 + 8))
    refs, _ = expand_frames([p])
    assert len(refs) == 1
    with pytest.raises(ClfzaError, match=f"{PIXELS_ENV}=4M"):
        read_ref(refs[0])
    ok = _gif_with_frame_at(tmp_path / "b.gif", 2, 3)  # a small shift is read as before
    assert gif_header(ok) == (1, (11, 10))
    frame, _ = read_ref(expand_frames([ok])[0][0])
    assert frame.shape[:2] == (11, 10)
