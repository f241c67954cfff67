"""Every solver kernel against the numpy float64 reference, on the default OpenCL device.

Tolerances (float32): one rounding is 6e-8 relative; the kernels chain at most a few tens of
flops per output on O(1) data, so element-wise results agree to ~1e-6 relative to the data
scale (we allow 1e-5). Sums over n = 3000-10000 terms: per-term errors of 6e-8 and a fixed fold
tree give ~1e-6 relative (we allow 1e-5). Chambolle with lam = 400 multiplies data by 400
before differencing, so its dual is compared at 1e-5 of its unit scale and the prox output at
2e-5 of the data scale.
"""

from __future__ import annotations

import numpy as np
import pytest

from clfza import Camera
from clfza import regularizers as R
from clfza.backends import get_backend
from clfza.backends._base import ProxState
from clfza.solvers._admm_ops import AdmmOps, FourierSolve
from clfza.solvers._fista_ops import FistaOps
from clfza.solvers._twist_ops import TwistOps

pytestmark = pytest.mark.agreement  # rerun on every OpenCL device (.ci/run)

SHAPE = (48, 64)  # non-square, rows != cols, catches transposed strides


@pytest.fixture(scope="module", params=[1, 3], ids=["grey", "rgb"])
def pair(request):
    nc = request.param
    cam = Camera(pitch=0.01, shape=SHAPE, r1=0.2, z1=100.0, z2=3.0, mask="gzp")
    B = get_backend("opencl", cam, nc=nc)
    N = get_backend("numpy", cam, nc=nc)
    rng = np.random.default_rng(7)
    y = rng.standard_normal((nc,) + SHAPE)
    B.set_measurement(y)
    N.set_measurement(y)
    return B, N, rng


def cpu_device_only(B) -> None:
    """Skip on GPUs: the one-pass TV kernels (tv_fused.cl) are the CPU devices' variants,
    which the backend never takes on a GPU (tests/test_oclgrind.py launches them directly on a
    simulated GPU for races and out-of-bounds accesses)."""
    if not B.rt.is_cpu:
        pytest.skip("the one-pass TV kernels run on CPU devices only")


def close(a, b, tol=1e-5):
    scale = max(1.0, float(np.max(np.abs(b))))
    assert np.max(np.abs(a - b)) <= tol * scale, np.max(np.abs(a - b)) / scale


def rnd(B, rng, scale=1.0):
    a = rng.standard_normal((B.nc,) + SHAPE) * scale
    return a, B.from_host(a)


def test_measurement_and_data_term(pair):
    B, N, rng = pair
    close(B.to_host(B.b), N.b)
    x, xd = rnd(B, rng)
    g, gd = N.empty(), B.empty()
    d = N.resid_grad(x, g).get()
    dd = B.resid_grad(xd, gd).get()
    close(B.to_host(gd), g)
    assert dd[0] == pytest.approx(d[0], rel=1e-5)
    # the unit gradient step (FISTA's) on both backends
    gs = N.empty()
    assert N.resid_grad(x, gs, step=True).get()[0] == d[0]
    np.testing.assert_allclose(gs, g + x, rtol=0, atol=1e-12 * np.abs(g + x).max())
    B.resid_grad(xd, gd, step=True)
    close(B.to_host(gd), gs)
    # Parseval value equals the literal residual norm
    r = N.y - np.stack([N.op.forward(c) for c in x])
    assert d[0] == pytest.approx(np.sum(r**2), rel=1e-10)


