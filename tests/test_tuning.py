"""Kernel variants chosen per device (clfza.backends._tuning): every variant against the numpy
float64 reference at small sizes, the cached choice is the one a backend uses, the first use
measures and caches, CLFZA_TUNE overrides, and ``clfza tune`` / ``clfza info`` show the choices.

Tolerances as in test_kernels_solvers.py (float32: 1e-5 of the data scale element-wise and for
sums, 2e-5 for the TV prox with lam = 400); a variant changes only the order of work (launch
shapes, rows per partial sum, strips), never the arithmetic per pixel, except the fused prox,
which the reference checks at the same tolerance as the three-kernel one."""

from __future__ import annotations

import json

import numpy as np
import pytest

from clfza import Camera
from clfza.backends import _tuning as tuning
from clfza.backends import get_backend
from clfza.backends._base import ProxState
from clfza.backends._opencl import OpenCLBackend
from clfza.errors import ClfzaError
from clfza.solvers._twist_ops import TwistOps

pytestmark = pytest.mark.agreement  # rerun on every OpenCL device (.ci/run)

SHAPE = (48, 64)


def _variants():
    out = [dict(tuning.DEFAULTS)]
    cands = dict(tuning.CANDIDATES)
    cands["local2d"] = tuple(cands["local2d"]) + tuning.GPU_LOCAL2D + ("7x5",)  # 7x5: falls back
    cands["local1d"] = tuple(cands["local1d"]) + tuning.GPU_LOCAL1D + (100,)
    for k, vs in cands.items():
        for v in vs:
            if v != tuning.DEFAULTS[k]:
                out.append({**tuning.DEFAULTS, k: v})
    out.append({"prox": "fused", "strip": 8, "rows": 4, "local2d": "auto", "local1d": 256,
                "fgp": "fused", "fgp_strip": 16, "prox_prefetch": "r4",
                "fgp_prefetch": "rw4"})
    out.append({"prox": "split", "strip": 8, "rows": 1, "local2d": "16x16", "local1d": 1024,
                "fgp": "split", "fgp_strip": 64, "prox_prefetch": "off",
                "fgp_prefetch": "r2"})
    out.append({**tuning.DEFAULTS, "fgp": "fused", "fgp_prefetch": "r2"})
    return out


VARIANTS = _variants()


def close(a, b, tol=1e-5):
    scale = max(1.0, float(np.max(np.abs(b))))
    assert np.max(np.abs(a - b)) <= tol * scale, np.max(np.abs(a - b)) / scale


@pytest.fixture(scope="module")
def pair():
    cam = Camera(pitch=0.01, shape=SHAPE, r1=0.2, z1=100.0, z2=3.0, mask="gzp")
    B = OpenCLBackend(cam, 1, tune=tuning.DEFAULTS)
    N = get_backend("numpy", cam)
    return B, N


@pytest.mark.parametrize("tune", VARIANTS,
                         ids=[",".join(f"{k}={v}" for k, v in t.items()
                                       if v != tuning.DEFAULTS[k]) or "defaults"
                              for t in VARIANTS])
