"""Batched device FFTs (issue 37): ``(P, Ny, Nx)`` stacks through :class:`DeviceFFT` with every
pass launched once for all planes, on both work-item mappings.

Tolerances. Each plane of a batched call and the same plane transformed alone are both within
the engine's bound of the exact transform (tests/test_fft_opencl.py: relative L2 error at most
C * eps * log2 N per 1-D transform, C = 1 for fast sizes and 2 for Bluestein sizes, the row
and column transforms added, plus 2 eps for the untangling), so they differ by at most twice
that bound. Usually they are bit-identical (the same kernels do the same arithmetic per
element); they need not be where more lines per launch pick other radices (the "batch"
mapping's row passes on CPU devices: fewer lines than a work-group run the radix-2..8 passes,
more run the generated radix-16..64 ones), or where a compiler contracts the vectorised and
the remainder work-items differently. Against numpy in float64, the bound itself, as in
tests/test_fft_opencl.py.
"""

from __future__ import annotations

import re
import sys
from pathlib import Path

import numpy as np
import pytest

from clfza.cl import DeviceArray
from clfza.errors import ClfzaError
from clfza.fft._opencl import CPU_BATCH_BYTES, DeviceFFT, is_fast_size

pytestmark = pytest.mark.agreement  # rerun on every OpenCL device (.ci/run)

DTYPES = [np.float32, np.float64]
CDT = {np.float32: np.complex64, np.float64: np.complex128}
SHAPES = [(64, 64), (48, 80), (30, 42), (256, 256)]
PLANES = [1, 2, 3, 5]
MAPPINGS = ["batch", "lines"]
ALL = 1 << 20  # planes_per_launch: every plane of these tests in one launch, CPU devices too
BENCH = Path(__file__).resolve().parents[1] / "bench"


def _need(rt, dtype):
    if np.dtype(dtype) == np.float64 and not rt.has_fp64:
        pytest.skip("device has no float64")


def _bound(dtype, shape) -> float:
    """The engine's error bound for a real 2-D transform of ``shape`` (see the module
    docstring)."""
    eps = np.finfo(dtype).eps
    ny, nx = shape
    m = nx // 2 if nx % 2 == 0 else nx

    def line(n):
        return (1.0 if is_fast_size(n) else 2.0) * eps * max(1.0, np.log2(max(n, 2)))

    return line(m) + line(ny) + 2 * eps


def _rel(a, b) -> float:
    return float(np.linalg.norm(a - b) / np.linalg.norm(b))


def _crandn(rng, shape):
    return rng.standard_normal(shape) + 1j * rng.standard_normal(shape)


def _per_plane_forward(rt, eng, x, dtype):
    out = []
    for p in range(x.shape[0]):
        xd = DeviceArray.from_host(rt, x[p].astype(dtype))
        X = DeviceArray.empty(rt, eng.spectrum_shape, CDT[dtype])
        eng.rfft2(xd, X)
        out.append(X.get())
    return np.stack(out)


def _per_plane_inverse(rt, eng, Z, dtype):
    out = []
    for p in range(Z.shape[0]):
        X = DeviceArray.from_host(rt, Z[p].astype(CDT[dtype]))
        y = DeviceArray.empty(rt, eng.shape, dtype)
        eng.irfft2(X, y)
        out.append(y.get())
    return np.stack(out)


