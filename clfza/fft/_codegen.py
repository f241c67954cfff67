"""Generated OpenCL source for the "batch" mapping of :mod:`clfza.fft._opencl`.

A Stockham pass of radix ``R`` (2, 3, 4, 5, 7, 8, 16, 32 or 64; any product of 2, 3, 5, 7
would do) is emitted as straight-line
scalar code: one work-item per (line, butterfly), the line index running along dimension 0 and
along contiguous memory (lines are the columns of a row-major array). Consecutive work-items
read consecutive complex values, so the pass is coalesced on GPUs and, on PoCL, the implicit
loop over the work-items of a group vectorises (no private arrays, no loops, no vector types in
the kernel body: each of those stops PoCL's work-group vectoriser). The small DFT of size ``R``
is a Cooley-Tukey split into the codelets 2, 3, 4, 5, 7 with its internal twiddles as
compile-time constants (computed in float64); the sign of the transform is compile-time too.

Element ``i`` of line ``b`` sits at ``i * W + b`` (complex elements), in plane ``p`` (global
dimension 2, when launched: a stack of such arrays, e.g. the columns of ``P`` spectra in one
launch) ``p * PS`` further; pass (radix ``R``,
``ns`` = product of the radices already applied), butterfly ``j < n/R``, ``k = j % ns``::

    v[r] = src[j + r*n/R] * tw[r * k * (n/(ns*R))],   v = DFT_R(v),
    dst[(j - k)*R + k + r*ns] = scale * v[r]

with ``tw[m] = exp(sign 2 pi i m / n)`` (a float64-derived table).

Each pass comes in two variants: a guarded one (lines ``x >= nb`` return; GPUs) and a
``_full`` one without the guard, whose last work-group is shifted back to end at line ``nb``
(CPU devices with ``nb >=`` the group width). Under the guard PoCL's vectoriser masks every
load and store, which made the passes several times slower (measured: docs/measurements.md,
clfza.fft._codegen).
"""

from __future__ import annotations

import math

__all__ = ["pass_source", "split_radices", "MAX_RADIX", "RADICES"]

MAX_RADIX = 64
#: the radices :func:`split_radices` uses
RADICES = (2, 3, 4, 5, 7, 8, 16, 32, 64)


