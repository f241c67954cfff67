"""Camera validation and presets; the OpenCL runtime's device choice and guards."""

from __future__ import annotations

import math

import numpy as np
import pytest

from clfza import Camera, reconstruct
from clfza.cl import _runtime as rtmod
from clfza.errors import ClfzaError, DeviceError

pytestmark = pytest.mark.agreement  # rerun on every OpenCL device (.ci/run)


def test_presets_hold_the_papers_setups():
    sim = Camera.preset("simulation")
    assert (sim.pitch, sim.shape, sim.r1, sim.z1, sim.z2) == (0.01, (512, 512), 0.23, 20, 3)
    exp = Camera.preset("experiment")
    assert exp.shape == (2400, 2400) and exp.pitch == 0.00375
    assert exp.r1p**2 == pytest.approx(math.pi / 29.75)


@pytest.mark.parametrize("kw, match", [
    (dict(pitch=0), "pitch"), (dict(pitch=-0.01), "pitch"), (dict(r1=float("nan")), "r1"),
    (dict(z1=-5), "z1"), (dict(z2=0), "z2"), (dict(shape=(1, 10)), "shape"),
    (dict(shape=(10,)), "shape"), (dict(R=0), "R"), (dict(mask="round"), "mask"),
    (dict(wavelength=3.0), "wavelength"),
])
def test_camera_rejects_bad_values(kw, match):
    args = dict(pitch=0.01, shape=(64, 64), r1=0.2, z1=20, z2=3)
    args.update(kw)
    with pytest.raises(ClfzaError, match=match):
        Camera(**args)


def test_camera_toml_errors(tmp_path):
    f = tmp_path / "cam.toml"
    f.write_text("[camera]\npitch = 0.01\nshape = [64, 64]\nr1 = 0.2\nz1 = 20\n")
    with pytest.raises(ClfzaError, match="missing.*z2"):
        Camera.from_toml(f)
    f.write_text("[camera]\npitch = 0.01\nshape = [64, 64]\nr1 = 0.2\nz1 = 20\nz2 = 3\nfoo=1\n")
    with pytest.raises(ClfzaError, match="unknown"):
        Camera.from_toml(f)
    f.write_text("pitch = = 3")
    with pytest.raises(ClfzaError, match="TOML"):
        Camera.from_toml(f)
    with pytest.raises(ClfzaError, match="does not exist"):
        Camera.from_toml(tmp_path / "nope.toml")


def test_runtime_picks_a_working_device(rt):
    assert rt.info.kind in ("CPU", "GPU", "accelerator")
    assert rtmod.probe_device(*next((d[0], d[1], d[3]) for d in rtmod._all_devices()
                                    if d[3].name.strip() == rt.info.name)) is None


def test_unknown_device_spec_is_a_clear_error():
    with pytest.raises(DeviceError, match="no OpenCL device matches"):
        rtmod.Runtime("no-such-device-xyz")


def test_no_platform_says_how_to_install_pocl(monkeypatch):
    monkeypatch.setattr(rtmod, "_platforms", lambda: (_ for _ in ()).throw(
        DeviceError(rtmod.INSTALL_HINT)))
    with pytest.raises(DeviceError, match="pocl"):
        rtmod.Runtime(None)


def test_allocation_guard(rt):
    with pytest.raises(DeviceError, match="MiB"):
        rt.check_alloc(rt.device.max_mem_alloc_size + 1)
    with pytest.raises(DeviceError, match="MiB"):
        rt.check_total(rt.device.global_mem_size * 2)


def test_build_failure_shows_the_log(rt, monkeypatch):
    monkeypatch.setattr(rtmod, "kernel_source",
                        lambda name: "__kernel void f(__global float *a) { a[0] = b; }")
    with pytest.raises(DeviceError, match="build of broken.cl failed"):
        rt.program("broken")


def test_missing_kernel_source():
    with pytest.raises(DeviceError, match="missing"):
        rtmod.kernel_source("does_not_exist")


def test_missing_kernel_source_from_a_checkout(tmp_path, monkeypatch):
    """clfza run from a checkout on CLFZA_KERNEL_DIR (tools/device_gpu_run.sh), where no
    ``clfza.kernels`` package exists: a missing source is still a DeviceError naming both."""
    def no_package(name):
        raise ModuleNotFoundError(f"No module named {name!r}")

    monkeypatch.setenv("CLFZA_KERNEL_DIR", str(tmp_path))
    monkeypatch.setattr(rtmod.resources, "files", no_package)
    with pytest.raises(DeviceError, match="missing .*CLFZA_KERNEL_DIR"):
        rtmod.kernel_source("does_not_exist")


@pytest.mark.parametrize("bad, match", [
    (np.full((64, 64), np.inf), "NaN or Inf"), (np.ones((32, 64)), "shape"),
    (np.ones((64, 64), dtype=complex), "dtype"), (np.ones((64, 64, 2)), "3 channels"),
])
def test_reconstruct_rejects_bad_measurements(bad, match):
    cam = Camera(pitch=0.01, shape=(64, 64), r1=0.07, z1=20, z2=3)
    with pytest.raises(ClfzaError, match=match):
        reconstruct(bad, cam, "bp", backend="numpy")


def test_bp_opencl_matches_numpy(rng):
    cam = Camera(pitch=0.01, shape=(64, 80), r1=0.07, z1=20, z2=3)
    y = rng.standard_normal(cam.shape)
    a, info = reconstruct(y, cam, "bp", backend="opencl")
    b, _ = reconstruct(y, cam, "bp", backend="numpy")
    assert np.abs(a - b).max() < 2e-5 * np.abs(b).max()
    assert info.timings["solve"] >= 0 and info.device
