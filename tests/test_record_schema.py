"""Records that read well (issue 35, item 4): every JSON record the commands write validates
against its documented schema (:data:`clfza.io.RECORD_SCHEMAS`, rendered as
``docs/records.md``); ``objective_last`` is a number, the histories have their own field and
``returned`` is always set.

The commands run in this process on 64 x 64 frames with the numpy backend.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

import clfza
from clfza import Camera
from clfza.cli import main
from clfza.io import RECORD_SCHEMAS, records_markdown, validate_record, write_array

pytestmark = pytest.mark.usefixtures("cli_logging")

ROOT = Path(__file__).resolve().parents[1]
CAM = "[camera]\npitch = 0.01\nshape = [64, 64]\nr1 = 0.07\nz1 = 20.0\nz2 = 3.0\nR = 0.6\n"


def kind_of(p: Path) -> str:
    """The record kind of a file the commands wrote, from its name."""
    if p.name.startswith("batch-"):
        return "batch"
    if p.name.endswith("-focus.json"):
        return "focus"
    if p.name == "sweep.json":
        return "sweep"
    if p.name.endswith("-camera.json"):
        return "calibrate"
    if p.parent.name == "sim":
        return "simulate"
    return "frame"


@pytest.fixture(scope="module")
def records(tmp_path_factory) -> dict[Path, dict]:
    """Every JSON record written by simulate, reconstruct (bp, fista, admm, wiener; grey and
    RGB; a batch with a stack), focus and sweep on tiny data."""
    d = tmp_path_factory.mktemp("records")
    cam_file = d / "cam.toml"
    cam_file.write_text(CAM)

    def ok(*argv) -> None:
        assert main([str(a) for a in argv]) == 0, argv

    ok("simulate", "checkerboard", "--camera", cam_file, "--out", d / "sim", "--name", "s",
       "--object-width", "2", "--noise", "photons=1e4,bits=12,seed=1", "-q")
    cam = Camera.load(cam_file)
    rgb = clfza.simulate(np.random.default_rng(2).random((24, 24, 3)), cam,
                         object_width=1.5).frame
    write_array(d / "rgb.tif", np.round(rgb / rgb.max() * 4000).astype(np.uint16))
    raw = d / "sim" / "s-raw.tif"
    common = ["--camera", cam_file, "--backend", "numpy", "-q"]
    ok("reconstruct", d / "sim", *common, "--out", d / "bp")
    for m in ("fista", "admm", "twist"):
        ok("reconstruct", raw, d / "rgb.tif", *common, "--method", m, "--iters", "3",
           "--out", d / m)
    ok("reconstruct", raw, *common, "--method", "wiener", "--out", d / "wiener")
    ok("reconstruct", raw, *common, "--method", "admm", "--model", "exact", "--iters", "3",
       "--out", d / "exact")
    ok("reconstruct", raw, raw, *common, "--stack-out", d / "stack.tif", "--out", d / "batch")
    assert main(["focus", str(raw), *map(str, common), "--z-range", "10,40", "--coarse", "9",
                 "--out", str(d / "focus")]) in (0, 1)  # a flat curve is exit 1, same record
    ok("sweep", raw, *common, "--method", "admm", "--iters", "2", "--tau", "1e-3:1e-2:3",
       "--out", d / "sweep")
    pcam = Camera(pitch=0.022, shape=(128, 128), r1=0.35, z1=250.0, z2=2.0, R=1.0, mask="fza")
    point = clfza.simulate(clfza.simulation.point_sources(pcam, [(0.0, 0.0, 1.0)]), pcam,
                           sensor_plane=True, noise=clfza.Noise(photons=20000, seed=4)).frame
    np.save(d / "pt.npy", point)
    ok("calibrate", d / "pt.npy", "--pitch", "0.022", "--z1", "250", "--z2", "2", "--out",
       d / "cal" / "pt-camera.toml", "-q")
    return {p: json.loads(p.read_text()) for p in sorted(d.rglob("*.json"))}


def test_docs_are_the_schema():
    assert (ROOT / "docs" / "records.md").read_text() == records_markdown() + "\n", \
        "regenerate docs/records.md with clfza.io.records_markdown()"


def test_every_field_is_described():
    def walk(s: dict, where: str):
        for k, v in s.get("properties", {}).items():
            assert v.get("description"), f"{where}.{k}"
            walk(v, f"{where}.{k}")

    for kind, s in RECORD_SCHEMAS.items():
        walk(s, kind)


def test_every_record_validates(records):
    kinds = {kind_of(p) for p in records}
    assert kinds == set(RECORD_SCHEMAS), kinds
    for p, rec in records.items():
        errs = validate_record(rec, kind_of(p))
        assert not errs, f"{p}: {errs}"


def test_objective_and_returned(records):
    frames = {p: r for p, r in records.items() if kind_of(p) == "frame"}
    assert len(frames) >= 10
    for p, r in frames.items():
        assert isinstance(r["returned"], dict), p
        if r["method"] == "bp":
            assert r["objective_last"] is None and r["returned"]["image"] == "direct"
            continue
        assert isinstance(r["objective_last"], float), p
        hist = r["objective_history"]
        assert isinstance(hist, list) and hist
        if r["method"] != "wiener":
            assert r["returned"]["image"] in ("last", "mean")
        if isinstance(hist[0], list):  # one history per colour channel: the sum of the ends
            assert r["objective_last"] == pytest.approx(sum(h[-1] for h in hist))
        else:
            assert r["objective_last"] == pytest.approx(hist[-1])


def test_validator_names_the_field():
    rec = {"clfza_version": "x", "date": "d", "extra": 1}
    errs = validate_record(rec, "batch")
    assert "$: undocumented field 'extra'" in errs and "$: missing field 'frames'" in errs
    frame = {"objective_last": [1.0, 2.0]}
    errs = validate_record(frame, {"type": "object", "properties": {
        "objective_last": RECORD_SCHEMAS["frame"]["properties"]["objective_last"]}})
    assert errs and errs[0].startswith("$.objective_last: expected number or null")