def test_every_variant_agrees_with_reference(pair, tune):
    B, N = pair
    B.apply_tuning(tune)
    assert B.tune == tune
    ny, nx = SHAPE
    assert B.rows == next(r for r in range(tune["rows"], 0, -1) if ny % r == 0)
    assert B.prox_is_fused("tv", 2, ProxState()) == (tune["prox"] == "fused" and B.rt.is_cpu)
    rng = np.random.default_rng(5)
    x, g, a = (rng.standard_normal((1,) + SHAPE) for _ in range(3))
    xd, gd, ad = B.from_host(x), B.from_host(g * 0.1), B.from_host(a)
    ob, on = B.empty(), N.empty()
    for th in (0.005, 0.5):  # paper mode's prox (fused or three kernels), lam = 400 and 4
        assert B.prox_step("tv", xd, gd, 0.5, th, ob, 2, ProxState()) == 2
        N.prox_step("tv", x, g * 0.1, 0.5, th, on, 2, ProxState())
        close(B.to_host(ob), on, 2e-5)
    sb, sn = ProxState(warm=True), ProxState(warm=True)  # the 2-D kernels, warm dual
    for _ in range(2):
        B.prox_step("tv", xd, gd, 0.5, 0.05, ob, 3, sb)
        N.prox_step("tv", x, g * 0.1, 0.5, 0.05, on, 3, sn)
    close(B.to_host(ob), on, 2e-5)
    vb = TwistOps.for_backend(B).combine(ob, ad, xd, gd, 1.96, 3.92, True, True).get()
    vn = TwistOps.for_backend(N).combine(on, a, x, g * 0.1, 1.96, 3.92, True, True).get()
    close(B.to_host(ob), on)
    assert vb[0] == pytest.approx(vn[0], rel=1e-5)
    assert vb[1] == vn[1]
    assert vb[2] == pytest.approx(vn[2], rel=1e-5)
    assert B.fgp_is_fused("tv", 2) == (tune["fgp"] == "fused" and B.rt.is_cpu)
    sb, sn = ProxState(warm=True), ProxState(warm=True)  # FISTA's prox (fused or 3 kernels)
    for nonneg in (False, True):
        vb = B.fgp_prox("tv", ob, ad, 0.3, 2, sb, nonneg).get()
        vn = N.fgp_prox("tv", on, a, 0.3, 2, sn, nonneg).get()
        close(B.to_host(ob), on, 2e-5)
        assert vb[:2] == pytest.approx(vn[:2], rel=1e-5)
    B.prox_step("l1", xd, ad, 0.5, 0.3, ob, 1, ProxState())  # 1-D kernels
    N.prox_step("l1", x, a, 0.5, 0.3, on, 1, ProxState())
    close(B.to_host(ob), on)
    B.lincomb(ob, 0.5, xd, -2.0, ad, 0.25, gd)
    N.lincomb(on, 0.5, x, -2.0, a, 0.25, g * 0.1)
    close(B.to_host(ob), on)
    assert B.reg_value(xd).get()[0] == pytest.approx(N.reg_value(x).get()[0], rel=1e-5)


@pytest.fixture
def cache(monkeypatch, tmp_path):
    monkeypatch.setenv("CLFZA_CACHE_DIR", str(tmp_path))
    monkeypatch.delenv("CLFZA_TUNE", raising=False)
    return tmp_path


def _cam(shape=SHAPE):
    return Camera(pitch=0.01, shape=shape, r1=0.2, z1=100.0, z2=3.0, mask="gzp")


def test_cached_choice_is_used(cache, rt, monkeypatch):
    """A backend takes its device's cached choices for its size class (and not the other
    class's), without measuring."""
    monkeypatch.setattr(tuning, "measure", lambda *a, **k: pytest.fail("measured"))
    small = {"prox": "split", "strip": 8, "rows": 1, "local2d": "auto", "local1d": 256,
             "fgp": "split", "fgp_strip": 16, "prox_prefetch": "off", "fgp_prefetch": "off"}
    large = {"prox": "fused", "strip": 16, "rows": 4, "local2d": "64x1", "local1d": "auto",
             "fgp": "fused", "fgp_strip": 64, "prox_prefetch": "r2", "fgp_prefetch": "rw4"}
    key = tuning.tuning_key(rt)
    (cache / "tuning.json").write_text(json.dumps(
        {key: {"small": {"choices": small}, "large": {"choices": large}}}))
    B = get_backend("opencl", _cam())
    assert B.tune == small
    assert not B.prox_is_fused("tv", 2, ProxState()) and not B.fgp_is_fused("tv", 2)
    assert B.rows == 1 and B._lw is None and B._l1 == (256,)
    monkeypatch.setattr(tuning, "SMALL_MAX", 40 * 64)  # SHAPE is now "large"
    B = get_backend("opencl", _cam())
    assert B.tune == large
    assert B.prox_is_fused("tv", 2, ProxState()) == B.rt.is_cpu
    assert B.fgp_is_fused("tv", 2) == B.rt.is_cpu and B.fgp_strip == 64
    assert B.strip == 16 and B.rows == 4 and B._l1 is None
    assert [int(v) for v in B._prox_pf] == [2, 0] and [int(v) for v in B._fgp_pf] == [4, 1]
    # CLFZA_TUNE pins a choice over the cache
    monkeypatch.setenv("CLFZA_TUNE", "strip=8,local1d=1024")
    B = get_backend("opencl", _cam())
    assert B.tune == {**large, "strip": 8, "local1d": 1024} and B._l1 == (1024,)
    monkeypatch.setenv("CLFZA_TUNE", "defaults")
    assert get_backend("opencl", _cam()).tune == tuning.DEFAULTS


