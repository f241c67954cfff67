"""Batched TwIST (issue 37): TwIST on the transfer-function model for a stack of frames, one
launch per kernel and round for all of them.

The reference of a batched solve is each frame's one-frame solve: the batch must give the
same images, iteration counts, stop reasons, objective histories, evaluations and TwIST's
per-frame decisions (monotone fallbacks, max_svd doublings, inner TV iterations) to float32
rounding; on CPU devices they are the same kernels on the same values, so the images are
bit-identical there. The batch-ready kernels (tv.cl's chambolle_* and tv_fused.cl's
chambolle2_fused with a frame dimension and per-frame step and lam, elementwise.cl's
twist_combine/twist_combine16 and mask_past with per-frame running flags) are checked against
the one-frame launches and the numpy float64 reference. Agreement tests: .ci/run reruns them
on every OpenCL implementation; tests/test_batch_twist_oclgrind.py runs the batch on the GPU
code paths under Oclgrind.
"""

from __future__ import annotations

import numpy as np
import pytest
from _batch_frames import N
from _batch_frames import frames as _frames

import clfza
from clfza.backends import ProxState, get_backend
from clfza.solvers import TwistOps, run_solver, run_solver_batch

pytestmark = pytest.mark.agreement

KW = dict(model="tf", backend="opencl", iters=30, tol=1e-3)
STATS = ("fallbacks", "max_svd_doublings", "max_svd", "inner_tv_iterations", "noop_ist_steps")


@pytest.fixture(scope="module")
def cam():
    return clfza.Camera.preset("simulation").with_shape((N, N))


def _same(batched, single, rtol: float = 1e-5) -> None:
    """Equal to float32 rounding: images (relative to the frame's scale), iterations, stop
    reasons, objective histories, evaluations and TwIST's counts."""
    scale = max(float(np.abs(single.image).max()), 1e-30)
    np.testing.assert_allclose(batched.image, single.image, rtol=0, atol=rtol * scale)
    assert batched.info.iterations == single.info.iterations
    assert batched.info.stop_reason == single.info.stop_reason
    assert batched.info.evaluations == single.info.evaluations
    for k in STATS:
        assert batched.info.stats.get(k) == single.info.stats.get(k), k
    np.testing.assert_allclose(np.hstack(batched.info.objective),
                               np.hstack(single.info.objective), rtol=rtol)


# ----------------------------------------------------------------------------------------
# the kernels
# ----------------------------------------------------------------------------------------
@pytest.mark.parametrize("prox", ["fused", "split", "warm-tol"])
def test_batched_chambolle_prox_is_each_frames_prox(cam, prox):
    """Chambolle's prox on a batch with one step s and threshold per frame (the mu and
    threshold factors) against the one-frame backend on each frame (the same kernels:
    bit-identical) and the numpy float64 reference; with the warm dual and tv_tol each frame
    stops its inner loop on its own change; a frame turned off is left as it was."""
    rng = np.random.default_rng(1)
    F = 3
    s = np.array([1.0, 0.5, 0.25])
    th = np.array([0.002, 0.01, 0.005]) * s
    xs, gs = rng.standard_normal((F, N, N)), 0.3 * rng.standard_normal((F, N, N))
    warm = prox == "warm-tol"
    # warm: 3 inner steps, the change checked after the 2nd (frames stop after 2 or 3: their
    # duals end in different buffers, realigned)
    iters, tol = (2, 0.0) if prox == "fused" else ((3, 0.0) if prox == "split" else (3, 0.008))
    B = get_backend("opencl", cam, frames=F)
    assert B.prox_is_fused("tv", iters, ProxState(warm=warm), tol) == (
        prox == "fused" and B.rt.is_cpu)
    N1 = get_backend("numpy", cam)
    ones = [get_backend("opencl", cam) for _ in range(F)]
    try:
        B.set_frame_params(mu=s, thr=2.0 / th)
        sb = ProxState(warm=warm)
        s1 = [ProxState(warm=warm) for _ in range(F)]
        out = B.empty()
        x, g = B.from_host(xs), B.from_host(gs)
        counts = set()
        for _ in range(3 if warm else 1):  # warm: later calls start from the kept dual
            B.prox_step("tv", x, g, 1.0, 2.0, out, iters, sb, tol)
            got = B.to_host(out).reshape(F, N, N)
            for f in range(F):
                one = ones[f]
                o1 = one.empty()
                n1 = one.prox_step("tv", one.from_host(xs[f][None]), one.from_host(gs[f][None]),
                                   s[f], th[f], o1, iters, s1[f], tol)
                assert B.prox_frame_iters[f] == n1
                counts.add(n1)
                np.testing.assert_array_equal(got[f], one.to_host(o1)[0])
                if not warm:
                    ref = N1.empty()
                    N1.prox_step("tv", xs[f][None], gs[f][None], s[f], th[f], ref, iters,
                                 ProxState())
                    assert np.abs(got[f] - ref[0]).max() <= 2e-5 * max(1.0, np.abs(ref).max())
        if warm:  # the frames' inner loops ended at different steps
            assert counts == {2, 3}
        B.set_frame_params(mu=s, thr=2.0 / th, running=[True, False, True])
        before = B.to_host(out).reshape(F, N, N)[1].copy()
        B.prox_step("tv", B.from_host(-xs), g, 1.0, 2.0, out, iters, sb, tol)
        after = B.to_host(out).reshape(F, N, N)
        np.testing.assert_array_equal(after[1], before)
        assert not np.array_equal(after[0], got[0])
    finally:
        B.set_frame_params()


