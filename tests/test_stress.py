"""Numerical stability stress tests (issues 5 and 14); run with ``pytest -m stress``.

Each case must give a finite image or a :class:`~clfza.ClfzaError` with a message (invalid
input); methods that promise a non-increasing objective (TwIST with ``monotone=True``, MFISTA)
must deliver one, on both models. Cases run in child processes so that a native crash fails
its case instead of the session. The cases are :func:`clfza.benchmarks._stability.cases` and
the exact-model categories of ``bench/stress_report.py`` (the experiment preset on small odd,
prime and even grids; measured PSFs; ADMM's options; extreme tau, frames and dynamic range;
``tau="auto"`` on both models), which also writes the report with the counts.

Cases that show a known bug run as strict xfails with the bug as the reason
(``stress_report.known_bug``), so that they stay visible and a fix is noticed.
"""

from __future__ import annotations

import functools
import importlib.util
from pathlib import Path

import pytest

from clfza.benchmarks import _stability as stability

pytestmark = pytest.mark.stress


def _bench_module():
    path = Path(__file__).resolve().parents[1] / "bench" / "stress_report.py"
    spec = importlib.util.spec_from_file_location("clfza_bench_stress_report", path)
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


SR = _bench_module()
CASES = stability.cases("test")
CATEGORIES = sorted({c.category for c in CASES})
EXACT = SR.exact_cases("test")
BUGS = [i for i, c in enumerate(EXACT) if SR.known_bug(c)]


def _problems(cases, idx, rows) -> list[str]:
    """Why the cases ``idx`` (with their result ``rows``) fail the stress contract: NaN/Inf,
    crash, a clear error where an image was expected (or the reverse), an unclear message,
    an objective rise where monotonicity is promised."""
    bad = []
    for i, r in zip(idx, rows, strict=True):
        c = cases[i]
        if r["outcome"] not in ("finite", "clear_error"):
            bad.append(f"{c.id}: {r['outcome']} {r.get('message', '')}")
        if r["outcome"] == "clear_error" and len(r["message"]) <= 15:
            bad.append(f"{c.id}: unclear message {r['message']!r}")
        if c.expect == "error" and r["outcome"] != "clear_error":
            bad.append(f"{c.id}: expected a clear error, got {r['outcome']}")
        if r.get("monotone_violations"):
            bad.append(f"{c.id}: {r['monotone_violations']} rise(s), largest relative "
                       f"{r['largest_relative_rise']:.2e}")
    return bad


@pytest.mark.parametrize("category", CATEGORIES)
def test_category_finite_or_clear_error(category):
    idx = [i for i, c in enumerate(CASES) if c.category == category]
    rows = stability.run_isolated("test", idx, log=lambda *a: None)
    bad = _problems(CASES, idx, rows)
    assert not bad, "\n".join(bad)


@pytest.mark.parametrize("category", SR.CATEGORIES)
def test_exact_category_finite_or_clear_error(category):
    idx = [i for i, c in enumerate(EXACT) if c.category == category and i not in BUGS]
    rows = SR.run_isolated("test", idx, log=lambda *a: None)
    bad = _problems(EXACT, idx, rows)
    assert not bad, "\n".join(bad)
    if category in SR.PAIRED:
        gaps = [f"{g['name']} {g['key']} against {g['reference']}: {g['psnr_f32']:.3f} / "
                f"{g['psnr_f64']:.3f} dB" for g in SR.paired_gaps(rows)
                if g["psnr_gap_db"] > 0.1]
        assert not gaps, "float32/float64 PSNR gap > 0.1 dB:\n" + "\n".join(gaps)


@functools.lru_cache(maxsize=1)
def _bug_rows() -> dict[int, dict]:
    return dict(zip(BUGS, SR.run_isolated("test", BUGS, log=lambda *a: None), strict=True))


@pytest.mark.parametrize("i", [pytest.param(
    i, id=EXACT[i].id, marks=pytest.mark.xfail(strict=True, reason=SR.known_bug(EXACT[i])))
    for i in BUGS])
def test_exact_known_bug(i):
    bad = _problems(EXACT, [i], [_bug_rows()[i]])
    assert not bad, "\n".join(bad)


@pytest.mark.parametrize("key", ["twist-tv-paper", "twist-l1", "fista-tv", "admm-tv"])
def test_float32_against_float64_1000_iterations(key):
    p = stability.precision_gap(key, n=128, iters=1000)
    assert p["finite"]
    assert p["psnr_gap_db"] < 0.1, p
    assert p["image_rel_diff"] < 1e-2, p
    if p["objective_gap"] is not None:
        assert p["objective_gap"] < 1e-3, p
    for tag, rises in p["monotone_rises"].items():
        assert not rises, f"{key} {tag}: {rises} objective rise(s) in 1000 iterations"




@pytest.mark.parametrize("key, extra", [
    pytest.param("twist-tv-paper", {}, id="twist-tv-paper"),
    pytest.param("fista-tv", {}, id="fista-tv"),
    pytest.param("admm-tv", {}, id="admm-tv"),
    pytest.param("admm-tv", {"average": False}, id="admm-tv-last-iterate")])
def test_exact_float32_against_float64_1000_iterations(key, extra):
    """The exact model (experiment preset on 64^2): OpenCL float32 against the numpy float64
    reference, 1000 iterations without early stop."""
    p = SR.exact_precision_gap(key, n=64, iters=1000, **extra)
    assert p["finite"]
    for tag, rises in p["monotone_rises"].items():
        assert not rises, f"{key} {tag}: {rises} objective rise(s) in 1000 iterations"
    assert p["psnr_gap_db"] < 0.1, p
    assert p["image_rel_diff"] < 1e-2, p
