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

Conventions follow numpy: the forward transform is unnormalised, the inverse divides by the
number of points. Twiddle and chirp tables are computed on the host in float64 (chirp phases
with ``m^2 mod 2n`` in integers) and rounded once to the working precision.

:class:`DeviceFFT` is the engine used by the operator ``K`` (``rfft2``/``irfft2`` on
:class:`~clfza.cl.DeviceArray`); :func:`plan` caches engines per shape, dtype and device;
:func:`fft1d_batched` and :func:`fft2` are complex helpers.
"""

from __future__ import annotations

import threading

import numpy as np

from ..cl.arrays import DeviceArray
from ..errors import ClfzaError

__all__ = ["DeviceFFT", "plan", "fft1d_batched", "fft2", "is_fast_size", "next_fast_size",
           "good_size", "fast_shape"]

FAST_PRIMES = (2, 3, 5, 7)
_MAX_LEN = 2**26  # int32 index arithmetic in the kernels stays far from overflow


# ----------------------------------------------------------------------------------------------
# sizes

def _factor_out(n: int) -> int:
    for p in FAST_PRIMES:
        while n % p == 0:
            n //= p
    return n


def is_fast_size(n: int) -> bool:
    """True when ``n >= 1`` has no prime factors other than 2, 3, 5 and 7."""
    return int(n) >= 1 and _factor_out(int(n)) == 1


def next_fast_size(n: int) -> int:
    """The smallest size ``>= n`` whose only prime factors are 2, 3, 5 and 7."""
    n = int(n)
    if n < 1:
        raise ClfzaError(f"FFT size must be >= 1, got {n}")
    while not is_fast_size(n):
        n += 1
    return n


good_size = next_fast_size


def fast_shape(shape) -> tuple[int, ...]:
    """``shape`` with every axis rounded up to :func:`next_fast_size`."""
    return tuple(next_fast_size(s) for s in shape)


def _radices(n: int) -> list[int]:
    """Stockham radix sequence for a fast size: as many 8s as possible, then 4/2, 3, 5, 7."""
    out: list[int] = []
    k = 0
    while n % 2 == 0:
        n //= 2
        k += 1
    out += [8] * (k // 3)
    if k % 3 == 2:
        out.append(4)
    elif k % 3 == 1:
        out.append(2)
    for p in (3, 5, 7):
        while n % p == 0:
            n //= p
            out.append(p)
    if n != 1:  # pragma: no cover - callers check is_fast_size
        raise ClfzaError(f"internal error: {n} left after factoring")
    return out


def _complex_of(dtype) -> np.dtype:
    return np.dtype(np.complex128 if np.dtype(dtype) == np.float64 else np.complex64)


def _check_dtype(dtype) -> np.dtype:
    dt = np.dtype(dtype)
    if dt not in (np.float32, np.float64):
        raise ClfzaError(f"FFT dtype must be float32 or float64, got {dt}")
    return dt


# ----------------------------------------------------------------------------------------------
# per-(device, dtype) kernels and 1-D line plans

class _Line:
    """Tables for one line length: radices and twiddles, or Bluestein's chirp and filter."""

    def __init__(self, ctx: _Kernels, n: int):
        self.n = n
        self.fast = is_fast_size(n)
        cdt = ctx.cdtype
        rt = ctx.rt
        if self.fast:
            self.radices = _radices(n)
            m = np.arange(n)
            w = np.exp(-2j * np.pi * m / n)  # float64 host table
            self.tw = {-1: DeviceArray.from_host(rt, w.astype(cdt)),
                       1: DeviceArray.from_host(rt, np.conj(w).astype(cdt))}
        else:
            L = 1 << (2 * n - 2).bit_length()  # power of two >= 2n - 1
            self.L = L
            m = np.arange(n, dtype=np.int64)
            phase = (m * m) % (2 * n)  # exact: exp(i pi m^2/n) has period 2n in m^2
            chirp = np.exp(-1j * np.pi * phase / n)  # forward chirp, float64
            self.chirp = {}
            self.filt = {}
            for s, c in ((-1, chirp), (1, np.conj(chirp))):
                h = np.zeros(L, np.complex128)
                h[:n] = np.conj(c)
                h[L - n + 1:] = np.conj(c[1:][::-1])
                F = np.fft.fft(h) / L  # the 1/L of the inverse length-L transform folded in
                self.chirp[s] = DeviceArray.from_host(rt, c.astype(cdt))
                self.filt[s] = DeviceArray.from_host(rt, F.astype(cdt))