@pytest.mark.parametrize("dtype", DTYPES)
@pytest.mark.parametrize("shape", SHAPES)
@pytest.mark.parametrize("planes", PLANES)
@pytest.mark.parametrize("mapping", MAPPINGS)
def test_batched_equals_per_plane_and_numpy(rt, rng, dtype, shape, planes, mapping):
    """One call on P planes (all in one launch, CPU devices too) gives each plane's transform
    alone and numpy's, forward and inverse; the inverse leaves its input unchanged."""
    _need(rt, dtype)
    cdt = CDT[dtype]
    eng = DeviceFFT(rt, shape, dtype, mapping=mapping, planes_per_launch=ALL)
    assert eng.launch_groups(planes) == [planes]
    bound = _bound(dtype, shape)
    x = rng.standard_normal((planes,) + shape)
    xd = DeviceArray.from_host(rt, x.astype(dtype))
    X = DeviceArray.empty(rt, (planes,) + eng.spectrum_shape, cdt)
    eng.rfft2(xd, X)
    got = X.get()
    alone = _per_plane_forward(rt, eng, x, dtype)
    ref = np.fft.rfft2(x)
    for p in range(planes):
        assert _rel(got[p], alone[p]) <= 2 * bound, p
        assert _rel(got[p], ref[p]) <= bound, p
    # inverse of arbitrary half spectra (numpy ignores the imaginary parts a real signal
    # cannot have, and so does the engine)
    Z = _crandn(rng, ref.shape).astype(cdt)
    X.set(Z)
    y = DeviceArray.empty(rt, x.shape, dtype)
    eng.irfft2(X, y)
    assert np.array_equal(X.get(), Z)
    got = y.get()
    alone = _per_plane_inverse(rt, eng, Z, dtype)
    want = np.fft.irfft2(Z.astype(np.complex128), s=shape)
    for p in range(planes):
        assert _rel(got[p], alone[p]) <= 2 * bound, p
        assert _rel(got[p], want[p]) <= bound, p
    # overwrite_x: the same inverse, X may change
    eng.irfft2(X, y, overwrite_x=True)
    for p in range(planes):
        assert _rel(y.get()[p], want[p]) <= bound, p


@pytest.mark.parametrize("dtype", DTYPES)
@pytest.mark.parametrize("mapping", MAPPINGS)
@pytest.mark.parametrize("shape,options", [
    ((37, 50), {}),                                         # Bluestein rows (25) and columns
    ((45, 35), {}),                                         # odd width: full complex rows
    ((34, 26), {"bluestein": False, "pad_to_fast": True}),  # zero-padded grid, 17 -> 18
])
def test_batched_other_sizes(rt, rng, dtype, mapping, shape, options):
    """Sizes that are not fast (Bluestein), odd widths and the padded grid, three planes in
    one call against numpy, forward and inverse (X unchanged)."""
    _need(rt, dtype)
    cdt = CDT[dtype]
    eng = DeviceFFT(rt, shape, dtype, mapping=mapping, planes_per_launch=ALL, **options)
    fs = eng.fft_shape
    bound = _bound(dtype, fs)
    x = rng.standard_normal((3,) + shape)
    xd = DeviceArray.from_host(rt, x.astype(dtype))
    X = DeviceArray.empty(rt, (3,) + eng.spectrum_shape, cdt)
    eng.rfft2(xd, X)
    ref = np.fft.rfft2(x, s=fs)
    got = X.get()
    alone = _per_plane_forward(rt, eng, x, dtype)
    for p in range(3):
        assert _rel(got[p], ref[p]) <= bound, p
        assert _rel(got[p], alone[p]) <= 2 * bound, p
    Z = _crandn(rng, ref.shape).astype(cdt)
    X.set(Z)
    y = DeviceArray.empty(rt, x.shape, dtype)
    eng.irfft2(X, y)
    assert np.array_equal(X.get(), Z)
    want = np.fft.irfft2(Z.astype(np.complex128), s=fs)[:, :shape[0], :shape[1]]
    for p in range(3):
        assert _rel(y.get()[p], want[p]) <= bound, p


