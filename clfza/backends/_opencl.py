"""The OpenCL backend: every core operation as one or two fused kernels (``kernels/*.cl``).

Arrays are :class:`~clfza.cl.DeviceArray` of shape ``(C, H, W)`` (zero-copy host memory on CPU
devices). FFTs go through the operator's FFT engine (host scipy.fft on CPU devices, on the
same memory). Nothing is read back except the small partial-sum arrays of the reductions,
when a solver asks for a scalar.

The solvers' own operations (:class:`~clfza.backends._base.Ops` families beside the solvers)
use what this backend offers them: its kernel registry (:meth:`OpenCLBackend.use_kernels`,
the one build path through :func:`build_program` and :meth:`Runtime.program`), the launch
helpers (``launch1d``, ``launch2d``, ``launch2d_reduce``, ``launch_rows_reduce``,
``spec_pass``), the reducers and the spectra ``X``, ``Y``.
"""

from __future__ import annotations

import time

import numpy as np

from ..camera import Camera
from ..cl import DeviceArray, Runtime, get_runtime, typed_kernel
from ..errors import ClfzaError
from ..models import OpenCLOperator
from . import _tuning as tuning
from ._base import Backend, ProxState, Scalars


def build_program(rt: Runtime, name: str, dtype, nc: int, rows: int = 1):
    """``common.cl + reduce.cl + <name>.cl`` with ``NC`` channels for ``dtype`` and
    ``RROWS = rows`` rows per contribution in the row-blocked reductions, built (once) by
    :meth:`Runtime.program`. float32 flushes denormals: decaying TV duals otherwise hit the
    CPU's slow denormal path."""
    dtype = np.dtype(dtype)
    include = ("common",) + (("reduce",) if name != "reduce" else ())
    flags = ("-cl-denorms-are-zero",) if dtype == np.float32 else ()
    return rt.program(name, dtype, {"NC": int(nc), "RROWS": int(rows), "FOLD": fold_of(rt)},
                      include=include, flags=flags)


def fold_of(rt: Runtime) -> int:
    """The reductions' fold factor (reduce.cl's ``FOLD``): 16 on CPU devices, 64 on GPUs,
    where each fold is a launch and a launch is the cost."""
    return 16 if rt.is_cpu else 64


REDUCE_HOST = 4096  # fold on the device until at most this many pairs are left
PAIR_FOLDS = True  # two reducers' deferred folds per launch (sum16x2); False: one per launch
FUSED_PROX_COLUMNS = 12  # tv_fused.cl: output columns per work-item (OUT_W)
FUSED_PROX_MIN_WIDTH = 16  # ... and its window: narrower images take the three tv.cl kernels
FUSED_FGP_COLUMNS = 10  # tv_fused.cl's fgp2_fused: output columns per work-item (FGP_OUT_W)
DUAL_PAD = 16  # floats added to the one-pass FGP's dual rows when the width is a multiple of 256
# The fused prox's strip height (rows per work-item, +3 warm-up rows), whether paper mode uses
# it at all, the rows per contribution of the row-blocked reductions (RROWS of reduce.cl:
# TwIST's combination; the largest that divides the row count, at most the tuned value) and
# the work-group shapes are chosen per device by measurement (clfza.backends._tuning; built-in
# defaults there; why per device: docs/measurements.md, clfza.backends._opencl).
# The core's kernels; the operation families add theirs (Ops.KERNELS, use_kernels).
KERNELS = (("tv", ("grad_fwd", "div_ref", "chambolle_step", "chambolle_first",
                   "chambolle_step_change", "chambolle_finish", "fgp_step", "fgp_finish")),
           ("elementwise", ("triad", "lincomb3", "soft_step", "project_nonneg", "shrink_vec")),
           ("reduce", ("sum16", "sum16x2", "dot_contrib", "diffnorm_contrib", "reg_contrib")),
           ("spectrum", ("resid_grad_spec",)))
SPEC_LANES = 8  # spectrum.cl's resid_grad_spec8: frequencies per work-item
# Kernels that take a batch of frames as their launch's third dimension (reduce.cl, above
# frame_image), and the element-wise ones launched over every frame's elements at once.
# Launching any other on a backend of several frames is an error, not a wrong image.
BATCH_KERNELS = frozenset({
    "sum16", "sum16x2", "dot_contrib", "diffnorm_contrib", "reg_contrib", "resid_grad_spec",
    "resid_grad_spec8", "admm_solve_spec", "admm_solve_spec8", "admm_rhs", "admm_update",
    "admm_update16", "admm_update_rhs", "admm_update_rhs16", "fgp_step", "fgp_finish",
    "chambolle_first", "chambolle_step", "chambolle_step_change", "chambolle_finish",
    "twist_combine", "twist_combine16"})
ELEMENTWISE_KERNELS = frozenset({"lincomb3", "project_nonneg", "triad", "soft_step",
                                 "fista_extrap", "mask_past"})


def dual_pitch(width: int) -> int:
    """Row pitch (floats) of the one-pass FGP's dual arrays for an image ``width`` wide.

    A width that is a multiple of 256 floats (1 KB) puts the same column of consecutive rows
    into a handful of cache sets; the kernel's strips, walking down ~135 rows per array, then
    evict each other's lines before the neighbouring strip reuses them. 16 floats more (one
    cache line) spreads the rows over every set (tv_fused.cl, above fgp2_fused; measured:
    docs/measurements.md, clfza.backends._opencl). Other widths keep their pitch.
    """
    return width + DUAL_PAD if width % 256 == 0 else width


