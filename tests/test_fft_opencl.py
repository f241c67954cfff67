"""OpenCL device FFTs (kernels/fft.cl, clfza.fft._opencl) against numpy.fft in float64.

Error bounds. With twiddles rounded once from float64 tables, a radix-R Stockham FFT has a
relative (L2) error that grows like log2 N: ||y - y_ref|| / ||y_ref|| <= C * eps * log2 N.
Measured on PoCL (random normal data): at most 0.25 eps log2 N for fast sizes and 0.6 eps
log2 N for Bluestein (float64, N = 17). We check C = 1 for Stockham sizes and C = 2 for
Bluestein sizes (two length-L transforms, L < 4N, plus rounded chirps: about twice the
operation count), i.e. roughly 2-4x margin above what was measured; never loosened.
"""

from __future__ import annotations

import numpy as np
import pytest

from clfza.cl import DeviceArray
from clfza.errors import ClfzaError
from clfza.fft import describe_policy, select_engine
from clfza.fft._opencl import (
    DeviceFFT,
    StockhamPlan,
    fast_shape,
    fft1d_batched,
    fft2,
    good_size,
    is_fast_size,
    next_fast_size,
    plan,
)

pytestmark = pytest.mark.agreement  # rerun on every OpenCL device (.ci/run)

DTYPES = [np.float32, np.float64]
CDT = {np.float32: np.complex64, np.float64: np.complex128}

POW2 = [2**k for k in range(3, 13)]                 # 8 .. 4096
MIXED = [3 * 8, 3 * 256, 3 * 1024, 5 * 16, 5 * 256, 7 * 8, 7 * 256, 9 * 7 * 5]
ODD = [15, 243, 625, 2401, 105]                     # odd, all factors in {3, 5, 7}
PRIME = [11, 17, 97, 1009, 4093]                    # Bluestein
SIZES_1D = POW2 + MIXED + ODD + PRIME


def _need(rt, dtype):
    if np.dtype(dtype) == np.float64 and not rt.has_fp64:
        pytest.skip("device has no float64")


def _bound(dtype, n) -> float:
    eps = np.finfo(dtype).eps
    c = 1.0 if is_fast_size(n) else 2.0
    return c * eps * max(1.0, np.log2(n))


def _rel(a, b) -> float:
    return float(np.linalg.norm(a - b) / np.linalg.norm(b))


def _crandn(rng, shape):
    return rng.standard_normal(shape) + 1j * rng.standard_normal(shape)


# ---------------------------------------------------------------------------------------------
# sizes

def test_fast_sizes():
    assert is_fast_size(1) and is_fast_size(4096) and is_fast_size(3 * 5 * 7 * 64)
    assert not is_fast_size(11) and not is_fast_size(2 * 4093)
    assert next_fast_size(11) == 12 and next_fast_size(97) == 98 and next_fast_size(4093) == 4096
    assert good_size(1009) == 1024
    assert fast_shape((97, 101)) == (98, 105)
    with pytest.raises(ClfzaError):
        next_fast_size(0)


# ---------------------------------------------------------------------------------------------
# batched 1-D complex transforms

@pytest.mark.parametrize("dtype", DTYPES)
@pytest.mark.parametrize("n", SIZES_1D)
def test_fft1d_rows_and_inverse(rt, rng, dtype, n):
    _need(rt, dtype)
    nb = 3
    a = _crandn(rng, (nb, n))
    d = DeviceArray.from_host(rt, a.astype(CDT[dtype]))
    out = fft1d_batched(d)
    ref = np.fft.fft(a, axis=-1)
    assert _rel(out.get(), ref) <= _bound(dtype, n)
    back = fft1d_batched(out, inverse=True)
    assert _rel(back.get(), a) <= 2 * _bound(dtype, n)     # two transforms
    inv = fft1d_batched(d, inverse=True)
    assert _rel(inv.get(), np.fft.ifft(a, axis=-1)) <= _bound(dtype, n)


