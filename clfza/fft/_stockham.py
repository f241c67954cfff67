"""The Stockham kernels of ``kernels/fft.cl`` for one device and dtype, and the executor of
batched 1-D complex transforms on raw buffers (:mod:`clfza.fft._opencl` builds its 2-D engine
on them; see its docstring for the algorithms).

:class:`_Kernels` holds the compiled kernels (cached per device, context and dtype by
:func:`_kernels`) and the per-length line plans (:class:`_Line`: twiddles, or Bluestein's
chirp and filter); :class:`StockhamPlan` enqueues transforms in the "batch" or "lines" mapping.
"""

from __future__ import annotations

import threading

import numpy as np

from ..cl import DeviceArray, complex_of, typed_kernel
from ..errors import ClfzaError
from ._codegen import pass_source, split_radices
from ._sizes import is_fast_size, radices

_FT_GPU, _FT_CPU = 16, 8  # tile edge of the batch mapping's transposes (fft_batch.cl)
MAPPINGS = ("batch", "lines")
#: the "lines" mapping's strided lines (the 2-D transforms' columns) that do not run in local
#: memory: ``"codelets"`` (the batch mapping's generated passes of radix up to 64, the lines
#: along contiguous memory: 2 launches for a column of 512 or 2048, issue 37's launch budget)
#: or ``"passes"`` (the radix-2..8 kernels of fft.cl: 3 and 4 launches); read when a plan is
#: made (bench/bench_gpu.py --fft-cols sets it to compare the two; docs/measurements.md,
#: clfza.fft._stockham)
LINES_COLUMNS = "codelets"
COLUMN_KINDS = ("codelets", "passes")


