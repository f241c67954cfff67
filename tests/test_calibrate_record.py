"""The calibration's record (issue 34, item 3): ``clfza calibrate`` writes FRAME-camera.json
beside the camera file, documented in :data:`clfza.io.RECORD_SCHEMAS` (``calibrate``) and
docs/records.md; it validates both when the capture determines R' and when it does not."""

from __future__ import annotations

import json

import numpy as np
import pytest

from clfza import Camera
from clfza.cli import main
from clfza.io import RECORD_SCHEMAS, validate_record
from clfza.simulation import Noise, point_sources, simulate

pytestmark = pytest.mark.usefixtures("cli_logging")


@pytest.mark.parametrize("R", [2.0, 4.0], ids=["edge-on-sensor", "past-sensor"])
def test_calibrate_record_validates(tmp_path, R):
    cam = Camera(pitch=0.022, shape=(256, 256), r1=0.5, z1=250.0, z2=2.0, R=R, mask="fza")
    frame = simulate(point_sources(cam, [(0.0, 0.0, 1.0)]), cam, sensor_plane=True,
                     noise=Noise(photons=20000, read_noise=3.0, bit_depth=12, seed=4)).frame
    np.save(tmp_path / "pt.npy", frame)
    rc = main(["calibrate", str(tmp_path / "pt.npy"), "--pitch", "0.022", "--z1", "250",
               "--z2", "2", "--out", str(tmp_path / "pt-camera.toml")])
    assert rc == 0
    rec = json.loads((tmp_path / "pt-camera.json").read_text())
    assert validate_record(rec, "calibrate") == []
    determined = rec["calibration"]["R_shadow"] is not None
    assert determined == (R == 2.0)
    assert rec["R_source"] == ("measured" if determined else "omitted")
    # the schema is closed: a field the calibration adds must be documented
    bad = dict(rec, calibration={**rec["calibration"], "new_field": 1})
    assert validate_record(bad, "calibrate") == ["$.calibration: undocumented field "
                                                 "'new_field'"]
    assert "calibrate" in RECORD_SCHEMAS