def test_first_use_measures_and_caches(cache, rt, monkeypatch):
    monkeypatch.setitem(tuning.CLASS_SIZE, "small", 64)
    got = tuning.choices(rt, *SHAPE, OpenCLBackend)
    entry = json.loads((cache / "tuning.json").read_text())[tuning.tuning_key(rt)]["small"]
    assert entry["choices"] == got and entry["size"] == 64
    expect = {"local1d", "local2d", "rows"} | ({"strip", "prox", "fgp_strip", "fgp",
                                                "prox_prefetch", "fgp_prefetch"}
                                               if rt.is_cpu else set())
    assert set(entry["ms"]) == expect
    for param, med in entry["ms"].items():
        assert set(med) == {str(c) for c in tuning.candidates(rt)[param]}
        assert all(v > 0 for v in med.values())
    monkeypatch.setattr(tuning, "measure", lambda *a, **k: pytest.fail("measured twice"))
    assert tuning.choices(rt, *SHAPE, OpenCLBackend) == got
    assert get_backend("opencl", _cam()).tune == got


def test_tune_env_parsing(monkeypatch):
    monkeypatch.setenv("CLFZA_TUNE", "prox=split, strip=8")
    assert tuning.overrides() == ({"prox": "split", "strip": 8}, "tune")
    monkeypatch.setenv("CLFZA_TUNE", "cached")
    assert tuning.overrides() == ({}, "cached")
    monkeypatch.setenv("CLFZA_TUNE", "local2d=16x16,local1d=auto,rows=4")
    assert tuning.overrides() == ({"local2d": "16x16", "local1d": "auto", "rows": 4}, "tune")
    monkeypatch.setenv("CLFZA_TUNE", "fgp_prefetch=rw4,prox_prefetch=off")
    assert tuning.overrides() == ({"fgp_prefetch": "rw4", "prox_prefetch": "off"}, "tune")
    assert [tuning.prefetch_args(v) for v in ("off", "r2", "rw4", "r12")] == [
        (0, 0), (2, 0), (4, 1), (12, 0)]
    for bad in ("colour=blue", "rows=two", "prox=fast", "local2d=wide", "strip=0", "strip",
                "fgp_prefetch=4", "fgp_prefetch=w4", "prox_prefetch=r0", "prox_prefetch=rw"):
        monkeypatch.setenv("CLFZA_TUNE", bad)
        with pytest.raises(ClfzaError, match="CLFZA_TUNE"):
            tuning.overrides()


def test_cli_tune_and_info(cache, rt, monkeypatch, capsys):
    from clfza.cl import _runtime as runtime
    from clfza.cli import main

    monkeypatch.setitem(tuning.CLASS_SIZE, "small", 64)
    monkeypatch.setattr(runtime, "measure_device", lambda index, *a, **k: 1.0)  # info's scores
    assert main(["tune", "--size", "small"]) == 0
    out = capsys.readouterr().out
    assert "small:" in out and "rows" in out and "local2d" in out and "tuning.json" in out
    assert main(["info"]) == 0
    out = capsys.readouterr().out
    assert "tuning (small, measured at 64^2)" in out
