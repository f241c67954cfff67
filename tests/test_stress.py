"""Numerical stability stress tests (issue 5, item 4); run with ``pytest -m stress``.

Each case must give a finite image or a :class:`~clfza.ClfzaError` with a message (invalid
input); methods that promise a non-increasing objective (TwIST with ``monotone=True``, MFISTA)
must deliver one. Cases run in child processes so that a native crash fails its case instead
of the session. ``bench/stress_report.py`` runs the same cases at a larger size and writes the
report with the counts.
"""

from __future__ import annotations

import pytest

from clfza.benchmarks import stability

pytestmark = pytest.mark.stress

CASES = stability.cases("test")
CATEGORIES = sorted({c.category for c in CASES})


@pytest.mark.parametrize("category", CATEGORIES)
def test_category_finite_or_clear_error(category):
    idx = [i for i, c in enumerate(CASES) if c.category == category]
    rows = stability.run_isolated("test", idx, log=lambda *a: None)
    bad = [f"{CASES[i].id}: {r['outcome']} {r.get('message', '')}"
           for i, r in zip(idx, rows, strict=True)
           if r["outcome"] not in ("finite", "clear_error")]
    assert not bad, "\n".join(bad)
    for i, r in zip(idx, rows, strict=True):
        if r["outcome"] == "clear_error":
            assert len(r["message"]) > 15, f"{CASES[i].id}: unclear message {r['message']!r}"
        if CASES[i].expect == "error":
            assert r["outcome"] == "clear_error", CASES[i].id
    rises = [f"{CASES[i].id}: {r['monotone_violations']} rise(s), largest relative "
             f"{r['largest_relative_rise']:.2e}" for i, r in zip(idx, rows, strict=True)
             if r.get("monotone_violations")]
    assert not rises, "\n".join(rises)


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
