"""bench/bench_kernel_bandwidth.py runs end to end at a small size on the default device: every
kernel of its byte model is launched and reported, and the files it promises are written.
(No timing is asserted: only that the report is complete and self-consistent.)"""

from __future__ import annotations

import json
from pathlib import Path

import pytest

BENCH = Path(__file__).resolve().parents[1] / "bench"


@pytest.fixture()
def bench_module(monkeypatch):
    monkeypatch.syspath_prepend(str(BENCH))
    import bench_kernel_bandwidth

    return bench_kernel_bandwidth


def test_kernel_bandwidth_report(bench_module, tmp_path, capsys):
    from clfza.cl import get_runtime

    dev = get_runtime().info.index
    assert bench_module.main(["--devices", dev, "--sizes", "32", "--rounds", "1",
                              "--out", str(tmp_path)]) == 0
    files = sorted(p.suffix for p in tmp_path.iterdir())
    assert files == [".json", ".md", ".png"]
    res = json.loads(next(tmp_path.glob("*.json")).read_text())
    rows = res["devices"][dev]["results"]["32"]["kernels"]
    assert set(rows) == set(bench_module.KERNELS)
    assert rows["triad"]["x_triad"] == pytest.approx(1.0)
    for r in rows.values():
        assert r["ms"] > 0 and r["GBps"] > 0 and r["x_triad"] > 0
    md = next(tmp_path.glob("*.md")).read_text()
    assert all(k in md for k in bench_module.KERNELS)


def test_kernel_bandwidth_refuses_bad_arguments(bench_module):
    with pytest.raises(SystemExit):
        bench_module.main(["--sizes", "8"])
    with pytest.raises(SystemExit):
        bench_module.main(["--rounds", "0"])