@pytest.mark.parametrize("sparse", [False, True])
def test_batched_combination_and_mask(cam, sparse):
    """twist_combine(16) and mask_past on a batch: each frame's output and sums as one
    frame's launch (bit-identical) and the numpy reference; frames turned off untouched."""
    rng = np.random.default_rng(2)
    F = 3
    h = [rng.standard_normal((F, N, N)) for _ in range(2)]
    ist = rng.standard_normal((F, N, N))
    ist[np.abs(ist) < 0.5] = 0.0  # exact zeros: the sparse mask
    B = get_backend("opencl", cam, frames=F)
    ops = TwistOps.for_backend(B)
    tn = TwistOps.for_backend(get_backend("numpy", cam))
    try:
        on = [True, False, True]
        B.set_frame_params(running=on)
        out = B.from_host(np.full((F, N, N), 7.0))
        a, b, c = (B.from_host(v) for v in (*h, ist))
        sums = ops.combine(out, a, b, c, 1.96, 3.92, sparse).get()
        got = B.to_host(out).reshape(F, N, N)
        assert (got[1] == 7.0).all()
        one = get_backend("opencl", cam)
        o1 = one.empty()
        for f in (0, 2):
            d = [one.from_host(v[f][None]) for v in (*h, ist)]
            s1 = TwistOps.for_backend(one).combine(o1, *d, 1.96, 3.92, sparse).get()
            np.testing.assert_array_equal(got[f], one.to_host(o1)[0])
            np.testing.assert_array_equal(sums[f, :3], s1[:3])
            ref = np.empty((1, N, N))
            r = tn.combine(ref, h[0][f][None], h[1][f][None], ist[f][None], 1.96, 3.92,
                           sparse).get()
            assert np.abs(got[f] - ref[0]).max() <= 2e-5 * np.abs(ref).max()
            np.testing.assert_allclose(sums[f, :3], r[:3], rtol=1e-4)
        B.set_frame_params(running=[False, True, True])
        ops.mask_past(a, b, c)
        ga, gb = (B.to_host(v).reshape(F, N, N) for v in (a, b))
        np.testing.assert_array_equal(ga[0], h[0][0].astype(np.float32))
        for f in (1, 2):
            m = ist[f] != 0
            np.testing.assert_array_equal(ga[f], (h[0][f] * m).astype(np.float32))
            np.testing.assert_array_equal(gb[f], (h[1][f] * m).astype(np.float32))
    finally:
        B.set_frame_params()


# ----------------------------------------------------------------------------------------
# the solver
# ----------------------------------------------------------------------------------------
@pytest.mark.parametrize("mode", ["paper", "efficient"])
def test_grey_batch_equals_one_frame_at_a_time(cam, mode):
    ys = _frames(cam, 4)
    taus = [0.002, 0.005, 0.01, 0.03]
    kw = dict(KW, mode=mode, min_iters=3)
    out = run_solver_batch(ys, cam, "twist", tau=taus, **kw)
    stops, fallbacks, inner = set(), set(), set()
    for y, t, b in zip(ys, taus, out, strict=True):
        ref = run_solver(y, cam, "twist", tau=t, **kw)
        _same(b, ref)
        np.testing.assert_array_equal(b.image, ref.image)  # the same kernels, the same values
        stops.add(b.info.iterations)
        fallbacks.add(b.info.stats["fallbacks"])
        inner.add(b.info.stats["inner_tv_iterations"])
        assert b.info.params["tau"] == t
        assert b.info.stats["batch"]["frames"] == 4
    # per-frame stops and monotone fallbacks (frames accepting and falling back in one
    # iteration); efficient mode: each frame's inner loop stops on its own tolerance
    assert len(stops) > 1 and len(fallbacks) > 1
    if mode == "efficient":
        assert len(inner) > 1