@pytest.mark.parametrize("mapping", MAPPINGS)
@pytest.mark.parametrize("shape,per_launch,groups", [
    ((48, 80), 2, [2, 2, 1]),   # plane bytes multiples of 128: sub-buffers of 2 planes
    ((30, 42), 2, [5]),         # 5040-byte planes: 8 planes keep 128-byte offsets, so all 5
    ((64, 64), 1, [1] * 5),
])
def test_planes_per_launch_groups(rt, rng, mapping, shape, per_launch, groups):
    """Fewer planes per launch than the call has: consecutive groups of planes (sub-buffers
    whose byte offsets meet the base-address alignment, else larger groups), same results."""
    if rt.device.mem_base_addr_align // 8 != 128:
        pytest.skip("the expected groups assume a 128-byte base-address alignment")
    eng = DeviceFFT(rt, shape, np.float32, mapping=mapping, planes_per_launch=per_launch)
    assert eng.launch_groups(5) == groups
    x = rng.standard_normal((5,) + shape)
    xd = DeviceArray.from_host(rt, x.astype(np.float32))
    X = DeviceArray.empty(rt, (5,) + eng.spectrum_shape, np.complex64)
    eng.rfft2(xd, X)
    bound = _bound(np.float32, shape)
    ref = np.fft.rfft2(x)
    for p in range(5):
        assert _rel(X.get()[p], ref[p]) <= bound, p
    Z = _crandn(rng, ref.shape).astype(np.complex64)
    X.set(Z)
    eng.irfft2(X, xd)
    assert np.array_equal(X.get(), Z)
    want = np.fft.irfft2(Z.astype(np.complex128), s=shape)
    for p in range(5):
        assert _rel(xd.get()[p], want[p]) <= bound, p


