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


def test_limit_counting_the_pairs_done(xlimit):
    """The informational ratio: a limit of as many FFT pairs as the solver did per iteration
    (TwIST's monotone fallbacks) plus the same arrays; one pair gives the targets' limit."""
    probes = [{"fft_pair_ms": 1.0, "triad_GBps": 8.0}, {"fft_pair_ms": 0.9, "triad_GBps": 10.0}]
    arrays_ms = xlimit.ARRAYS_TOUCHED["twist"] * 512 * 512 * 4 / 10e9 * 1e3
    assert xlimit.limit_ms(512, "twist", probes) == pytest.approx(0.9 + arrays_ms)
    rec = {"method": "twist", "probes": probes, "steady_ms": 2.2,
           "evaluations_per_iteration_steady": 1.13}
    res = {"sizes": [512], "devices": {"0:0": {"name": "impl 0:0", "results": {"512": {
        s: dict(rec) for s, _, _ in xlimit.SOLVERS}}}}}
    xlimit.add_pair_counts(res)
    got = res["devices"]["0:0"]["results"]["512"]["twist-paper"]
    assert got["limit_pairs_ms"] == pytest.approx(1.13 * 0.9 + arrays_ms)
    assert got["steady_x_pairs"] == pytest.approx(2.2 / (1.13 * 0.9 + arrays_ms))
    text = "\n".join(xlimit.pair_lines(res))
    assert f"x{got['steady_x_pairs']:.2f} (1.13)" in text and "| 512^2 | twist-paper |" in text


def test_report_rewritten_from_json(xlimit, tmp_path, capsys):
    """--from-json writes the report files again from a run's JSON without measuring; a file
    that is not a bench_xlimit result is one clear line and exit status 2."""
    from clfza.cl import get_runtime

    run = tmp_path / "run"
    dev = get_runtime().info.index
    assert xlimit.main(["--devices", dev, "--sizes", "32", "--rounds", "1", "--short", "2",
                        "--long", "4", "--out", str(run)]) == 0
    src = next(run.glob("*.json"))
    again = tmp_path / "again"
    assert xlimit.main(["--from-json", str(src), "--out", str(again)]) == 0
    assert sorted(p.suffix for p in again.iterdir()) == [".json", ".md", ".png"]
    assert next(again.glob("*.md")).read_text() == next(run.glob("*.md")).read_text()
    bad = tmp_path / "bad.json"
    bad.write_text('{"sizes": [32]}')
    capsys.readouterr()
    assert xlimit.main(["--from-json", str(bad), "--out", str(tmp_path / "x")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "cannot read a bench_xlimit result" in err[0]
    assert not (tmp_path / "x").exists()


def test_revision_sees_a_modified_clfza(tmp_path, monkeypatch):
    """The benchmarks' record of the code measured (bench_tau.revision): a change under
    clfza/ reads as modified, a change elsewhere does not; by default in this repository."""
    import shutil
    import subprocess

    if shutil.which("git") is None:
        pytest.skip("git is not installed")
    monkeypatch.syspath_prepend(str(BENCH))
    import bench_tau

    assert (bench_tau.ROOT / "clfza" / "__init__.py").is_file()
    repo = tmp_path / "repo"
    for rel in ("clfza/__init__.py", "bench/bench_x.py"):
        (repo / rel).parent.mkdir(parents=True, exist_ok=True)
        (repo / rel).write_text("x = 1\n")

    def git(*args):
        subprocess.run(["git", "-C", str(repo), "-c", "user.name=t", "-c", "user.email=t@t",
                        *args], check=True, capture_output=True)

    git("init", "-q")
    git("add", ".")
    git("commit", "-qm", "start")
    monkeypatch.chdir(repo / "bench")  # where a benchmark script may run from
    assert bench_tau.revision(repo)["clfza_modified"] is False
    (repo / "bench" / "bench_x.py").write_text("x = 2\n")
    assert bench_tau.revision(repo)["clfza_modified"] is False
    (repo / "clfza" / "__init__.py").write_text("x = 2\n")
    rev = bench_tau.revision(repo)
    assert rev["clfza_modified"] is True and len(rev["commit"]) == 40