@pytest.mark.parametrize("extra", [
    {"tv_iters": 3},                     # the split Chambolle kernels
    {"mode": "efficient", "tv_iters": 5},  # odd inner steps with tv_tol: duals realigned
    {"stop": "step", "tol": 1e-3, "min_iters": 3},  # the step rule: per-frame diffnorm
    {"monotone": False, "sparse": False},
    {"fft": "device"},                   # the device FFT's batched transforms
    {"lambda1": 0.5},                    # larger steps: max_svd doublings
])
def test_options_batch_like_one_frame(cam, extra):
    ys = _frames(cam, 3, seed=1)
    taus = [0.002, 0.01, 0.03]
    kw = {**KW, **extra}
    out = run_solver_batch(ys, cam, "twist", tau=taus, **kw)
    for y, t, b in zip(ys, taus, out, strict=True):
        assert b.info.stats["batch"]["frames"] == 3
        _same(b, run_solver(y, cam, "twist", tau=t, **kw))


@pytest.mark.parametrize("colour", ["independent", "joint"])
def test_colour_frames_batch(cam, colour):
    ys = _frames(cam, 2, colour=True, seed=2)
    kw = dict(KW, colour=colour)
    out = run_solver_batch(ys, cam, "twist", tau=0.01, **kw)
    for y, b in zip(ys, out, strict=True):
        assert b.image.shape == (N, N, 3)
        assert b.info.stats["batch"]["frames"] == (6 if colour == "independent" else 2)
        _same(b, run_solver(y, cam, "twist", tau=0.01, **kw))


def test_tau_auto_batch_equals_one_frame_at_a_time(cam):
    """tau="auto" through each frame's discrepancy search (TwIST's stages batched, with the
    paper's count of iterations), the final solve from the search's iterate as one frame's."""
    ys = _frames(cam, 3, seed=6)
    kw = dict(model="tf", backend="opencl", tau="auto", iters=20)
    out = run_solver_batch(ys, cam, "twist", **kw)
    for y, b in zip(ys, out, strict=True):
        ref = run_solver(y, cam, "twist", **kw)
        assert b.info.stats["batch"]["frames"] == 3
        assert b.info.params["tau"] == pytest.approx(ref.info.params["tau"], rel=1e-6)
        a, r = b.info.stats["tau_auto"], ref.info.stats["tau_auto"]
        assert a["stage_iterations_total"] == r["stage_iterations_total"]
        np.testing.assert_allclose(a["stages"], r["stages"], rtol=1e-5)
        _same(b, ref)


def test_batch_against_the_float64_reference(cam):
    """The batch in float32 against the numpy float64 one-frame solve: a few iterations,
    1e-4 of the data scale (as tests/test_api_solvers.py)."""
    ys = _frames(cam, 3, seed=3)
    taus = [0.005, 0.01, 0.02]
    kw = dict(model="tf", iters=4)
    out = run_solver_batch(ys, cam, "twist", tau=taus, backend="opencl", **kw)
    for y, t, b in zip(ys, taus, out, strict=True):
        ref = run_solver(y, cam, "twist", tau=t, backend="numpy", **kw).image
        assert np.abs(b.image - ref).max() <= 1e-4 * np.abs(ref).max()


def test_l1_runs_alone_and_says_why(cam):
    ys = _frames(cam, 2, seed=4)
    kw = {**KW, "tau": 0.01, "iters": 5, "reg": "l1"}
    out = run_solver_batch(ys, cam, "twist", **kw)
    for y, b in zip(ys, out, strict=True):
        assert b.info.stats["batch"]["frames"] == 1
        assert "reg='l1'" in b.info.stats["batch"]["alone"]
        np.testing.assert_array_equal(b.image, run_solver(y, cam, "twist", **kw).image)
