"""OpenCL FFTs for devices of any vendor: Stockham autosort kernels (``kernels/fft.cl``).

Building blocks
---------------
* Batched 1-D complex transforms of any length: lengths whose factors are 2, 3, 5 and 7 ("fast"
  sizes) run as Stockham autosort passes of radix 8, 4, 2, 3, 5 and 7, either all passes of a
  line inside one work-group in local memory (when the line fits) or one launch per pass in
  global memory; other lengths use Bluestein's chirp-z algorithm with a power-of-two
  convolution.
* Real transforms pack a real row of even length ``N`` as ``N/2`` complex values, transform
  those and untangle the half spectrum (fused into the local-memory row kernel); odd lengths
  go through a full complex transform.
* 2-D transforms: rows, then columns (columns are batched with the batch index running along
  contiguous memory, so that both GPUs (coalescing) and PoCL (vectorisation across
  work-items) read contiguous memory).
* Stacks of ``P`` planes ``(P, Ny, Nx)`` (colour channels, a batch of frames) take one launch
  per pass for all planes, as one plane does: the rows of all planes (and the transposes of
  the "batch" mapping) are one batch of ``P * Ny`` lines; the column passes take the plane as
  a further global dimension. CPU devices cap the planes per launch at a cache-sized stack
  (:data:`CPU_BATCH_BYTES`); GPUs take them all.
* CPU devices (PoCL): the "batch" mapping's kernels run without per-work-item edge guards
  (the last work-group is shifted back onto the edge instead; a guard makes PoCL mask every
  load and store), and every kernel has its scalar argument types fixed (pyopencl's untyped
  scalar path is slow; both measured: docs/measurements.md, clfza.fft._opencl).

Conventions follow numpy: the forward transform is unnormalised, the inverse divides by the
number of points. Twiddle and chirp tables are computed on the host in float64 (chirp phases
with ``m^2 mod 2n`` in integers) and rounded once to the working precision.

:class:`DeviceFFT` is the engine used by the operator ``K`` (``rfft2``/``irfft2`` on
:class:`~clfza.cl.DeviceArray`); :func:`plan` caches engines per shape, dtype and device;
:func:`fft1d_batched` and :func:`fft2` are complex helpers. The sizes live in
:mod:`clfza.fft._sizes`, the kernels and the batched 1-D executor in :mod:`clfza.fft._stockham`
(both re-exported here).
"""

from __future__ import annotations

import math
import threading
from collections import OrderedDict

import numpy as np

from ..cl import DeviceArray, complex_of
from ..errors import ClfzaError
from ._sizes import (  # noqa: F401  (re-exported: the sizes)
    FAST_PRIMES,
    fast_shape,
    good_size,
    is_fast_size,
    next_fast_size,
)
from ._stockham import (  # noqa: F401  (re-exported: the executor, for tests and benchmarks)
    MAPPINGS,
    StockhamPlan,
    check_dtype,
    device_key,
    pad_ld,
)

__all__ = ["DeviceFFT", "plan", "fft1d_batched", "fft2", "is_fast_size", "next_fast_size",
           "good_size", "fast_shape"]

_MAX_LEN = 2**26  # int32 index arithmetic in the kernels stays far from overflow

CPU_BATCH_BYTES = 1 << 20
"""Real input bytes per launch on CPU devices (:class:`DeviceFFT`'s default
``planes_per_launch`` there): every pass sweeps all planes of its launch, and a stack whose
intermediates (about five times its input) no longer fit the processor's caches runs every
pass from main memory, slower on the CPU runtimes than a plane per launch (issue 37's
report); small planes still share launches. GPUs, launch-bound, take all planes at once."""


# ----------------------------------------------------------------------------------------------
# the engine

def _check_shape(shape) -> tuple[int, int]:
    try:
        ny, nx = (int(s) for s in shape)
    except (TypeError, ValueError):
        raise ClfzaError(f"FFT shape must be a pair (rows, cols), got {shape!r}") from None
    if ny < 1 or nx < 2:
        raise ClfzaError(f"FFT shape needs >= 1 row and >= 2 columns, got {shape!r}")
    if ny * nx > _MAX_LEN:
        raise ClfzaError(f"FFT shape {shape!r} exceeds {_MAX_LEN} points")
    return ny, nx