@pytest.mark.parametrize("nc", [1, 3])
@pytest.mark.parametrize("shape", [(6, 14), (9, 29), (12, 30), (7, 33), (5, 18)])
def test_data_term_spectrum_widths(shape, nc):
    """The data term's spectrum pass (on CPUs spectrum.cl's resid_grad_spec8: 8 frequencies of
    a half-spectrum row per work-item; the gradient and the unit gradient step) against the
    float64 reference at widths whose half
    spectrum is exactly one vector with both special columns in it (14: column 0 and the
    Nyquist column weigh 1), two vectors with the Nyquist column in the last lane (30), an odd
    width (29: no Nyquist column, a 7-lane tail), a 1-lane tail holding the Nyquist column
    (18) and a tail of an odd width (33); value and gradient at float32's tolerance, and the
    same for ADMM's Fourier x-update (admm_solve_spec8)."""
    cam = Camera(pitch=0.01, shape=shape, r1=0.05, z1=100.0, z2=3.0, mask="gzp")
    B, N = get_backend("opencl", cam, nc=nc), get_backend("numpy", cam, nc=nc)
    rng = np.random.default_rng(3)
    y, x = rng.standard_normal((2, nc) + shape)
    B.set_measurement(y)
    N.set_measurement(y)
    g, gd = N.empty(), B.empty()
    d = N.resid_grad(x, g).get()
    dd = B.resid_grad(B.from_host(x), gd).get()
    close(B.to_host(gd), g)
    assert dd[0] == pytest.approx(d[0], rel=1e-5)
    # the unit gradient step x + K^T (y - K x), added on the spectrum: the same value
    ds = B.resid_grad(B.from_host(x), gd, step=True).get()
    close(B.to_host(gd), g + x)
    assert ds[0] == dd[0]
    # ADMM's x-update (admm_solve_spec8 on CPUs): the division and the new x's data term
    fb, fn = FourierSolve.for_backend(B), FourierSolve.for_backend(N)
    fb.setup(0.7, 0.1)
    fn.setup(0.7, 0.1)
    xb, xn = B.empty(), N.empty()
    vb = fb.solve(B.from_host(x), xb, True).get()
    vn = fn.solve(x, xn, True).get()
    close(B.to_host(xb), xn)
    assert vb[0] == pytest.approx(vn[0], rel=1e-5)


def test_grad_div(pair):
    B, N, rng = pair
    u, ud = rnd(B, rng)
    g1, g2 = B.empty(), B.empty()
    B.grad(ud, g1, g2)
    r1, r2 = R.grad_ref(u)
    close(B.to_host(g1), r1)
    close(B.to_host(g2), r2)
    out = B.empty()
    B.div(ud, g1, out)
    close(B.to_host(out), R.div_ref(u, r1))


@pytest.mark.parametrize("warm,iters", [(False, 1), (False, 2), (False, 5), (True, 2)])
def test_chambolle_prox(pair, warm, iters):
    """Cold (paper mode, 1, 2 and 5 inner iterations) and warm-started duals."""
    B, N, rng = pair
    x, xd = rnd(B, rng)
    g, gd = rnd(B, rng, 0.1)
    sb, sn = ProxState(warm=warm), ProxState(warm=warm)
    ob, on = B.empty(), N.empty()
    for _ in range(2 if warm else 1):  # warm: the second call starts from the first's dual
        kb = B.prox_step("tv", xd, gd, 0.5, 0.005, ob, iters, sb)
        kn = N.prox_step("tv", x, g, 0.5, 0.005, on, iters, sn)
        assert kb == kn == iters
    close(B.to_host(ob), on, 2e-5)


@pytest.mark.parametrize("shape", [(48, 64), (37, 24), (50, 16), (70, 136), (33, 29),
                                   (41, 37)])
