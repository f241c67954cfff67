"""The OpenCL backend: every solver operation as one or two fused kernels (``kernels/*.cl``).

Arrays are :class:`~clfza.cl.DeviceArray` of shape ``(C, H, W)`` (zero-copy host memory on CPU
devices). FFTs go through the operator's FFT engine (host scipy.fft on CPU devices, on the
same memory). Nothing is read back except the small partial-sum arrays of the reductions,
when a solver asks for a scalar.
"""

from __future__ import annotations

import time

import numpy as np

from ..camera import Camera
from ..cl import tuning
from ..cl.arrays import DeviceArray
from ..cl.operator import OpenCLOperator
from ..cl.runtime import Runtime, get_runtime
from ..errors import ClfzaError
from .base import Backend, ProxState, Scalars
from .numpy_backend import diff_symbol


def build_program(rt: Runtime, name: str, dtype, nc: int, rows: int = 1):
    """``common.cl + reduce.cl + <name>.cl`` with ``NC`` channels for ``dtype`` and
    ``RROWS = rows`` rows per contribution in the row-blocked reductions, built (once) by
    :meth:`Runtime.program`. float32 flushes denormals: decaying TV duals otherwise hit the
    CPU's slow denormal path."""
    dtype = np.dtype(dtype)
    include = ("common",) + (("reduce",) if name != "reduce" else ())
    flags = ("-cl-denorms-are-zero",) if dtype == np.float32 else ()
    return rt.program(name, dtype, {"NC": int(nc), "RROWS": int(rows)}, include=include,
                      flags=flags)


REDUCE_HOST = 4096  # fold on the device until at most this many pairs are left
FUSED_PROX_COLUMNS = 8  # tv_fused.cl: output columns per work-item (the width must divide)
# The fused prox's strip height (rows per work-item, +2 warm-up rows), whether paper mode uses
# it at all, twist_combine's rows per contribution (RROWS of reduce.cl; the largest that divides
# the row count, at most the tuned value) and the work-group shapes are chosen per device by
# measurement (clfza.cl.tuning; built-in defaults there). Measured on a 2-core Xeon: strip 8
# beat 32 by 1.35-1.7x; rows 1/2/4 took 5.9/3.7/3.8 ms at 2048^2 on Zen 5.
KERNELS = (("tv", ("grad_fwd", "div_ref", "chambolle_step", "chambolle_first",
                   "chambolle_step_change", "chambolle_finish", "fgp_step", "fgp_finish")),
           ("elementwise", ("triad", "lincomb3", "soft_step", "project_nonneg", "shrink_vec",
                            "twist_combine", "mask_past", "fista_extrap", "admm_rhs",
                            "admm_update")),
           ("reduce", ("sum16", "dot_contrib", "diffnorm_contrib", "reg_contrib")),
           ("spectrum", ("resid_grad_spec", "admm_solve_spec")))


class DeviceScalars(Scalars):
    """A few thousand partial sums per plane left by ``sum16`` (one or two planes); summed on
    the host in float64 in a fixed order when read (a missing second plane reads as 0)."""

    def __init__(self, part: DeviceArray, m: int, scale: float = 1.0, planes: int = 2):
        self.part, self.m, self.scale, self.planes = part, m, scale, planes

    def get(self) -> np.ndarray:
        a = self.part.host_view() if self.part.host is not None else self.part.get()
        out = np.zeros(max(2, self.planes))
        out[:self.planes] = a[:self.planes, :self.m].astype(np.float64).sum(axis=1)
        return out * self.scale


