"""bench/bench_wake.py: the latency figures of a small kernel on the default device, and the
report's arithmetic (the wake per iteration is 2 device visits per objective evaluation times
the wake per visit; the limit is bench_xlimit's). No timing is asserted."""

from __future__ import annotations

from pathlib import Path

import pytest

BENCH = Path(__file__).resolve().parents[1] / "bench"


@pytest.fixture()
def wake(monkeypatch):
    monkeypatch.syspath_prepend(str(BENCH))
    import bench_wake

    return bench_wake


def test_latencies_on_the_default_device(wake, rt):
    us = wake.latencies(rt.info.index, 50e-6, reps=40)
    for k in ("chained_us", "after_finish_us", "after_host_us", "gated_us"):
        assert us[k] > 0
    assert us["wake_us"] == pytest.approx(us["after_host_us"] - us["chained_us"])


def _round(wake_us: float, steady_ms: float) -> dict:
    probe = {"fft_pair_ms": 0.8, "triad_GBps": 40.0}
    return {"name": "impl", "device": "cpu", "chained_us": 10.0, "after_finish_us": 20.0,
            "after_host_us": 10.0 + wake_us, "gated_us": 30.0, "wake_us": wake_us,
            "steady_ms": steady_ms, "evaluations_per_iteration": 1.25,
            "probes": [probe, {"fft_pair_ms": 0.9, "triad_GBps": 30.0}]}


def test_summary_arithmetic(wake):
    s = wake.summarise(512, [_round(80.0, 2.0), _round(100.0, 1.8), _round(60.0, 2.2)])
    lim = 0.8 + 4 * 512 * 512 * 4 / 40e9 * 1e3  # the best probe's FFT pair and bandwidth
    assert s["limit_ms"] == pytest.approx(lim)
    assert s["wake_us"] == 80.0 and s["steady_ms"] == 2.0  # medians
    assert s["visits_per_iteration"] == pytest.approx(2.5)
    assert s["wake_ms_per_iteration"] == pytest.approx(0.2)
    assert s["steady_x"] == pytest.approx(2.0 / lim)
    assert s["steady_without_wake_x"] == pytest.approx(1.8 / lim)


def test_report_files(wake, tmp_path):
    res = {"machine": {"cpu_model": "cpu", "cores_usable": 2, "date": "today"}, "n": 512,
           "rounds": 1, "host_us": 450.0, "load_start": [0, 0, 0], "load_end": [0, 0, 0],
           "revision": {"commit": "abc"},
           "devices": {"0:0": wake.summarise(512, [_round(80.0, 2.0)])}}
    text = wake.markdown(res)
    assert "| impl | 10.0 | 20.0 | 90.0 | 30.0 | 80.0 |" in text
    wake.plot(res, tmp_path / "w.png")
    assert (tmp_path / "w.png").stat().st_size > 0