@pytest.mark.parametrize("th", [0.005, 0.5])
@pytest.mark.parametrize("prefetch", ["off", "rw4"])
def test_fused_paper_prox(shape, th, prefetch, monkeypatch):
    """Paper mode's prox in one pass (tv_fused.cl: 12 columns per work-item with a 16-lane
    window, strips of 32 rows after 3 warm-up rows) against the float64 reference: heights
    that are not multiples of the strip, widths that are and are not multiples of 12 (the last
    work-item of a row stores fewer columns), odd and prime widths, windows hanging over both
    image edges, lam = 400 and 4. Tolerance as for the unfused prox (2e-5 of the data scale).
    The fused variant is pinned (the device's tuned choice may be the three kernels), with and
    without software prefetch (which must change nothing)."""
    monkeypatch.setenv("CLFZA_TUNE", f"prox=fused,strip=32,prox_prefetch={prefetch}")
    cam = Camera(pitch=0.01, shape=shape, r1=0.2, z1=100.0, z2=3.0, mask="gzp")
    B, N = get_backend("opencl", cam), get_backend("numpy", cam)
    cpu_device_only(B)
    assert B.prox_is_fused("tv", 2, ProxState())
    rng = np.random.default_rng(11)
    x = rng.standard_normal((1,) + shape)
    g = rng.standard_normal((1,) + shape) * 0.1
    ob, on = B.empty(), N.empty()
    assert B.prox_step("tv", B.from_host(x), B.from_host(g), 0.5, th, ob, 2, ProxState()) == 2
    N.prox_step("tv", x, g, 0.5, th, on, 2, ProxState())
    close(B.to_host(ob), on, 2e-5)


@pytest.mark.parametrize("shape, strip", [((48, 64), 16), ((37, 29), 32), ((41, 37), 16),
                                          ((50, 16), 64), ((5, 40), 16), ((70, 136), 32),
                                          ((21, 256), 16)])
@pytest.mark.parametrize("nonneg", [False, True])
@pytest.mark.parametrize("prefetch", ["off", "rw4"])
def test_fused_fgp(shape, strip, nonneg, prefetch, monkeypatch):
    """FISTA's FGP prox in one pass (tv_fused.cl's fgp2_fused: 10 columns per work-item, 3 halo
    lanes, 7 warm-up rows, periodic in both directions) against the float64 reference over
    three warm calls (the dual carried between them): widths not multiples of 10, odd and
    prime sizes, a height below the warm-up (rows wrap more than once), strips longer than the
    image, a width of 256 (the dual's rows padded to 272 floats). Result, new dual (through the
    next call) and both sums (TV, l1) within float32's tolerance (2e-5 of the data scale, as
    the split kernels); with and without software prefetch."""
    monkeypatch.setenv("CLFZA_TUNE", f"fgp=fused,fgp_strip={strip},fgp_prefetch={prefetch}")
    cam = Camera(pitch=0.01, shape=shape, r1=0.2, z1=100.0, z2=3.0, mask="gzp")
    B, N = get_backend("opencl", cam), get_backend("numpy", cam)
    cpu_device_only(B)
    assert B.fgp_is_fused("tv", 2) and not B.fgp_is_fused("tv", 3)
    rng = np.random.default_rng(5)
    sb, sn = ProxState(warm=True), ProxState(warm=True)
    ob, on = B.empty(), N.empty()
    for _ in range(3):
        b = rng.standard_normal((1,) + shape)
        vb = B.fgp_prox("tv", ob, B.from_host(b), 0.3, 2, sb, nonneg).get()
        vn = N.fgp_prox("tv", on, b, 0.3, 2, sn, nonneg).get()
        close(B.to_host(ob), on, 2e-5)
        assert vb[:2] == pytest.approx(vn[:2], rel=1e-5)


def test_fgp_dual_pitch_and_tuning_switch(monkeypatch):
    """The one-pass FGP keeps its dual with rows padded where the width is a multiple of 256
    (dual_pitch: cache-set spreading), the split kernels at the image's width; a warm dual
    carried across a switch between the two (a retune mid-solve) is copied into the other
    layout, so the sequence of results still follows the float64 reference."""
    from clfza.backends._opencl import dual_pitch

    assert [dual_pitch(w) for w in (255, 256, 512, 1000, 2048)] == [255, 272, 528, 1000, 2064]
    monkeypatch.setenv("CLFZA_TUNE", "fgp=fused,fgp_strip=16")
    shape = (24, 256)
    cam = Camera(pitch=0.01, shape=shape, r1=0.2, z1=100.0, z2=3.0, mask="gzp")
    B, N = get_backend("opencl", cam), get_backend("numpy", cam)
    cpu_device_only(B)
    rng = np.random.default_rng(8)
    sb, sn = ProxState(warm=True), ProxState(warm=True)
    ob, on = B.empty(), N.empty()
    for k in range(4):
        if k == 2:
            B.apply_tuning({**B.tune, "fgp": "split"})
            assert not B.fgp_is_fused("tv", 2)
        b = rng.standard_normal((1,) + shape)
        B.fgp_prox("tv", ob, B.from_host(b), 0.3, 2, sb, True)
        N.fgp_prox("tv", on, b, 0.3, 2, sn, True)
        close(B.to_host(ob), on, 2e-5)
        assert sb.arrays["p"][0].shape[-1] == (272 if k < 2 else 256)


