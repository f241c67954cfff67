"""Batched FISTA (issue 37): FISTA on the transfer-function model for a stack of frames, one
launch per step for all of them.

The reference of a batched solve is each frame's one-frame solve: the batch must give the
same images, iteration counts, stop reasons, objective histories and rejected-step counts
(MFISTA's monotone step, decided per frame) to float32 rounding; on CPU devices they are the
same kernels on the same values, so the images are bit-identical there. The batch-ready
kernels (kernels/tv.cl's fgp_step/fgp_finish, tv_fused.cl's fgp2_fused with a frame
dimension and per-frame weights, elementwise.cl's fista_extrap with per-frame coefficients)
are checked against the one-frame launches and the numpy float64 reference. Agreement tests:
.ci/run reruns them on every OpenCL implementation; tests/test_batch_fista_oclgrind.py runs
the batch on the GPU code paths under Oclgrind.
"""

from __future__ import annotations

import numpy as np
import pytest
from _batch_frames import N
from _batch_frames import frames as _frames

import clfza
from clfza.backends import ProxState, get_backend
from clfza.solvers import FistaOps, run_solver, run_solver_batch

pytestmark = pytest.mark.agreement

KW = dict(model="tf", backend="opencl", iters=60, tol=2e-4)


@pytest.fixture(scope="module")
def cam():
    return clfza.Camera.preset("simulation").with_shape((N, N))


def _same(batched, single, rtol: float = 1e-5) -> None:
    """Equal to float32 rounding: images (relative to the frame's scale), iterations, stop
    reasons, objective histories, evaluations and rejected steps."""
    scale = max(float(np.abs(single.image).max()), 1e-30)
    np.testing.assert_allclose(batched.image, single.image, rtol=0, atol=rtol * scale)
    assert batched.info.iterations == single.info.iterations
    assert batched.info.stop_reason == single.info.stop_reason
    assert batched.info.evaluations == single.info.evaluations
    assert batched.info.stats.get("rejected") == single.info.stats.get("rejected")
    np.testing.assert_allclose(np.hstack(batched.info.objective),
                               np.hstack(single.info.objective), rtol=rtol)


# ----------------------------------------------------------------------------------------
# the kernels
# ----------------------------------------------------------------------------------------
@pytest.mark.parametrize("fgp", ["fused", "split"])
@pytest.mark.parametrize("iters", [2, 3])
def test_batched_fgp_prox_is_each_frames_prox(cam, fgp, iters):
    """The FGP prox of a batch with one weight per frame (the threshold factors), warm dual
    kept across calls, against the one-frame backend's launches on each frame (the same
    kernels: bit-identical) and the numpy float64 reference (float32 tolerance); a stopped
    frame's output and dual are left as they were."""
    rng = np.random.default_rng(1)
    F = 3
    weights = np.array([0.05, 0.2, 0.6])
    bs = [rng.standard_normal((F, N, N)) for _ in range(2)]
    B = get_backend("opencl", cam, frames=F)
    B.apply_tuning({**B.tune, "fgp": fgp})
    fused = B.fgp_is_fused("tv", iters)
    assert fused == (fgp == "fused" and iters == 2 and B.rt.is_cpu)
    N1 = get_backend("numpy", cam)
    ones = [get_backend("opencl", cam, frames=1) for _ in range(F)]
    try:
        B.set_frame_params(thr=weights)
        sb = ProxState(warm=True)
        s1 = [ProxState(warm=True) for _ in range(F)]
        sn = [ProxState(warm=True) for _ in range(F)]
        out = B.empty()
        for b in bs:  # the second call starts from the first's dual
            bd = B.from_host(b)
            sums = B.fgp_prox("tv", out, bd, 1.0, iters, sb, True).get()
            got = B.to_host(out).reshape(F, N, N)
            assert sums.shape == (F, 2)
            for f in range(F):
                one = ones[f]
                one.apply_tuning({**one.tune, "fgp": fgp})
                o1 = one.empty()
                ref1 = one.fgp_prox("tv", o1, one.from_host(b[f][None]), weights[f], iters,
                                    s1[f], True).get()
                np.testing.assert_array_equal(got[f], one.to_host(o1)[0])
                np.testing.assert_array_equal(sums[f], ref1)
                on = N1.empty()
                N1.fgp_prox("tv", on, b[f][None], weights[f], iters, sn[f], True)
                scale = max(1.0, float(np.abs(on).max()))
                assert np.abs(got[f] - on[0]).max() <= 2e-5 * scale
        # frame 1 stopped: its kernels return at once, its output stays
        B.set_frame_params(thr=weights, running=[True, False, True])
        before = B.to_host(out).reshape(F, N, N)[1].copy()
        B.fgp_prox("tv", out, B.from_host(-bs[0]), 1.0, iters, sb, True).get()
        after = B.to_host(out).reshape(F, N, N)
        np.testing.assert_array_equal(after[1], before)
        assert not np.array_equal(after[0], got[0])
    finally:
        B.set_frame_params()