@pytest.mark.parametrize("dtype", DTYPES)
@pytest.mark.parametrize("n", [8, 64, 512, 4096, 24, 80, 56, 243, 97])
def test_fft1d_columns(rt, rng, dtype, n):
    """Batched along contiguous memory (the column layout of a 2-D array), in place."""
    _need(rt, dtype)
    a = _crandn(rng, (n, 5))
    d = DeviceArray.from_host(rt, a.astype(CDT[dtype]))
    fft1d_batched(d, d, axis=0)
    assert _rel(d.get(), np.fft.fft(a, axis=0)) <= _bound(dtype, n)


@pytest.mark.parametrize("dtype", DTYPES)
@pytest.mark.parametrize("n", [8, 2048, 4096, 96, 1280, 1792, 105, 17, 1009])
@pytest.mark.parametrize("layout", ["rows", "cols"])
@pytest.mark.parametrize("columns", ["codelets", "passes"])
def test_global_passes(rt, rng, dtype, n, layout, columns):
    """The one-launch-per-pass paths outside local memory (long lines; GPU columns: the
    generated codelets or fft.cl's radix-2..8 passes) on their own; 4 and 37 lines (the
    codelets' work-groups of 32 or 64 lines, a partial one)."""
    _need(rt, dtype)
    if layout == "rows" and columns == "passes":
        pytest.skip("rows take the same path either way")
    ex = StockhamPlan(rt, dtype, local_rows=False, local_cols=False, columns=columns)
    _global_case(rt, rng, dtype, n, layout, ex, 4)
    if layout == "cols":
        _global_case(rt, rng, dtype, n, layout, ex, 37)


def _global_case(rt, rng, dtype, n, layout, ex, nb):
    a = _crandn(rng, (nb, n) if layout == "rows" else (n, nb))
    src = DeviceArray.from_host(rt, a.astype(CDT[dtype]))
    dst = DeviceArray.empty(rt, a.shape, CDT[dtype])
    if layout == "rows":
        ex.c2c(src.buf, dst.buf, n, nb, 1, n, -1)
        ref = np.fft.fft(a, axis=1)
    else:
        ex.c2c(src.buf, dst.buf, n, nb, nb, 1, -1)
        ref = np.fft.fft(a, axis=0)
    assert _rel(dst.get(), ref) <= _bound(dtype, n)
    # in place, inverse with 1/n
    ex.c2c(dst.buf, dst.buf, n, nb, *((1, n) if layout == "rows" else (nb, 1)), 1, 1.0 / n)
    assert _rel(dst.get(), a) <= 2 * _bound(dtype, n)


@pytest.mark.parametrize("dtype", DTYPES)
def test_parseval_1d(rt, rng, dtype):
    _need(rt, dtype)
    for n in (4096, 3072, 4093):
        a = _crandn(rng, (2, n))
        A = fft1d_batched(DeviceArray.from_host(rt, a.astype(CDT[dtype]))).get()
        e_t = np.sum(np.abs(a) ** 2)
        e_f = np.sum(np.abs(A.astype(np.complex128)) ** 2) / n
        # |(|A|^2/n - |a|^2)| / |a|^2 <= 2 * (relative error of A) + rounding of the sums
        assert abs(e_f - e_t) / e_t <= 2 * _bound(dtype, n) + 4 * np.finfo(dtype).eps


@pytest.mark.parametrize("dtype", DTYPES)
@pytest.mark.parametrize("shape", [(64, 48), (30, 17), (128, 128)])
def test_complex_fft2(rt, rng, dtype, shape):
    _need(rt, dtype)
    a = _crandn(rng, shape)
    d = DeviceArray.from_host(rt, a.astype(CDT[dtype]))
    out = fft2(d)
    bound = _bound(dtype, shape[0]) + _bound(dtype, shape[1])
    assert _rel(out.get(), np.fft.fft2(a)) <= bound
    fft2(out, out, inverse=True)
    assert _rel(out.get(), a) <= 2 * bound


# ---------------------------------------------------------------------------------------------
# real 2-D transforms (the engine used by the operator K)

