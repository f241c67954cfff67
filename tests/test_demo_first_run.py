"""The first run's times reach the demo's and the benchmarks' records (issue 36: "the demo, the
benchmarks and the JSON records time the compile and any first-use tuning apart from the
solve"): what the command line's warm-up measured where it happened (the CPU devices'
measurement, the first compile, the tuning) is what ``metrics.json`` and the benchmark JSON
hold, never 0 after a compile. A cold compile is simulated: a fresh clfza cache folder (the
device not recorded as warm) and a stand-in for ``clfza.cl.check.warm_up`` that reports a
compile and writes a tuning entry, as a first run does. Nothing here asserts a duration."""

from __future__ import annotations

import json

import pytest

import clfza.benchmarks as benchmarks
from clfza.backends import tuning_key
from clfza.cl import write_cache
from clfza.cli import _bench, _common, _demo, main

COMPILE_S, WARM_S, TUNING_S = 1.5, 2.5, 0.75  # what the stand-in warm-up reports


@pytest.fixture
def fresh_cache(tmp_path, monkeypatch, rt):
    """A clean clfza cache (nothing compiled, tuned or measured) for the default device,
    opened beforehand (its choice is not measured again here)."""
    monkeypatch.setenv("CLFZA_CACHE_DIR", str(tmp_path / "cache"))
    return rt


def _cold_warm_up(rt, calls):
    """A warm_up that compiled and tuned: the tuner writes its entry with its own seconds."""

    def warm_up(device=None, *, force=False):
        calls.append(device)
        write_cache("tuning.json", {tuning_key(rt): {"small": {"seconds": TUNING_S,
                                                               "choices": {}}}})
        return {"device": rt.info.describe(), "seconds": WARM_S, "compile_s": COMPILE_S}

    return warm_up


def test_first_run_times_each_step(fresh_cache, monkeypatch):
    rt, calls = fresh_cache, []
    monkeypatch.setattr(_common, "warm_up", _cold_warm_up(rt, calls))

    def open_measuring(device=None):  # the default's choice measures one CPU device
        write_cache("device_scores.json", {"some CPU device": 12.0})
        return rt

    monkeypatch.setattr(_common, "get_runtime", open_measuring)
    fr = _common.first_run(None)
    assert calls == [None]
    assert fr["compiled"] and fr["compile_s"] == COMPILE_S and fr["warm_up_s"] == WARM_S
    assert fr["tuning_s"] == TUNING_S and fr["devices_measured"] == 1
    assert fr["seconds"] == fr["device_s"] + WARM_S and fr["device"] == rt.info.describe()
    line = _common.first_run_line(fr)
    assert "measuring 1 CPU device" in line and "OpenCL builds 1.5 s" in line
    assert "tuning 0.8 s" in line


def test_first_run_on_a_warm_device_records_no_compile(fresh_cache, monkeypatch):
    monkeypatch.setattr(_common, "warm_up", lambda device=None, force=False: None)
    fr = _common.first_run(None)
    assert not fr["compiled"] and fr["compile_s"] == 0.0 and fr["tuning_s"] == 0.0
    assert isinstance(fr["tuning_s"], float)
    assert fr["devices_measured"] == 0 and _common.first_run_line(fr) is None


def test_setup_record_passes_the_first_run_through():
    fr = {"device": "d", "device_s": 4.0, "devices_measured": 2, "compiled": True,
          "warm_up_s": WARM_S, "compile_s": COMPILE_S, "tuning_s": TUNING_S, "seconds": 6.5}
    warm = {"seconds": 0.25, "compile_s": 0.125}
    s = _demo.setup_record(fr, warm)
    assert s["first_run"] is fr and s["warm_up"] is warm
    assert s["compile_s"] == COMPILE_S + 0.125 and s["seconds"] == 6.5 + 0.25
    assert s["device_s"] == 4.0 and s["tuning_s"] == TUNING_S
    assert _demo.setup_record(None, None) is None
    assert _demo.setup_record(None, warm)["compile_s"] == 0.125


def test_demo_records_the_first_compile(fresh_cache, monkeypatch, tmp_path, capsys,
                                        cli_logging):
    """``clfza demo`` on a cold device: metrics.json's setup holds the warm-up's compile time
    (it held 0.0, the compile having happened before the demo's own warm-up), and the printed
    warm-up lines carry it."""
    rt, calls = fresh_cache, []
    monkeypatch.setattr(_common, "warm_up", _cold_warm_up(rt, calls))
    monkeypatch.setattr(_demo, "_demo_methods", lambda: list(_demo.DEMO_METHODS))  # BP only
    assert main(["demo", "--quiet", "--out", str(tmp_path / "out")]) == 0
    assert len(calls) == 1
    (metrics,) = (tmp_path / "out").glob("demo-*/metrics.json")
    setup = json.loads(metrics.read_text())["setup"]
    assert setup["first_run"]["compiled"] and setup["first_run"]["compile_s"] == COMPILE_S
    assert setup["first_run"]["tuning_s"] == TUNING_S
    assert setup["compile_s"] == COMPILE_S + setup["warm_up"]["compile_s"]
    assert setup["tuning_s"] == TUNING_S
    assert [r["method"] for r in json.loads(metrics.read_text())["results"]] == ["bp"]


def test_demo_prints_the_first_run_line(fresh_cache, monkeypatch, tmp_path, capsys):
    monkeypatch.setattr(_common, "warm_up", _cold_warm_up(fresh_cache, []))
    fr = _common.first_run(None)
    _demo.run_demo(tmp_path, methods=list(_demo.DEMO_METHODS), first_run=fr)
    out = capsys.readouterr().out
    assert "first run (not timed below)" in out and "OpenCL builds 1.5 s" in out


def test_bench_records_the_first_run(monkeypatch, tmp_path, capsys):
    """``clfza bench`` hands the warm-up's record to clfza.benchmarks.run, which writes it
    into the time-error and scaling JSON beside (never in) the rows."""
    fr = {"device": "d", "device_s": 4.0, "devices_measured": 0, "compiled": True,
          "warm_up_s": WARM_S, "compile_s": COMPILE_S, "tuning_s": TUNING_S, "seconds": 6.5}
    monkeypatch.setattr(_bench, "warm_first_run", lambda args: fr)
    got = []
    monkeypatch.setattr(benchmarks, "run", lambda profile, out, first_run=None:
                        got.append(first_run))
    assert main(["bench", "--out", str(tmp_path / "b")]) == 0
    assert got == [fr] and "OpenCL builds 1.5 s" in capsys.readouterr().out
    sc = benchmarks.scaling.run("tiny", tmp_path, sizes=[64], methods=["bp"], label="t",
                                log=lambda *a: None, first_run=fr)
    js = json.loads((tmp_path / "scaling_t.json").read_text())
    assert js["first_run"] == fr == sc["first_run"]
    assert all("first_run" not in r for r in js["rows"])
    te = benchmarks.timeerror.run("tiny", tmp_path, cases=[], label="t", log=lambda *a: None,
                                  first_run=fr)
    assert json.loads((tmp_path / "time_error_t.json").read_text())["first_run"] == fr
    assert te["first_run"] == fr
