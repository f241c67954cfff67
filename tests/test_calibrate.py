"""Calibration from a point-source shot (clfza.camera._calibrate), the mask centre as a camera
parameter, and the depth rescaling of a calibrated r1'."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from clfza import Camera
from clfza.camera._calibrate import calibrate, camera_toml
from clfza.camera._masks import zone_plate
from clfza.cli import main
from clfza.errors import ClfzaError
from clfza.simulation import Noise, point_sources, shadow_pattern, simulate

NOISE = Noise(photons=20000, read_noise=3, bit_depth=12)


def _sensor(clean: np.ndarray, seed: int) -> np.ndarray:
    """Photon noise (20000 e- at the peak), 3 e- read noise, 12 bits, 90% exposure."""
    rng = np.random.default_rng(seed)
    e = rng.poisson(clean / clean.max() * 20000) + rng.normal(0.0, 3.0, clean.shape)
    return np.round(np.clip(e / 20000 * 0.9, 0.0, 1.0) * 4095)


@pytest.fixture(scope="module")
def experiment_binned():
    """The experiment preset (2400^2 of 3.75 um) with its mask 7.5, -4.2 px off centre,
    binned 3x3 to 800^2 of 11.25 um: pixel-integrated zones up to the Nyquist limit."""
    cam = dataclasses.replace(Camera.preset("experiment"), mask_center=(7.5, -4.2))
    clean = shadow_pattern(cam, cam.shape).reshape(800, 3, 800, 3).sum(axis=(1, 3))
    center = ((1200 + 7.5 - 1) / 3, (1200 - 4.2 - 1) / 3)  # binned pixel k is 3k + 1
    return _sensor(clean, 0), cam, center


@pytest.fixture(scope="module")
def gzp_frame():
    """A GZP camera without aperture (zones alias in the corners), centre off by -3.3, 4.6."""
    cam = Camera(pitch=0.01, shape=(512, 512), r1=0.23, z1=20.0, z2=3.0, mask="gzp",
                 mask_center=(-3.3, 4.6))
    return _sensor(shadow_pattern(cam, cam.shape), 1), cam, (256 - 3.3, 256 + 4.6)


def _check(cal, cam: Camera, center, pitch_ratio: float = 1.0) -> None:
    assert cal.confident, cal.warnings
    assert cal.r1_shadow_squared == pytest.approx(cam.r1p**2, rel=2e-3)
    assert abs(cal.center[0] - center[0]) < 0.5 and abs(cal.center[1] - center[1]) < 0.5
    if cam.R_shadow is None:
        assert cal.R_shadow is None
    else:
        assert cal.R_shadow == pytest.approx(cam.R_shadow, rel=0.02)
    assert cal.mask == cam.mask
    assert abs(cal.phase) < 0.05


def test_experiment_binned(experiment_binned):
    frame, cam, center = experiment_binned
    cal = calibrate(frame, 0.01125, z1=300.0, z2=3.0)
    _check(cal, cam, center)
    assert cal.fill > 0.7  # binned pixels integrate the zones
    fitted = cal.camera(300.0, 3.0)
    assert fitted.R == pytest.approx(4.56, rel=0.02)
    assert fitted.mask_center == pytest.approx((center[0] - 400, center[1] - 400), abs=0.5)


def test_experiment_point_source():
    """A point source through ``simulate(..., sensor_plane=True)`` on the binned grid."""
    cam = Camera.preset("experiment").with_shape((800, 800), 0.01125)
    dy, dx = 3, -2
    m = cam.magnification
    obj = point_sources(cam, [(-dx * cam.pitch / m, -dy * cam.pitch / m, 1.0)])
    frame = simulate(obj, cam, sensor_plane=True, noise=NOISE).frame
    cal = calibrate(frame, cam.pitch, z1=cam.z1, z2=cam.z2)
    _check(cal, cam, (400 + dy, 400 + dx))
    assert cal.harmonic_ratio == pytest.approx(1 / 3, abs=0.05)


def test_gzp_without_aperture(gzp_frame):
    frame, cam, center = gzp_frame
    cal = calibrate(frame, cam.pitch, z1=cam.z1, z2=cam.z2)
    _check(cal, cam, center)
    assert cal.harmonic_ratio < 0.05
    binned = calibrate(frame, cam.pitch, bin=2, mask="gzp")  # centre in input pixels
    assert abs(binned.center[0] - center[0]) < 0.5 and abs(binned.center[1] - center[1]) < 0.5
    assert binned.r1_shadow_squared == pytest.approx(cam.r1p**2, rel=2e-3)


def test_bad_frames():
    with pytest.raises(ClfzaError, match="all zero"):
        calibrate(np.zeros((64, 64)), 0.01)
    bad = np.ones((64, 64))
    bad[3, 3] = np.nan
    with pytest.raises(ClfzaError, match="NaN"):
        calibrate(bad, 0.01)
    noise = np.random.default_rng(0).poisson(100.0, (256, 256))
    with pytest.raises(ClfzaError, match="no zone pattern"):
        calibrate(noise, 0.01)
    with pytest.raises(ClfzaError, match="mask"):
        calibrate(noise, 0.01, mask="square")


def test_low_confidence_is_reported(gzp_frame, tmp_path, capsys):
    """Zones under noise twice their amplitude: found, but flagged; the CLI writes nothing
    and exits non-zero."""
    frame, cam, _ = gzp_frame
    rng = np.random.default_rng(5)
    noisy = frame + rng.normal(0.0, 2 * frame.std(), frame.shape)
    cal = calibrate(noisy, cam.pitch)
    assert not cal.confident and "residual" in cal.warnings[0]
    np.save(tmp_path / "noisy.npy", noisy)
    out = tmp_path / "cam.toml"
    rc = main(["calibrate", str(tmp_path / "noisy.npy"), "--pitch", "0.01", "--z1", "20",
               "--z2", "3", "--out", str(out)])
    assert rc == 2 and not out.exists()
    assert "low-confidence" in capsys.readouterr().err


def test_cli_writes_camera_once(gzp_frame, tmp_path, capsys):
    frame, cam, center = gzp_frame
    np.save(tmp_path / "psf.npy", frame.astype(np.uint16))
    out = tmp_path / "cam.toml"
    args = ["calibrate", str(tmp_path / "psf.npy"), "--pitch", "0.01", "--z1", "20", "--z2",
            "3", "--out", str(out)]
    assert main(args) == 0
    text = capsys.readouterr().out
    assert "r1'^2" in text and "centre" in text and "mask    gzp" in text
    got = Camera.from_toml(out)
    assert got.r1p**2 == pytest.approx(cam.r1p**2, rel=2e-3)
    assert got.mask == "gzp" and got.R is None and got.shape == (512, 512)
    assert got.mask_center == pytest.approx(cam.mask_center, abs=0.5)
    assert got.r1 == pytest.approx(cam.r1, rel=2e-3)
    before = out.read_text()
    assert main(args) == 2 and out.read_text() == before
    assert "--force" in capsys.readouterr().err
    assert main(args + ["--force"]) == 0


def test_camera_toml_text(experiment_binned):
    frame, cam, _ = experiment_binned
    cal = calibrate(frame[200:600, 200:600], 0.01125, mask="fza")
    text = camera_toml(cal, math.inf, 3.0, name="inf")
    assert "z1 = inf" in text and "r1_shadow_squared" in text


# ----------------------------------------------------------------------------------------
# the mask centre as a camera parameter
# ----------------------------------------------------------------------------------------
def test_zone_plate_center_shifts_pattern_and_aperture():
    plain = zone_plate((101, 101), 0.01, 0.1, kind="fza", R=0.35)
    moved = zone_plate((101, 101), 0.01, 0.1, kind="fza", R=0.35, center=(3, -5))
    assert np.array_equal(moved, np.roll(plain, (3, -5), axis=(0, 1)))
    assert np.array_equal(zone_plate((64, 64), 0.01, 0.1, center=(0.0, 0.0)),
                          zone_plate((64, 64), 0.01, 0.1))
    with pytest.raises(ClfzaError, match="center"):
        zone_plate((64, 64), 0.01, 0.1, center=(np.nan, 0))


def test_camera_mask_center_round_trip(tmp_path):
    cam = dataclasses.replace(Camera.preset("simulation"), mask_center=(1.5, -2))
    assert cam.mask_center == (1.5, -2.0)
    assert Camera.from_dict(cam.to_dict()) == cam
    assert cam.summary()["mask_center_px"] == [1.5, -2.0]
    (tmp_path / "c.toml").write_text("[camera]\npitch = 0.01\nshape = [64, 64]\nr1 = 0.2\n"
                                     "z1 = 20\nz2 = 3\nmask_center = [0.5, -1.25]\n")
    assert Camera.from_toml(tmp_path / "c.toml").mask_center == (0.5, -1.25)
    assert cam.with_shape((256, 256), pitch=0.02).mask_center == (0.75, -1.0)
    for bad in ([1.0], "ab", [math.inf, 0.0]):
        with pytest.raises(ClfzaError, match="mask_center"):
            dataclasses.replace(cam, mask_center=bad)


def test_device_zone_plate_refuses_offset():
    from clfza.models._device_operator import device_zone_plate

    with pytest.raises(ClfzaError, match="centred"):
        device_zone_plate(None, (64, 64), 0.01, 0.1, center=(1.0, 0.0))


# ----------------------------------------------------------------------------------------
# depth rescaling of a calibrated r1'
# ----------------------------------------------------------------------------------------
def test_at_depth_rescales_calibrated_r1p():
    cam = Camera.preset("experiment")  # r1'^2 = pi / 29.75 calibrated at z1 = 300
    assert cam.at_depth(300.0).r1p == cam.r1p
    inf = cam.at_depth(math.inf)
    assert inf.r1p == pytest.approx(cam.r1p / (1 + 3.0 / 300.0), rel=1e-14)
    z = 50.0
    assert cam.at_depth(z).r1p == pytest.approx(cam.r1p * (1 + 3 / z) / (1 + 3 / 300), 1e-14)
    assert cam.at_depth(z).at_depth(300.0).r1p == pytest.approx(cam.r1p, rel=1e-14)
    plain = Camera.preset("simulation")  # not calibrated: (1 + z2/z1) r1
    assert plain.at_depth(40.0).r1p == pytest.approx(0.23 * (1 + 3 / 40), rel=1e-14)
    assert plain.at_depth(40.0).r1_shadow is None