SHAPES_2D = [(8, 8), (16, 16), (64, 64), (256, 256), (512, 512),       # squares 2^k
             (48, 96), (96, 80), (112, 56), (384, 192),                 # 3, 5, 7 * 2^k
             (64, 30), (30, 64), (20, 512), (512, 14),                  # non-square
             (15, 21), (21, 15), (45, 35), (9, 243),                    # odd
             (17, 34), (64, 97), (97, 64), (101, 103), (22, 46),        # prime / Bluestein
             (1, 16), (2, 2), (3, 2)]


def _engine_bound(dtype, shape) -> float:
    ny, nx = shape
    # rows of length nx (via nx/2 complex when even) and columns of length ny
    m = nx // 2 if nx % 2 == 0 else nx
    return _bound(dtype, max(m, 2)) + _bound(dtype, max(ny, 2)) + 2 * np.finfo(dtype).eps


@pytest.mark.parametrize("dtype", DTYPES)
@pytest.mark.parametrize("shape", SHAPES_2D)
def test_rfft2_irfft2(rt, rng, dtype, shape):
    _need(rt, dtype)
    cdt = CDT[dtype]
    x = rng.standard_normal(shape)
    eng = DeviceFFT(rt, shape, dtype)
    assert eng.spectrum_shape == (shape[0], shape[1] // 2 + 1)
    xd = DeviceArray.from_host(rt, x.astype(dtype))
    X = DeviceArray.empty(rt, eng.spectrum_shape, cdt)
    eng.rfft2(xd, X)
    ref = np.fft.rfft2(x)
    bound = _engine_bound(dtype, shape)
    assert _rel(X.get(), ref) <= bound
    # round trip; X must be left unchanged by the inverse
    X0 = X.get()
    y = DeviceArray.empty(rt, shape, dtype)
    eng.irfft2(X, y)
    assert np.array_equal(X.get(), X0)
    assert _rel(y.get(), x) <= 2 * bound
    # inverse of an arbitrary (non-Hermitian) half spectrum matches numpy's irfft2, which
    # ignores the imaginary parts that a real signal cannot have
    Z = _crandn(rng, ref.shape)
    X.set(Z.astype(cdt))
    eng.irfft2(X, y)
    assert _rel(y.get(), np.fft.irfft2(Z, s=shape)) <= bound


@pytest.mark.parametrize("dtype", DTYPES)
@pytest.mark.parametrize("shape", [(64, 64), (96, 160), (34, 26), (45, 35)])
@pytest.mark.parametrize("local", [(False, False), (True, False), (False, True)])
@pytest.mark.parametrize("columns", ["codelets", "passes"])
def test_rfft2_paths(rt, rng, dtype, shape, local, columns):
    """Every combination of local-memory / global-pass kernels for rows and columns (the
    columns' global passes: the generated codelets or fft.cl's passes)."""
    _need(rt, dtype)
    if local[1] and columns == "passes":
        pytest.skip("local columns take no global passes")
    x = rng.standard_normal(shape)
    eng = DeviceFFT(rt, shape, dtype, local_rows=local[0], local_cols=local[1],
                    columns=columns)
    xd = DeviceArray.from_host(rt, x.astype(dtype))
    X = DeviceArray.empty(rt, eng.spectrum_shape, CDT[dtype])
    eng.rfft2(xd, X)
    bound = _engine_bound(dtype, shape)
    assert _rel(X.get(), np.fft.rfft2(x)) <= bound
    eng.irfft2(X, xd)
    assert _rel(xd.get(), x) <= 2 * bound


@pytest.mark.parametrize("dtype", DTYPES)
@pytest.mark.parametrize("shape", [(64, 64), (96, 160), (34, 26), (45, 35), (1, 8), (40, 2)])
@pytest.mark.parametrize("mapping", ["batch", "lines"])
def test_rfft2_mappings(rt, rng, dtype, shape, mapping):
    """Both work-item mappings on every device (the default is one of them per device kind)."""
    _need(rt, dtype)
    x = rng.standard_normal(shape)
    eng = DeviceFFT(rt, shape, dtype, mapping=mapping)
    assert eng.mapping == mapping
    xd = DeviceArray.from_host(rt, x.astype(dtype))
    X = DeviceArray.empty(rt, eng.spectrum_shape, CDT[dtype])
    eng.rfft2(xd, X)
    bound = _engine_bound(dtype, shape)
    assert _rel(X.get(), np.fft.rfft2(x)) <= bound
    eng.irfft2(X, xd)
    assert _rel(xd.get(), x) <= 2 * bound


@pytest.mark.parametrize("dtype", DTYPES)
@pytest.mark.parametrize("shape", [(64, 64), (96, 160), (45, 35), (97, 64), (1, 8), (40, 2)])
@pytest.mark.parametrize("mapping", ["batch", "lines"])
def test_irfft2_overwrite_x(rt, rng, dtype, shape, mapping):
    """``overwrite_x=True`` (the inverse may work in its input) gives the inverse of an
    arbitrary half spectrum to the same bound as the non-destructive call, on both mappings,
    fast, odd, padded (Bluestein) and one-row grids."""
    _need(rt, dtype)
    eng = DeviceFFT(rt, shape, dtype, mapping=mapping)
    Z = _crandn(rng, eng.spectrum_shape)
    X = DeviceArray.from_host(rt, Z.astype(CDT[dtype]))
    y = DeviceArray.empty(rt, shape, dtype)
    eng.irfft2(X, y, overwrite_x=True)
    assert _rel(y.get(), np.fft.irfft2(Z, s=shape)) <= _engine_bound(dtype, shape)


@pytest.mark.parametrize("dtype", DTYPES)
@pytest.mark.parametrize("shape,options", [
    ((64, 64), {}),               # plane bytes multiples of any base-address alignment
    ((6, 14), {}),                # planes not aligned (sub-buffers would be refused)
    ((45, 35), {}),               # odd width (full complex rows)
    ((34, 26), {"bluestein": False, "pad_to_fast": True}),  # zero-padded grid, 17 -> 18
])
@pytest.mark.parametrize("mapping", ["batch", "lines"])
@pytest.mark.parametrize("overwrite_x", [False, True])
def test_rfft2_planes(rt, rng, dtype, shape, options, mapping, overwrite_x):
    """``(C, Ny, Nx)`` arrays (joint colour on the device FFT; all planes in one launch per
    pass, tests/test_fft_batch.py): each plane transformed as a single grid is, whatever the
    planes' byte offsets; the inverse leaves the spectrum unchanged unless ``overwrite_x``;
    plane counts that differ are refused."""
    _need(rt, dtype)
    cdt = CDT[dtype]
    x = rng.standard_normal((3,) + shape)
    eng = DeviceFFT(rt, shape, dtype, mapping=mapping, **options)
    fs = eng.fft_shape
    xd = DeviceArray.from_host(rt, x.astype(dtype))
    X = DeviceArray.empty(rt, (3,) + eng.spectrum_shape, cdt)
    eng.rfft2(xd, X)
    bound = _engine_bound(dtype, fs)
    ref = np.fft.rfft2(x, s=fs)
    got = X.get()
    for c in range(3):
        assert _rel(got[c], ref[c]) <= bound, c
    Z = _crandn(rng, ref.shape)
    X.set(Z.astype(cdt))
    y = DeviceArray.empty(rt, x.shape, dtype)
    eng.irfft2(X, y, overwrite_x=overwrite_x)
    want = np.fft.irfft2(Z, s=fs)[:, :shape[0], :shape[1]]
    got = y.get()
    for c in range(3):
        assert _rel(got[c], want[c]) <= bound, c
    if not overwrite_x:
        assert np.array_equal(X.get(), Z.astype(cdt))
    with pytest.raises(ClfzaError, match="differ in planes"):
        eng.rfft2(xd, DeviceArray.empty(rt, (2,) + eng.spectrum_shape, cdt))


@pytest.mark.parametrize("dtype", DTYPES)
@pytest.mark.parametrize("shape", [(64, 64), (3, 37, 53), (1, 30, 17), (2, 1, 16)])
@pytest.mark.parametrize("zero_copy", [True, False])
def test_host_engine_overwrite_x(rt, rng, dtype, shape, zero_copy):
    """The host engine's inverse with and without ``overwrite_x`` (column pass in place, then
    the rows' complex-to-real transform) against numpy in float64, one and several channel
    planes; ``zero_copy=False`` is the copy-through-host path a GPU takes (forced here)."""
    import types

    from clfza.fft._host import HostFFT

    _need(rt, dtype)
    ny, nx = shape[-2:]
    eng = HostFFT(rt if zero_copy else types.SimpleNamespace(zero_copy=False), (ny, nx),
                  dtype)
    Z = _crandn(rng, shape[:-1] + (nx // 2 + 1,))
    want = np.fft.irfft2(Z, s=(ny, nx))
    for overwrite in (False, True):
        X = DeviceArray.from_host(rt, Z.astype(CDT[dtype]))
        y = DeviceArray.empty(rt, shape, dtype)
        eng.irfft2(X, y, overwrite_x=overwrite)
        assert _rel(y.get(), want) <= 2 * _engine_bound(dtype, (ny, nx))
        if not overwrite:
            assert np.array_equal(X.get(), Z.astype(CDT[dtype]))


@pytest.mark.parametrize("dtype", DTYPES)
@pytest.mark.parametrize("n", [2, 64, 2048, 96, 105, 17])
@pytest.mark.parametrize("layout", ["rows", "cols"])
def test_batch_mapping_c2c(rt, rng, dtype, n, layout):
    """The batch mapping's generated passes (and transposes for rows) on their own."""
    _need(rt, dtype)
    ex = StockhamPlan(rt, dtype, mapping="batch")
    nb = 5
    a = _crandn(rng, (nb, n) if layout == "rows" else (n, nb))
    src = DeviceArray.from_host(rt, a.astype(CDT[dtype]))
    dst = DeviceArray.empty(rt, a.shape, CDT[dtype])
    lay = (1, n) if layout == "rows" else (nb, 1)
    ex.c2c(src.buf, dst.buf, n, nb, *lay, -1)
    assert _rel(dst.get(), np.fft.fft(a, axis=1 if layout == "rows" else 0)) <= _bound(dtype, n)
    ex.c2c(dst.buf, dst.buf, n, nb, *lay, 1, 1.0 / n)  # in place, inverse with 1/n
    assert _rel(dst.get(), a) <= 2 * _bound(dtype, n)


@pytest.mark.parametrize("dtype", DTYPES)
@pytest.mark.parametrize("n", [64, 96])
@pytest.mark.parametrize("nb", [32, 45])
@pytest.mark.parametrize("layout", ["rows", "cols"])
def test_batch_mapping_line_counts(rt, rng, dtype, n, nb, layout):
    """Line counts at and above the batch group width (32): on CPU devices the guard-free
    passes, whose last work-group is shifted back onto the last lines (45 = 32 + 13)."""
    _need(rt, dtype)
    ex = StockhamPlan(rt, dtype, mapping="batch")
    a = _crandn(rng, (nb, n) if layout == "rows" else (n, nb))
    src = DeviceArray.from_host(rt, a.astype(CDT[dtype]))
    dst = DeviceArray.empty(rt, a.shape, CDT[dtype])
    lay = (1, n) if layout == "rows" else (nb, 1)
    ex.c2c(src.buf, dst.buf, n, nb, *lay, 1)
    assert _rel(dst.get(), n * np.fft.ifft(a, axis=1 if layout == "rows" else 0)) <= _bound(
        dtype, n)


def test_split_radices_and_mapping_names(rt):
    from clfza.fft._codegen import RADICES, split_radices

    for n in [2, 8, 64, 128, 1024, 2048, 4096, 8192, 3072, 1280, 1792, 315, 2401, 2**20]:
        rad = split_radices(n)
        assert int(np.prod(rad)) == n and set(rad) <= set(RADICES)
    assert split_radices(2048) == [64, 32] and split_radices(1) == []
    with pytest.raises(ClfzaError):
        DeviceFFT(rt, (8, 8), np.float32, mapping="rows")
    assert DeviceFFT(rt, (8, 8), np.float32).mapping == ("batch" if rt.is_cpu else "lines")


@pytest.mark.parametrize("dtype", DTYPES)
def test_rfft2_parseval(rt, rng, dtype):
    _need(rt, dtype)
    shape = (256, 512)
    x = rng.standard_normal(shape)
    eng = plan(rt, shape, dtype)
    X = DeviceArray.empty(rt, eng.spectrum_shape, CDT[dtype])
    xd = DeviceArray.from_host(rt, x.astype(dtype))   # alive until the queue finishes
    eng.rfft2(xd, X)
    S = np.abs(X.get().astype(np.complex128)) ** 2
    # half spectrum: columns 1 .. nx/2-1 stand for two bins each
    e_f = (S[:, 0].sum() + S[:, -1].sum() + 2 * S[:, 1:-1].sum()) / x.size
    e_t = np.sum(x.astype(dtype).astype(np.float64) ** 2)
    assert abs(e_f - e_t) / e_t <= 2 * _engine_bound(dtype, shape) + 4 * np.finfo(dtype).eps


@pytest.mark.slow
@pytest.mark.parametrize("n", [1024, 2048, 4096])
def test_rfft2_large(rt, rng, n):
    x = rng.standard_normal((n, n))
    eng = plan(rt, (n, n), np.float32)
    X = DeviceArray.empty(rt, eng.spectrum_shape, np.complex64)
    xd = DeviceArray.from_host(rt, x.astype(np.float32))
    eng.rfft2(xd, X)
    assert _rel(X.get(), np.fft.rfft2(x)) <= _engine_bound(np.float32, (n, n))


# ---------------------------------------------------------------------------------------------
# plans, policy, padding, errors

def test_plan_cache(rt):
    a = plan(rt, (64, 64), np.float32)
    assert plan(rt, (64, 64), np.float32) is a
    assert plan(rt, (64, 32), np.float32) is not a
    assert a.name == "opencl-stockham"


def test_plan_cache_is_bounded_least_recently_used_first(rt, monkeypatch):
    from clfza.fft import _opencl as fo

    monkeypatch.setattr(fo, "MAX_PLANS", 3)
    monkeypatch.setattr(fo, "_PLANS", fo.OrderedDict())
    a = plan(rt, (8, 8), np.float32)
    b = plan(rt, (8, 16), np.float32)
    plan(rt, (16, 8), np.float32)
    assert plan(rt, (8, 8), np.float32) is a      # used again: now the most recent
    plan(rt, (16, 16), np.float32)                 # a fourth: drops the least recent, b
    assert len(fo._PLANS) == 3
    assert plan(rt, (8, 8), np.float32) is a
    assert plan(rt, (8, 16), np.float32) is not b  # made anew


def test_select_engine_policy(rt, monkeypatch):
    monkeypatch.delenv("CLFZA_FFT", raising=False)
    eng = select_engine(rt, (32, 32), np.float32, "device")
    assert eng.name == "opencl-stockham"
    auto = select_engine(rt, (32, 32), np.float32, "auto")
    assert auto.name == ("host-scipy" if rt.is_cpu else "opencl-stockham")
    monkeypatch.setenv("CLFZA_FFT", "device")
    assert select_engine(rt, (32, 32), np.float32).name == "opencl-stockham"
    monkeypatch.setenv("CLFZA_FFT", "bogus")
    with pytest.raises(ClfzaError, match="CLFZA_FFT"):
        select_engine(rt, (32, 32), np.float32)
    monkeypatch.delenv("CLFZA_FFT")
    with pytest.raises(ClfzaError, match="policy"):
        select_engine(rt, (32, 32), np.float32, "cufft")
    text = describe_policy(rt)
    assert ("scipy" in text) if rt.is_cpu else ("Stockham" in text)
    assert "Stockham" in describe_policy(rt, "device")


def test_vkfft_missing_or_working(rt):
    from clfza.fft._vkfft import VkFFTEngine, vkfft_available

    if vkfft_available():
        eng = VkFFTEngine(rt, (32, 32), np.float32)
        assert eng.name == "vkfft"
    else:
        with pytest.raises(ClfzaError, match="pip install pyvkfft"):
            VkFFTEngine(rt, (32, 32), np.float32)


def test_unsupported_size_error_and_padding(rt, rng):
    with pytest.raises(ClfzaError, match=r"nearest fast shape is \(98, 105\)"):
        DeviceFFT(rt, (97, 101), np.float32, bluestein=False)
    eng = DeviceFFT(rt, (97, 101), np.float32, bluestein=False, pad_to_fast=True)
    assert eng.fft_shape == (98, 105) and eng.spectrum_shape == (98, 53)
    x = rng.standard_normal((97, 101))
    X = DeviceArray.empty(rt, eng.spectrum_shape, np.complex64)
    xd = DeviceArray.from_host(rt, x.astype(np.float32))
    eng.rfft2(xd, X)
    ref = np.fft.rfft2(x, s=(98, 105))
    bound = _engine_bound(np.float32, (98, 105))
    assert _rel(X.get(), ref) <= bound
    y = DeviceArray.empty(rt, (97, 101), np.float32)
    eng.irfft2(X, y)           # the leading block of the padded inverse is x itself
    assert _rel(y.get(), x) <= 2 * bound
    # fast sizes need no padding
    assert DeviceFFT(rt, (96, 100), np.float32, bluestein=False).fft_shape == (96, 100)


def test_bad_inputs(rt):
    with pytest.raises(ClfzaError):
        DeviceFFT(rt, (64,), np.float32)
    with pytest.raises(ClfzaError):
        DeviceFFT(rt, (0, 64), np.float32)
    with pytest.raises(ClfzaError):
        DeviceFFT(rt, (64, 64), np.int32)
    with pytest.raises(ClfzaError):
        DeviceFFT(rt, "ab", np.float32)
    eng = DeviceFFT(rt, (16, 16), np.float32)
    x = DeviceArray.empty(rt, (16, 16), np.float32)
    X = DeviceArray.empty(rt, (16, 9), np.complex64)
    with pytest.raises(ClfzaError, match="rfft2 output"):
        eng.rfft2(x, DeviceArray.empty(rt, (16, 16), np.complex64))
    with pytest.raises(ClfzaError, match="rfft2 input"):
        eng.rfft2(DeviceArray.empty(rt, (16, 16), np.float64 if rt.has_fp64 else np.int32), X)
    with pytest.raises(ClfzaError, match="DeviceArray"):
        eng.rfft2(np.zeros((16, 16), np.float32), X)
    with pytest.raises(ClfzaError, match="irfft2 input"):
        eng.irfft2(x, x)
    with pytest.raises(ClfzaError):
        fft1d_batched(x)                      # real array
    with pytest.raises(ClfzaError):
        fft1d_batched(X, DeviceArray.empty(rt, (16, 8), np.complex64))
    with pytest.raises(ClfzaError):
        fft1d_batched(np.zeros(8, np.complex64))
    with pytest.raises(ClfzaError):
        DeviceArray.empty(rt, (0, 16), np.float32)


def test_joint_colour_refuses_a_one_plane_engine(rt, monkeypatch):
    """An FFT engine that takes one plane per call (VkFFT's) cannot run joint colour: a clear
    ClfzaError naming the engines that can, before any work."""
    from clfza import Camera
    from clfza.backends import get_backend

    monkeypatch.setattr(DeviceFFT, "batched", False)  # stands in for a one-plane engine
    cam = Camera(pitch=0.01, shape=(32, 32), r1=0.2, z1=100.0, z2=3.0, mask="gzp")
    with pytest.raises(ClfzaError, match="fft='device' or fft='host', not 'opencl-stockham'"):
        get_backend("opencl", cam, nc=3, fft="device")
    assert get_backend("opencl", cam, nc=1, fft="device").nc == 1
