"""bench/bench_gpu.py (issue 13, item 5) runs end to end at a small size on the default device
with the solvers on the device FFT, the path they take on GPUs: the FFT pair round-trips, every
solver is reported (joint colour too) with its launches and host reads per iteration, the PSNR
record is filled in, and the files it promises are written. Where
no vendor FFT is importable the report says why instead of a number. (No timing is asserted.)"""

from __future__ import annotations

import json
from pathlib import Path

import pytest

pytestmark = pytest.mark.agreement  # rerun on every OpenCL device (.ci/run)

BENCH = Path(__file__).resolve().parents[1] / "bench"


@pytest.fixture()
def bench_module(monkeypatch):
    monkeypatch.syspath_prepend(str(BENCH))
    import bench_gpu

    return bench_gpu


def test_gpu_bench_smoke_run(bench_module, tmp_path):
    from clfza.cl import get_runtime

    dev = get_runtime().info.index
    assert bench_module.main(["--device", dev, "--fft", "device", "--sizes", "32", "--rounds",
                              "1", "--short", "2", "--long", "4", "--fft-reps", "2",
                              "--psnr-iters", "4", "--out", str(tmp_path)]) == 0
    assert sorted(p.suffix for p in tmp_path.iterdir()) == [".json", ".md", ".png"]
    res = json.loads(next(tmp_path.glob("*.json")).read_text())
    assert res["device"] == dev and res["solver_fft"] == "device"
    rec = res["sizes"]["32"]
    assert rec["fft"]["engine"] != "HostFFT" and rec["fft"]["pair_ms"] > 0
    assert rec["fft"]["roundtrip_max_rel_error"] < 1e-5  # float32 FFT pair, 32^2
    assert set(rec["solvers"]) == {s for s, _, _ in bench_module.SOLVERS}
    assert all(s["steady_ms"] > 0 or s["run_ms"] > 0 for s in rec["solvers"].values())
    # every iteration launches kernels; TwIST and FISTA decide on their objective each
    # iteration, so they wait for it (zero-copy CPU devices: a wait; GPUs: a blocking read)
    for s in [*rec["solvers"].values(), rec["colour"]]:
        assert s["launches_per_iteration"] >= 3
        if s["method"] != "admm":
            assert s["finishes_per_iteration"] + s["reads_per_iteration"] >= 1
    a = rec["admm_psnr"]
    assert a["iterations"] == 4 and a["admm_final_psnr"] > 0 and a["twist_paper_psnr"] > 0
    assert a["checked_iterations"] == [1, 2, 3, 4]
    v = rec["vendor_fft"]
    assert v["available"] or v["why"]
    md = next(tmp_path.glob("*.md")).read_text()
    assert "twist-paper" in md and ("cuFFT" in md or "No vendor FFT" in md)
    assert "joint colour (C = 3)" in md and "| launches | waits | reads |" in md


def test_gpu_bench_refuses_bad_arguments(bench_module):
    for bad in (["--short", "5", "--long", "5"], ["--sizes", "8"], ["--rounds", "0"],
                ["--fft", "nonsense"]):
        with pytest.raises(SystemExit):
            bench_module.main(bad)