def test_batched_extrapolation_takes_each_frames_coefficients(cam):
    """fista_extrap with one (a1, a2) per frame (each frame's monotone step) against the numpy
    reference, and scalar coefficients on a batch against one frame's launch (the same
    kernel, the factors 1: bit-identical)."""
    rng = np.random.default_rng(2)
    F = 3
    w1, w2 = rng.standard_normal((F, N, N)), rng.standard_normal((F, N, N))
    B = get_backend("opencl", cam, frames=F)
    ops = FistaOps.for_backend(B)
    a1 = np.array([1.4, 0.7, 1.1])
    out = B.empty()
    ops.extrap(out, a1, B.from_host(w1), 1 - a1, B.from_host(w2))
    ref = np.empty((F, N, N))
    FistaOps.for_backend(get_backend("numpy", cam)).extrap(ref, a1, w1, 1 - a1, w2)
    np.testing.assert_allclose(B.to_host(out).reshape(F, N, N), ref, rtol=0,
                               atol=2e-6 * np.abs(ref).max())
    ops.extrap(out, 1.3, B.from_host(w1), -0.3, B.from_host(w2))
    one = get_backend("opencl", cam, frames=1)
    o1 = one.empty()
    FistaOps.for_backend(one).extrap(o1, 1.3, one.from_host(w1[2][None]), -0.3,
                                     one.from_host(w2[2][None]))
    np.testing.assert_array_equal(B.to_host(out).reshape(F, N, N)[2], one.to_host(o1)[0])


# ----------------------------------------------------------------------------------------
# the solver
# ----------------------------------------------------------------------------------------
@pytest.mark.parametrize("nonneg", [False, True])
def test_grey_batch_equals_one_frame_at_a_time(cam, nonneg):
    ys = _frames(cam, 4)
    taus = [0.002, 0.005, 0.01, 0.03]
    out = run_solver_batch(ys, cam, "fista", tau=taus, nonneg=nonneg, **KW)
    stops, rejected = set(), set()
    for y, t, b in zip(ys, taus, out, strict=True):
        ref = run_solver(y, cam, "fista", tau=t, nonneg=nonneg, **KW)
        _same(b, ref)
        stops.add(b.info.iterations)
        rejected.add(b.info.stats["rejected"])
        assert b.info.params["tau"] == t
        assert b.info.stats["batch"]["frames"] == 4
        assert b.info.stats["weight"] == pytest.approx(t / 2)
    # the frames stopped at different iterations (the per-frame stop) and, with nonneg,
    # rejected different numbers of steps (the per-frame monotone step, frames accepting and
    # rejecting in the same iteration)
    assert len(stops) > 1
    if nonneg:
        assert len(rejected) > 1


@pytest.mark.parametrize("extra", [
    {"tv_iters": 3},                      # the split FGP kernels (fgp_step, fgp_finish)
    {"stop": "step", "tol": 1e-3},        # the step rule: per-frame diffnorm
    {"monotone": False},                  # plain FISTA
    {"fft": "device", "nonneg": True},    # the device FFT's batched transforms
])
def test_options_batch_like_one_frame(cam, extra):
    ys = _frames(cam, 3, seed=1)
    taus = [0.002, 0.01, 0.03]
    kw = {**KW, **extra}
    out = run_solver_batch(ys, cam, "fista", tau=taus, **kw)
    for y, t, b in zip(ys, taus, out, strict=True):
        assert b.info.stats["batch"]["frames"] == 3
        _same(b, run_solver(y, cam, "fista", tau=t, **kw))


