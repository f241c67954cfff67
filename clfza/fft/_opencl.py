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

    Notes
    -----
    Same contract as :class:`~clfza.fft.HostFFT`: ``rfft2(x, X)`` is unnormalised, ``irfft2(X,
    x)`` divides by ``Ny * Nx``, and ``irfft2`` leaves ``X`` unchanged. Both only enqueue
    work: keep the arrays alive until the queue has finished (on CPU devices their host
    memory is the buffer). Scratch buffers are allocated once per engine. Use :func:`plan` to
    share engines per shape, dtype and device.

    Arrays of shape ``(C, Ny, Nx)`` (joint colour) are transformed plane by plane in one call:
    each plane is a sub-buffer of the array where its byte offset meets the device's
    base-address alignment (``CL_DEVICE_MEM_BASE_ADDR_ALIGN``; no copy), else it is copied
    through a plane-sized scratch buffer.
    """

    name = "opencl-stockham"
    batched = True  # (H, W), or (C, H, W) plane by plane

    def __init__(self, rt, shape, dtype=np.float32, *, bluestein: bool = True,
                 pad_to_fast: bool = False, local_rows: bool | None = None,
                 local_cols: bool | None = None, mapping: str | None = None):
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
        self.ex = StockhamPlan(rt, self.dtype, local_rows, local_cols, mapping)
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
        """Validate ``a`` as ``shape`` or ``(C, *shape)`` of ``dtype``; return ``C``."""
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

    def _plane(self, a: DeviceArray, i: int, stage: str):
        """``(buffer, byte offset, bytes)`` of plane ``i`` of a ``(C, ...)`` array: a
        sub-buffer (offset None) where the offset meets the device's base-address alignment,
        else the scratch buffer ``stage`` (the caller copies the plane in or out). Padded
        grids always stage: a rectangular copy from a sub-buffer (their zero-padding) is a
        segmentation fault in PoCL 3.0 and 3.1 (``clEnqueueCopyBufferRect``, even at offset 0;
        found by tests/test_fft_opencl.py's plane test)."""
        nbytes = a.nbytes // a.shape[0]
        off = i * nbytes
        if off % self._align == 0 and not self.padded:
            return a.buf.get_sub_region(off, nbytes), None, nbytes
        return self.ex.scratch(stage, -(-nbytes // self.cdtype.itemsize)), off, nbytes

    def _planewise(self, src: DeviceArray, dst: DeviceArray, one) -> None:
        """``one(src_plane_buf, dst_plane_buf)`` for every plane of ``(C, ...)`` arrays."""
        cl, q = self.rt.cl, self.rt.queue
        for i in range(src.shape[0]):
            sbuf, soff, sn = self._plane(src, i, "stage_src")
            dbuf, doff, dn = self._plane(dst, i, "stage_dst")
            if soff is not None:
                cl.enqueue_copy(q, sbuf, src.buf, byte_count=sn, src_offset=soff)
            one(sbuf, dbuf)
            if doff is not None:
                cl.enqueue_copy(q, dst.buf, dbuf, byte_count=dn, dst_offset=doff)

    def _launch2(self, name, gsize, *args) -> None:
        self.ex.K.k[name](self.rt.queue, gsize, None, *args)

    def _rows_local(self, kernel: str, src, dst, sign: int, scale: float) -> bool:
        """Even-width rows in one work-group each (``fft_local_r2c`` or ``fft_local_c2r``,
        twiddles of the half length ``m`` for ``sign``); False where the device has no
        local kernel for ``m`` or local rows are off (the caller then runs the passes)."""
        K = self.ex.K
        ks = K.local(self.m) if self.ex.local_rows else None
        if ks is None:
            return False
        T = ks["T"]
        ks[kernel](self.rt.queue, (self.fft_shape[0] * T,), (T,), src, dst,
                   K.line(self.m).tw[sign].buf, self.twh.buf, np.int32(self.nxh), K.real(scale))
        return True

    # -- rows --------------------------------------------------------------------------------
    def _rows_r2c(self, xbuf, Xbuf, scale: float = 1.0) -> None:
        """Real rows (ny, nx) -> half spectra (ny, nxh)."""
        ex, K = self.ex, self.ex.K
        ny, nx = self.fft_shape
        i32 = np.int32
        if self.even:
            if self._rows_local("fft_local_r2c", xbuf, Xbuf, -1, scale):
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

    def _rows_c2r(self, Xbuf, xbuf, scale: float) -> None:
        """Half spectra (ny, nxh) -> real rows (ny, nx), times ``scale`` (unnormalised)."""
        ex, K = self.ex, self.ex.K
        ny, nx = self.fft_shape
        i32 = np.int32
        if self.even:
            if self._rows_local("fft_local_c2r", Xbuf, xbuf, 1, scale):
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
    def _batch_r2c(self, xbuf, Xbuf) -> None:
        """rfft2 as column transforms: transpose the rows (read as ``m`` complex values),
        transform them along the columns, untangle while transposing back, then transform the
        columns of the half spectrum in place."""
        ex, K = self.ex, self.ex.K
        ny, _ = self.fft_shape
        m, nxh = self.m, self.nxh
        ld = pad_ld(ny)
        Zt = self.ex.scratch("Zt", m * ld)
        ex.transpose(xbuf, Zt, ny, m, ldd=ld)
        Z = ex.batch_passes(Zt, m, ny, ld, -1) if m > 1 else Zt
        K.tiled("r2c_untangle_t", ny, m + 1, Z, Xbuf, self.twh.buf, np.int32(m), np.int32(ny),
                np.int32(ld), K.real(1.0))
        if ny > 1:
            ex.batch_passes(Xbuf, ny, nxh, nxh, -1, 1.0, Xbuf)

    def _batch_c2r(self, Xbuf, xbuf, scale: float, overwrite_x: bool = False) -> None:
        """irfft2, the steps of :meth:`_batch_r2c` reversed; ``Xbuf`` is not written unless
        ``overwrite_x`` (the column passes then end in it)."""
        ex, K = self.ex, self.ex.K
        ny, _ = self.fft_shape
        m, nxh = self.m, self.nxh
        out = (1.0, Xbuf) if overwrite_x else ()
        C = ex.batch_passes(Xbuf, ny, nxh, nxh, 1, *out) if ny > 1 else Xbuf
        ld = pad_ld(ny)
        Zt = self.ex.scratch("Zt", m * ld)
        K.tiled("c2r_untangle_t", m, ny, C, Zt, self.twh.buf, np.int32(m), np.int32(ny),
                np.int32(ld), w=True)
        Z = ex.batch_passes(Zt, m, ny, ld, 1) if m > 1 else Zt
        ex.transpose(Z, xbuf, m, ny, scale, lds=ld)

    # -- public ------------------------------------------------------------------------------
    def rfft2(self, x: DeviceArray, X: DeviceArray) -> None:
        """``X = rfft2(x)`` (unnormalised) for ``(Ny, Nx)`` or ``(C, Ny, Nx)`` ``x``, enqueued
        on the runtime's queue."""
        c = self._check(x, self.shape, self.dtype, "rfft2 input")
        if self._check(X, self.spectrum_shape, self.cdtype, "rfft2 output") != c:
            raise ClfzaError(f"rfft2 input {x.shape} and output {X.shape} differ in planes")
        if c == 1:
            self._rfft2_plane(x.buf, X.buf)
        else:
            self._planewise(x, X, self._rfft2_plane)

    def irfft2(self, X: DeviceArray, x: DeviceArray, overwrite_x: bool = False) -> None:
        """``x = irfft2(X)`` (divides by ``Ny * Nx``); ``X`` is left unchanged unless
        ``overwrite_x`` (then the column pass runs in place in ``X``, as in :meth:`rfft2`)."""
        c = self._check(X, self.spectrum_shape, self.cdtype, "irfft2 input")
        if self._check(x, self.shape, self.dtype, "irfft2 output") != c:
            raise ClfzaError(f"irfft2 input {X.shape} and output {x.shape} differ in planes")
        if c == 1:
            self._irfft2_plane(X.buf, x.buf, overwrite_x)
        else:  # a staged plane is a copy: overwriting it leaves X unchanged
            self._planewise(X, x, lambda s, d: self._irfft2_plane(s, d, overwrite_x))

    def _rfft2_plane(self, xbuf, Xbuf) -> None:
        ny, nx = self.fft_shape
        if self.padded:
            xbuf = self._pad_in(xbuf)
        if self.batch_real:
            self._batch_r2c(xbuf, Xbuf)
            return
        self._rows_r2c(xbuf, Xbuf)
        self.ex.c2c(Xbuf, Xbuf, ny, self.nxh, self.nxh, 1, -1)

    def _irfft2_plane(self, Xbuf, xbuf, overwrite_x: bool) -> None:
        ny, nx = self.fft_shape
        if self.batch_real:
            if self.padded:
                P = self.ex.scratch("pad", (ny * nx + 1) // 2)
                self._batch_c2r(Xbuf, P, 1.0 / (ny * nx), overwrite_x)
                self._crop_out(P, xbuf)
            else:
                self._batch_c2r(Xbuf, xbuf, 1.0 / (ny * nx), overwrite_x)
            return
        C = Xbuf if overwrite_x else self.ex.scratch("cols", ny * self.nxh)
        self.ex.c2c(Xbuf, C, ny, self.nxh, self.nxh, 1, 1)
        if self.padded:
            P = self.ex.scratch("pad", (ny * nx + 1) // 2)
            self._rows_c2r(C, P, 1.0 / (ny * nx))
            self._crop_out(P, xbuf)
        else:
            self._rows_c2r(C, xbuf, 1.0 / (ny * nx))

    # -- padding (bluestein=False, pad_to_fast=True) -----------------------------------------
    def _pad_in(self, xbuf):
        ny, nx = self.fft_shape
        P = self.ex.scratch("pad", (ny * nx + 1) // 2)
        cl = self.rt.cl
        isz = self.dtype.itemsize
        q = self.rt.queue
        zero = np.zeros(1, self.dtype)
        cl.enqueue_fill_buffer(q, P, zero, 0, ny * nx * isz)
        sy, sx = self.shape
        cl.enqueue_copy(q, P, xbuf, src_origin=(0, 0, 0), dst_origin=(0, 0, 0),
                        region=(sx * isz, sy, 1), src_pitches=(sx * isz, sx * sy * isz),
                        dst_pitches=(nx * isz, nx * ny * isz))
        return P

    def _crop_out(self, P, xbuf) -> None:
        ny, nx = self.fft_shape
        sy, sx = self.shape
        isz = self.dtype.itemsize
        self.rt.cl.enqueue_copy(self.rt.queue, xbuf, P, src_origin=(0, 0, 0),
                                dst_origin=(0, 0, 0), region=(sx * isz, sy, 1),
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