def test_fused_prox_only_where_it_applies(monkeypatch):
    """The one-pass prox needs TV, 2 cold inner iterations, no adaptive stop, one channel, a
    width of at least its 16-lane window and a CPU device; everything else (every GPU) runs the
    three tv.cl kernels."""
    monkeypatch.setenv("CLFZA_TUNE", "prox=fused")
    cam = Camera(pitch=0.01, shape=(40, 64), r1=0.2, z1=100.0, z2=3.0, mask="gzp")
    B = get_backend("opencl", cam)
    assert B.prox_is_fused("tv", 2, ProxState()) == B.rt.is_cpu
    assert not B.prox_is_fused("tv", 3, ProxState())
    assert not B.prox_is_fused("tv", 2, ProxState(warm=True))
    assert not B.prox_is_fused("tv", 2, ProxState(), tol=1e-3)
    assert not B.prox_is_fused("l1", 2, ProxState())
    assert not get_backend("opencl", cam, nc=3).prox_is_fused("tv", 2, ProxState())
    narrow = Camera(pitch=0.01, shape=(40, 15), r1=0.2, z1=100.0, z2=3.0, mask="gzp")
    assert not get_backend("opencl", narrow).prox_is_fused("tv", 2, ProxState())


def test_chambolle_adaptive_inner_stop(pair):
    """tv_tol: the same stopping decisions and result on both backends; a loose tolerance stops
    early, tol = 0 runs every step."""
    B, N, rng = pair
    x, xd = rnd(B, rng)
    g, gd = rnd(B, rng, 0.1)
    for tol, expect_early in ((0.5, True), (0.0, False)):
        sb, sn = ProxState(warm=True), ProxState(warm=True)
        ob, on = B.empty(), N.empty()
        kb = [B.prox_step("tv", xd, gd, 0.5, 0.05, ob, 8, sb, tol) for _ in range(3)]
        kn = [N.prox_step("tv", x, g, 0.5, 0.05, on, 8, sn, tol) for _ in range(3)]
        assert kb == kn
        assert (min(kb) < 8) == expect_early
        close(B.to_host(ob), on, 2e-5)


def test_soft_and_nonneg(pair):
    B, N, rng = pair
    x, xd = rnd(B, rng)
    g, gd = rnd(B, rng)
    ob, on = B.empty(), N.empty()
    B.prox_step("l1", xd, gd, 0.5, 0.3, ob, 0, ProxState())
    N.prox_step("l1", x, g, 0.5, 0.3, on, 0, ProxState())
    close(B.to_host(ob), on)
    B.project_nonneg(ob, xd)
    close(B.to_host(ob), np.maximum(x, 0))


def test_shrink_vec(pair):
    B, N, rng = pair
    t1, t1d = rnd(B, rng)
    t2, t2d = rnd(B, rng)
    z1, z2 = B.empty(), B.empty()
    B.shrink(z1, z2, t1d, t2d, 0.8)
    r1, r2 = R.shrink_vec(t1, t2, 0.8)
    close(B.to_host(z1), r1)
    close(B.to_host(z2), r2)