class _Reducer:
    """Folds a contribution array of ``n`` pairs with ``sum16`` into one of a ring of small
    result buffers (the ring keeps earlier results readable for a few more reductions)."""

    def __init__(self, backend, n: int, ring: int = 8, planes: int = 2):
        rt = backend.rt
        self.B = backend
        self.n = n
        self.contrib = DeviceArray.empty(rt, (planes, n), backend.dtype)
        self.levels = []  # (m_in, m_out) per fold
        m = n
        while m > REDUCE_HOST:
            mo = -(-m // 16)
            self.levels.append((m, mo))
            m = mo
        self.m_final = m
        self.tmp = (DeviceArray.empty(rt, (planes, self.levels[0][1]), backend.dtype)
                    if len(self.levels) > 1 else None)
        self.ring = [DeviceArray.empty(rt, (planes, m), backend.dtype) for _ in range(ring)]
        self.i = 0

    def reduce(self, scale: float = 1.0, planes: int = 2) -> DeviceScalars:
        """Fold the first ``planes`` planes of the contributions (1: the kernel wrote only the
        first sum, and the fold reads half as much)."""
        self.i = (self.i + 1) % len(self.ring)
        out = self.ring[self.i]
        if not self.levels:
            self.B.rt.cl.enqueue_copy(self.B.rt.queue, out.buf, self.contrib.buf,
                                     byte_count=planes * self.n * self.contrib.dtype.itemsize)
            return DeviceScalars(out, self.n, scale, planes)
        k = self.B.k["sum16"]
        q = self.B.rt.queue
        src = self.contrib
        bufs = [self.tmp, self.contrib]  # ping-pong: the contributions are free after fold 1
        for li, (mi, mo) in enumerate(self.levels):
            dst = out if li == len(self.levels) - 1 else bufs[li % 2]
            k(q, (mo, planes), None, src.buf, dst.buf, np.int32(mo), np.int32(mi))
            src = dst
        return DeviceScalars(out, self.m_final, scale, planes)


class OpenCLBackend(Backend):
    """OpenCL implementation (float32 by default; float64 where the device has it)."""

    name = "opencl"

    def __init__(self, camera: Camera, nc: int = 1, runtime: Runtime | None = None,
                 dtype=np.float32, fft: str = "auto", device: str | None = None,
                 tune: dict | None = None):
        t0 = time.perf_counter()
        self.rt = rt = runtime or get_runtime(device)
        c0 = rt.compile_seconds
        self.camera = camera
        self.nc = int(nc)
        self.dtype = np.dtype(dtype)
        self.device = rt.info.name
        self.op = self._make_operator(camera, fft)
        self.shape = tuple(self.op.shape)
        if self.nc > 1 and not self.op.fft.batched:  # clfza.fft.FFTEngine
            raise ClfzaError("joint colour (C = 3) needs the host FFT engine (fft='host')")
        self.fft = self.op.fft
        self.ffts = 0
        ny, nx = self.shape
        self.ws = nx // 2 + 1
        self.n = self.nc * ny * nx
        self.cshape = (self.nc,) + self.shape
        self.sshape = (self.nc, ny, self.ws)
        self.X = DeviceArray.empty(rt, self.sshape, self.op.cdtype)
        self.Y = DeviceArray.empty(rt, self.sshape, self.op.cdtype)
        self.inv = None
        self.r = self.dtype.type
        self.i32 = np.int32
        self._spec_tail = (np.int32(self.ws), np.int32(ny), np.int32(nx % 2 == 0))
        self._b = self.empty()
        self._tmp = None
        self.red = _Reducer(self, ny * nx, planes=3)
        self.red_s = _Reducer(self, ny * self.ws)
        # Work-groups of one row (X, 1) on CPU devices for the spectrum kernels: PoCL then
        # vectorises along the row (docs/design.md s.6); the image-plane kernels' shapes, the
        # prox variant and twist_combine's row blocking are tuned per device (apply_tuning).
        self._lws = self._local(self.ws, ny, "row")
        self.k = {}
        self.tune = None
        self.red_rows = None
        self.apply_tuning(tuning.choices(rt, ny, nx, OpenCLBackend) if tune is None else tune)
        rt.finish()
        self.compile_s = rt.compile_seconds - c0
        self.plan_s = time.perf_counter() - t0 - self.compile_s

    def _make_operator(self, camera: Camera, fft: str):
        """The forward model's device operator (the transfer-function model, Eq. 17); it owns
        the FFT engine on the solver grid."""
        return OpenCLOperator(camera, self.rt, dtype=self.dtype, fft=fft, warn=False)

    def apply_tuning(self, tune: dict) -> None:
        """Use the kernel variants ``tune`` (clfza.cl.tuning.PARAMS; missing keys take the
        built-in defaults): rebuilds what depends on them. Variants that do not fit this
        image (a work-group that does not divide it, the fused prox off a CPU) fall back."""
        rt, t = self.rt, {**tuning.DEFAULTS, **(tune or {})}
        ny, nx = self.shape
        rows = max(1, min(int(t["rows"]), ny))
        rows = next(r for r in range(rows, 0, -1) if ny % r == 0)
        if rows != getattr(self, "rows", None) or not self.k:
            self.rows = rows
            for prog, names in KERNELS:
                prg = build_program(rt, prog, self.dtype, self.nc,
                                    rows if prog == "elementwise" else 1)
                for nm in names:
                    self.k[nm] = rt.cl.Kernel(prg, nm)
            # the row-blocked reduction of twist_combine: one contribution per `rows` rows
            self.red_rows = _Reducer(self, (ny // rows) * nx, planes=3)
        # paper mode's TV prox (2 cold Chambolle iterations) as one explicitly vectorised
        # pass (kernels/tv_fused.cl, CPU devices) or the three tv.cl kernels
        self._prox_fused = None
        self.strip = max(1, int(t["strip"]))
        if (t["prox"] == "fused" and rt.is_cpu and self.dtype == np.float32 and self.nc == 1
                and nx % FUSED_PROX_COLUMNS == 0):
            prg = build_program(rt, "tv_fused", self.dtype, self.nc)
            self._prox_fused = rt.cl.Kernel(prg, "chambolle2_fused")
            self._fused_grid = (nx // FUSED_PROX_COLUMNS, -(-ny // self.strip))
        self._lw = self._local(nx, ny, t["local2d"])
        self._lw_rows = self._local(nx, ny // rows, t["local2d"])
        self._l1 = self._local1(self.n, t["local1d"])
        self.tune = t

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

    # launch helpers -------------------------------------------------------------------
    # Kernel arguments need no keep-alive list: a DeviceArray dropped while a kernel is queued
    # parks its memory until the queue drains (clfza.cl.arrays.DeviceArray.__del__).
    def _1d(self, name, *args):
        self.k[name](self.rt.queue, (self.n,), self._l1, *args, self.i32(self.n))

    def _2d(self, name, *args):
        ny, nx = self.shape
        self.k[name](self.rt.queue, (nx, ny), self._lw, *args, self.i32(nx), self.i32(ny))

    def _2d_red(self, name, *args, scale: float = 1.0, planes: int = 2) -> DeviceScalars:
        ny, nx = self.shape
        self.k[name](self.rt.queue, (nx, ny), self._lw, *args, self.red.contrib.buf,
                     self.i32(nx), self.i32(ny))
        return self.red.reduce(scale, planes)

    def _spec_red(self, name, *args, scale: float = 1.0, planes: int = 2) -> DeviceScalars:
        ny, nx = self.shape
        self.k[name](self.rt.queue, (self.ws, ny), self._lws, *args, self.red_s.contrib.buf,
                     *self._spec_tail)
        return self.red_s.reduce(scale, planes)

    # arrays ---------------------------------------------------------------------------
    def empty(self):
        return DeviceArray.empty(self.rt, self.cshape, self.dtype)

    def from_host(self, a):
        a = np.broadcast_to(np.asarray(a, dtype=np.float64), self.cshape)
        return DeviceArray.from_host(self.rt, a.astype(self.dtype), self.dtype)

    def to_host(self, a):
        out = a.get().astype(np.float64)
        return out

    def copy(self, dst, src):
        self.rt.cl.enqueue_copy(self.rt.queue, dst.buf, src.buf)

    def finish(self):
        self.rt.finish()

    # data term ------------------------------------------------------------------------
    def set_measurement(self, y):
        yd = self.from_host(y)
        self.fft.rfft2(yd, self.Y)
        self.ffts += self.nc
        # b = K^T y (Backend.b; clfza.model.back_propagate is the specification): the gradient
        # of the data term at x = 0, from the spectrum Y kept for resid_grad (no extra FFT)
        zero = self.empty()
        self.rt.cl.enqueue_fill_buffer(self.rt.queue, zero.buf, self.r(0), 0, zero.nbytes)
        self.resid_grad(zero, self._b)
        self.ynorm2 = float(np.sum(np.asarray(y, np.float64) ** 2))

    @property
    def b(self):
        return self._b

    def resid_grad(self, x, g) -> Scalars:
        ny, nx = self.shape
        self.fft.rfft2(x, self.X)
        res = self._spec_red("resid_grad_spec", self.X.buf, self.Y.buf, self.op.H.buf,
                             scale=1.0 / (ny * nx), planes=1)
        self.fft.irfft2(self.X, g)
        self.ffts += self.nc
        return res

    # regularisers ---------------------------------------------------------------------
    def reg_value(self, x) -> Scalars:
        return self._2d_red("reg_contrib", x.buf)

    def _pair(self, state: ProxState, key: str):
        a = state.arrays.get(key)
        if a is None:
            a = (self.empty(), self.empty())
            state.arrays[key] = a
        return a

    def prox_is_fused(self, reg, iters, state: ProxState, tol: float = 0.0) -> bool:
        """Whether :meth:`prox_step` runs as the one-pass kernel of tv_fused.cl: TV, exactly
        2 inner iterations from a zero dual that is not kept (paper mode's simulation
        setting), float32, one channel, on a CPU device, width a multiple of 8."""
        return (self._prox_fused is not None and reg == "tv" and int(iters) == 2
                and not state.warm and tol <= 0)

    def prox_step(self, reg, x, g, s, th, out, iters, state: ProxState, tol: float = 0.0,
                  check_every: int = 2) -> int:
        r = self.r
        if reg == "l1":
            self._1d("soft_step", out.buf, x.buf, g.buf, r(s), r(th))
            return 0
        lam = 2.0 / th
        if self.prox_is_fused(reg, iters, state, tol):
            ny, nx = self.shape
            self._prox_fused(self.rt.queue, self._fused_grid, None, out.buf, x.buf, g.buf,
                             r(s), r(lam), self.i32(self.strip), self.i32(nx),
                             self.i32(ny))
            return 2
        p = self._pair(state, "p")
        q = self._pair(state, "q")
        first = not (state.warm and state.valid)
        done = 0
        for k in range(1, int(iters) + 1):
            check = tol > 0 and not first and k % check_every == 0 and k < iters
            if check:
                ch = self._2d_red("chambolle_step_change", p[0].buf, p[1].buf, q[0].buf,
                                  q[1].buf, x.buf, g.buf, r(s), r(lam))
            else:
                self._2d("chambolle_first" if first else "chambolle_step", p[0].buf, p[1].buf,
                         q[0].buf, q[1].buf, x.buf, g.buf, r(s), r(lam))
            p, q = q, p
            first = False
            done = k
            if check:
                d = ch.get()
                if d[0] <= tol * tol * d[1]:
                    break
        if first:  # zero iterations: p = 0 -> u = v
            self.lincomb(out, 1.0, x, s, g)
        else:
            self._2d("chambolle_finish", out.buf, x.buf, g.buf, r(s), r(lam), p[0].buf,
                     p[1].buf)
        state.arrays["p"], state.arrays["q"] = p, q
        state.valid = True
        return done

    def twist_combine(self, out, xm2, xm1, xist, alpha, beta, sparse, want_tv=True):
        r = self.r
        ny, nx = self.shape
        self.k["twist_combine"](self.rt.queue, (nx, ny // self.rows), self._lw_rows, out.buf,
                                xm2.buf, xm1.buf, xist.buf, r(1 - alpha), r(alpha - beta),
                                r(beta), self.i32(sparse), self.i32(want_tv),
                                self.red_rows.contrib.buf, self.i32(nx), self.i32(ny))
        return self.red_rows.reduce(1.0, planes=3)

    def mask_past(self, xm1, xm2, xist):
        self._1d("mask_past", xm1.buf, xm2.buf, xist.buf)

    def fgp_prox(self, reg, out, b, weight, iters, state, nonneg):
        r = self.r
        if reg == "l1":
            self._1d("soft_step", out.buf, b.buf, b.buf, r(0), r(weight))
            if nonneg:
                self._1d("project_nonneg", out.buf, out.buf)
            return self.reg_value(out)
        p = self._pair(state, "p")
        pn = self._pair(state, "pn")
        ra = self._pair(state, "ra")
        rb = self._pair(state, "rb")
        if not (state.warm and state.valid):
            for a in p:
                self.rt.cl.enqueue_fill_buffer(self.rt.queue, a.buf, self.r(0), 0, a.nbytes)
        t = 1.0
        rin = p
        for _ in range(int(iters)):
            t_new = 0.5 * (1 + np.sqrt(1 + 4 * t * t))
            mom = (t - 1) / t_new
            self._2d("fgp_step", b.buf, rin[0].buf, rin[1].buf, p[0].buf, p[1].buf, pn[0].buf,
                     pn[1].buf, ra[0].buf, ra[1].buf, r(weight), r(mom), self.i32(nonneg))
            # p_new is the current dual; the old p buffer is free for the next p_new
            p, pn = pn, p
            rin, ra, rb = ra, rb, ra
            t = t_new
        state.arrays.update(p=p, pn=pn, ra=ra, rb=rb)
        state.valid = True
        return self._2d_red("fgp_finish", out.buf, b.buf, p[0].buf, p[1].buf, r(weight),
                            self.i32(nonneg))

    # element-wise ---------------------------------------------------------------------
    def lincomb(self, out, a, X, b=0.0, Y=None, c=0.0, Z=None):
        r = self.r
        Y = X if Y is None else Y
        Z = X if Z is None else Z
        self._1d("lincomb3", out.buf, r(a), X.buf, r(b), Y.buf, r(c), Z.buf)

    def fista_extrap(self, out, a1, X1, G1, a2, X2, G2):
        r = self.r
        self._1d("fista_extrap", out.buf, r(a1), X1.buf, G1.buf, r(a2), X2.buf, G2.buf)

    def diffnorm(self, a, b) -> Scalars:
        return self._2d_red("diffnorm_contrib", a.buf, b.buf)

    def dot(self, a, b) -> Scalars:
        return self._2d_red("dot_contrib", a.buf, b.buf)

    def grad(self, u, g1, g2):
        """Forward differences (reference convention), for tests."""
        self._2d("grad_fwd", u.buf, g1.buf, g2.buf)

    def div(self, p1, p2, out):
        """The reference divergence, for tests."""
        self._2d("div_ref", p1.buf, p2.buf, out.buf)

    def shrink(self, z1, z2, t1, t2, thr):
        self._2d("shrink_vec", z1.buf, z2.buf, t1.buf, t2.buf, self.r(thr))

    def project_nonneg(self, out, v):
        self._1d("project_nonneg", out.buf, v.buf)

    def triad(self, a, b, c, s):
        self._1d("triad", a.buf, b.buf, c.buf, self.r(s))

    # ADMM -----------------------------------------------------------------------------
    def admm_setup(self, rho, mu):
        H2 = self.op.H2.get().astype(np.float64)
        den = H2 + rho * diff_symbol(self.shape) + mu
        inv = np.where(den > 0, 1.0 / np.where(den > 0, den, 1.0), 0.0)
        self.inv = DeviceArray.from_host(self.rt, inv.astype(self.dtype))

    def admm_rhs(self, out, q1, q2, v, s, rho, mu):
        r = self.r
        self._2d("admm_rhs", out.buf, self._b.buf, q1.buf, q2.buf, v.buf, s.buf, r(rho), r(mu))

    def admm_solve(self, rhs, x, want):
        ny, nx = self.shape
        self.fft.rfft2(rhs, self.X)
        ny, nx = self.shape
        self.k["admm_solve_spec"](self.rt.queue, (self.ws, ny), self._lws, self.X.buf,
                                  self.Y.buf,
                                  self.op.H.buf, self.inv.buf, self.red_s.contrib.buf,
                                  self.i32(want), *self._spec_tail)
        res = self.red_s.reduce(1.0 / (ny * nx), planes=1) if want else None
        self.fft.irfft2(self.X, x)
        self.ffts += self.nc
        return res

    def admm_update(self, x, u1, u2, q1, q2, v, s, thr, nonneg):
        return self._2d_red("admm_update", x.buf, u1.buf, u2.buf, q1.buf, q2.buf, v.buf,
                            s.buf, self.r(thr), self.i32(nonneg))