@pytest.mark.parametrize("colour", ["independent", "joint"])
def test_colour_frames_batch(cam, colour):
    ys = _frames(cam, 2, colour=True, seed=2)
    kw = dict(KW, colour=colour, nonneg=True)
    out = run_solver_batch(ys, cam, "fista", tau=0.01, **kw)
    for y, b in zip(ys, out, strict=True):
        assert b.image.shape == (N, N, 3)
        assert b.info.stats["batch"]["frames"] == (6 if colour == "independent" else 2)
        _same(b, run_solver(y, cam, "fista", tau=0.01, **kw))


def test_tau_auto_batch_equals_one_frame_at_a_time(cam):
    """tau="auto" through each frame's discrepancy search (the stages of all frames in
    lockstep, FISTA's stages batched), the final solve from the Wiener estimate as one
    frame's: the same stages, tau and image."""
    ys = _frames(cam, 3, seed=6)
    kw = dict(model="tf", backend="opencl", tau="auto", iters=40)
    out = run_solver_batch(ys, cam, "fista", **kw)
    for y, b in zip(ys, out, strict=True):
        ref = run_solver(y, cam, "fista", **kw)
        assert b.info.stats["batch"]["frames"] == 3
        assert b.info.params["tau"] == pytest.approx(ref.info.params["tau"], rel=1e-6)
        a, r = b.info.stats["tau_auto"], ref.info.stats["tau_auto"]
        assert a["stage_iterations_total"] == r["stage_iterations_total"]
        np.testing.assert_allclose(a["stages"], r["stages"], rtol=1e-5)
        assert a["residual2"] == pytest.approx(r["residual2"], rel=1e-5)
        _same(b, ref)


def test_batch_against_the_float64_reference(cam):
    """The batch in float32 against the numpy float64 one-frame solve: a few iterations
    without a stopping rule, 1e-4 of the data scale (as tests/test_api_solvers.py)."""
    ys = _frames(cam, 3, seed=3)
    taus = [0.005, 0.01, 0.02]
    kw = dict(model="tf", iters=5, min_iters=5, stop="none", nonneg=True)
    out = run_solver_batch(ys, cam, "fista", tau=taus, backend="opencl", **kw)
    for y, t, b in zip(ys, taus, out, strict=True):
        ref = run_solver(y, cam, "fista", tau=t, backend="numpy", **kw).image
        assert np.abs(b.image - ref).max() <= 1e-4 * np.abs(ref).max()


@pytest.mark.parametrize("extra, why", [
    ({"reg": "l1"}, "reg='l1'"),           # soft thresholding takes one weight per launch
    ({"model": "exact"}, "'exact' model"),
    ({"checkpoints": 5}, "checkpoints"),
])
def test_what_cannot_batch_runs_alone_and_says_why(cam, extra, why):
    ys = _frames(cam, 2, seed=4)
    kw = {**KW, "tau": 0.01, "iters": 10, **extra}
    out = run_solver_batch(ys, cam, "fista", **kw)
    for y, b in zip(ys, out, strict=True):
        assert b.info.stats["batch"]["frames"] == 1
        assert why in b.info.stats["batch"]["alone"]
        np.testing.assert_array_equal(b.image, run_solver(y, cam, "fista", **kw).image)


def test_frames_per_solve_auto_counts_fista(cam, monkeypatch):
    """``frames_per_solve="auto"``: FISTA batches (on a GPU, sized by its memory), one frame
    at a time on CPU devices and off OpenCL."""
    from clfza.solvers import _batch

    assert _batch.frames_per_solve_for("fista", "numpy", None, (N, N)) == 1

    class Dev:
        global_mem_size = 8 << 30
        max_mem_alloc_size = 2 << 30

    class Rt:
        is_cpu = False
        device = Dev()

    monkeypatch.setattr(_batch, "get_runtime", lambda device: Rt())
    plane = 512 * 512 * 4
    expect = min(_batch.GPU_MAX_FRAMES,
                 int(8 * 2**30 * _batch.GPU_MEMORY_SHARE) // (_batch.ARRAYS_PER_FRAME * plane))
    assert _batch.frames_per_solve_for("fista", "opencl", None, (512, 512)) == expect > 1
    Rt.is_cpu = True
    assert _batch.frames_per_solve_for("fista", "opencl", None, (512, 512)) == 1