def check_combine(B, N, a, b, s, ad, bd, sd, sparse):
    """TwIST's combination of (a, b, s) on ``B`` (device copies ad, bd, sd) against the float64
    reference ``N``, with TV and with l1: the combination and its three sums. Returns both
    backends' TwistOps."""
    ob, on = B.empty(), N.empty()
    tb, tn = TwistOps.for_backend(B), TwistOps.for_backend(N)
    for want_tv in (True, False):
        vb = tb.combine(ob, ad, bd, sd, 1.96, 3.92, sparse, want_tv).get()
        vn = tn.combine(on, a, b, s, 1.96, 3.92, sparse, want_tv).get()
        close(B.to_host(ob), on)
        assert vb[0] == pytest.approx(vn[0], rel=1e-5)
        assert vb[1] == vn[1]  # a count of zeros: exact
        assert vb[2] == pytest.approx(vn[2], rel=1e-5)  # regulariser of x_ist
        assert vn[2] == pytest.approx(R.tv_value(s) if want_tv else R.l1_value(s))
    return tb, tn


@pytest.mark.parametrize("sparse", [False, True])
def test_twist_combine_and_mask(pair, sparse):
    B, N, rng = pair
    a, ad = rnd(B, rng)
    b, bd = rnd(B, rng)
    s = R.soft(rng.standard_normal((B.nc,) + SHAPE), 0.5)  # many exact zeros
    sd = B.from_host(s)
    tb, tn = check_combine(B, N, a, b, s, ad, bd, sd, sparse)
    tb.mask_past(bd, ad, sd)
    tn.mask_past(b, a, s)
    close(B.to_host(ad), a)
    close(B.to_host(bd), b)


@pytest.mark.parametrize("rows", [50, 49])
def test_row_blocked_reductions_any_height(rows, monkeypatch):
    """twist_combine sums RROWS = 2 or 1 rows per contribution (the largest up to the tuned
    value, pinned to 2 here, that divides the height): heights 50 (RROWS 2) and 49 (1)."""
    monkeypatch.setenv("CLFZA_TUNE", "rows=2")
    shape = (rows, 63)
    cam = Camera(pitch=0.01, shape=shape, r1=0.2, z1=100.0, z2=3.0, mask="gzp")
    B, N = get_backend("opencl", cam), get_backend("numpy", cam)
    assert B.rows == (2 if rows % 2 == 0 else 1)
    rng = np.random.default_rng(3)
    a, b, s = (rng.standard_normal((1,) + shape) for _ in range(3))
    ob, on = B.empty(), N.empty()
    vb = TwistOps.for_backend(B).combine(ob, B.from_host(a), B.from_host(b), B.from_host(s),
                                         1.96, 3.92, False, True).get()
    vn = TwistOps.for_backend(N).combine(on, a, b, s, 1.96, 3.92, False, True).get()
    close(B.to_host(ob), on)
    assert vb[0] == pytest.approx(vn[0], rel=1e-5)
    assert vb[2] == pytest.approx(vn[2], rel=1e-5)


def test_reductions_deterministic(pair):
    B, N, rng = pair
    a, ad = rnd(B, rng)
    b, bd = rnd(B, rng)
    v = B.reg_value(ad).get()
    assert v[0] == pytest.approx(R.tv_value(a), rel=1e-5)
    assert v[1] == pytest.approx(R.l1_value(a), rel=1e-5)
    d = B.diffnorm(ad, bd).get()
    assert d[0] == pytest.approx(np.sum((a - b) ** 2), rel=1e-5)
    assert d[1] == pytest.approx(np.sum(a**2), rel=1e-5)
    assert B.dot(ad, bd).get()[0] == pytest.approx(np.sum(a * b), rel=1e-4, abs=1e-3)
    # a fixed fold order: repeated reductions are bit-for-bit equal
    assert all(np.array_equal(B.reg_value(ad).get(), v) for _ in range(5))


@pytest.mark.parametrize("iters", [1, 2, 3, 5])
def test_fgp_warm_dual(pair, iters):
    """FGP with a warm dual (two calls) against the reference: 1 inner iteration (no momentum
    array at all), 2 (the first step's is p_new itself, the last's has no reader: none
    written), 3 and 5 (written between the first and the last step)."""
    B, N, rng = pair
    b, bd = rnd(B, rng)
    for nonneg in (False, True):
        sb, sn = ProxState(warm=True), ProxState(warm=True)
        ob, on = B.empty(), N.empty()
        for _ in range(2):
            vb = B.fgp_prox("tv", ob, bd, 0.3, iters, sb, nonneg).get()
            vn = N.fgp_prox("tv", on, b, 0.3, iters, sn, nonneg).get()
        close(B.to_host(ob), on)
        assert vb[0] == pytest.approx(vn[0], rel=1e-5)


