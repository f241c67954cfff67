"""Smoke tests of the benchmark machinery (issue 5) on a tiny grid: the result files exist and
carry the documented keys. No timing assertions (the machine may be shared)."""

from __future__ import annotations

import json

import numpy as np
import pytest

from clfza import ClfzaError
from clfza.benchmarks import _machine as machine
from clfza.benchmarks import _methods as methods
from clfza.benchmarks import _scaling as scaling
from clfza.benchmarks import _scenes as scenes
from clfza.benchmarks import _stability as stability
from clfza.benchmarks import _timeerror as timeerror


def test_machine_record_keys():
    rec = machine.machine_record()
    for k in ("cpu_model", "cores", "device", "versions", "date", "load_average"):
        assert k in rec
    for lib in ("clfza", "numpy", "scipy", "pyopencl", "scikit-image"):
        assert lib in rec["versions"]
    assert machine.machine_slug(rec)


def test_triad_and_fft_pair(rt):
    b = machine.triad_bandwidth_opencl(1 << 16, repeats=2)
    assert b["correct"] and b["gb_per_s"] > 0
    assert machine.triad_bandwidth_numpy(1 << 16, repeats=2)["gb_per_s"] > 0
    assert machine.fft_pair_time((64, 64), repeats=2) > 0


def test_usaf_target_geometry():
    img, elements = scenes.usaf_target(256, width_mm=20.0)
    assert img.shape == (256, 256) and 0 <= img.min() and img.max() <= 1
    assert len(elements) == 18
    e = elements[0]
    assert e["lp_per_mm"] == pytest.approx(2.0 ** e["group"])
    assert scenes.usaf_lp_per_mm(1, 4) == pytest.approx(2 ** 1.5)


@pytest.mark.parametrize("name", scenes.SCENES)
def test_scenes_simulate(name):
    cam = timeerror.bench_camera(64)
    sm = scenes.measurement(name, cam, None)
    m = sm.measurement
    assert m.y.shape[:2] == (64, 64) and np.isfinite(m.y).all()
    assert (m.y.ndim == 3) == (name == "rgb")


def test_bench_camera_keeps_sampling_ratio():
    r512 = timeerror.bench_camera(512).regime.ratio
    assert timeerror.bench_camera(256).regime.ratio == pytest.approx(r512)
    assert timeerror.bench_camera(2048).regime.ratio == pytest.approx(r512)
    assert timeerror.bench_camera(512).mask == "gzp"


def test_work_model_and_time_to_target():
    spec = methods.by_key(["bp"])[0]
    assert spec.limit_seconds(100, 4, 1e-3, 1e9) == pytest.approx(1e-3 + 2.5 * 400 / 1e9)
    curve = [{"time_s": 0.1, "psnr": 10.0}, {"time_s": 0.2, "psnr": 20.0}]
    assert timeerror.time_to_target(curve, 15.0) == 0.2
    assert timeerror.time_to_target(curve, 25.0) is None
    with pytest.raises(ClfzaError):
        methods.by_key(["nope"])


def test_time_error_tiny(tmp_path):
    r = timeerror.run("tiny", tmp_path, label="smoke", log=lambda *a: None)
    js = json.loads((tmp_path / "time_error_smoke.json").read_text())
    for k in ("machine", "limits", "rows", "time_to_paper", "metrics_note", "paper_row"):
        assert k in js
    assert (tmp_path / "time_error_smoke.png").stat().st_size > 0
    assert (tmp_path / "time_error_smoke.md").read_text().startswith("# Time against error")
    row = next(r for r in js["rows"] if r["key"] == "twist-tv-paper")
    for k in ("curve", "final", "per_iter_s", "limit_per_iter_s", "ratio_to_limit",
              "work_model", "device", "dtype"):
        assert k in row
    assert {"psnr", "ssim", "mse", "time_s", "iteration"} <= set(row["curve"][-1])
    assert r["time_to_paper"]


def test_trace_keeps_the_run_of_median_time():
    # the selection, not the clock: of the runs' times, the row's is the (lower) median, and
    # its curve is that run's
    cam = timeerror.bench_camera(32)
    meas = scenes.measurement("natural", cam, None, object_width=20.0 * 32 / 512).measurement
    spec = methods.by_key(["admm-tv"])[0]
    tr = timeerror.trace(meas.y, cam, spec, "numpy", meas.truth, iters=5, dtype=np.float64,
                         repeats=4)
    assert tr["repeats"] == 4 and len(tr["runs_s"]) == 4
    assert tr["solve_s"] == sorted(tr["runs_s"])[1]  # ADMM: no search, the solve clock
    assert timeerror._median_run([(None, 3.0, 0), (None, 1.0, 0), (None, 2.0, 0)])[1] == 2.0
    for bad in (0, -1, 1.5, True):  # refused before any solve, not per method as a skip
        with pytest.raises(ClfzaError, match="repeats"):
            timeerror.run("tiny", None, repeats=bad, log=lambda *a: None)


def test_scaling_tiny(tmp_path):
    r = scaling.run("tiny", tmp_path, label="smoke", log=lambda *a: None)
    js = json.loads((tmp_path / "scaling_smoke.json").read_text())
    assert js["rows"] and js["fits"] and js["limit_rows"] and "machine" in js
    assert (tmp_path / "scaling_smoke.png").stat().st_size > 0
    assert {"exponent_vs_N2", "nlogn_ratio"} <= set(r["fits"][0])


def test_stress_cases_classify():
    allc = stability.cases("test")
    pick = [c for c in allc if (c.category, c.name, c.key) in {
        ("rejected", "nan", "admm-tv"), ("degenerate", "zero", "twist-tv-paper"),
        ("shape", "5x3", "bp")}]
    assert len(pick) >= 3
    for c in pick:
        r = stability.run_case(c)
        assert r["outcome"] in ("finite", "clear_error"), r
    r = stability.summarise([{"outcome": "finite"}, {"outcome": "clear_error"}], [])
    assert r["cases"] == 2 and r["nonfinite"] == 0 and r["crashes"] == 0
