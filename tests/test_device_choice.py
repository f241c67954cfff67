"""The default device by measurement (cached on disk), device specs naming implementations,
and the Intel ICD helper. The measurement itself is replaced by fixed numbers here; it runs
for real on the first default runtime of a session with several CPU devices."""

from __future__ import annotations

import json

import pytest

from clfza.cl import _runtime as R
from clfza.cl import intel_icd

DISPATCH = R.measure_device  # the runtime's own: calls the registered measurement


def _fake_devices(n):
    class Plat:
        def __init__(self, i):
            self.name = "Fake OpenCL"
            self.version = f"OpenCL 3.0 Fake {i}.0"

    class Dev:
        def __init__(self, i):
            self.name = f"fake cpu {i}"
            self.driver_version = f"{i}.0"
            self.type = 2  # CL_DEVICE_TYPE_CPU
            self.global_mem_size = self.max_mem_alloc_size = 1 << 30
            self.max_compute_units = 2
            self.double_fp_config = 1

    return [(i, 0, Plat(i), Dev(i)) for i in range(n)]


@pytest.fixture
def fake(monkeypatch, tmp_path):
    cl = pytest.importorskip("pyopencl")
    assert cl.device_type.CPU == 2
    monkeypatch.setenv("CLFZA_CACHE_DIR", str(tmp_path))
    monkeypatch.delenv("CLFZA_DEVICE_CHOICE", raising=False)
    monkeypatch.delenv("PYOPENCL_CTX", raising=False)  # --cl-device sets it for the session
    devs = _fake_devices(3)
    monkeypatch.setattr(R, "_all_devices", lambda: devs)
    monkeypatch.setattr(R, "probe_device", lambda pi, di, dev: None)
    calls = []
    ms = {"0:0": 5.0, "1:0": 3.0, "2:0": 4.0}

    def measure(index, n=R.MEASURE_SIZE, iters=R.MEASURE_ITERS):
        calls.append(index)
        return ms[index]

    monkeypatch.setattr(R, "measure_device", measure)
    return devs, calls, tmp_path


def test_default_is_fastest_measured_and_cached(fake):
    devs, calls, tmp = fake
    assert R._pick(None)[0] == 1
    assert calls == ["0:0", "1:0", "2:0"] * R.MEASURE_ROUNDS  # rounds over the devices
    cached = json.loads((tmp / "device_scores.json").read_text())
    assert sorted(cached.values()) == [3.0, 4.0, 5.0]
    n = len(calls)
    assert R._pick(None)[0] == 1 and len(calls) == n  # from the cache: no new measurement
    assert all(v["cached"] for v in R.device_scores().values())


def test_measurement_rounds_interleave_and_keep_the_best(fake, monkeypatch):
    """A load burst during one device's first turn does not decide the choice: the devices
    are measured in turn, round after round, and each keeps its best."""
    devs, calls, tmp = fake
    true = {"0:0": 5.0, "1:0": 3.0, "2:0": 4.0}

    def measure(index, n=R.MEASURE_SIZE, iters=R.MEASURE_ITERS):
        calls.append(index)
        return true[index] * (3.0 if len(calls) <= 2 else 1.0)  # busy for the first two

    monkeypatch.setattr(R, "measure_device", measure)
    monkeypatch.setattr(R, "MEASURE_ROUNDS", 2)
    assert R._pick(None)[0] == 1
    assert sorted(json.loads((tmp / "device_scores.json").read_text()).values()) == [3.0, 4.0,
                                                                                     5.0]


def test_explicit_choice_and_first_skip_measuring(fake, monkeypatch):
    devs, calls, _ = fake
    assert R._pick("2:0")[0] == 2
    assert R._pick("Fake 2.0")[0] == 2  # the platform's version names an implementation
    monkeypatch.setenv("CLFZA_DEVICE_CHOICE", "first")
    assert R._pick(None)[0] == 0
    assert calls == []


def test_failed_measurement_is_never_preferred(fake, monkeypatch):
    devs, calls, _ = fake

    def broken(index, **kw):
        if index == "1:0":
            raise RuntimeError("boom")
        return {"0:0": 5.0, "2:0": 4.0}[index]

    monkeypatch.setattr(R, "measure_device", broken)
    assert R._pick(None)[0] == 2


def test_choice_report_lists_fastest_first(fake):
    lines = R.choice_report()
    assert "[1:0]" in lines[1] and "fastest" in lines[1]


def test_measurement_is_injected_from_above(fake, monkeypatch):
    """The runtime imports no solver: without a registered measurement nothing is measured
    or cached (the first device is taken); clfza.reconstruction._device_choice registers the real
    one."""
    devs, calls, tmp = fake
    monkeypatch.setattr(R, "measure_device", DISPATCH)
    monkeypatch.setattr(R, "_MEASURER", None)
    assert R._pick(None)[0] == 0 and not (tmp / "device_scores.json").exists()
    assert all(v["ms"] is None and not v["cached"] for v in R.device_scores().values())
    assert "not measured" in R.choice_report()[1]
    monkeypatch.setattr(R, "_MEASURER", lambda i, n, it: {"0:0": 5.0, "1:0": 3.0, "2:0": 4.0}[i])
    assert R._pick(None)[0] == 1
    from clfza.reconstruction import _device_choice as device_choice

    device_choice.install()
    assert R._MEASURER is device_choice.measure_device


def test_intel_icd_register(tmp_path):
    prefix, system, vendors = tmp_path / "venv", tmp_path / "sys", tmp_path / "vendors"
    (prefix / "lib").mkdir(parents=True)
    system.mkdir()
    (system / "pocl.icd").write_text("libpocl.so.2\n")
    with pytest.raises(FileNotFoundError, match="clfza\\[intel\\]"):
        intel_icd.register(str(prefix), str(vendors), str(system))
    lib = prefix / "lib" / "libintelocl.so.2026.1.0"
    lib.write_bytes(b"")
    (prefix / "lib" / "libintelocl.so").symlink_to(lib.name)
    (prefix / "lib" / "libintelocl.so-gdb.py").write_text("")
    assert intel_icd.register(str(prefix), str(vendors), str(system)) == str(lib)
    assert (vendors / "intel-cpu.icd").read_text().strip() == str(lib)
    assert (vendors / "pocl.icd").resolve() == (system / "pocl.icd").resolve()
    env = intel_icd.environment(str(prefix))
    assert env["LD_LIBRARY_PATH"].split(":")[0] == str(prefix / "lib")
