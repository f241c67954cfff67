"""Batched TwIST on the GPU code paths under Oclgrind (``-m oclgrind``): no out-of-bounds
access, no data race, and the batch equal to one frame at a time.

Oclgrind simulates a device that reports itself as a GPU, so the batch takes the GPU paths
there: the split Chambolle kernels (tv.cl's chambolle_first/step/step_change/finish with a
frame dimension, per-frame step and lam, the warm dual's per-frame inner stop), the
row-blocked twist_combine, mask_past over the frames, the device FFT over the frames' planes.
The CPU devices' one-pass prox (tv_fused.cl's chambolle2_fused) and twist_combine16 are
launched directly on a batch of two frames with their own factors, one of them off. A child
process runs them at 32^2 (as tests/test_oclgrind.py: Oclgrind's ICD alone,
``OCLGRIND_DATA_RACES=1``); the test fails on any such report or disagreement.
"""

from __future__ import annotations

import sys
from pathlib import Path

import pytest
from _batch_frames import assert_oclgrind_clean, oclgrind_frames


@pytest.mark.oclgrind
def test_batched_twist_clean_under_oclgrind(oclgrind):
    p = oclgrind([str(Path(__file__).resolve())])
    assert_oclgrind_clean(p)
    assert p.stdout.count("batched twist") == 2, p.stdout[-2000:]
    assert "batched fused prox" in p.stdout, p.stdout[-2000:]
    assert "batched combine16" in p.stdout, p.stdout[-2000:]


def _child() -> int:
    import warnings

    import numpy as np

    import clfza
    from clfza.backends import ProxState, get_backend
    from clfza.backends._opencl import FUSED_PROX_COLUMNS, build_program
    from clfza.cl import DeviceArray
    from clfza.solvers import TwistOps, run_solver, run_solver_batch

    warnings.simplefilter("ignore")
    rt, rng, cam, frames, taus = oclgrind_frames()
    # paper mode (fallbacks per frame), and efficient mode: the warm dual with the per-frame
    # inner stop (chambolle_step_change) and 3 inner steps (duals realigned)
    for extra in ({}, {"mode": "efficient", "tv_iters": 3}):
        kw = dict(iters=5, model="tf", fft="device", backend="opencl", **extra)
        got = run_solver_batch(frames, cam, "twist", tau=taus, **kw)
        err = 0.0
        for g, f, t in zip(got, frames, taus, strict=True):
            assert g.info.stats["batch"]["frames"] == 3, g.info.stats["batch"]
            ref = run_solver(f, cam, "twist", tau=t, **kw)
            scale = max(1.0, float(np.abs(ref.image).max()))
            e = float(np.abs(g.image - ref.image).max()) / scale
            assert e <= 1e-5, e
            assert g.info.stats["fallbacks"] == ref.info.stats["fallbacks"]
            assert g.info.evaluations == ref.info.evaluations
            err = max(err, e)
        print("batched twist", extra, f"{err:.1e}", flush=True)
    # the CPU devices' one-pass prox on a batch of 2 frames, launched directly: per-frame step
    # and lam from fpar, frame 1 off (its output untouched)
    kern = build_program(rt, "tv_fused", np.float32, 1).chambolle2_fused
    shape, strip, F = (21, 29), 8, 2
    x = rng.standard_normal((F,) + shape)
    g = 0.1 * rng.standard_normal((F,) + shape)
    xd, gd = (DeviceArray.from_host(rt, a.astype(np.float32)) for a in (x, g))
    out = DeviceArray.from_host(rt, np.zeros((F,) + shape, np.float32))
    grid = (-(-shape[1] // FUSED_PROX_COLUMNS), -(-shape[0] // strip), F)
    s, th = (0.5, 0.25), (0.005, 0.002)
    fpar = DeviceArray.from_host(rt, np.array([[1, s[0], 2 / th[0], 1],
                                               [1, s[1], 2 / th[1], 0]], np.float32))
    kern(rt.queue, grid, None, out.buf, xd.buf, gd.buf, np.float32(1.0), np.float32(1.0),
         np.int32(strip), np.int32(3), np.int32(1), fpar.buf, np.int32(shape[1]),
         np.int32(shape[0]))
    camf = clfza.Camera(pitch=0.01, shape=shape, r1=0.2, z1=100.0, z2=3.0, mask="gzp")
    N = get_backend("numpy", camf)
    ref = N.empty()
    N.prox_step("tv", x[0][None], g[0][None], s[0], th[0], ref, 2, ProxState())
    og = out.get().astype(np.float64)
    err = float(np.abs(og[0] - ref[0]).max()) / max(1.0, float(np.abs(ref).max()))
    assert err <= 2e-5, err
    assert not og[1].any()  # the frame turned off: nothing written
    print("batched fused prox", shape, f"{err:.1e}", flush=True)
    # twist_combine16 on a batch of 2 frames (a 13-column tail), frame 0 off
    kern = build_program(rt, "elementwise", np.float32, 1).twist_combine16
    shape = (5, 29)
    h = [rng.standard_normal((F,) + shape) for _ in range(3)]
    d = [DeviceArray.from_host(rt, a.astype(np.float32)) for a in h]
    out = DeviceArray.from_host(rt, np.zeros((F,) + shape, np.float32))
    grid = (-(-shape[1] // 16), shape[0], F)
    contrib = DeviceArray.from_host(rt, np.zeros(F * 3 * grid[0] * grid[1], np.float32))
    fpar = DeviceArray.from_host(rt, np.array([[1, 1, 1, 0], [1, 1, 1, 1]], np.float32))
    kern(rt.queue, grid, None, out.buf, *(a.buf for a in d), np.float32(1 - 1.96),
         np.float32(1.96 - 3.92), np.float32(3.92), np.int32(1), np.int32(1), fpar.buf,
         contrib.buf, np.int32(shape[1]), np.int32(shape[0]))
    camf = clfza.Camera(pitch=0.01, shape=shape, r1=0.2, z1=100.0, z2=3.0, mask="gzp")
    ref = np.empty((1,) + shape)
    sums = TwistOps.for_backend(get_backend("numpy", camf)).combine(
        ref, *(a[1][None] for a in h), 1.96, 3.92, True)
    og = out.get().astype(np.float64)
    err = float(np.abs(og[1] - ref[0]).max()) / max(1.0, float(np.abs(ref).max()))
    assert err <= 2e-6, err
    assert not og[0].any()
    c = contrib.get().astype(np.float64).reshape(F, 3, -1).sum(axis=2)
    assert np.allclose(c[1], sums.get()[:3], rtol=1e-5), (c[1], sums.get())
    print("batched combine16", shape, f"{err:.1e}", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(_child())
