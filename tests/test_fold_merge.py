"""Deferred folds (clfza.backends._opencl._Reducer, OpenCLBackend.flush_folds): two reducers'
folds queued together run as one ``sum16x2`` launch per level, and every sum is the one a fold
of its own gives, bit for bit, and within float32 rounding of the numpy float64 reference.

Sizes: 320^2 on CPU devices (fold 16) gives the image reducer two levels and the spectral one
one (the levels of the two folds differ); 96^2 on the GPU path (fold 64, Oclgrind) one each.
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pytest

import clfza
from clfza.backends import get_backend

pytestmark = pytest.mark.agreement  # rerun on every OpenCL device (.ci/run)


def _tv_l1(x: np.ndarray) -> tuple[float, float]:
    """The reference of reg_contrib's sums: circular TV (backward differences) and l1."""
    dx = x - np.roll(x, 1, axis=-1)
    dy = x - np.roll(x, 1, axis=-2)
    return float(np.sum(np.sqrt(dx * dx + dy * dy))), float(np.sum(np.abs(x)))


def _launches(B, fn):
    import pyopencl as cl

    names = []
    launch = cl._cl.enqueue_nd_range_kernel

    def counted(q, k, *a, **kw):
        names.append(k.function_name)
        return launch(q, k, *a, **kw)

    cl._cl.enqueue_nd_range_kernel = counted
    try:
        out = fn()
    finally:
        cl._cl.enqueue_nd_range_kernel = launch
    return out, names


def _pair(B, x, g):
    """The data term's sum (spectral reducer) and the regulariser's (image reducer) of one
    point, read together: their folds are deferred to the first read."""
    data = B.resid_grad(x, g)
    reg = B.reg_value(x)
    assert len(B._folds) == (B.red_s.levels != []) + (B.red.levels != [])
    return data.get(), reg.get()


@pytest.mark.parametrize("frames", [1, 2])
def test_merged_folds_equal_separate_folds_and_the_reference(frames):
    n = 320
    cam = clfza.Camera(pitch=0.01, shape=(n, n), r1=0.2, z1=100.0, z2=3.0, mask="gzp")
    B = get_backend("opencl", cam, frames=frames) if frames > 1 else get_backend("opencl", cam)
    assert B.red.levels and B.red_s.levels  # both fold on the device
    rng = np.random.default_rng(5)
    x_h = rng.standard_normal((frames, n, n))
    y_h = rng.standard_normal((frames, n, n))
    B.set_measurement(y_h if frames > 1 else y_h[0])
    x, g = B.from_host(x_h.reshape(B.cshape)), B.empty()
    B.flush_folds()  # earlier folds (set_measurement's) out of the way
    (data, reg), names = _launches(B, lambda: _pair(B, x, g))
    folds = [k for k in names if k.startswith("sum16")]
    merged = min(len(B.red.levels), len(B.red_s.levels))
    assert folds.count("sum16x2") == merged
    assert len(folds) == max(len(B.red.levels), len(B.red_s.levels)), names
    # each fold alone (read before the other is queued): the same bits
    data1 = B.resid_grad(x, g).get()
    reg1 = B.reg_value(x).get()
    np.testing.assert_array_equal(data, data1)
    np.testing.assert_array_equal(reg, reg1)
    # the float64 references (float32 inputs: per-term rounding ~1e-7, sums of 1e5 terms)
    x32 = x_h.astype(np.float32).astype(np.float64)
    for f in range(frames):
        tv, l1 = _tv_l1(x32[f])
        got = reg if frames == 1 else reg[f]
        np.testing.assert_allclose(got[:2], (tv, l1), rtol=1e-5)
        R = get_backend("numpy", cam)  # float64 reference of the data term's sum
        R.set_measurement(y_h[f])
        want = R.resid_grad(x32[f][None], R.empty()).get()[0]
        np.testing.assert_allclose((data if frames == 1 else data[f])[0], want, rtol=1e-4)


def test_three_pending_folds_pair_then_single():
    """Three reducers pending: the first two share a launch, the third folds alone."""
    n = 320
    cam = clfza.Camera(pitch=0.01, shape=(n, n), r1=0.2, z1=100.0, z2=3.0, mask="gzp")
    B = get_backend("opencl", cam)
    rng = np.random.default_rng(6)
    B.set_measurement(rng.standard_normal((n, n)))
    x, g = B.from_host(rng.standard_normal((1, n, n))), B.empty()
    from clfza.solvers._twist_ops import TwistOps

    TwistOps.for_backend(B)  # builds twist_combine
    reds = [B.red_s, B.red, B.red_rows]
    if any(not r.levels for r in reds):
        pytest.skip("a reducer without a device fold at this size on this device")

    def three():
        d = B.resid_grad(x, g)
        r = B.reg_value(x)
        c = B.launch_rows_reduce("twist_combine", g.buf, x.buf, x.buf, x.buf, B.r(0.0),
                                 B.r(1.0), B.r(0.0), B.i32(1), B.i32(1), B.fpar.buf,
                                 planes=3)
        return d.get(), r.get(), c.get()

    B.flush_folds()
    (d, r, c), names = _launches(B, three)
    assert names.count("sum16x2") >= 1 and "sum16" in names
    np.testing.assert_array_equal(r, B.reg_value(x).get())
    np.testing.assert_array_equal(d, B.resid_grad(x, g).get())


# ----- Oclgrind: the GPU path's merged fold (fold 64) -----------------------------------------


@pytest.mark.oclgrind
def test_merged_fold_clean_under_oclgrind(oclgrind):
    import re

    p = oclgrind([str(Path(__file__).resolve())], timeout=1200)
    assert p.returncode == 0, p.stdout[-2000:] + p.stderr[-4000:]
    assert "device: Oclgrind" in p.stdout, p.stdout
    assert "merged fold ok" in p.stdout, p.stdout[-2000:]
    reports = [ln for ln in p.stderr.splitlines()
               if re.search(r"Invalid (read|write)|data race|out of bounds", ln, re.I)]
    assert not reports, "\n".join(reports[:40])


def _child() -> int:
    import warnings

    warnings.simplefilter("ignore")
    from clfza.cl import get_runtime

    rt = get_runtime()
    print(f"device: {rt.info.name} ({rt.info.kind})", flush=True)
    n = 96  # GPU path: 96^2 pixels and 49 x 96 frequencies, both > 4096: one fold each
    cam = clfza.Camera(pitch=0.01, shape=(n, n), r1=0.2, z1=100.0, z2=3.0, mask="gzp")
    rng = np.random.default_rng(7)
    for frames in (1, 2):
        B = get_backend("opencl", cam, fft="device", frames=frames)
        assert B.red.levels and B.red_s.levels, (B.red.levels, B.red_s.levels)
        x_h = rng.standard_normal((frames, n, n))
        B.set_measurement(rng.standard_normal((frames, n, n)) if frames > 1
                          else rng.standard_normal((n, n)))
        x, g = B.from_host(x_h.reshape(B.cshape)), B.empty()
        B.flush_folds()
        (data, reg), names = _launches(B, lambda B=B, x=x, g=g: _pair(B, x, g))
        assert names.count("sum16x2") == 1, names
        np.testing.assert_array_equal(reg, B.reg_value(x).get())
        np.testing.assert_array_equal(data, B.resid_grad(x, g).get())
        x32 = x_h.astype(np.float32).astype(np.float64)
        for f in range(frames):
            got = reg if frames == 1 else reg[f]
            np.testing.assert_allclose(got[:2], _tv_l1(x32[f]), rtol=1e-5)
    print("merged fold ok", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(_child())
