"""Batched FISTA on the GPU code paths under Oclgrind (``-m oclgrind``): no out-of-bounds
access, no data race, and the batch equal to one frame at a time.

Oclgrind simulates a device that reports itself as a GPU, so the batch takes the GPU paths
there: the split FGP kernels (tv.cl's fgp_step and fgp_finish with a frame dimension), the
device FFT over the frames' planes, the device-chosen work-groups, the per-frame
extrapolation. The CPU devices' one-pass FGP (tv_fused.cl's fgp2_fused) is launched directly
on a batch of two frames with their own weights, one of them stopped. A child process runs
them at 32^2 (as tests/test_oclgrind.py: Oclgrind's ICD alone, ``OCLGRIND_DATA_RACES=1``);
the test fails on any such report or disagreement.
"""

from __future__ import annotations

import sys
from pathlib import Path

import pytest
from _batch_frames import assert_oclgrind_clean, oclgrind_frames


@pytest.mark.oclgrind
def test_batched_fista_clean_under_oclgrind(oclgrind):
    p = oclgrind([str(Path(__file__).resolve())])
    assert_oclgrind_clean(p)
    assert p.stdout.count("batched fista") == 2, p.stdout[-2000:]
    assert "batched fused fgp" in p.stdout, p.stdout[-2000:]


def _child() -> int:
    import warnings

    import numpy as np

    import clfza
    from clfza.backends import ProxState, get_backend
    from clfza.backends._opencl import FUSED_FGP_COLUMNS, build_program
    from clfza.cl import DeviceArray
    from clfza.solvers import run_solver, run_solver_batch

    warnings.simplefilter("ignore")
    rt, rng, cam, frames, taus = oclgrind_frames()
    # grey frames with their own tau (nonneg: the monotone step rejects), and the split FGP
    # with 3 inner iterations (its momentum array)
    for extra in ({"nonneg": True}, {"tv_iters": 3}):
        kw = dict(iters=6, min_iters=6, stop="none", model="tf", fft="device",
                  backend="opencl", **extra)
        got = run_solver_batch(frames, cam, "fista", tau=taus, **kw)
        err = 0.0
        for g, f, t in zip(got, frames, taus, strict=True):
            assert g.info.stats["batch"]["frames"] == 3, g.info.stats["batch"]
            ref = run_solver(f, cam, "fista", tau=t, **kw)
            scale = max(1.0, float(np.abs(ref.image).max()))
            e = float(np.abs(g.image - ref.image).max()) / scale
            assert e <= 1e-5, e
            assert g.info.stats["rejected"] == ref.info.stats["rejected"]
            err = max(err, e)
        print("batched fista", extra, f"{err:.1e}", flush=True)
    # the CPU devices' one-pass FGP on a batch of 2 frames, launched directly: per-frame
    # weights from fpar, frame 1 stopped (its outputs untouched)
    kern = build_program(rt, "tv_fused", np.float32, 1).fgp2_fused
    shape, strip, pq, F = (21, 29), 8, 29, 2
    b = rng.standard_normal((F,) + shape)
    p = 0.3 * rng.standard_normal((2, F) + shape)
    bd = DeviceArray.from_host(rt, b.astype(np.float32))
    p0, p1 = (DeviceArray.from_host(rt, a.astype(np.float32)) for a in p)
    z = DeviceArray.from_host(rt, np.zeros((F,) + shape, np.float32))
    q0, q1 = (DeviceArray.from_host(rt, np.zeros((F,) + shape, np.float32)) for _ in range(2))
    grid = (-(-shape[1] // FUSED_FGP_COLUMNS), -(-shape[0] // strip), F)
    contrib = DeviceArray.from_host(rt, np.zeros(F * 2 * grid[0] * grid[1], np.float32))
    weights = (0.3, 0.7)
    fpar = DeviceArray.from_host(rt, np.array([[1, 1, weights[0], 1], [1, 1, weights[1], 0]],
                                              np.float32))
    kern(rt.queue, grid, None, z.buf, q0.buf, q1.buf, bd.buf, p0.buf, p1.buf, np.float32(1.0),
         np.int32(1), np.int32(strip), np.int32(3), np.int32(1), fpar.buf, contrib.buf,
         np.int32(shape[1]), np.int32(shape[0]), np.int32(pq))
    cam = clfza.Camera(pitch=0.01, shape=shape, r1=0.2, z1=100.0, z2=3.0, mask="gzp")
    N = get_backend("numpy", cam)
    st = ProxState(warm=True)
    st.arrays["p"], st.valid = p[:, 0:1], True
    ref = N.empty()
    N.fgp_prox("tv", ref, b[0][None], weights[0], 2, st, True)
    zg = z.get().astype(np.float64)
    err = float(np.abs(zg[0] - ref[0]).max()) / max(1.0, float(np.abs(ref).max()))
    assert err <= 2e-5, err
    assert not zg[1].any() and not q0.get()[1].any()  # the stopped frame: nothing written
    print("batched fused fgp", shape, f"{err:.1e}", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(_child())