class DeviceFFT:
    """Real 2-D FFTs on an OpenCL device (the "device" policy of :func:`clfza.fft.select_engine`).

    Parameters
    ----------
    rt : Runtime
        The device (:func:`clfza.cl.get_runtime`).
    shape : (int, int)
        Real grid ``(Ny, Nx)``; the spectrum has shape ``(Ny, Nx // 2 + 1)``.
    dtype : numpy dtype
        float32 or float64 (spectra complex64 / complex128).
    bluestein : bool
        Transform sizes with prime factors other than 2, 3, 5, 7 by Bluestein's algorithm
        (default). When False such sizes raise :class:`ClfzaError` naming the nearest fast size,
        unless ``pad_to_fast``.
    pad_to_fast : bool
        Zero-pad the grid to :func:`fast_shape` instead: ``rfft2`` takes ``(Ny, Nx)`` real input
        and writes the spectrum of the padded grid (``spectrum_shape``), ``irfft2`` returns the
        leading ``(Ny, Nx)`` block of the padded inverse. Only used for sizes that are not fast
        when ``bluestein`` is False.
    local_rows, local_cols : bool, optional
        Force the local-memory (whole line per work-group) kernels on or off for rows / columns
        (``"lines"`` mapping); default per device kind.
    mapping : {"batch", "lines"}, optional
        How work-items map onto the transform. ``"batch"`` (default on CPU devices): one
        work-item per (line, butterfly) with the lines along contiguous memory and the
        butterflies of a radix-R (R <= 64) pass in registers, the row transforms done as column
        transforms between tiled transposes that also do the real-to-complex untangling; PoCL
        vectorises these across lines. ``"lines"`` (default on GPUs): a whole line per
        work-group in local memory (or one kernel per pass when it does not fit). Giving
        ``local_rows`` or ``local_cols`` selects ``"lines"``.
    planes_per_launch : int, optional
        At most this many planes of a ``(P, Ny, Nx)`` stack per launch (see Notes). Default:
        all of them on GPUs; on CPU devices as many as keep a launch's real input within
        :data:`CPU_BATCH_BYTES` (at least one).
    columns : {"codelets", "passes"}, optional
        The ``"lines"`` mapping's column transforms outside local memory: the generated
        passes of radix up to 64 (``"codelets"``, fewer launches) or fft.cl's radix-2..8
        passes; default :data:`clfza.fft._stockham.LINES_COLUMNS`.

    Notes
    -----
    Same contract as :class:`~clfza.fft.HostFFT`: ``rfft2(x, X)`` is unnormalised, ``irfft2(X,
    x)`` divides by ``Ny * Nx``, and ``irfft2`` leaves ``X`` unchanged. Both only enqueue
    work: keep the arrays alive until the queue has finished (on CPU devices their host
    memory is the buffer). Scratch buffers are allocated once per engine. Use :func:`plan` to
    share engines per shape, dtype and device.

    Arrays of shape ``(P, Ny, Nx)`` (colour channels, a batch of frames) are transformed in
    one call, every pass launched once for all planes of a launch (up to
    ``planes_per_launch``; all ``P`` by default on GPUs), so such a call makes as many kernel
    launches as one plane does: the rows of all planes are one batch of ``P * Ny`` rows (and
    in the "batch" mapping the transposes and untangling treat the stack as one
    ``(P * Ny, Nx)`` array), the column passes (and Bluestein's chirp multiplications) take
    the plane as a further global dimension. This holds for Bluestein sizes too (more
    launches per call than fast sizes, but no more for more planes). The zero-padded grid
    (``pad_to_fast``) copies all planes in and out with one rectangular copy each and always
    runs all planes in one launch. Fewer planes per launch than ``P`` split the stack into
    sub-buffers of consecutive planes, their number rounded up to keep each sub-buffer's byte
    offset a multiple of the device's base-address alignment
    (``CL_DEVICE_MEM_BASE_ADDR_ALIGN``). Scratch buffers grow with the planes per launch and
    are kept for later calls.
    """

    name = "opencl-stockham"
    batched = True  # (H, W), or (P, H, W) in one call

    def __init__(self, rt, shape, dtype=np.float32, *, bluestein: bool = True,
                 pad_to_fast: bool = False, local_rows: bool | None = None,
                 local_cols: bool | None = None, mapping: str | None = None,
                 planes_per_launch: int | None = None, columns: str | None = None):
        self.rt = rt
        self.shape = _check_shape(shape)
        self.dtype = rt.check_dtype(check_dtype(dtype))
        self.cdtype = complex_of(self.dtype)
        ny, nx = self.shape
        slow = [s for s in self.shape if not is_fast_size(s)]
        self.padded = False
        if slow and not bluestein:
            if not pad_to_fast:
                fs = fast_shape(self.shape)
                raise ClfzaError(
                    f"FFT shape {self.shape} has sizes {slow} with prime factors other than "
                    f"2, 3, 5, 7; the nearest fast shape is {fs} (use bluestein=True, "
                    "pad_to_fast=True, or crop/pad the data to that shape)")
            self.padded = True
            ny, nx = fast_shape(self.shape)
        self.fft_shape = (ny, nx)
        self.ex = StockhamPlan(rt, self.dtype, local_rows, local_cols, mapping, columns)
        self.mapping = self.ex.mapping
        K = self.ex.K
        self.nxh = nx // 2 + 1
        self.even = nx % 2 == 0
        self.m = nx // 2
        if self.even:
            k = np.arange(self.m + 1)
            twh = np.exp(-2j * np.pi * k / nx)
            self.twh = DeviceArray.from_host(rt, twh.astype(self.cdtype))
            K.line(self.m)
        K.line(ny)
        K.line(nx)
        if planes_per_launch is None and rt.is_cpu:
            planes_per_launch = max(1, CPU_BATCH_BYTES // (ny * nx * self.dtype.itemsize))
        if planes_per_launch is not None and int(planes_per_launch) < 1:
            raise ClfzaError(f"planes_per_launch must be >= 1, got {planes_per_launch!r}")
        self.planes_per_launch = None if planes_per_launch is None else int(planes_per_launch)
        self._align = max(1, rt.device.mem_base_addr_align // 8)  # bits -> bytes
        # batch mapping of the real transform: even width, fast half width and height
        self.batch_real = (self.mapping == "batch" and self.even and is_fast_size(self.m)
                           and is_fast_size(ny))

    # -- helpers ---------------------------------------------------------------------------
    @property
    def spectrum_shape(self) -> tuple[int, int]:
        """Shape of the half spectrum ``X`` (of the padded grid when padding)."""
        return self.fft_shape[0], self.nxh

    def _check(self, a, shape, dtype, what: str) -> int:
        """Validate ``a`` as ``shape`` or ``(P, *shape)`` of ``dtype``; return ``P``."""
        if not isinstance(a, DeviceArray):
            raise ClfzaError(f"{what} must be a DeviceArray, got {type(a).__name__}")
        if a.rt.context is not self.rt.context:
            raise ClfzaError(f"{what} lives on another OpenCL context than this FFT plan")
        shape = tuple(shape)
        if a.dtype != dtype or not (a.shape == shape or (len(a.shape) == 3 and a.shape[0] >= 1
                                                         and a.shape[1:] == shape)):
            raise ClfzaError(f"{what} must be a {shape} (or (C, *shape)) {dtype} device "
                             f"array, got {a.shape} {a.dtype}")
        return a.shape[0] if len(a.shape) == 3 else 1

    def launch_groups(self, planes: int) -> list[int]:
        """The planes of each group that one set of launches transforms, for a call on
        ``planes`` planes (``[planes]``: every pass launched once for all of them)."""
        k = self._group(planes)
        return [min(k, planes - p0) for p0 in range(0, planes, k)]

    def _group(self, planes: int) -> int:
        """Planes per launch for a call on ``planes`` planes: ``planes_per_launch`` rounded up
        to a count of planes whose real and spectrum bytes are multiples of the base-address
        alignment (sub-buffers must start there), or all planes (padded grids always: a
        rectangular copy from a sub-buffer is a segmentation fault in PoCL 3.0 and 3.1,
        ``clEnqueueCopyBufferRect``)."""
        cap = self.planes_per_launch
        if cap is None or cap >= planes or self.padded:
            return planes
        a = self._align
        rb = self.shape[0] * self.shape[1] * self.dtype.itemsize
        sb = self.fft_shape[0] * self.nxh * self.cdtype.itemsize
        q = math.lcm(a // math.gcd(rb, a), a // math.gcd(sb, a))
        return min(planes, max(q, cap // q * q))

    def _groups(self, src: DeviceArray, dst: DeviceArray, planes: int):
        """``(src buffer, dst buffer, planes)`` per launch group (sub-buffers of consecutive
        planes, or the arrays' own buffers for one group)."""
        k = self._group(planes)
        if k >= planes:
            yield src.buf, dst.buf, planes
            return
        sn, dn = src.nbytes // planes, dst.nbytes // planes
        for p0 in range(0, planes, k):
            n = min(k, planes - p0)
            yield (src.buf.get_sub_region(p0 * sn, n * sn),
                   dst.buf.get_sub_region(p0 * dn, n * dn), n)

    def _launch2(self, name, gsize, *args) -> None:
        self.ex.K.k[name](self.rt.queue, gsize, None, *args)

    def _rows_local(self, kernel: str, src, dst, nrows: int, sign: int, scale: float) -> bool:
        """``nrows`` even-width rows in one work-group each (``fft_local_r2c`` or
        ``fft_local_c2r``, twiddles of the half length ``m`` for ``sign``); False where the
        device has no local kernel for ``m`` or local rows are off (the caller then runs the
        passes)."""
        K = self.ex.K
        ks = K.local(self.m) if self.ex.local_rows else None
        if ks is None:
            return False
        T = ks["T"]
        ks[kernel](self.rt.queue, (nrows * T,), (T,), src, dst,
                   K.line(self.m).tw[sign].buf, self.twh.buf, np.int32(self.nxh), K.real(scale))
        return True

    # -- rows (the rows of all planes are one batch) -----------------------------------------
    def _rows_r2c(self, xbuf, Xbuf, planes: int, scale: float = 1.0) -> None:
        """Real rows (planes * ny, nx) -> half spectra (planes * ny, nxh)."""
        ex, K = self.ex, self.ex.K
        ny, nx = self.fft_shape
        ny *= planes
        i32 = np.int32
        if self.even:
            if self._rows_local("fft_local_r2c", xbuf, Xbuf, ny, -1, scale):
                return
            m = self.m
            Z = self.ex.scratch("rowsZ", ny * m)
            ex.c2c(xbuf, Z, m, ny, 1, m, -1)
            self._launch2("r2c_post", (m + 1, ny), Z, Xbuf, self.twh.buf, i32(m), i32(ny),
                          K.real(scale))
            return
        Z = self.ex.scratch("rowsZ", ny * nx)
        Z2 = self.ex.scratch("rowsZ2", ny * nx)
        self._launch2("real_to_complex", (nx, ny), xbuf, Z, i32(nx), i32(ny))
        ex.c2c(Z, Z2, nx, ny, 1, nx, -1, scale)
        self._launch2("crop_cols", (self.nxh, ny), Z2, Xbuf, i32(nx), i32(self.nxh), i32(ny))

    def _rows_c2r(self, Xbuf, xbuf, planes: int, scale: float) -> None:
        """Half spectra (planes * ny, nxh) -> real rows (planes * ny, nx), times ``scale``
        (unnormalised)."""
        ex, K = self.ex, self.ex.K
        ny, nx = self.fft_shape
        ny *= planes
        i32 = np.int32
        if self.even:
            if self._rows_local("fft_local_c2r", Xbuf, xbuf, ny, 1, scale):
                return
            m = self.m
            Z = self.ex.scratch("rowsZ", ny * m)
            self._launch2("c2r_pre", (m, ny), Xbuf, Z, self.twh.buf, i32(m), i32(ny))
            ex.c2c(Z, xbuf, m, ny, 1, m, 1, scale)
            return
        Z = self.ex.scratch("rowsZ", ny * nx)
        Z2 = self.ex.scratch("rowsZ2", ny * nx)
        self._launch2("hermitian_expand", (nx, ny), Xbuf, Z, i32(nx), i32(ny))
        ex.c2c(Z, Z2, nx, ny, 1, nx, 1)
        self._launch2("take_real", (nx, ny), Z2, xbuf, i32(nx), i32(ny), K.real(scale))

    # -- batch mapping -------------------------------------------------------------------
    def _batch_r2c(self, xbuf, Xbuf, planes: int) -> None:
        """rfft2 as column transforms: transpose the rows (read as ``m`` complex values),
        transform them along the columns, untangle while transposing back, then transform the
        columns of the half spectrum in place. A stack of planes is one ``(planes * ny, nx)``
        array up to the last step, whose passes take the plane as a further dimension."""
        ex, K = self.ex, self.ex.K
        ny, _ = self.fft_shape
        m, nxh = self.m, self.nxh
        nb = planes * ny
        ld = pad_ld(nb)
        Zt = self.ex.scratch("Zt", m * ld)
        ex.transpose(xbuf, Zt, nb, m, ldd=ld)
        Z = ex.batch_passes(Zt, m, nb, ld, -1) if m > 1 else Zt
        K.tiled("r2c_untangle_t", nb, m + 1, Z, Xbuf, self.twh.buf, np.int32(m), np.int32(nb),
                np.int32(ld), K.real(1.0))
        if ny > 1:
            ex.batch_passes(Xbuf, ny, nxh, nxh, -1, 1.0, Xbuf, planes, ny * nxh)

    def _batch_c2r(self, Xbuf, xbuf, planes: int, scale: float, overwrite_x: bool = False
                   ) -> None:
        """irfft2, the steps of :meth:`_batch_r2c` reversed; ``Xbuf`` is not written unless
        ``overwrite_x`` (the column passes then end in it)."""
        ex, K = self.ex, self.ex.K
        ny, _ = self.fft_shape
        m, nxh = self.m, self.nxh
        if ny > 1:
            C = ex.batch_passes(Xbuf, ny, nxh, nxh, 1, 1.0, Xbuf if overwrite_x else None,
                                planes, ny * nxh)
        else:
            C = Xbuf
        nb = planes * ny
        ld = pad_ld(nb)
        Zt = self.ex.scratch("Zt", m * ld)
        K.tiled("c2r_untangle_t", m, nb, C, Zt, self.twh.buf, np.int32(m), np.int32(nb),
                np.int32(ld), w=True)
        Z = ex.batch_passes(Zt, m, nb, ld, 1) if m > 1 else Zt
        ex.transpose(Z, xbuf, m, nb, scale, lds=ld)

    # -- public ------------------------------------------------------------------------------
    def rfft2(self, x: DeviceArray, X: DeviceArray) -> None:
        """``X = rfft2(x)`` (unnormalised) for ``(Ny, Nx)`` or ``(P, Ny, Nx)`` ``x``, enqueued
        on the runtime's queue."""
        c = self._check(x, self.shape, self.dtype, "rfft2 input")
        if self._check(X, self.spectrum_shape, self.cdtype, "rfft2 output") != c:
            raise ClfzaError(f"rfft2 input {x.shape} and output {X.shape} differ in planes")
        for xb, Xb, n in self._groups(x, X, c):
            self._rfft2(xb, Xb, n)

    def irfft2(self, X: DeviceArray, x: DeviceArray, overwrite_x: bool = False) -> None:
        """``x = irfft2(X)`` (divides by ``Ny * Nx``); ``X`` is left unchanged unless
        ``overwrite_x`` (then the column pass runs in place in ``X``, as in :meth:`rfft2`)."""
        c = self._check(X, self.spectrum_shape, self.cdtype, "irfft2 input")
        if self._check(x, self.shape, self.dtype, "irfft2 output") != c:
            raise ClfzaError(f"irfft2 input {X.shape} and output {x.shape} differ in planes")
        for Xb, xb, n in self._groups(X, x, c):
            self._irfft2(Xb, xb, n, overwrite_x)

    def _rfft2(self, xbuf, Xbuf, planes: int) -> None:
        ny, nx = self.fft_shape
        if self.padded:
            xbuf = self._pad_in(xbuf, planes)
        if self.batch_real:
            self._batch_r2c(xbuf, Xbuf, planes)
            return
        self._rows_r2c(xbuf, Xbuf, planes)
        self.ex.c2c(Xbuf, Xbuf, ny, self.nxh, self.nxh, 1, -1, 1.0, planes, ny * self.nxh)

    def _irfft2(self, Xbuf, xbuf, planes: int, overwrite_x: bool) -> None:
        ny, nx = self.fft_shape
        scale = 1.0 / (ny * nx)
        out = self.ex.scratch("pad", (planes * ny * nx + 1) // 2) if self.padded else xbuf
        if self.batch_real:
            self._batch_c2r(Xbuf, out, planes, scale, overwrite_x)
        else:
            C = Xbuf if overwrite_x else self.ex.scratch("cols", planes * ny * self.nxh)
            self.ex.c2c(Xbuf, C, ny, self.nxh, self.nxh, 1, 1, 1.0, planes, ny * self.nxh)
            self._rows_c2r(C, out, planes, scale)
        if self.padded:
            self._crop_out(out, xbuf, planes)

    # -- padding (bluestein=False, pad_to_fast=True) -----------------------------------------
    def _pad_in(self, xbuf, planes: int):
        """Zero-pad ``planes`` real grids into the scratch buffer ``pad`` (one fill, one
        rectangular copy for all planes); returns it."""
        ny, nx = self.fft_shape
        P = self.ex.scratch("pad", (planes * ny * nx + 1) // 2)
        cl = self.rt.cl
        isz = self.dtype.itemsize
        q = self.rt.queue
        zero = np.zeros(1, self.dtype)
        cl.enqueue_fill_buffer(q, P, zero, 0, planes * ny * nx * isz)
        sy, sx = self.shape
        cl.enqueue_copy(q, P, xbuf, src_origin=(0, 0, 0), dst_origin=(0, 0, 0),
                        region=(sx * isz, sy, planes), src_pitches=(sx * isz, sx * sy * isz),
                        dst_pitches=(nx * isz, nx * ny * isz))
        return P

    def _crop_out(self, P, xbuf, planes: int) -> None:
        """The leading ``(Ny, Nx)`` block of every padded plane of ``P`` into ``xbuf``."""
        ny, nx = self.fft_shape
        sy, sx = self.shape
        isz = self.dtype.itemsize
        self.rt.cl.enqueue_copy(self.rt.queue, xbuf, P, src_origin=(0, 0, 0),
                                dst_origin=(0, 0, 0), region=(sx * isz, sy, planes),
                                src_pitches=(nx * isz, nx * ny * isz),
                                dst_pitches=(sx * isz, sx * sy * isz))

    def __repr__(self) -> str:
        return (f"DeviceFFT(shape={self.shape}, dtype={self.dtype}, device="
                f"{self.rt.info.name!r})")


MAX_PLANS = 16
"""Plans kept (least recently used dropped first): each holds device scratch and twiddles, a
few arrays of its shape, and a focus sweep or a planner over many frame sizes would otherwise
keep one per size for the life of the process."""
_PLANS: OrderedDict[tuple, DeviceFFT] = OrderedDict()
_PLOCK = threading.Lock()


def plan(rt, shape, dtype=np.float32, **options) -> DeviceFFT:
    """A cached :class:`DeviceFFT` per (shape, dtype, device, options), at most
    :data:`MAX_PLANS` of them.

    Engines share nothing mutable across threads except the queue; use one thread per runtime.
    """
    from . import _stockham  # lazy: its LINES_COLUMNS as it is now (a benchmark may switch it)

    options = {"columns": _stockham.LINES_COLUMNS, **options}
    key = (tuple(int(s) for s in shape), np.dtype(dtype).str, device_key(rt),
           id(rt.context), tuple(sorted(options.items())))
    with _PLOCK:
        p = _PLANS.get(key)
        if p is not None:
            _PLANS.move_to_end(key)
    if p is None:
        p = DeviceFFT(rt, shape, dtype, **options)
        with _PLOCK:
            _PLANS[key] = p
            while len(_PLANS) > MAX_PLANS:
                _PLANS.popitem(last=False)
    return p


# ----------------------------------------------------------------------------------------------
# complex helpers

_EXECS: dict[tuple, StockhamPlan] = {}


def _exec_for(rt, dtype) -> StockhamPlan:
    key = (device_key(rt), id(rt.context), np.dtype(dtype).str)
    ex = _EXECS.get(key)
    if ex is None:
        ex = StockhamPlan(rt, dtype)
        _EXECS[key] = ex
    return ex


def _real_of(cdtype) -> np.dtype:
    cdt = np.dtype(cdtype)
    if cdt == np.complex64:
        return np.dtype(np.float32)
    if cdt == np.complex128:
        return np.dtype(np.float64)
    raise ClfzaError(f"complex FFTs need complex64 or complex128 device arrays, got {cdt}")


def fft1d_batched(a: DeviceArray, out: DeviceArray | None = None, *, axis: int = -1,
                  inverse: bool = False) -> DeviceArray:
    """Complex FFT of every line of a 1-D or 2-D device array along ``axis``.

    Parameters
    ----------
    a : DeviceArray
        complex64 or complex128, 1-D or 2-D.
    out : DeviceArray, optional
        Same shape and dtype; may be ``a`` itself (in place). Default: a new array.
    axis : int
        The transformed axis (0, 1 or -1).
    inverse : bool
        Inverse transform (divides by the line length, like ``numpy.fft.ifft``).

    Returns
    -------
    DeviceArray
        ``out``.
    """
    if not isinstance(a, DeviceArray):
        raise ClfzaError(f"fft1d_batched needs a DeviceArray, got {type(a).__name__}")
    rdt = _real_of(a.dtype)
    if len(a.shape) not in (1, 2):
        raise ClfzaError(f"fft1d_batched takes 1-D or 2-D arrays, got shape {a.shape}")
    shape = a.shape if len(a.shape) == 2 else (1, a.shape[0])
    ax = axis % len(a.shape)
    if len(a.shape) == 1:
        ax = 1
    if out is None:
        out = DeviceArray.empty(a.rt, a.shape, a.dtype)
    elif not isinstance(out, DeviceArray) or out.shape != a.shape or out.dtype != a.dtype:
        raise ClfzaError(f"out must be a {a.shape} {a.dtype} DeviceArray")
    ny, nx = shape
    n, nb, es, bs = (nx, ny, 1, nx) if ax == 1 else (ny, nx, nx, 1)
    if n * nb > _MAX_LEN:
        raise ClfzaError(f"array of {n * nb} points exceeds {_MAX_LEN}")
    s = 1 if inverse else -1
    _exec_for(a.rt, rdt).c2c(a.buf, out.buf, n, nb, es, bs, s, 1.0 / n if inverse else 1.0)
    return out


def fft2(a: DeviceArray, out: DeviceArray | None = None, *, inverse: bool = False
         ) -> DeviceArray:
    """Complex 2-D FFT of a complex64/complex128 device array (numpy conventions)."""
    if not isinstance(a, DeviceArray) or len(a.shape) != 2:
        raise ClfzaError("fft2 needs a 2-D complex DeviceArray")
    out = fft1d_batched(a, out, axis=1, inverse=inverse)
    return fft1d_batched(out, out, axis=0, inverse=inverse)
