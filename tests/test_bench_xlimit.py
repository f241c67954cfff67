"""bench/bench_xlimit.py's report of issue 13's default-device target: the default device's
steady-state time against the fastest measured device, per size and solver, with TwIST held to
at most 1.10x (the other solvers for information); and an end-to-end run at a small size on the
default device writes the files it promises. (No timing is asserted.)"""

from __future__ import annotations

import json
from pathlib import Path

import pytest

BENCH = Path(__file__).resolve().parents[1] / "bench"


@pytest.fixture()
def xlimit(monkeypatch):
    monkeypatch.syspath_prepend(str(BENCH))
    import bench_xlimit

    return bench_xlimit


def _res(ms: dict[str, dict[str, float]], default: str) -> dict:
    """A result record with steady-state ms per device and solver at one size."""
    return {"sizes": [512], "default_device": default,
            "devices": {k: {"name": f"impl {k}", "results": {"512": {
                s: {"steady_ms": v} for s, v in per.items()}}} for k, per in ms.items()}}


def test_default_against_the_fastest(xlimit):
    ms = {"1:0": {"twist-paper": 1.10, "fista-nonneg": 2.0, "admm": 1.0},
          "0:0": {"twist-paper": 1.00, "fista-nonneg": 1.0, "admm": 1.5}}
    rows = {r["solver"]: r for r in xlimit.default_vs_best(_res(ms, "1:0"))}
    assert rows["twist-paper"]["best"] == "0:0"
    assert rows["twist-paper"]["ratio"] == pytest.approx(1.10)
    assert rows["twist-paper"]["met"] is True  # at most 10 % slower
    assert rows["fista-nonneg"]["ratio"] == pytest.approx(2.0)
    assert rows["fista-nonneg"]["met"] is None  # TwIST only
    assert rows["admm"]["best"] == "1:0" and rows["admm"]["ratio"] == 1.0
    ms["1:0"]["twist-paper"] = 1.11
    rows = {r["solver"]: r for r in xlimit.default_vs_best(_res(ms, "1:0"))}
    assert rows["twist-paper"]["met"] is False
    text = "\n".join(xlimit.default_lines(_res(ms, "1:0")))
    assert "x1.110 (over)" in text and "impl 0:0" in text


def test_default_not_measured(xlimit):
    res = _res({"0:0": {"twist-paper": 1.0, "fista-nonneg": 1.0, "admm": 1.0}}, "2:0")
    assert xlimit.default_vs_best(res) == []
    assert "not among those measured" in xlimit.default_lines(res)[0]


def test_xlimit_smoke_run(xlimit, tmp_path):
    from clfza.cl import get_runtime

    dev = get_runtime().info.index
    assert xlimit.main(["--devices", dev, "--sizes", "32", "--rounds", "1", "--short", "2",
                        "--long", "4", "--out", str(tmp_path)]) == 0
    assert sorted(p.suffix for p in tmp_path.iterdir()) == [".json", ".md", ".png"]
    res = json.loads(next(tmp_path.glob("*.json")).read_text())
    assert res["default_device"] == dev
    rows = res["default_vs_best"]
    assert {r["solver"] for r in rows} == {s for s, _, _ in xlimit.SOLVERS}
    assert all(r["best"] == dev and r["ratio"] == 1.0 for r in rows)  # one device measured
    assert "The default device against the fastest" in next(tmp_path.glob("*.md")).read_text()