class _Emitter:
    def __init__(self, sign: int):
        self.sign = sign
        self.lines: list[str] = []
        self.n = 0

    def tmp(self, re: str, im: str) -> tuple[str, str]:
        i = self.n
        self.n += 1
        self.lines.append(f"    const real t{i}r = {re}, t{i}i = {im};")
        return f"t{i}r", f"t{i}i"

    # complex helpers on (re, im) name pairs -----------------------------------------------
    def add(self, a, b):
        return self.tmp(f"{a[0]} + {b[0]}", f"{a[1]} + {b[1]}")

    def sub(self, a, b):
        return self.tmp(f"{a[0]} - {b[0]}", f"{a[1]} - {b[1]}")

    def rot(self, a):
        """a * (sign * i): no arithmetic, a renaming with a negation."""
        if self.sign < 0:  # -i (x + iy) = y - ix
            return self.tmp(a[1], f"-{a[0]}")
        return self.tmp(f"-{a[1]}", a[0])

    def twiddle(self, a, e: int, R: int):
        """a * exp(sign 2 pi i e / R) with constants."""
        e %= R
        if e == 0:
            return a
        if (4 * e) % R == 0:
            q = 4 * e // R  # multiple of a quarter turn
            if q == 2:
                return self.tmp(f"-{a[0]}", f"-{a[1]}")
            if q == 1:
                return self.rot(a)
            b = self.rot(a)
            return self.tmp(f"-{b[0]}", f"-{b[1]}")
        ang = self.sign * 2.0 * math.pi * e / R
        c, s = math.cos(ang), math.sin(ang)
        if (8 * e) % R == 0:  # odd multiple of an eighth turn: |c| = |s| = h
            h = f"(real){abs(c):.20f}"
            x, y = a
            # (x + iy)(c + is) = (cx - sy) + i(sx + cy)
            re = f"{'' if c > 0 else '-'}{x} {'-' if s > 0 else '+'} {y}"
            im = f"{'' if s > 0 else '-'}{x} {'+' if c > 0 else '-'} {y}"
            return self.tmp(f"{h} * ({re})", f"{h} * ({im})")
        cr, sr = f"(real){c:.20e}", f"(real){s:.20e}"
        return self.tmp(f"{cr} * {a[0]} - {sr} * {a[1]}", f"{sr} * {a[0]} + {cr} * {a[1]}")

    def scale(self, a, c: float):
        return self.tmp(f"(real){c:.20e} * {a[0]}", f"(real){c:.20e} * {a[1]}")

    # codelets -----------------------------------------------------------------------------
    def dft(self, x: list) -> list:
        R = len(x)
        if R == 1:
            return list(x)
        if R == 2:
            return [self.add(x[0], x[1]), self.sub(x[0], x[1])]
        if R == 4:
            t0, t1 = self.add(x[0], x[2]), self.sub(x[0], x[2])
            t2, t3 = self.add(x[1], x[3]), self.rot(self.sub(x[1], x[3]))
            return [self.add(t0, t2), self.add(t1, t3), self.sub(t0, t2), self.sub(t1, t3)]
        if R in (3, 5, 7):
            return self._odd(x)
        # R = R1 * R2, n = n1*R2 + n2, k = k1 + R1*k2
        R1 = _first_factor(R)
        R2 = R // R1
        Y = []
        for n2 in range(R2):
            y = self.dft([x[n1 * R2 + n2] for n1 in range(R1)])
            Y.append([self.twiddle(y[k1], n2 * k1, R) for k1 in range(R1)])
        X = [None] * R
        for k1 in range(R1):
            z = self.dft([Y[n2][k1] for n2 in range(R2)])
            for k2 in range(R2):
                X[k1 + R1 * k2] = z[k2]
        return X

    def _odd(self, x: list) -> list:
        """Odd prime R: y[k] = x0 + sum_r a_r cos(2 pi r k/R) + sign i sum_r b_r sin(...)."""
        R = len(x)
        h = (R - 1) // 2
        a = [self.add(x[r], x[R - r]) for r in range(1, h + 1)]
        b = [self.sub(x[r], x[R - r]) for r in range(1, h + 1)]
        y0 = x[0]
        for ar in a:
            y0 = self.add(y0, ar)
        out = [y0] + [None] * (R - 1)
        for k in range(1, h + 1):
            mr = [x[0][0]]
            mi = [x[0][1]]
            tr, ti = [], []
            for r in range(1, h + 1):
                c = math.cos(2 * math.pi * r * k / R)
                s = math.sin(2 * math.pi * r * k / R)
                mr.append(f"(real){c:.20e} * {a[r - 1][0]}")
                mi.append(f"(real){c:.20e} * {a[r - 1][1]}")
                tr.append(f"(real){s:.20e} * {b[r - 1][0]}")
                ti.append(f"(real){s:.20e} * {b[r - 1][1]}")
            m = self.tmp(" + ".join(mr), " + ".join(mi))
            t = self.rot(self.tmp(" + ".join(tr), " + ".join(ti)))
            out[k] = self.add(m, t)
            out[R - k] = self.sub(m, t)
        return out


def _first_factor(R: int) -> int:
    if R % 4 == 0 and R > 4:
        return 4
    for p in (2, 3, 5, 7):
        if R % p == 0:
            return p
    return R  # pragma: no cover


def _factors(n: int) -> list[int]:
    out = []
    for p in (2, 3, 5, 7):
        while n % p == 0:
            out.append(p)
            n //= p
    if n != 1:
        raise ValueError(f"{n} is not a product of 2, 3, 5, 7")
    return out