def check_dtype(dtype) -> np.dtype:
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
            self.radices = radices(n)
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
        self.dtype = check_dtype(dtype)
        self.cdtype = complex_of(self.dtype)
        self.real = self.dtype.type
        prg = rt.program("fft", self.dtype)
        cl = rt.cl
        self.k = {name: typed_kernel(cl, prg, name) for name in (
            "r2c_post", "c2r_pre", "real_to_complex", "crop_cols", "hermitian_expand",
            "take_real", "bluestein_pre", "bluestein_mul", "bluestein_post")}
        self.passk = {r: typed_kernel(cl, prg, f"stockham_pass{r}")
                      for r in (2, 3, 4, 5, 7, 8)}
        dev = rt.device
        self.max_wg = int(dev.max_work_group_size)
        self.local_bytes = int(dev.local_mem_size) - 256
        self._lines: dict[int, _Line] = {}
        self._local: dict[int, dict | None] = {}
        self._batch: dict[int, dict] = {}
        self._bk: dict | None = None
        self.ft = _FT_CPU if rt.is_cpu else _FT_GPU
        self._lock = threading.Lock()

    # -- "batch" mapping: generated Stockham passes and tiled transposes --------------------
    def batch_pass(self, R: int, sign: int, full: bool = False):
        """The generated radix-``R`` pass kernel of the batch mapping for one sign; ``full``:
        the variant without the guard on the line index (whole work-groups only)."""
        with self._lock:
            ks = self._batch.get((R, full))
        if ks is None:
            rt = self.rt
            prg = rt.program(f"fft_pass{R}" + ("_full" if full else ""), self.dtype,
                             source=pass_source(R, -1, full) + pass_source(R, 1, full))
            ks = {s: typed_kernel(rt.cl, prg, f"stockham_batch_{'fi'[s > 0]}{R}"
                                  + ("_full" if full else ""))
                  for s in (-1, 1)}
            with self._lock:
                self._batch[R, full] = ks
        return ks[sign]

    def bk(self, name: str):
        """A kernel of ``fft_batch.cl`` (tiled transposes and untangling)."""
        with self._lock:
            bk = self._bk
        if bk is None:
            prg = self.rt.program("fft_batch", self.dtype,
                                  {"FT": self.ft, "LOCAL_TILES": int(not self.rt.is_cpu)})
            names = ("transpose_c", "r2c_untangle_t", "c2r_untangle_t")
            if self.rt.is_cpu:
                names += ("transpose_c_full", "transpose_c_fullw", "r2c_untangle_t_full",
                          "c2r_untangle_t_full", "c2r_untangle_t_fullw")
            bk = {k: typed_kernel(self.rt.cl, prg, k) for k in names}
            with self._lock:
                self._bk = bk
        return bk[name]

    def tiled(self, name: str, d0: int, d1: int, *args, w: bool = False) -> None:
        """Launch the ``fft_batch.cl`` kernel ``name`` over ``d0 x d1`` work-items in FT x FT
        groups: on CPU devices, when both extents are at least FT, its ``_full`` variant (no
        edge guards, the last groups shifted back onto the edges), or with ``w`` its
        ``_fullw`` variant (dimension 0 along the written rows: contiguous writes, strided
        reads); else the guarded kernel."""
        ft = self.ft
        g = (-(-d0 // ft) * ft, -(-d1 // ft) * ft)
        full = self.rt.is_cpu and d0 >= ft and d1 >= ft
        if full and w:
            self.bk(name + "_fullw")(self.rt.queue, g[::-1], (ft, ft), *args)
            return
        self.bk(name + ("_full" if full else ""))(self.rt.queue, g, (ft, ft), *args)

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
                and T <= self.max_wg and len(radices(n)) <= 12):
            rad = radices(n)
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
                ks = {name: typed_kernel(cl, prg, name)
                      for name in ("fft_local_c2c", "fft_local_r2c", "fft_local_c2r")}
                wg = min(int(k.get_work_group_info(cl.kernel_work_group_info.WORK_GROUP_SIZE,
                                                   self.rt.device)) for k in ks.values())
                if wg < T:
                    ks = None
                else:
                    ks["T"] = T
                    if C > 1:
                        kc = typed_kernel(cl, prg, "fft_local_cols")
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


def device_key(rt) -> int:
    return int(rt.device.int_ptr)


def _kernels(rt, dtype) -> _Kernels:
    dt = check_dtype(dtype)
    key = (device_key(rt), id(rt.context), dt.str)
    with _KLOCK:
        k = _KERNELS.get(key)
    if k is None:
        k = _Kernels(rt, dt)
        with _KLOCK:
            _KERNELS[key] = k
    return k


def pad_ld(n: int) -> int:
    """Row stride (complex values) for an intermediate with ``n`` columns: multiples of 64
    (512-byte and larger power-of-two strides) get 8 more, so that the ``R`` rows a pass
    reads do not all map to the same cache sets."""
    return n + 8 if n % 64 == 0 else n


# ----------------------------------------------------------------------------------------------
# executor: batched 1-D complex transforms on raw buffers

class StockhamPlan:
    """Enqueues batched 1-D complex transforms on buffers, with its own scratch buffers.

    ``mapping``: ``"batch"`` (generated passes with the batch of lines along contiguous memory,
    rows through tiled transposes; the default on CPU devices, where PoCL vectorises across
    lines) or ``"lines"`` (a line per work-group in local memory, or per-pass kernels; the
    default elsewhere). Giving ``local_rows`` or ``local_cols`` selects ``"lines"`` unless a
    mapping is named. ``local_rows`` / ``local_cols``: whether lines with unit element stride
    (rows) / other strides (columns) use the local-memory kernel when they fit; None picks per
    device kind. ``columns``: how the "lines" mapping runs strided lines that are not in local
    memory (:data:`COLUMN_KINDS`; default :data:`LINES_COLUMNS`).
    """

    def __init__(self, rt, dtype, local_rows: bool | None = None,
                 local_cols: bool | None = None, mapping: str | None = None,
                 columns: str | None = None):
        self.rt = rt
        self.K = _kernels(rt, dtype)
        self.dtype = self.K.dtype
        self.cdtype = self.K.cdtype
        if mapping is None:
            explicit = local_rows is not None or local_cols is not None
            mapping = "batch" if (rt.is_cpu and not explicit) else "lines"
        if mapping not in MAPPINGS:
            raise ClfzaError(f"FFT mapping must be one of {MAPPINGS}, got {mapping!r}")
        self.mapping = mapping
        # work-group width along the batch: PoCL vectorises 8-16 lanes; GPUs want warps
        self.bw = 32 if rt.is_cpu else 64
        self.local_rows = True if local_rows is None else bool(local_rows)
        # GPUs: strided lines in one work-group read uncoalesced memory; passes with the batch
        # along contiguous memory are better. PoCL: measured in bench/bench_fft.py.
        self.local_cols = (rt.is_cpu if local_cols is None else bool(local_cols))
        columns = LINES_COLUMNS if columns is None else columns
        if columns not in COLUMN_KINDS:
            raise ClfzaError(f"FFT columns must be one of {COLUMN_KINDS}, got {columns!r}")
        self.columns = columns
        self._scratch: dict[str, DeviceArray] = {}

    def scratch(self, name: str, nelem: int):
        """The complex device buffer ``name`` of at least ``nelem`` elements, kept between
        calls (grown when too small). The plan's own passes and the 2-D transform that owns
        it (:class:`~clfza.fft._opencl.DeviceFFT`) share this pool: each uses its own names."""
        a = self._scratch.get(name)
        if a is None or a.size < nelem:
            a = DeviceArray.empty(self.rt, (int(nelem),), self.cdtype)
            self._scratch[name] = a
        return a.buf

    def _use_local(self, n: int, es: int) -> bool:
        if not (self.local_rows if es == 1 else self.local_cols):
            return False
        return self.K.local(n) is not None

    def c2c(self, src, dst, n: int, nb: int, es: int, bs: int, sign: int, scale: float = 1.0,
            planes: int = 1, ps: int = 0) -> None:
        """dst = scale * FFT_sign(src) over ``nb`` lines of ``n`` points (layout es, bs) in
        each of ``planes`` planes ``ps`` complex values apart, every pass one launch for all
        planes (planes whose lines continue each other's, ``ps == nb * bs``, are one batch of
        ``planes * nb`` lines; others are a further global dimension of the kernels)."""
        K = self.K
        q = self.rt.queue
        ln = K.line(n)
        r = K.real
        if planes > 1 and ps == nb * bs:
            nb, planes, ps = nb * planes, 1, 0
        if planes == 1:
            ps = 0
        if not ln.fast:
            self._bluestein(ln, src, dst, nb, es, bs, sign, scale, planes, ps)
            return
        if self.mapping == "batch" and n > 1:
            if bs == 1:  # lines along contiguous memory: the passes read them directly
                self.batch_passes(src, n, nb, es, sign, scale, dst, planes, ps)
                return
            if es == 1 and bs == n and planes == 1:  # contiguous rows: transpose, passes, back
                ld = pad_ld(nb)
                T = self.scratch("rowsT", n * ld)
                self.transpose(src, T, nb, n, ldd=ld)
                R = self.batch_passes(T, n, nb, ld, sign, 1.0)
                self.transpose(R, dst, n, nb, scale, lds=ld)
                return
        if n == 1:
            if src is not dst or scale != 1.0:
                self._local(ln, src, dst, nb, es, bs, sign, scale, planes, ps)
            return
        if self._use_local(n, es):
            self._local(ln, src, dst, nb, es, bs, sign, scale, planes, ps)
            return
        if es != 1 and bs == 1 and self.columns == "codelets":
            # strided lines side by side in memory (columns): the generated passes, the
            # batch mapping's, fewer and larger radices than the per-pass kernels below
            self.batch_passes(src, n, nb, es, sign, scale, dst, planes, ps)
            return
        # one launch per pass, ping-pong through two scratch buffers
        extent = (planes - 1) * ps + (nb - 1) * bs + (n - 1) * es + 1
        s1 = self.scratch("pass1", extent)
        s2 = self.scratch("pass2", extent)
        P = len(ln.radices)
        bufs = [src]
        for _ in range(P - 1):
            bufs.append(s1 if bufs[-1] is not s1 else s2)
        copy_back = P == 1 and src is dst
        bufs.append(s1 if copy_back else dst)
        batch_fast = es != 1 and bs == 1
        pg = (planes,) if planes > 1 else ()  # the plane dimension (one plane: 2-D as ever)
        ns = 1
        for p, R in enumerate(ln.radices):
            nq = n // R
            if batch_fast:  # rows of 64 work-items along contiguous memory (kernel guards b)
                gsize, lsize = (-(-nb // 64) * 64, nq) + pg, (64, 1) + (1,) * len(pg)
            else:
                gsize, lsize = (nq, nb) + pg, None
            sc = scale if p == P - 1 else 1.0
            K.passk[R](q, gsize, lsize, bufs[p], bufs[p + 1], ln.tw[sign].buf, np.int32(n),
                       np.int32(ns), np.int32(es), np.int32(bs), np.int32(nb), np.int32(ps),
                       np.int32(batch_fast), r(sign), r(sc))
            ns *= R
        if copy_back:
            isz = self.cdtype.itemsize
            self.rt.cl.enqueue_copy(q, dst, s1, byte_count=extent * isz)

    # -- batch mapping ------------------------------------------------------------------
    def transpose(self, src, dst, rows: int, cols: int, scale: float = 1.0,
                  lds: int | None = None, ldd: int | None = None) -> None:
        """dst (cols, rows) = scale * src (rows, cols)^T, complex (src != dst); row strides
        ``lds`` / ``ldd`` (default ``cols`` / ``rows``)."""
        ldd = rows if ldd is None else ldd
        # destination rows 512 bytes apart or a multiple of that: writes along them (the rows
        # that a tile of scattered writes hits otherwise share their cache sets)
        self.K.tiled("transpose_c", cols, rows, src, dst, np.int32(rows), np.int32(cols),
                     np.int32(cols if lds is None else lds), np.int32(ldd),
                     self.K.real(scale), w=ldd % 64 == 0)

    def batch_passes(self, src, n: int, nb: int, W: int, sign: int, scale: float = 1.0,
                     dst=None, planes: int = 1, ps: int = 0):
        """FFT of ``nb`` lines of a fast length ``n``, element ``i`` of line ``b`` at ``i*W + b``,
        in each of ``planes`` planes ``ps`` complex values apart (global dimension 2 of every
        pass: one launch per pass for all planes; one plane launches 2-D as ever).

        Ping-pongs through the scratch buffers ``b1``/``b2`` (never writing ``src`` unless it is
        ``dst``; results keep the layout of ``src``) and returns the buffer holding the result:
        ``dst`` when given, else a scratch buffer.
        """
        K, q = self.K, self.rt.queue
        ln = K.line(n)
        # CPU devices: the generated kernels without a guard on the line index (under such a
        # guard PoCL masks every load and store: docs/measurements.md, clfza.fft._stockham),
        # their last work-group shifted back to end at line nb (lines done twice are written
        # twice with the same values; src != dst). That needs nb >= bw: fewer lines run the
        # generic radix-2..8 passes of fft.cl (few lines are cheap; no guarded variant of the
        # big codelets to compile).
        bw = self.bw
        small = self.rt.is_cpu and nb < bw
        rad = ln.radices if small else split_radices(n)
        if planes == 1:
            ps = 0
        extent = (planes - 1) * ps + (n - 1) * W + nb
        pg, pl = ((planes,), (1,)) if planes > 1 else ((), ())
        bufs = [self.scratch("b1", extent), self.scratch("b2", extent)]
        if not rad:
            if dst is None:
                dst = bufs[0]
            if dst is not src or scale != 1.0:
                self.transpose(src, dst, 1, extent, scale)
            return dst
        cur = src
        ns = 1
        tw = ln.tw[sign].buf
        gx = -(-nb // bw) * bw
        i32 = np.int32
        for p, R in enumerate(rad):
            last = p == len(rad) - 1
            if last and dst is not None and dst is not cur:
                out = dst
            else:
                out = bufs[0] if cur is not bufs[0] else bufs[1]
            sc = K.real(scale if last else 1.0)
            if small:
                K.passk[R](q, (64, n // R) + pg, (64, 1) + pl, cur, out, tw, i32(n), i32(ns),
                           i32(W), i32(1), i32(nb), i32(ps), i32(1), K.real(sign), sc)
            else:
                K.batch_pass(R, sign, self.rt.is_cpu)(q, (gx, n // R) + pg, (bw, 1) + pl, cur,
                                                      out, tw, i32(n), i32(ns), i32(W), i32(nb),
                                                      i32(ps), sc)
            ns *= R
            cur = out
        if dst is not None and cur is not dst:  # one pass in place: copy back
            self.rt.cl.enqueue_copy(q, dst, cur, byte_count=extent * self.cdtype.itemsize)
            cur = dst
        return cur

    def _local(self, ln: _Line, src, dst, nb, es, bs, sign, scale, planes=1, ps=0) -> None:
        K = self.K
        ks = K.local(ln.n)
        T = ks["T"]
        pg, pl = ((planes,), (1,)) if planes > 1 else ((), ())
        if bs == 1 and es != 1 and "fft_local_cols" in ks:
            C = ks["C"]
            ks["fft_local_cols"](self.rt.queue, (-(-nb // C) * T * C,) + pg, (T * C,) + pl, src,
                                 dst, ln.tw[sign].buf, np.int32(es), np.int32(nb), np.int32(ps),
                                 K.real(sign), K.real(scale))
            return
        ks["fft_local_c2c"](self.rt.queue, (nb * T,) + pg, (T,) + pl, src, dst, ln.tw[sign].buf,
                            np.int32(es), np.int32(bs), np.int32(ps), K.real(sign),
                            K.real(scale))

    def _bluestein(self, ln: _Line, src, dst, nb, es, bs, sign, scale, planes=1, ps=0
                   ) -> None:
        """Bluestein over ``planes`` planes: the lines of all planes are the rows of one
        scratch array, so its transforms and product are one batch; pre and post take the
        planes as a further global dimension."""
        K = self.K
        q = self.rt.queue
        n, L = ln.n, ln.L
        nt = nb * planes
        A = self.scratch("bluestein", nt * L)
        w = ln.chirp[sign].buf
        pg = (planes,) if planes > 1 else ()
        K.k["bluestein_pre"](q, (L, nb) + pg, None, src, A, w, np.int32(n), np.int32(L),
                             np.int32(es), np.int32(bs), np.int32(nb), np.int32(ps))
        self.c2c(A, A, L, nt, 1, L, -1)
        K.k["bluestein_mul"](q, (L, nt), None, A, ln.filt[sign].buf, np.int32(L), np.int32(nt))
        self.c2c(A, A, L, nt, 1, L, 1)
        K.k["bluestein_post"](q, (n, nb) + pg, None, A, dst, w, np.int32(n), np.int32(L),
                              np.int32(es), np.int32(bs), np.int32(nb), np.int32(ps),
                              K.real(scale))