class _Kernels:
    """Kernels of ``fft.cl`` for one runtime and dtype, plus cached line plans.

    The generic program (Stockham passes in global memory, packing and Bluestein helpers)
    takes every size as an argument; the local-memory line kernels are compiled per line
    length (``-DLOCAL_N=...`` and the radix of every pass) and cached by the runtime.
    """

    def __init__(self, rt, dtype):
        self.rt = rt
        self.dtype = _check_dtype(dtype)
        self.cdtype = _complex_of(self.dtype)
        self.real = self.dtype.type
        prg = rt.program("fft", self.dtype)
        cl = rt.cl
        self.k = {name: cl.Kernel(prg, name) for name in (
            "r2c_post", "c2r_pre", "real_to_complex", "crop_cols", "hermitian_expand",
            "take_real", "bluestein_pre", "bluestein_mul", "bluestein_post")}
        self.passk = {r: cl.Kernel(prg, f"stockham_pass{r}") for r in (2, 3, 4, 5, 7, 8)}
        dev = rt.device
        self.max_wg = int(dev.max_work_group_size)
        self.local_bytes = int(dev.local_mem_size) - 256
        self._lines: dict[int, _Line] = {}
        self._local: dict[int, dict | None] = {}
        self._lock = threading.Lock()

    def line(self, n: int) -> _Line:
        with self._lock:
            ln = self._lines.get(n)
            if ln is None:
                ln = _Line(self, n)
                self._lines[n] = ln
        return ln

    def local(self, n: int) -> dict | None:
        """The local-memory kernels for lines of ``n`` points, or None when they do not fit."""
        with self._lock:
            if n in self._local:
                return self._local[n]
        ks = None
        T = max(1, -(-n // 8))
        if (is_fast_size(n) and n * self.cdtype.itemsize <= self.local_bytes
                and T <= self.max_wg and len(_radices(n)) <= 12):
            rad = _radices(n)
            # CPU devices: a column kernel with C adjacent lines per group (64-byte reads)
            isz = self.cdtype.itemsize
            C = 64 // isz
            if not (self.rt.is_cpu and C * n * isz <= self.local_bytes and T * C <= self.max_wg):
                C = 1
            defs = {"LOCAL_N": n, "LOCAL_T": T, "NPASS": len(rad), "LOCAL_C": C}
            ns = 1
            for i, r in enumerate(rad):
                defs[f"R{i}"] = r
                defs[f"S{i}"] = ns
                ns *= r
            cl = self.rt.cl
            try:
                prg = self.rt.program("fft", self.dtype, defs)
                ks = {name: cl.Kernel(prg, name)
                      for name in ("fft_local_c2c", "fft_local_r2c", "fft_local_c2r")}
                wg = min(int(k.get_work_group_info(cl.kernel_work_group_info.WORK_GROUP_SIZE,
                                                   self.rt.device)) for k in ks.values())
                if wg < T:
                    ks = None
                else:
                    ks["T"] = T
                    if C > 1:
                        kc = cl.Kernel(prg, "fft_local_cols")
                        if int(kc.get_work_group_info(
                                cl.kernel_work_group_info.WORK_GROUP_SIZE,
                                self.rt.device)) >= T * C:
                            ks["fft_local_cols"] = kc
                            ks["C"] = C
            except ClfzaError:  # e.g. too much local memory for this compiler: use passes
                ks = None
        with self._lock:
            self._local[n] = ks
        return ks

_KERNELS: dict[tuple[int, str], _Kernels] = {}
_KLOCK = threading.Lock()


def _device_key(rt) -> int:
    return int(rt.device.int_ptr)


def _kernels(rt, dtype) -> _Kernels:
    dt = _check_dtype(dtype)
    key = (_device_key(rt), id(rt.context), dt.str)
    with _KLOCK:
        k = _KERNELS.get(key)
    if k is None:
        k = _Kernels(rt, dt)
        with _KLOCK:
            _KERNELS[key] = k
    return k


# ----------------------------------------------------------------------------------------------
# executor: batched 1-D complex transforms on raw buffers

class _Exec:
    """Enqueues batched 1-D complex transforms on buffers, with its own scratch buffers.

    ``local_rows`` / ``local_cols``: whether lines with unit element stride (rows) / other
    strides (columns) use the local-memory kernel when they fit; None picks per device kind.
    """

    def __init__(self, rt, dtype, local_rows: bool | None = None,
                 local_cols: bool | None = None):
        self.rt = rt
        self.K = _kernels(rt, dtype)
        self.dtype = self.K.dtype
        self.cdtype = self.K.cdtype
        self.local_rows = True if local_rows is None else bool(local_rows)
        # GPUs: strided lines in one work-group read uncoalesced memory; passes with the batch
        # along contiguous memory are better. PoCL: measured in bench/bench_fft.py.
        self.local_cols = (rt.is_cpu if local_cols is None else bool(local_cols))
        self._scratch: dict[str, DeviceArray] = {}

    def scratch(self, name: str, nelem: int):
        a = self._scratch.get(name)
        if a is None or a.size < nelem:
            if a is not None:  # queued kernels may still use the old one (zero-copy memory)
                self.rt.finish()
            a = DeviceArray.empty(self.rt, (int(nelem),), self.cdtype)
            self._scratch[name] = a
        return a.buf

    def _use_local(self, n: int, es: int) -> bool:
        if not (self.local_rows if es == 1 else self.local_cols):
            return False
        return self.K.local(n) is not None

    def c2c(self, src, dst, n: int, nb: int, es: int, bs: int, sign: int, scale: float = 1.0
            ) -> None:
        """dst = scale * FFT_sign(src) over ``nb`` lines of ``n`` points (layout es, bs)."""
        K = self.K
        q = self.rt.queue
        ln = K.line(n)
        r = K.real
        if not ln.fast:
            self._bluestein(ln, src, dst, nb, es, bs, sign, scale)
            return
        if n == 1:
            if src is not dst or scale != 1.0:
                self._local(ln, src, dst, nb, es, bs, sign, scale)
            return
        if self._use_local(n, es):
            self._local(ln, src, dst, nb, es, bs, sign, scale)
            return
        # one launch per pass, ping-pong through two scratch buffers
        extent = (nb - 1) * bs + (n - 1) * es + 1
        s1 = self.scratch("pass1", extent)
        s2 = self.scratch("pass2", extent)
        P = len(ln.radices)
        bufs = [src]
        for _ in range(P - 1):
            bufs.append(s1 if bufs[-1] is not s1 else s2)
        copy_back = P == 1 and src is dst
        bufs.append(s1 if copy_back else dst)
        batch_fast = es != 1 and bs == 1
        ns = 1
        for p, R in enumerate(ln.radices):
            nq = n // R
            if batch_fast:  # rows of 64 work-items along contiguous memory (kernel guards b)
                gsize, lsize = (-(-nb // 64) * 64, nq), (64, 1)
            else:
                gsize, lsize = (nq, nb), None
            sc = scale if p == P - 1 else 1.0
            K.passk[R](q, gsize, lsize, bufs[p], bufs[p + 1], ln.tw[sign].buf, np.int32(n),
                       np.int32(ns), np.int32(es), np.int32(bs), np.int32(nb),
                       np.int32(batch_fast), r(sign), r(sc))
            ns *= R
        if copy_back:
            isz = self.cdtype.itemsize
            self.rt.cl.enqueue_copy(q, dst, s1, byte_count=extent * isz)

    def _local(self, ln: _Line, src, dst, nb, es, bs, sign, scale) -> None:
        K = self.K
        ks = K.local(ln.n)
        T = ks["T"]
        if bs == 1 and es != 1 and "fft_local_cols" in ks:
            C = ks["C"]
            ks["fft_local_cols"](self.rt.queue, (-(-nb // C) * T * C,), (T * C,), src, dst,
                                 ln.tw[sign].buf, np.int32(es), np.int32(nb), K.real(sign),
                                 K.real(scale))
            return
        ks["fft_local_c2c"](self.rt.queue, (nb * T,), (T,), src, dst, ln.tw[sign].buf,
                            np.int32(es), np.int32(bs), K.real(sign), K.real(scale))

    def _bluestein(self, ln: _Line, src, dst, nb, es, bs, sign, scale) -> None:
        K = self.K
        q = self.rt.queue
        n, L = ln.n, ln.L
        A = self.scratch("bluestein", nb * L)
        w = ln.chirp[sign].buf
        K.k["bluestein_pre"](q, (L, nb), None, src, A, w, np.int32(n), np.int32(L),
                             np.int32(es), np.int32(bs), np.int32(nb))
        self.c2c(A, A, L, nb, 1, L, -1)
        K.k["bluestein_mul"](q, (L, nb), None, A, ln.filt[sign].buf, np.int32(L), np.int32(nb))
        self.c2c(A, A, L, nb, 1, L, 1)
        K.k["bluestein_post"](q, (n, nb), None, A, dst, w, np.int32(n), np.int32(L),
                              np.int32(es), np.int32(bs), np.int32(nb), K.real(scale))


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
        Force the local-memory (whole line per work-group) kernels on or off for rows / columns;
        default per device kind.

    Notes
    -----
    Same contract as :class:`~clfza.fft.HostFFT`: ``rfft2(x, X)`` is unnormalised, ``irfft2(X,
    x)`` divides by ``Ny * Nx``, and ``irfft2`` leaves ``X`` unchanged. Both only enqueue
    work: keep the arrays alive until the queue has finished (on CPU devices their host
    memory is the buffer). Scratch buffers are allocated once per engine. Use :func:`plan` to
    share engines per shape, dtype and device.
    """

    name = "opencl-stockham"

    def __init__(self, rt, shape, dtype=np.float32, *, bluestein: bool = True,
                 pad_to_fast: bool = False, local_rows: bool | None = None,
                 local_cols: bool | None = None):
        self.rt = rt
        self.shape = _check_shape(shape)
        self.dtype = _check_dtype(dtype)
        if self.dtype == np.float64 and not rt.has_fp64:
            raise ClfzaError(f"device {rt.info.name!r} has no float64 support; use float32")
        self.cdtype = _complex_of(self.dtype)
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
        self.ex = _Exec(rt, self.dtype, local_rows, local_cols)
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
        self._buf: dict[str, DeviceArray] = {}

    # -- helpers ---------------------------------------------------------------------------
    @property
    def spectrum_shape(self) -> tuple[int, int]:
        """Shape of the half spectrum ``X`` (of the padded grid when padding)."""
        return self.fft_shape[0], self.nxh

    def _b(self, name: str, nelem: int):
        a = self._buf.get(name)
        if a is None or a.size < nelem:
            if a is not None:  # queued kernels may still use the old one (zero-copy memory)
                self.rt.finish()
            a = DeviceArray.empty(self.rt, (int(nelem),), self.cdtype)
            self._buf[name] = a
        return a.buf

    def _check(self, a, shape, dtype, what: str) -> None:
        if not isinstance(a, DeviceArray):
            raise ClfzaError(f"{what} must be a DeviceArray, got {type(a).__name__}")
        if a.rt.context is not self.rt.context:
            raise ClfzaError(f"{what} lives on another OpenCL context than this FFT plan")
        if a.shape != tuple(shape) or a.dtype != dtype:
            raise ClfzaError(f"{what} must be a {tuple(shape)} {dtype} device array, got "
                             f"{a.shape} {a.dtype}")

    def _launch2(self, name, gsize, *args) -> None:
        self.ex.K.k[name](self.rt.queue, gsize, None, *args)

    # -- rows --------------------------------------------------------------------------------
    def _rows_r2c(self, xbuf, Xbuf, scale: float = 1.0) -> None:
        """Real rows (ny, nx) -> half spectra (ny, nxh)."""
        ex, K = self.ex, self.ex.K
        ny, nx = self.fft_shape
        i32 = np.int32
        if self.even:
            m = self.m
            ln = K.line(m)
            ks = K.local(m) if ex.local_rows else None
            if ks is not None:
                T = ks["T"]
                ks["fft_local_r2c"](self.rt.queue, (ny * T,), (T,), xbuf, Xbuf, ln.tw[-1].buf,
                                    self.twh.buf, i32(self.nxh), K.real(scale))
                return
            Z = self._b("rowsZ", ny * m)
            ex.c2c(xbuf, Z, m, ny, 1, m, -1)
            self._launch2("r2c_post", (m + 1, ny), Z, Xbuf, self.twh.buf, i32(m), i32(ny),
                          K.real(scale))
            return
        Z = self._b("rowsZ", ny * nx)
        Z2 = self._b("rowsZ2", ny * nx)
        self._launch2("real_to_complex", (nx, ny), xbuf, Z, i32(nx), i32(ny))
        ex.c2c(Z, Z2, nx, ny, 1, nx, -1, scale)
        self._launch2("crop_cols", (self.nxh, ny), Z2, Xbuf, i32(nx), i32(self.nxh), i32(ny))

    def _rows_c2r(self, Xbuf, xbuf, scale: float) -> None:
        """Half spectra (ny, nxh) -> real rows (ny, nx), times ``scale`` (unnormalised)."""
        ex, K = self.ex, self.ex.K
        ny, nx = self.fft_shape
        i32 = np.int32
        if self.even:
            m = self.m
            ln = K.line(m)
            ks = K.local(m) if ex.local_rows else None
            if ks is not None:
                T = ks["T"]
                ks["fft_local_c2r"](self.rt.queue, (ny * T,), (T,), Xbuf, xbuf, ln.tw[1].buf,
                                    self.twh.buf, i32(self.nxh), K.real(scale))
                return
            Z = self._b("rowsZ", ny * m)
            self._launch2("c2r_pre", (m, ny), Xbuf, Z, self.twh.buf, i32(m), i32(ny))
            ex.c2c(Z, xbuf, m, ny, 1, m, 1, scale)
            return
        Z = self._b("rowsZ", ny * nx)
        Z2 = self._b("rowsZ2", ny * nx)
        self._launch2("hermitian_expand", (nx, ny), Xbuf, Z, i32(nx), i32(ny))
        ex.c2c(Z, Z2, nx, ny, 1, nx, 1)
        self._launch2("take_real", (nx, ny), Z2, xbuf, i32(nx), i32(ny), K.real(scale))

    # -- public ------------------------------------------------------------------------------
    def rfft2(self, x: DeviceArray, X: DeviceArray) -> None:
        """``X = rfft2(x)`` (unnormalised), enqueued on the runtime's queue."""
        self._check(x, self.shape, self.dtype, "rfft2 input")
        self._check(X, self.spectrum_shape, self.cdtype, "rfft2 output")
        ny, nx = self.fft_shape
        xbuf = x.buf
        if self.padded:
            xbuf = self._pad_in(x)
        self._rows_r2c(xbuf, X.buf)
        self.ex.c2c(X.buf, X.buf, ny, self.nxh, self.nxh, 1, -1)

    def irfft2(self, X: DeviceArray, x: DeviceArray) -> None:
        """``x = irfft2(X)`` (divides by ``Ny * Nx``); ``X`` is left unchanged."""
        self._check(X, self.spectrum_shape, self.cdtype, "irfft2 input")
        self._check(x, self.shape, self.dtype, "irfft2 output")
        ny, nx = self.fft_shape
        C = self._b("cols", ny * self.nxh)
        self.ex.c2c(X.buf, C, ny, self.nxh, self.nxh, 1, 1)
        if self.padded:
            P = self._b("pad", (ny * nx + 1) // 2)
            self._rows_c2r(C, P, 1.0 / (ny * nx))
            self._crop_out(P, x)
        else:
            self._rows_c2r(C, x.buf, 1.0 / (ny * nx))

    # -- padding (bluestein=False, pad_to_fast=True) -----------------------------------------
    def _pad_in(self, x: DeviceArray):
        ny, nx = self.fft_shape
        P = self._b("pad", (ny * nx + 1) // 2)
        cl = self.rt.cl
        isz = self.dtype.itemsize
        q = self.rt.queue
        zero = np.zeros(1, self.dtype)
        cl.enqueue_fill_buffer(q, P, zero, 0, ny * nx * isz)
        sy, sx = self.shape
        cl.enqueue_copy(q, P, x.buf, src_origin=(0, 0, 0), dst_origin=(0, 0, 0),
                        region=(sx * isz, sy, 1), src_pitches=(sx * isz, sx * sy * isz),
                        dst_pitches=(nx * isz, nx * ny * isz))
        return P

    def _crop_out(self, P, x: DeviceArray) -> None:
        ny, nx = self.fft_shape
        sy, sx = self.shape
        isz = self.dtype.itemsize
        self.rt.cl.enqueue_copy(self.rt.queue, x.buf, P, src_origin=(0, 0, 0),
                                dst_origin=(0, 0, 0), region=(sx * isz, sy, 1),
                                src_pitches=(nx * isz, nx * ny * isz),
                                dst_pitches=(sx * isz, sx * sy * isz))

    def __repr__(self) -> str:
        return (f"DeviceFFT(shape={self.shape}, dtype={self.dtype}, device="
                f"{self.rt.info.name!r})")


_PLANS: dict[tuple, DeviceFFT] = {}
_PLOCK = threading.Lock()


def plan(rt, shape, dtype=np.float32, **options) -> DeviceFFT:
    """A cached :class:`DeviceFFT` per (shape, dtype, device, options).

    Engines share nothing mutable across threads except the queue; use one thread per runtime.
    """
    key = (tuple(int(s) for s in shape), np.dtype(dtype).str, _device_key(rt),
           id(rt.context), tuple(sorted(options.items())))
    with _PLOCK:
        p = _PLANS.get(key)
    if p is None:
        p = DeviceFFT(rt, shape, dtype, **options)
        with _PLOCK:
            _PLANS[key] = p
    return p


# ----------------------------------------------------------------------------------------------
# complex helpers

_EXECS: dict[tuple, _Exec] = {}


def _exec_for(rt, dtype) -> _Exec:
    key = (_device_key(rt), id(rt.context), np.dtype(dtype).str)
    ex = _EXECS.get(key)
    if ex is None:
        ex = _Exec(rt, dtype)
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
    if a.rt.zero_copy:
        # `a` may be a temporary whose host memory (the buffer's storage on CPU devices) is
        # freed when this returns: finish while it is alive.
        a.rt.finish()
    return out


def fft2(a: DeviceArray, out: DeviceArray | None = None, *, inverse: bool = False
         ) -> DeviceArray:
    """Complex 2-D FFT of a complex64/complex128 device array (numpy conventions)."""
    if not isinstance(a, DeviceArray) or len(a.shape) != 2:
        raise ClfzaError("fft2 needs a 2-D complex DeviceArray")
    out = fft1d_batched(a, out, axis=1, inverse=inverse)
    return fft1d_batched(out, out, axis=0, inverse=inverse)