class DeviceScalars(Scalars):
    """A few thousand partial sums per plane left by ``sum16`` (one or two planes); summed on
    the host in float64 in a fixed order when read (a missing second plane reads as 0).

    Of a batch of ``frames`` frames (the frames' planes one after the other): ``get()``
    returns an array ``(frames, planes)``, a frame's sums in its row."""

    def __init__(self, part: DeviceArray, m: int, scale: float = 1.0, planes: int = 2,
                 frames: int = 1, flush=None):
        self.part, self.m, self.scale, self.planes = part, m, scale, planes
        self.frames = frames
        self._copy = None  # (host array, event) of a started read
        self._flush = flush  # launches the backend's deferred folds (this one's among them)

    def start_read(self) -> None:
        if self._flush is not None:
            self._flush()
            self._flush = None
        if self.part.host is None and self._copy is None:
            part = self.part
            out = np.empty(part.shape, part.dtype)
            self._copy = out, part.rt.cl.enqueue_copy(part.rt.queue, out, part.buf,
                                                      is_blocking=False)

    def get(self) -> np.ndarray:
        if self._flush is not None:
            self._flush()
            self._flush = None
        if self._copy is not None:
            a, event = self._copy
            event.wait()
        else:
            a = self.part.host_view() if self.part.host is not None else self.part.get()
        k, f = self.planes, self.frames
        sums = a[:k * f, :self.m].astype(np.float64).sum(axis=1).reshape(f, k)
        out = np.zeros((f, max(2, k)))
        out[:, :k] = sums
        out *= self.scale
        return out[0] if f == 1 else out