def test_lincombs(pair):
    B, N, rng = pair
    b, bd = rnd(B, rng)
    x, xd = rnd(B, rng)
    ob = B.empty()
    B.lincomb(ob, 0.5, xd, -2.0, bd, 3.0, xd)
    close(B.to_host(ob), 0.5 * x - 2 * b + 3 * x)
    FistaOps.for_backend(B).extrap(ob, 1.3, xd, -0.3, bd)
    close(B.to_host(ob), 1.3 * x - 0.3 * b)


@pytest.mark.parametrize("nonneg", [False, True])
def test_admm_ops(pair, nonneg):
    B, N, rng = pair
    ob, on = AdmmOps.for_backend(B), AdmmOps.for_backend(N)
    xb, xn = FourierSolve.for_backend(B), FourierSolve.for_backend(N)
    xb.setup(0.05, 0.02)
    xn.setup(0.05, 0.02)
    arrs = [rnd(B, rng, 0.3) for _ in range(7)]
    h = [a for a, _ in arrs]
    d = [ad for _, ad in arrs]
    ob.rhs(d[0], d[1], d[2], d[3], d[4], 0.05, 0.02)
    on.rhs(h[0], h[1], h[2], h[3], h[4], 0.05, 0.02)
    close(B.to_host(d[0]), h[0])
    vb = xb.solve(d[0], d[5], True).get()
    vn = xn.solve(h[0], h[5], True).get()
    close(B.to_host(d[5]), h[5])
    assert vb[0] == pytest.approx(vn[0], rel=1e-5)
    ub = ob.update(d[5], d[1], d[2], d[3], d[4], d[6], d[0], 0.1, nonneg).get()
    un = on.update(h[5], h[1], h[2], h[3], h[4], h[6], h[0], 0.1, nonneg).get()
    for k in (1, 2, 3, 4, 6, 0):
        close(B.to_host(d[k]), h[k])
    np.testing.assert_allclose(ub, un, rtol=1e-5)



@pytest.mark.parametrize("shape", [(5, 14), (9, 16), (7, 17), (11, 29), (6, 33), (4, 48),
                                   (2, 40), (17, 2)])
@pytest.mark.parametrize("sparse", [False, True])
def test_twist_combine_row_vectors(shape, sparse):
    """TwIST's combination with 16 columns per work-item (elementwise.cl's twist_combine16,
    CPU devices, float32, one channel) against the float64 reference: every tail length class
    (the last work-item of a row takes W mod 16 columns), widths below one vector, the first
    work-item's wrapped left neighbour, the wrapped row above, two rows; the combination and
    all three sums, with TV and with l1. x_ist has exact zeros in some left neighbours and rows
    above, so the sparse mask reaches the neighbours' values too."""
    cam = Camera(pitch=0.01, shape=shape, r1=0.2, z1=100.0, z2=3.0, mask="gzp")
    B, N = get_backend("opencl", cam), get_backend("numpy", cam)
    assert B.rows16 == (B.rt.is_cpu and B.dtype == np.float32)
    rng = np.random.default_rng(10)
    a, b = (rng.standard_normal((1,) + shape) for _ in range(2))
    s = R.soft(rng.standard_normal((1,) + shape), 0.6)
    check_combine(B, N, a, b, s, B.from_host(a), B.from_host(b), B.from_host(s), sparse)