def split_radices(n: int, max_radix: int = MAX_RADIX) -> list[int]:
    """Radices whose product is ``n``, drawn from a small fixed set (:data:`RADICES`).

    The power of two ``2^k`` in ``n`` is split into ``ceil(k / log2(max_radix))`` balanced
    power-of-two radices (1024 = 32 * 32, 2048 = 64 * 32); every factor 3, 5, 7 is a pass of
    its own. A fixed set keeps the number of compiled kernels small (each one a noticeable
    build on a cold cache with PoCL: docs/measurements.md, clfza.fft._codegen).
    """
    if n == 1:
        return []
    f = _factors(n)
    k = f.count(2)
    out = []
    if k:
        lim = max(1, int(math.log2(max_radix)))
        npass = -(-k // lim)
        out = [1 << (k // npass + (1 if i < k % npass else 0)) for i in range(npass)]
    return out + sorted(p for p in f if p != 2)


def pass_source(R: int, sign: int, full: bool | None = None) -> str:
    """OpenCL source of the radix-``R`` pass kernels for one sign.

    Parameters
    ----------
    R : int
        Radix (any product of 2, 3, 5, 7 up to :data:`MAX_RADIX`).
    sign : int
        ``-1`` forward, ``+1`` inverse.
    full : bool, optional
        Only the ``_full`` (True) or only the guarded (False) kernel; default both.

    Returns
    -------
    str
        Source of the kernels ``stockham_batch_{f|i}{R}`` (guarded: line ``x`` is the global
        id 0, lines ``x >= nb`` return) and/or ``stockham_batch_{f|i}{R}_full`` (no guard:
        needs ``nb`` >= the local size; the last work-group is shifted back onto lines
        ``[nb - lsize, nb)``, so lines may be done twice, writing the same values). Arguments:
        ``src, dst, tw`` (real pointers to interleaved complex values), ``n``, ``ns``, ``W``
        (element stride of a line, complex values), ``nb`` (lines per plane), ``ps`` (plane
        stride, complex values), ``scale``. Global size ``(>= nb, n/R)`` for one plane or
        ``(>= nb, n/R, planes)``, local size ``(lsize, 1)`` or ``(lsize, 1, 1)``; ``src`` and
        ``dst`` must differ.

    Notes
    -----
    PoCL vectorises the implicit loop over the work-items of a group. Under a per-work-item
    guard it masks every load and store, which made a pass several times slower than the
    ``_full`` form (measured: docs/measurements.md, clfza.fft._codegen). The twiddles depend
    on the butterfly only and are loaded first.
    """
    em = _Emitter(sign)
    xs = []
    for r in range(R):
        em.lines.append(f"    const real x{r}r = sp[{r} * st], x{r}i = sp[{r} * st + 1];")
        xs.append((f"x{r}r", f"x{r}i"))
    wl = [f"    const real w{r}r = tw[2 * {r} * tstep], w{r}i = tw[2 * {r} * tstep + 1];"
          for r in range(1, R)]
    tw = [xs[0]]
    for r in range(1, R):
        a, w = xs[r], (f"w{r}r", f"w{r}i")
        tw.append(em.tmp(f"{a[0]} * {w[0]} - {a[1]} * {w[1]}",
                         f"{a[0]} * {w[1]} + {a[1]} * {w[0]}"))
    ys = em.dft(tw)
    for r, y in enumerate(ys):
        em.lines.append(f"    dp[{r} * sd] = scale * {y[0]}; dp[{r} * sd + 1] = scale * {y[1]};")
    body = "\n".join(em.lines)
    twl = "\n".join(wl)
    name = f"stockham_batch_{'f' if sign < 0 else 'i'}{R}"
    return "".join(_kernel_text(name + sfx, R, guard, twl, body)
                   for sfx, guard in (("", True), ("_full", False))
                   if full is None or full != guard)


def _kernel_text(name: str, R: int, guard: bool, twl: str, body: str) -> str:
    if guard:
        g = "    if (x >= nb) return;\n"
        xdef = "get_global_id(0)"
    else:  # the last group is shifted back onto lines [nb - lsize, nb)
        g = ""
        xdef = ("min((int)(get_group_id(0) * get_local_size(0)), nb - (int)get_local_size(0))"
                " + (int)get_local_id(0)")
    return f"""
__kernel void {name}(__global const real *src, __global real *dst, __global const real *tw,
                     const int n, const int ns, const int W, const int nb, const int ps,
                     const real scale)
{{
    const int x = {xdef};
    const int j = get_global_id(1);
    const int nq = n / {R};
    const int k = j % ns;
    const int tstep = k * (nq / ns);
    const long po = (long)get_global_id(2) * ps;  // the plane: uniform across a work-group
    __global const real *sp = src + 2 * (po + (long)j * W + x);
    const long st = 2 * (long)nq * W;
    __global real *dp = dst + 2 * (po + (long)((j - k) * {R} + k) * W + x);
    const long sd = 2 * (long)ns * W;
{twl}
{g}{body}
}}
"""
