"""The Wiener ``lam`` search's evaluations (clfza.solvers._wiener._lam_steps): the bracket's
decisions taken on the points Brent's search evaluates first, each distinct ``lam`` evaluated
once. The search must return, bit for bit, the ``(lam, ratio)`` of its specification (decide
on ``lo`` and ``hi`` themselves, then Brent on ``log lam`` from ``[log lo, log hi]``, then the
ratio at the root), with fewer evaluations, including where a decision value lies within
DECIDE_MARGIN of the target (then re-evaluated at the end point)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from clfza.errors import ClfzaError
from clfza.solvers._wiener import LAM_FLOOR, LAM_XTOL, _lam_steps, brentq_steps


def _specification(hmax, target, norm):
    """The search as specified: every evaluation asked for, none remembered."""
    lo, hi = LAM_FLOOR * hmax, 1e6 * hmax
    if not target > 0 or (yield lo) >= target:
        lam = lo
    elif (yield hi) <= target:
        lam = hi
    else:
        search = brentq_steps(math.log(lo), math.log(hi), LAM_XTOL)
        u = next(search)
        try:
            while True:
                fx = math.log((yield math.exp(u)) / target)
                if math.isnan(fx):
                    raise ClfzaError("the Wiener lam search met a NaN residual")
                u = search.send(fx)
        except StopIteration as e:
            lam = math.exp(e.value)
    ratio = (yield lam) / norm if norm > 0 else float("inf")
    return float(lam), float(ratio)


def _run(gen, f):
    asked = []
    try:
        x = next(gen)
        while True:
            asked.append(x)
            x = gen.send(f(x))
    except StopIteration as e:
        return e.value, asked


def _outcome(gen, f):
    asked = []

    def g(lam):
        asked.append(lam)
        return f(lam)
    try:
        return _run(gen, g)[0], asked
    except ClfzaError as e:
        return str(e), asked


def _discrepancy(rng, n=4000):
    """A predicted residual as wiener_lams sums it: sum w (lam / (r + lam))^2."""
    r = rng.uniform(0, 1, n) ** 4 * 10 ** rng.uniform(-3, 3)
    w = rng.exponential(1.0, n)

    def f(lam):
        fl = lam / (r + lam)
        return float(np.sum(w * fl * fl))
    return f, float(w.sum())


def test_the_same_lam_and_ratio_as_the_specification_with_fewer_evaluations():
    rng = np.random.default_rng(11)
    kinds = set()
    for _ in range(300):
        f, total = _discrepancy(rng)
        hmax = 10 ** rng.uniform(-4, 4)
        # targets below f(lo) (lam at its floor), inside, above f(hi) (its ceiling), zero
        target = total * 10 ** rng.uniform(-14, 0.3) if rng.random() > 0.05 else 0.0
        norm = target / 0.5 if rng.random() > 0.05 else 0.0
        want, asked_spec = _run(_specification(hmax, target, norm), f)
        got, asked = _run(_lam_steps(hmax, target, norm), f)
        assert got == want
        assert len(set(asked)) == len(asked) <= len(asked_spec)
        lo, hi = LAM_FLOOR * hmax, 1e6 * hmax
        kinds.add("floor" if want[0] == lo else "ceiling" if want[0] == hi else "brent")
        if target > 0 and want[0] not in (lo, hi):  # Brent: the two bracket points and
            # the ratio's were evaluated already
            assert len(asked) <= len(asked_spec) - 2 - (norm > 0)
    assert kinds == {"floor", "ceiling", "brent"}


@pytest.mark.parametrize("end", ["lo", "hi"])
def test_a_decision_at_the_margin_is_taken_on_the_end_point(end):
    """A target equal to the residual at exp(log(end)) (or a hair from it) is decided on
    the residual at the end point itself, as the specification decides."""
    rng = np.random.default_rng(12)
    for _ in range(40):
        f, _ = _discrepancy(rng)
        hmax = 10 ** rng.uniform(-3, 3)
        e = LAM_FLOOR * hmax if end == "lo" else 1e6 * hmax
        for target in (f(math.exp(math.log(e))), f(e), f(e) * (1 + 1e-15), f(e) * (1 - 1e-15)):
            want, got = (_outcome(g(hmax, target, 2 * target), f)
                         for g in (_specification, _lam_steps))
            assert got[0] == want[0]  # the same (lam, ratio), or the same error (a target
            # between the residuals at lo and at exp(log(lo)): Brent's bracket has no sign
            # change, in the specification too)
            assert e in got[1]  # the end point itself was evaluated for the decision


def test_non_finite_residuals_as_the_specification():
    with pytest.raises(ClfzaError, match="NaN residual"):
        _run(_lam_steps(1.0, 1.0, 2.0), lambda lam: float("nan"))
    got, _ = _run(_lam_steps(1.0, 1.0, 2.0), lambda lam: float("inf"))
    assert got == _run(_specification(1.0, 1.0, 2.0), lambda lam: float("inf"))[0]