def test_planes_per_launch_default(rt):
    """GPUs take every plane in one launch; CPU devices as many as keep a launch's real input
    within CPU_BATCH_BYTES (at least one), which a stack of small planes shares."""
    big = DeviceFFT(rt, (512, 512), np.float32)
    small = DeviceFFT(rt, (64, 64), np.float32)
    if rt.is_cpu:
        assert big.planes_per_launch == max(1, CPU_BATCH_BYTES // (512 * 512 * 4))
        assert small.planes_per_launch == CPU_BATCH_BYTES // (64 * 64 * 4) >= 8
    else:
        assert big.planes_per_launch is None and big.launch_groups(8) == [8]
    assert small.launch_groups(8) == [8]
    with pytest.raises(ClfzaError, match="planes_per_launch"):
        DeviceFFT(rt, (64, 64), np.float32, planes_per_launch=0)


@pytest.fixture()
def counting(monkeypatch):
    """bench/bench_gpu.py's launch counter (every pyopencl kernel call goes through
    ``enqueue_nd_range_kernel``): batched calls counted the way the benchmark counts them."""
    monkeypatch.syspath_prepend(str(BENCH))
    import bench_gpu

    return bench_gpu.counting


@pytest.mark.parametrize("mapping", MAPPINGS)
@pytest.mark.parametrize("shape", [(64, 64), (256, 256), (30, 42), (37, 50)])
def test_launches_do_not_grow_with_planes(rt, rng, counting, mapping, shape):
    """One call on 4 planes makes as many kernel launches as one on a single plane, forward and
    inverse, for fast sizes; for Bluestein sizes no more (its inner transforms of the lines of
    all planes may take fewer, larger radices on CPU devices, as more lines do)."""
    eng = DeviceFFT(rt, shape, np.float32, mapping=mapping, planes_per_launch=ALL)
    counts = {}
    for planes in (1, 4):
        lead = (planes,) if planes > 1 else ()
        xd = DeviceArray.from_host(rt, rng.standard_normal(lead + shape).astype(np.float32))
        X = DeviceArray.empty(rt, lead + eng.spectrum_shape, np.complex64)
        eng.rfft2(xd, X)  # compiles and sizes the scratch buffers outside the count
        eng.irfft2(X, xd)
        rt.finish()
        with counting() as c:
            eng.rfft2(xd, X)
        with counting() as d:
            eng.irfft2(X, xd)
        rt.finish()
        counts[planes] = (c["launches"], d["launches"])
    assert counts[1][0] >= 2 and counts[1][1] >= 2
    if all(is_fast_size(n) for n in shape):
        assert counts[4] == counts[1], counts
    else:
        assert counts[4][0] <= counts[1][0] and counts[4][1] <= counts[1][1], counts


# ----- Oclgrind ------------------------------------------------------------------------------
ERRORS = re.compile(r"Invalid (read|write)|data race|out of bounds", re.IGNORECASE)
CONTROL_END = "@@clfza-oclgrind-controls-done"
_CONTROLS = """
__kernel void oob(__global float *a) { a[get_global_id(0)] += a[get_global_id(0) + 1]; }
__kernel void race(__global float *a) { a[0] = (float)get_global_id(0); }
"""


@pytest.mark.oclgrind
def test_batched_fft_clean_under_oclgrind(oclgrind):
    """The batched transforms under Oclgrind (a simulated GPU: the "lines" mapping by default,
    every plane in one launch), three planes of 16 x 24 (column passes in global memory, and
    in local memory when forced), the "batch" mapping's guarded GPU kernels and a Bluestein
    size (13 x 22) too: no out-of-bounds access, no data race
    (``OCLGRIND_DATA_RACES=1``; controls prove both checks are on), results as numpy's."""
    p = oclgrind([str(Path(__file__).resolve())])
    assert p.returncode == 0, p.stdout[-2000:] + p.stderr[-4000:]
    assert "device: Oclgrind" in p.stdout, p.stdout
    assert p.stdout.count("batched fft") == 4, p.stdout[-2000:]
    control, _, rest = p.stderr.partition(CONTROL_END)
    assert re.search(r"Invalid read", control), control[-2000:]
    assert re.search(r"data race", control, re.IGNORECASE), control[-2000:]
    reports = [ln for ln in rest.splitlines() if ERRORS.search(ln)]
    assert not reports, "\n".join(reports[:40])


def _child() -> int:
    """Under Oclgrind: the controls, then batched calls checked against numpy."""
    import warnings

    from clfza.cl import get_runtime

    warnings.simplefilter("ignore")
    rt = get_runtime()
    print(f"device: {rt.info.name} ({rt.info.kind})", flush=True)
    ctl = rt.build(_CONTROLS)
    a = DeviceArray.from_host(rt, np.zeros(16, np.float32))
    ctl.oob(rt.queue, (16,), (16,), a.buf)
    ctl.race(rt.queue, (16,), (16,), a.buf)
    rt.finish()
    sys.stderr.write("\n" + CONTROL_END + "\n")
    sys.stderr.flush()
    rng = np.random.default_rng(5)
    for shape, options in (((16, 24), {}), ((16, 24), {"local_cols": True}),
                           ((16, 24), {"mapping": "batch"}), ((13, 22), {})):
        eng = DeviceFFT(rt, shape, np.float32, **options)
        assert eng.launch_groups(3) == [3]
        x = rng.standard_normal((3,) + shape)
        xd = DeviceArray.from_host(rt, x.astype(np.float32))
        X = DeviceArray.empty(rt, (3,) + eng.spectrum_shape, np.complex64)
        eng.rfft2(xd, X)
        bound = _bound(np.float32, shape)
        ref = np.fft.rfft2(x)
        errs = [_rel(X.get()[p], ref[p]) for p in range(3)]
        assert max(errs) <= bound, errs
        X0 = X.get()
        y = DeviceArray.empty(rt, x.shape, np.float32)
        eng.irfft2(X, y)
        assert np.array_equal(X.get(), X0)
        assert max(_rel(y.get()[p], x[p]) for p in range(3)) <= 2 * bound
        eng.irfft2(X, y, overwrite_x=True)
        assert max(_rel(y.get()[p], x[p]) for p in range(3)) <= 2 * bound
        print("batched fft", shape, options, f"{max(errs):.1e}", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(_child())