class _Reducer:
    """Folds a contribution array of ``n`` pairs with ``sum16`` into one of a ring of small
    result buffers (the ring keeps earlier results readable for a few more reductions).

    The fold is deferred: :meth:`reduce` queues it on the backend
    (:meth:`OpenCLBackend.flush_folds`), which launches it when its sums are read or its
    contributions are about to be overwritten (:attr:`target`), together with the other
    reducers' folds queued meanwhile: two folds per launch (``sum16x2``). A solver that reads
    two sums of one iteration together (the data term's and the regulariser's) then pays one
    fold launch, not two."""

    def __init__(self, backend, n: int, ring: int = 8, planes: int = 2):
        rt = backend.rt
        self.B = backend
        self.n = n
        self.frames = f = backend.frames
        planes *= f  # a batch: every frame's planes, one after the other
        self.levels = []  # (m_in, m_out) per fold
        m = n
        fold = fold_of(rt)
        while m > REDUCE_HOST:
            mo = -(-m // fold)
            self.levels.append((m, mo))
            m = mo
        self.m_final = m
        self.tmp = (DeviceArray.empty(rt, (planes, self.levels[0][1]), backend.dtype)
                    if len(self.levels) > 1 else None)
        # zeros: a stopped frame of a batch writes no contributions, and its (ignored) sums
        # then read what was there before, never uninitialised memory
        self.ring = [DeviceArray.from_host(rt, np.zeros((planes, m), backend.dtype))
                     for _ in range(ring)]
        # folded on the device: the producer writes here; else straight into a ring slot
        self.contrib = (DeviceArray.from_host(rt, np.zeros((planes, n), backend.dtype))
                        if self.levels
                        else None)
        self.i = 0
        self.pending = None  # (ring slot, rows) of a fold queued on the backend

    @property
    def target(self):
        """The buffer the next producer kernel writes its contributions to: the array that
        :meth:`reduce` folds, or, with nothing to fold, the ring slot that :meth:`reduce`
        hands out next (no copy)."""
        if self.levels:
            if self.pending is not None:  # its fold reads these contributions first
                self.B.flush_folds()
            return self.contrib.buf
        return self.ring[(self.i + 1) % len(self.ring)].buf

    def reduce(self, scale: float = 1.0, planes: int = 2) -> DeviceScalars:
        """Fold the first ``planes`` planes of the contributions (1: the kernel wrote only the
        first sum, and the fold reads half as much)."""
        self.i = (self.i + 1) % len(self.ring)
        out = self.ring[self.i]
        f = self.frames
        if not self.levels:  # the producer wrote into this slot (target)
            return DeviceScalars(out, self.n, scale, planes, f)
        if self.pending is not None:  # (a producer that skipped target: not in this code)
            self.B.flush_folds()
        self.pending = (out, planes * f)
        self.B._folds.append(self)
        return DeviceScalars(out, self.m_final, scale, planes, f, flush=self.B.flush_folds)

    def fold_level(self, li: int, src: DeviceArray):
        """Level ``li`` of the pending fold from ``src``: ``(src, dst, m_out, m_in, rows)``.
        Ping-pong between ``tmp`` and the contributions (free after the first level); the
        last level writes the ring slot."""
        mi, mo = self.levels[li]
        out, rows = self.pending
        dst = out if li == len(self.levels) - 1 else (self.tmp, self.contrib)[li % 2]
        return src, dst, mo, mi, rows


def frame_norms2(y: np.ndarray, frames: int):
    """``||y||^2`` in float64 (one frame: a float) or per frame (``frames`` > 1: an array), as
    ``np.asarray(y, np.float64) ** 2`` summed (over all of ``y``, or over each frame's share
    of its C-order elements), bit for bit: a C-contiguous ``y`` is squared frame by frame
    into one reused float64 row, each row's sum numpy's pairwise sum of that row alone (the
    same additions), without the stack-sized float64 temporary.

    Examples
    --------
    >>> y = np.arange(8.0).reshape(2, 2, 2)
    >>> frame_norms2(y, 2).tolist(), frame_norms2(y, 1)
    ([14.0, 126.0], 140.0)
    """
    a = np.asarray(y)
    if not (a.flags.c_contiguous and a.dtype in (np.float32, np.float64) and a.size
            and a.size % frames == 0):
        y2 = np.asarray(a, np.float64) ** 2
        return float(np.sum(y2)) if frames == 1 else y2.reshape(frames, -1).sum(axis=1)
    rows = a.reshape(frames, -1)
    buf = np.empty(rows.shape[1])
    out = np.empty(frames)
    for f, row in enumerate(rows):
        out[f] = np.square(row, out=buf, dtype=np.float64).sum()
    return float(out[0]) if frames == 1 else out


class OpenCLBackend(Backend):
    """OpenCL implementation (float32 by default; float64 where the device has it)."""

    name = "opencl"

    def __init__(self, camera: Camera, nc: int = 1, runtime: Runtime | None = None,
                 dtype=np.float32, fft: str = "auto", device: str | None = None,
                 tune: dict | None = None, frames: int = 1):
        t0 = time.perf_counter()
        self.rt = rt = runtime or get_runtime(device)
        c0 = rt.compile_seconds
        self.camera = camera
        self.nc = int(nc)
        self.frames = int(frames)
        if self.frames < 1:
            raise ClfzaError(f"frames must be >= 1, got {frames}")
        self.dtype = np.dtype(dtype)
        self.device = rt.info.name
        self.op = self._make_operator(camera, fft)
        self.shape = tuple(self.op.shape)
        if (self.nc > 1 or self.frames > 1) and not self.op.fft.batched:  # clfza.fft.FFTEngine
            raise ClfzaError(f"joint colour (C = 3) and batches of frames need an FFT engine "
                             f"that takes (C, H, W) arrays: fft='device' or fft='host', not "
                             f"{self.op.fft.name!r}")
        self.fft = self.op.fft
        self.ffts = 0
        ny, nx = self.shape
        self.ws = nx // 2 + 1
        # a batch's arrays hold its frames one after the other: (F C, H, W)
        self.n = self.frames * self.nc * ny * nx
        self.cshape = (self.frames * self.nc,) + self.shape
        self.sshape = (self.frames * self.nc, ny, self.ws)
        # per frame: the factors of the penalties and the threshold, and whether it runs
        # (reduce.cl's fpar; all ones: the kernels' own arguments, every frame running)
        self._fpar_host = np.ones((self.frames, 4), self.dtype)
        self.fpar = DeviceArray.from_host(rt, self._fpar_host.copy(), self.dtype)
        self._sent: list = []  # (event, host copy) of write_async's writes not yet done
        self.X = DeviceArray.empty(rt, self.sshape, self.op.cdtype)
        self.Y = DeviceArray.empty(rt, self.sshape, self.op.cdtype)
        self.r = self.dtype.type
        self.i32 = np.int32
        self._spec_tail = (np.int32(self.ws), np.int32(ny), np.int32(nx % 2 == 0))
        self._b = self.empty()
        self._tmp = None
        self._folds: list = []  # reducers whose fold is deferred (flush_folds)
        self.red = _Reducer(self, ny * nx, planes=3)
        # spec8: the half-spectrum passes on CPUs, float32, 8 frequencies per work-item as
        # float16 vectors (spectrum.cl's resid_grad_spec8; measured: docs/measurements.md,
        # clfza.backends._opencl), one contribution each; elsewhere one frequency per
        # work-item. red_s holds the contributions of the one in use.
        self.spec8 = rt.is_cpu and self.dtype == np.float32
        self._spec_grid = ((-(-self.ws // SPEC_LANES), ny) if self.spec8 else (self.ws, ny))
        self.red_s = _Reducer(self, self._spec_grid[0] * ny)
        # Work-groups of one row (X, 1) on CPU devices for the spectrum kernels: PoCL then
        # vectorises along the row (docs/design.md s.6); the image-plane kernels' shapes, the
        # prox variant and the row blocking of the RROWS reductions are tuned per device
        # (apply_tuning).
        self._lws = self._local(self.ws, ny, "row")
        self.k = {}  # kernels by name: the core's and those the operation families use
        self._kernels = {prog: list(names) for prog, names in KERNELS}  # program -> names
        if self.spec8:
            self._kernels["spectrum"].append("resid_grad_spec8")
        self.tune = None
        self.red_rows = None
        self._red16 = None  # launch_rows16_reduce's contributions, made at first use
        self.apply_tuning(tuning.choices(rt, ny, nx, OpenCLBackend) if tune is None else tune)
        rt.finish()
        self.compile_s = rt.compile_seconds - c0
        self.plan_s = time.perf_counter() - t0 - self.compile_s


    @property
    def fourier_diagonal(self) -> bool:
        return self.exact is None
    def _make_operator(self, camera: Camera, fft: str):
        """The forward model's device operator (the transfer-function model, Eq. 17); it owns
        the FFT engine on the solver grid."""
        return OpenCLOperator(camera, self.rt, dtype=self.dtype, fft=fft, warn=False)

    def apply_tuning(self, tune: dict) -> None:
        """Use the kernel variants ``tune`` (clfza.backends._tuning.PARAMS; missing keys take the
        built-in defaults): rebuilds what depends on them. Variants that do not fit this
        image (a work-group that does not divide it, the fused prox off a CPU) fall back."""
        rt, t = self.rt, {**tuning.DEFAULTS, **(tune or {})}
        ny, nx = self.shape
        rows = max(1, min(int(t["rows"]), ny))
        rows = next(r for r in range(rows, 0, -1) if ny % r == 0)
        if rows != getattr(self, "rows", None) or not self.k:
            self.rows = rows
            for prog, names in self._kernels.items():  # every kernel in use, with the new RROWS
                self._build(prog, names)
            # the row-blocked reduction (launch_rows_reduce; TwIST's combination): one
            # contribution per `rows` rows
            self.red_rows = _Reducer(self, (ny // rows) * nx, planes=3)
        # paper mode's TV prox (2 cold Chambolle iterations) as one explicitly vectorised
        # pass (kernels/tv_fused.cl, CPU devices) or the three tv.cl kernels
        self._prox_fused = self._fgp_fused = None
        self.strip = max(1, int(t["strip"]))
        self.fgp_strip = max(1, int(t["fgp_strip"]))
        self._prox_pf = [self.i32(v) for v in tuning.prefetch_args(t["prox_prefetch"])]
        self._fgp_pf = [self.i32(v) for v in tuning.prefetch_args(t["fgp_prefetch"])]
        one_pass_ok = (rt.is_cpu and self.dtype == np.float32 and self.nc == 1
                       and nx >= FUSED_PROX_MIN_WIDTH)
        prg = (build_program(rt, "tv_fused", self.dtype, self.nc)
               if one_pass_ok and "fused" in (t["prox"], t["fgp"]) else None)
        if t["prox"] == "fused" and prg is not None:
            self._prox_fused = typed_kernel(rt.cl, prg, "chambolle2_fused")
            self._fused_grid = (-(-nx // FUSED_PROX_COLUMNS), -(-ny // self.strip))
        # FISTA's FGP prox with 2 inner iterations: one pass (tv_fused.cl) or three kernels
        if t["fgp"] == "fused" and prg is not None:
            self._fgp_fused = typed_kernel(rt.cl, prg, "fgp2_fused")
            self._fgp_grid = (-(-nx // FUSED_FGP_COLUMNS), -(-ny // self.fgp_strip))
            self.red_fgp = _Reducer(self, self._fgp_grid[0] * self._fgp_grid[1], planes=2)
        self._lw = self._local(nx, ny, t["local2d"])
        self._lw_rows = self._local(nx, ny // rows, t["local2d"])
        self._l1 = self._local1(self.n, t["local1d"])
        self.tune = t

    def use_kernels(self, *groups) -> None:
        """Make the kernels ``groups`` = ``((program, (kernel, ...)), ...)`` of
        ``kernels/<program>.cl`` available in :attr:`k` (an operation family's
        :attr:`~clfza.backends._base.Ops.KERNELS`): built with :func:`build_program` (each
        program and set of defines is compiled once per runtime, :meth:`Runtime.program`), and
        rebuilt with the rest when :meth:`apply_tuning` changes the ``elementwise`` program's
        ``RROWS``."""
        for prog, names in groups:
            new = [nm for nm in names if nm not in self._kernels.get(prog, ())]
            for nm in new:
                other = next((p for p, ns in self._kernels.items() if p != prog and nm in ns),
                             None)
                if other is not None:
                    raise ClfzaError(f"kernel {nm!r} of {prog}.cl: {other}.cl's kernel of "
                                     "that name is already in use on this backend")
            if new:
                self._kernels.setdefault(prog, []).extend(new)
                self._build(prog, new)

    def _build(self, prog: str, names) -> None:
        prg = build_program(self.rt, prog, self.dtype, self.nc,
                            self.rows if prog == "elementwise" else 1)
        for nm in names:
            self.k[nm] = typed_kernel(self.rt.cl, prg, nm)

    def _local(self, w: int, h: int, how="row"):
        """A 2-D work-group for a (w, h) range: ``row`` (CPU devices: one row, or the largest
        of 256..8 that divides it; elsewhere the implementation's choice), ``auto`` (None) or
        ``"AxB"`` where it divides the range and fits the device, else ``row``."""
        maxwg = int(self.rt.device.max_work_group_size)
        if isinstance(how, str) and "x" in how:
            a, _, b = how.partition("x")
            if a.isdigit() and b.isdigit():
                a, b = int(a), int(b)
                if a * b <= maxwg and w % a == 0 and h % b == 0:
                    return (a, b)
            how = "row"
        if how == "auto" or not self.rt.is_cpu:
            return None
        if w <= maxwg:
            return (w, 1)
        for lx in (256, 128, 64, 32, 16, 8):
            if w % lx == 0:
                return (lx, 1)
        return None

    def _local1(self, n: int, how):
        """A 1-D work-group: None (``auto``) or ``how`` items where it divides ``n``."""
        if isinstance(how, int) or str(how).isdigit():
            m = int(how)
            if 0 < m <= int(self.rt.device.max_work_group_size) and n % m == 0:
                return (m,)
        return None

    # launch helpers (the core's and the operation families') -----------------------------
    # Kernel arguments need no keep-alive list: a DeviceArray dropped while a kernel is queued
    # parks its memory until the queue drains (clfza.cl._arrays.DeviceArray.__del__).
    def _batch(self, name: str, gsize: tuple, local):
        """The launch's global and local sizes for a batch: the frames as a third
        dimension (unchanged for one frame); kernels not written for it are refused."""
        if self.frames == 1:
            return gsize, local
        if name not in BATCH_KERNELS:
            raise ClfzaError(f"kernel {name!r} does not take a batch of frames "
                             f"({self.frames} on this backend): this operation runs one frame "
                             f"at a time")
        return gsize + (self.frames,), (None if local is None else tuple(local) + (1,))

    def launch1d(self, name, *args):
        """Kernel ``name`` over all ``n = F C H W`` elements: ``(*args, n)``."""
        if self.frames > 1 and name not in ELEMENTWISE_KERNELS:
            raise ClfzaError(f"kernel {name!r} does not take a batch of frames")
        self.k[name](self.rt.queue, (self.n,), self._l1, *args, self.i32(self.n))

    def launch2d(self, name, *args):
        """Kernel ``name`` over the image plane ``(W, H)`` (and the frames): ``(*args, W,
        H)``."""
        ny, nx = self.shape
        g, lw = self._batch(name, (nx, ny), self._lw)
        self.k[name](self.rt.queue, g, lw, *args, self.i32(nx), self.i32(ny))

    def launch2d_reduce(self, name, *args, scale: float = 1.0, planes: int = 2,
                        fold: bool = True) -> DeviceScalars | None:
        """Kernel ``name`` over the image plane with one contribution per pixel to ``planes``
        sums, ``(*args, contrib, W, H)``, folded into :class:`DeviceScalars` (times
        ``scale``); without ``fold`` (sums nobody reads) nothing is folded and None
        returned."""
        ny, nx = self.shape
        g, lw = self._batch(name, (nx, ny), self._lw)
        self.k[name](self.rt.queue, g, lw, *args, self.red.target, self.i32(nx), self.i32(ny))
        return self.red.reduce(scale, planes) if fold else None

    def launch_rows_reduce(self, name, *args, scale: float = 1.0, planes: int = 2
                           ) -> DeviceScalars:
        """Kernel ``name`` of the ``elementwise`` program over ``(W, H / rows)``, each
        work-item summing ``rows`` (RROWS) rows into one contribution: ``(*args, contrib,
        W, H)``, folded into :class:`DeviceScalars`."""
        ny, nx = self.shape
        g, lw = self._batch(name, (nx, ny // self.rows), self._lw_rows)
        self.k[name](self.rt.queue, g, lw, *args, self.red_rows.target, self.i32(nx),
                     self.i32(ny))
        return self.red_rows.reduce(scale, planes)

    @property
    def rows16(self) -> bool:
        """Whether image-plane kernels with a ``16`` variant (16 columns of a row per
        work-item as float16 vectors: elementwise.cl's ``admm_update16``) run that variant:
        CPU devices, float32, one channel."""
        return self.spec8 and self.nc == 1

    def launch_rows16_reduce(self, name, *args, planes: int = 2, fold: bool = True
                             ) -> DeviceScalars | None:
        """Kernel ``name`` over ``(ceil(W / 16), H)`` work-items, ``planes`` (2 or 3)
        contributions each: ``(*args, contrib, W, H)``, folded into :class:`DeviceScalars`
        (without ``fold``: not folded, None)."""
        ny, nx = self.shape
        if self._red16 is None:
            self._red16 = _Reducer(self, -(-nx // 16) * ny, planes=3)
        g, _ = self._batch(name, (-(-nx // 16), ny), None)
        self.k[name](self.rt.queue, g, None, *args, self._red16.target, self.i32(nx),
                     self.i32(ny))
        return self._red16.reduce(planes=planes) if fold else None

    def spec_pass(self, name, before, after=()) -> _Reducer:
        """A half-spectrum kernel with one sum: ``name(*before, contrib, *after, Wh, H, W
        even)``; on CPUs in float32 its row-vector variant ``name + "8"`` (8 frequencies per
        work-item, :data:`SPEC_LANES`). Returns the reducer holding the contributions."""
        name, local = (name + "8", None) if self.spec8 else (name, self._lws)
        g, local = self._batch(name, self._spec_grid, local)
        self.k[name](self.rt.queue, g, local, *before, self.red_s.target, *after,
                     *self._spec_tail)
        return self.red_s

    # arrays ---------------------------------------------------------------------------
    def empty(self):
        return DeviceArray.empty(self.rt, self.cshape, self.dtype)

    def scratch_image(self):
        """The first ``C H W`` reals of the spectrum scratch ``X`` (at least as large: ``C H
        (W/2 + 1)`` complex numbers). For FISTA's extrapolated point: the forward FFT then
        writes into memory the prox has just read, and one image-sized array fewer goes round
        per iteration (measured: docs/measurements.md, clfza.backends._opencl)."""
        return self.X.leading_view(self.cshape, self.dtype)

    def zeros(self):
        a = self.empty()
        self.rt.cl.enqueue_fill_buffer(self.rt.queue, a.buf, self.r(0), 0, a.nbytes)
        return a

    def from_host(self, a):
        a = np.broadcast_to(np.asarray(a, dtype=np.float64), self.cshape)
        return DeviceArray.from_host(self.rt, a.astype(self.dtype), self.dtype)

    def to_host(self, a):
        out = a.get().astype(np.float64)
        return out

    def copy(self, dst, src):
        self.rt.cl.enqueue_copy(self.rt.queue, dst.buf, src.buf)

    # batches of frames ----------------------------------------------------------------
    def copy_frame(self, dst, src, f: int) -> None:
        """Frame ``f`` of batch array ``src`` into the same frame of ``dst`` (queued)."""
        per = src.nbytes // self.frames
        self.rt.cl.enqueue_copy(self.rt.queue, dst.buf, src.buf, byte_count=per,
                                src_offset=f * per, dst_offset=f * per)

    def frame_to_host(self, a, f: int) -> np.ndarray:
        """Frame ``f`` of a batch's array as a float64 ``(C, H, W)`` host copy (waits for the
        queue up to that copy)."""
        per = a.nbytes // self.frames
        out = np.empty((self.nc,) + self.shape, self.dtype)
        self.rt.cl.enqueue_copy(self.rt.queue, out, a.buf, src_offset=f * per,
                                is_blocking=True)
        return out.astype(np.float64)

    def set_frame_params(self, rho=1.0, mu=1.0, thr=1.0, running=None) -> None:
        """Per-frame factors of the penalty, second-penalty and threshold arguments of the
        batch kernels (scalars or arrays of ``frames``), and which frames still run
        (``running``: booleans; a stopped frame's kernels return at once). Written through
        the queue, so kernels already queued see the values they were queued with."""
        p = self._fpar_host
        for col, v in enumerate((rho, mu, thr)):
            p[:, col] = np.broadcast_to(np.asarray(v, np.float64), (self.frames,))
        if running is not None:
            p[:, 3] = np.broadcast_to(np.asarray(running, bool), (self.frames,))
        self.write_async(self.fpar, p.copy())

    def write_async(self, dst: DeviceArray, host: np.ndarray) -> None:
        """Copy ``host`` into ``dst`` through the (in-order) queue without waiting: kernels
        queued before it read the old values, kernels queued after it the new ones. ``host``
        is kept alive until its write is done (the caller must not change it)."""
        cl = self.rt.cl
        event = cl.enqueue_copy(self.rt.queue, dst.buf, host, is_blocking=False)
        done = cl.command_execution_status.COMPLETE
        self._sent = [(e, h) for e, h in self._sent
                      if e.command_execution_status != done] + [(event, host)]

    def _one_frame(self, what: str) -> None:
        if self.frames > 1:
            raise ClfzaError(f"{what} runs one frame at a time ({self.frames} frames on this "
                             "backend)")

    def finish(self):
        self.rt.finish()

    def flush_folds(self) -> None:
        """Launch the reducers' deferred folds (:class:`_Reducer`): level by level, two
        reducers' folds per launch (``sum16x2``; one alone: ``sum16``), each plane folded as
        ``sum16`` folds it."""
        jobs, self._folds = self._folds, []
        if not jobs:
            return
        q, i32 = self.rt.queue, np.int32
        src = {id(r): r.contrib for r in jobs}
        for li in range(max(len(r.levels) for r in jobs)):
            live = [r.fold_level(li, src[id(r)]) for r in jobs if li < len(r.levels)]
            for a in range(0, len(live), 2 if PAIR_FOLDS else 1):
                if PAIR_FOLDS and a + 1 < len(live):
                    (s0, d0, mo0, mi0, p0), (s1, d1, mo1, mi1, p1) = live[a:a + 2]
                    self.k["sum16x2"](q, (max(mo0, mo1), p0 + p1), None, s0.buf, d0.buf,
                                      i32(mo0), i32(mi0), s1.buf, d1.buf, i32(mo1), i32(mi1),
                                      i32(p0))
                else:
                    s0, d0, mo0, mi0, p0 = live[a]
                    self.k["sum16"](q, (mo0, p0), None, s0.buf, d0.buf, i32(mo0), i32(mi0))
            for r in jobs:
                if li < len(r.levels):
                    src[id(r)] = r.fold_level(li, src[id(r)])[1]
        for r in jobs:
            r.pending = None

    # data term ------------------------------------------------------------------------
    def set_measurement(self, y):
        a = np.asarray(y)
        if a.dtype not in (np.float32, np.float64):
            a = a.astype(np.float64)  # other types through float64, as from_host takes them
        # the upload: one conversion pass, on zero-copy devices straight into the new buffer's
        # host memory (from_host converts a copy, then copies it in: a second frame-sized pass)
        yd = DeviceArray.empty(self.rt, self.cshape, self.dtype)
        if yd.host is not None:
            np.copyto(yd.host, np.broadcast_to(a, self.cshape))  # new: nothing queued on it
        else:
            yd.set(np.broadcast_to(a, self.cshape))
        self.fft.rfft2(yd, self.Y)
        self.ffts += self.nc * self.frames
        # b = K^T y (Backend.b; clfza.models._transfer.back_propagate is the specification): the
        # gradient of the data term at x = 0 (resid_grad's passes), from the spectrum Y kept for
        # resid_grad. The spectrum of x = 0 is zero: X is filled with zeros on the device, not
        # transformed from a zero image (the same values, one forward FFT fewer per plane;
        # counted as resid_grad counts its pair)
        ny, nx = self.shape
        self.rt.cl.enqueue_fill_buffer(self.rt.queue, self.X.buf, self.r(0), 0, self.X.nbytes)
        self.spec_pass("resid_grad_spec", (self.X.buf, self.Y.buf, self.op.H.buf),
                       (self.i32(0),)).reduce(1.0 / (ny * nx), 1)
        self.fft.irfft2(self.X, self._b, overwrite_x=True)
        self.ffts += self.nc * self.frames
        self.ynorm2 = frame_norms2(a, self.frames)

    @property
    def b(self):
        return self._b

    def resid_grad(self, x, g, step: bool = False) -> Scalars:
        ny, nx = self.shape
        self.fft.rfft2(x, self.X)
        res = self.spec_pass("resid_grad_spec", (self.X.buf, self.Y.buf, self.op.H.buf),
                             (self.i32(step),)).reduce(1.0 / (ny * nx), 1)
        self.fft.irfft2(self.X, g, overwrite_x=True)
        self.ffts += self.nc * self.frames
        return res

    # regularisers ---------------------------------------------------------------------
    def reg_value(self, x) -> Scalars:
        return self.launch2d_reduce("reg_contrib", x.buf)

    def _pair(self, state: ProxState, key: str, pitch: int | None = None):
        """The two arrays ``state.arrays[key]`` (a dual's components), ``(C, H, pitch)`` with
        the image in the first W columns of each row (``pitch`` defaults to W). Arrays kept
        with another pitch (the tuning switched between the one-pass and split FGP) are
        copied into new ones, so a warm dual survives."""
        shape = self.cshape[:-1] + (pitch or self.cshape[-1],)
        a = state.arrays.get(key)
        if a is not None and a[0].shape != shape:
            w = min(shape[-1], a[0].shape[-1])
            old, a = a, tuple(DeviceArray.empty(self.rt, shape, self.dtype) for _ in range(2))
            for src, dst in zip(old, a, strict=True):
                host = np.zeros(shape, self.dtype)
                host[..., :w] = src.get()[..., :w]
                dst.set(host)
            state.arrays[key] = a
        if a is None:
            a = tuple(DeviceArray.empty(self.rt, shape, self.dtype) for _ in range(2))
            state.arrays[key] = a
        return a

    def prox_is_fused(self, reg, iters, state: ProxState, tol: float = 0.0) -> bool:
        """Whether :meth:`prox_step` runs as the one-pass kernel of tv_fused.cl: TV, exactly
        2 inner iterations from a zero dual that is not kept (paper mode's simulation
        setting), float32, one channel, on a CPU device, width at least 16."""
        return (self._prox_fused is not None and reg == "tv" and int(iters) == 2
                and not state.warm and tol <= 0)

    def fgp_is_fused(self, reg, iters) -> bool:
        """Whether :meth:`fgp_prox` runs as the one-pass kernel of tv_fused.cl (fgp2_fused):
        TV, exactly 2 inner iterations (FISTA's default), float32, one channel, a CPU device,
        width at least 16."""
        return self._fgp_fused is not None and reg == "tv" and int(iters) == 2

    def prox_step(self, reg, x, g, s, th, out, iters, state: ProxState, tol: float = 0.0,
                  check_every: int = 2) -> int:
        """:meth:`Backend.prox_step`; on a batch of frames (TV only) each frame's step is
        ``s`` times its ``mu`` factor and its ``lam = 2 / th`` times its threshold factor
        (:meth:`set_frame_params`), a frame whose ``running`` flag is off is left as it was
        (output and dual), and with ``tol`` each frame stops its inner loop on its own
        change (the others go on); returns the most inner iterations a frame ran, and
        :attr:`prox_frame_iters` holds each frame's."""
        r = self.r
        if reg == "l1":
            self._one_frame("the l1 prox")
            self.launch1d("soft_step", out.buf, x.buf, g.buf, r(s), r(th))
            return 0
        lam = 2.0 / th
        F = self.frames
        active = self._fpar_host[:, 3] != 0
        if self.prox_is_fused(reg, iters, state, tol):
            ny, nx = self.shape
            grid = self._fused_grid + ((F,) if F > 1 else ())
            self._prox_fused(self.rt.queue, grid, None, out.buf, x.buf, g.buf,
                             r(s), r(lam), self.i32(self.strip), *self._prox_pf, self.fpar.buf,
                             self.i32(nx), self.i32(ny))
            self.prox_frame_iters = np.where(active, 2, 0)
            return 2
        p = self._pair(state, "p")
        q = self._pair(state, "q")
        first = not (state.warm and state.valid)
        done = 0
        steps = np.zeros(F, int)  # each frame's inner steps (its dual: p after even, q odd)
        going = active.copy()
        for k in range(1, int(iters) + 1):
            check = tol > 0 and not first and k % check_every == 0 and k < iters
            if check:
                ch = self.launch2d_reduce("chambolle_step_change", p[0].buf, p[1].buf,
                                          q[0].buf, q[1].buf, x.buf, g.buf, r(s), r(lam),
                                          self.fpar.buf)
            else:
                self.launch2d("chambolle_first" if first else "chambolle_step", p[0].buf,
                              p[1].buf, q[0].buf, q[1].buf, x.buf, g.buf, r(s), r(lam),
                              self.fpar.buf)
            p, q = q, p
            first = False
            done = k
            steps[going] = k
            if check:
                d = np.asarray(ch.get()).reshape(F, -1)
                met = going & (d[:, 0] <= tol * tol * d[:, 1])
                if met.all() or not (going & ~met).any():
                    break
                if met.any():  # those frames' inner loops end here; the others go on
                    going &= ~met
                    self._set_running(going)
        if F > 1:
            if not np.array_equal(going, active):
                self._set_running(active)
            # a frame that ran fewer steps (or none) than `done` by an odd number keeps its
            # dual in q: copied into p, where the finish and the next call read it
            for f in np.flatnonzero((done - steps) % 2 == 1):
                self.copy_frame(p[0], q[0], f)
                self.copy_frame(p[1], q[1], f)
        self.prox_frame_iters = np.where(active, steps, 0)
        if first:  # zero iterations: p = 0 -> u = v
            self.lincomb(out, 1.0, x, s, g)
        else:
            self.launch2d("chambolle_finish", out.buf, x.buf, g.buf, r(s), r(lam), p[0].buf,
                          p[1].buf, self.fpar.buf)
        state.arrays["p"], state.arrays["q"] = p, q
        state.valid = True
        return done

    def _set_running(self, running) -> None:
        """The frames' running flags changed, their factors kept (queued)."""
        p = self._fpar_host
        p[:, 3] = np.asarray(running, bool)
        self.write_async(self.fpar, p.copy())

    def fgp_prox(self, reg, out, b, weight, iters, state, nonneg):
        """:meth:`Backend.fgp_prox`; on a batch of frames (TV only) each frame's weight is
        ``weight`` times its threshold factor (:meth:`set_frame_params`), and a stopped
        frame's kernels return at once."""
        r = self.r
        if reg == "l1":
            self._one_frame("the l1 prox")
            self.launch1d("soft_step", out.buf, b.buf, b.buf, r(0), r(weight))
            if nonneg:
                self.launch1d("project_nonneg", out.buf, out.buf)
            return self.reg_value(out)
        fused = self.fgp_is_fused(reg, iters)
        ny, nx = self.shape
        pitch = dual_pitch(nx) if fused else nx
        p = self._pair(state, "p", pitch)
        pn = self._pair(state, "pn", pitch)
        if not (state.warm and state.valid):
            for a in p:
                self.rt.cl.enqueue_fill_buffer(self.rt.queue, a.buf, self.r(0), 0, a.nbytes)
        if fused:
            grid = self._fgp_grid + ((self.frames,) if self.frames > 1 else ())
            self._fgp_fused(self.rt.queue, grid, None, out.buf, pn[0].buf, pn[1].buf,
                            b.buf, p[0].buf, p[1].buf, r(weight), self.i32(nonneg),
                            self.i32(self.fgp_strip), *self._fgp_pf, self.fpar.buf,
                            self.red_fgp.target,
                            self.i32(nx), self.i32(ny), self.i32(pitch))
            state.arrays.update(p=pn, pn=p)
            state.valid = True
            return self.red_fgp.reduce(1.0, 2)
        ra = self._pair(state, "ra")
        rb = self._pair(state, "rb")
        t = 1.0
        rin = p
        for k in range(int(iters)):
            t_new = 0.5 * (1 + np.sqrt(1 + 4 * t * t))
            mom = (t - 1) / t_new
            # r_next = p_new + mom (p_new - p_old): needed by a next step, and p_new itself
            # where mom == 0 (the first step)
            with_r = k + 1 < int(iters) and mom != 0.0
            self.launch2d("fgp_step", b.buf, rin[0].buf, rin[1].buf, p[0].buf, p[1].buf,
                          pn[0].buf, pn[1].buf, ra[0].buf, ra[1].buf, r(weight), r(mom),
                          self.i32(nonneg), self.i32(with_r), self.fpar.buf)
            # p_new is the current dual; the old p buffer is free for the next p_new
            p, pn = pn, p
            if with_r:
                rin, ra, rb = ra, rb, ra
            else:
                rin = p
            t = t_new
        state.arrays.update(p=p, pn=pn, ra=ra, rb=rb)
        state.valid = True
        return self.launch2d_reduce("fgp_finish", out.buf, b.buf, p[0].buf, p[1].buf,
                                    r(weight), self.i32(nonneg), self.fpar.buf)

    # element-wise ---------------------------------------------------------------------
    def lincomb(self, out, a, X, b=0.0, Y=None, c=0.0, Z=None):
        r = self.r
        Y = X if Y is None else Y
        Z = X if Z is None else Z
        self.launch1d("lincomb3", out.buf, r(a), X.buf, r(b), Y.buf, r(c), Z.buf)

    def diffnorm(self, a, b) -> Scalars:
        return self.launch2d_reduce("diffnorm_contrib", a.buf, b.buf)

    def dot(self, a, b) -> Scalars:
        return self.launch2d_reduce("dot_contrib", a.buf, b.buf)

    def grad(self, u, g1, g2):
        """Forward differences (reference convention), for tests."""
        self.launch2d("grad_fwd", u.buf, g1.buf, g2.buf)

    def div(self, p1, p2, out):
        """The reference divergence, for tests."""
        self.launch2d("div_ref", p1.buf, p2.buf, out.buf)

    def shrink(self, z1, z2, t1, t2, thr):
        self.launch2d("shrink_vec", z1.buf, z2.buf, t1.buf, t2.buf, self.r(thr))

    def project_nonneg(self, out, v):
        self.launch1d("project_nonneg", out.buf, v.buf)

    def triad(self, a, b, c, s):
        self.launch1d("triad", a.buf, b.buf, c.buf, self.r(s))