@pytest.mark.parametrize("shape", [(5, 14), (9, 16), (7, 17), (11, 29), (6, 33), (4, 48)])
@pytest.mark.parametrize("nonneg", [False, True])
def test_admm_update_row_vectors(shape, nonneg):
    """ADMM's update with 16 columns per work-item (elementwise.cl's admm_update16, CPU
    devices, float32, one channel) against the float64 reference: widths below, at and past
    one vector and with every tail length class (the last work-item of a row takes W mod 16
    columns), the first work-item's wrapped left neighbour, the wrapped row above; all seven
    arrays and both sums."""
    cam = Camera(pitch=0.01, shape=shape, r1=0.2, z1=100.0, z2=3.0, mask="gzp")
    B, N = get_backend("opencl", cam), get_backend("numpy", cam)
    assert B.rows16 == (B.rt.is_cpu and B.dtype == np.float32)
    ob, on = AdmmOps.for_backend(B), AdmmOps.for_backend(N)
    rng = np.random.default_rng(8)
    h = [0.3 * rng.standard_normal((1,) + shape) for _ in range(7)]
    d = [B.from_host(a) for a in h]
    ub = ob.update(d[0], d[1], d[2], d[3], d[4], d[5], d[6], 0.1, nonneg).get()
    un = on.update(h[0], h[1], h[2], h[3], h[4], h[5], h[6], 0.1, nonneg).get()
    for k in range(7):
        close(B.to_host(d[k]), h[k])
    np.testing.assert_allclose(ub, un, rtol=1e-5)


@pytest.mark.parametrize("shape, nc", [((5, 14), 1), ((9, 16), 1), ((7, 17), 1),
                                       ((11, 29), 1), ((6, 33), 1), ((4, 48), 1), ((2, 40), 1),
                                       ((17, 2), 1), ((7, 17), 3), ((2, 40), 3)])
@pytest.mark.parametrize("nonneg, mu", [(True, 0.3), (False, 0.0), (False, 0.2)])
def test_admm_update_then_rhs(shape, nc, nonneg, mu):
    """ADMM's update followed by the next right-hand side (AdmmOps.update_rhs; on CPU devices
    one kernel, elementwise.cl's admm_update_rhs16, which recomputes the row below's q2 and the
    next column's q1 from the old split and writes the new split to the spare pair) against
    the float64 reference's update then rhs: every tail length class, the wrapped column right
    of a row's last work-item, the wrapped row below, two rows, two columns; the new split, v,
    s, the right-hand side and both sums. The old split is left as it was (nothing read is
    overwritten) and the pairs come back swapped. Colour (nc = 3, vectorial shrink) runs the
    one-pixel-per-work-item kernel admm_update_rhs, which GPUs run for every frame."""
    cam = Camera(pitch=0.01, shape=shape, r1=0.2, z1=100.0, z2=3.0, mask="gzp")
    B, N = get_backend("opencl", cam, nc=nc), get_backend("numpy", cam, nc=nc)
    rng = np.random.default_rng(9)
    y = rng.standard_normal((nc,) + shape)
    B.set_measurement(y)
    N.set_measurement(y)
    ob, on = AdmmOps.for_backend(B), AdmmOps.for_backend(N)
    h = [0.3 * rng.standard_normal((nc,) + shape) for _ in range(7)]  # x u1 u2 q1 q2 v s
    d = [B.from_host(a) for a in h]
    old_u1 = h[1].copy()
    spare_b, out_b, out_n = (B.empty(), B.empty()), B.empty(), N.empty()
    sb, ub, fb = ob.update_rhs(d[0], (d[1], d[2]), spare_b, (d[3], d[4]), d[5], d[6], out_b,
                               0.2, nonneg, 0.7, mu)
    sn, un, _ = on.update_rhs(h[0], (h[1], h[2]), (N.empty(), N.empty()), (h[3], h[4]), h[5],
                              h[6], out_n, 0.2, nonneg, 0.7, mu)
    assert ub is spare_b and fb[0] is d[1]
    np.testing.assert_array_equal(B.to_host(d[1]), old_u1.astype(np.float32))
    for a, b in ((ub[0], un[0]), (ub[1], un[1]), (d[5], h[5]), (d[6], h[6]), (out_b, out_n)):
        close(B.to_host(a), b)
    np.testing.assert_allclose(sb.get(), sn.get(), rtol=1e-5)
