"""GPU code paths under Oclgrind: no out-of-bounds access, no data race (``-m oclgrind``).

Oclgrind (Debian package ``oclgrind``) simulates an OpenCL device that reports itself as a GPU,
so clfza takes its GPU paths there: every kernel program compiled (float32 and float64) with
the portable built-ins a GPU driver gets, row-wide work-groups chosen by the device, the
three-kernel TV prox, the device FFT with its local-memory "lines" mapping (and the "batch"
mapping, forced; three planes in one call too), every iterative solver with the device FFT
(TwIST in joint colour too); and the CPU devices' one-pass TV
prox and 16-column kernels, launched directly. A child process runs them at 32^2-64^2 with
Oclgrind's ICD alone in a vendors folder (``OCL_ICD_VENDORS``; nothing is registered system-wide)
and ``OCLGRIND_DATA_RACES=1``; invalid reads and writes are always checked. The test fails on
any such report, or when the results disagree with the numpy float64 reference (float32:
1e-4 of the data scale after a few iterations, like tests/test_api_solvers.py).

Not checked: Oclgrind's uninitialised-value mode (``--uninitialized``) gave only false positives
for clfza: it does not see ``clEnqueueFillBuffer`` (the zeroed duals and measurements), and it
flags a ``vload16`` whose lanes are partly uninitialised when only defined lanes reach a
``vstore8``.

Slow (a simulator: ~1-3 min), hence out of the default run; .ci/run runs it where oclgrind is
installed.
"""

from __future__ import annotations

import re
import sys
from pathlib import Path

import pytest

ERRORS = re.compile(r"Invalid (read|write)|data race|out of bounds", re.IGNORECASE)
CONTROL_END = "@@clfza-oclgrind-controls-done"
_CONTROLS = """
__kernel void oob(__global float *a) { a[get_global_id(0)] += a[get_global_id(0) + 1]; }
__kernel void race(__global float *a) { a[0] = (float)get_global_id(0); }
"""


@pytest.mark.oclgrind
def test_gpu_paths_clean_under_oclgrind(oclgrind):
    p = oclgrind([str(Path(__file__).resolve())])
    assert p.returncode == 0, p.stdout[-2000:] + p.stderr[-4000:]
    assert "device: Oclgrind" in p.stdout, p.stdout
    assert "built tv_fused.cl" in p.stdout and "built exact.cl" in p.stdout, p.stdout[-2000:]
    assert "exact admm" in p.stdout and "exact fista" in p.stdout, p.stdout[-2000:]
    assert "exact admm apg" in p.stdout, p.stdout[-2000:]
    assert p.stdout.count("fused prox") == 2, p.stdout[-2000:]
    assert p.stdout.count("fused fgp") == 3, p.stdout[-2000:]
    assert p.stdout.count("spectrum rows") == 6, p.stdout[-2000:]
    assert p.stdout.count("crop x spec8") == 4, p.stdout[-2000:]
    assert p.stdout.count("admm update+rhs") == 2, p.stdout[-2000:]
    assert p.stdout.count("fft planes") == 2, p.stdout[-2000:]
    assert "solver twist joint colour" in p.stdout, p.stdout[-2000:]
    assert p.stdout.count("batched admm") == 2, p.stdout[-2000:]
    control, _, rest = p.stderr.partition(CONTROL_END)
    # the controls (an out-of-bounds read, a write-write race) prove the checks are on
    assert re.search(r"Invalid read", control), control[-2000:]
    assert re.search(r"data race", control, re.IGNORECASE), control[-2000:]
    reports = [ln for ln in rest.splitlines() if ERRORS.search(ln)]
    assert not reports, "\n".join(reports[:40])


# ----- child process ---------------------------------------------------------------------------
def _close(a, b, tol):
    import numpy as np

    scale = max(1.0, float(np.max(np.abs(b))))
    err = float(np.max(np.abs(a - b))) / scale
    assert err <= tol, err
    return err


def _child() -> int:
    import warnings

    import numpy as np

    import clfza
    from clfza.backends import get_backend
    from clfza.cl import DeviceArray, get_runtime
    from clfza.cl.check import hot_ops
    from clfza.fft._opencl import DeviceFFT

    warnings.simplefilter("ignore")
    rt = get_runtime()
    print(f"device: {rt.info.name} ({rt.info.kind})", flush=True)
    # controls: one out-of-bounds read, one write-write race; then the marker
    ctl = rt.build(_CONTROLS)
    a = DeviceArray.from_host(rt, np.zeros(16, np.float32))
    ctl.oob(rt.queue, (16,), (16,), a.buf)
    ctl.race(rt.queue, (16,), (16,), a.buf)
    rt.finish()
    sys.stderr.write("\n" + CONTROL_END + "\n")
    sys.stderr.flush()
    rng = np.random.default_rng(3)
    # every kernels/*.cl program compiles as a GPU driver would get it (the portable OpenCL
    # built-ins: no CLFZA_CPU or CLFZA_POCL paths), float32 and float64, 1 and 3 channels
    from importlib import resources

    from clfza.backends._opencl import build_program

    for f in sorted(resources.files("clfza.kernels").iterdir(), key=lambda f: f.name):
        if f.name.endswith(".cl") and f.name != "common.cl":
            for dtype in (np.float32, np.float64):
                for nc in (1, 3):
                    build_program(rt, f.name[:-3], dtype, nc)
            print("built", f.name, flush=True)
    # every hot solver kernel once (GPU launch shapes), at 64^2 (> 4096 pixels: sum16 folds)
    cam = clfza.Camera(pitch=0.01, shape=(64, 72), r1=0.2, z1=100.0, z2=3.0, mask="gzp")
    B = get_backend("opencl", cam, fft="device")
    for name, fn in hot_ops(B):
        fn()
        B.finish()
        print("kernel", name, flush=True)
    _fused_prox(rt, rng)
    _spectrum_rows(rt, rng)
    _crop_spec(rt, rng)
    _admm_rows(rt, rng)
    _twist_rows(rt, rng)
    # device FFT, both mappings, fast and Bluestein sizes, against numpy
    for shape in ((32, 48), (30, 28)):
        x = rng.standard_normal(shape)
        for mapping in ("lines", "batch"):
            eng = DeviceFFT(rt, shape, np.float32, mapping=mapping)
            xd = DeviceArray.from_host(rt, x.astype(np.float32))
            X = DeviceArray.empty(rt, eng.spectrum_shape, np.complex64)
            eng.rfft2(xd, X)
            ref = np.fft.rfft2(x)
            err = _close(X.get(), ref, 1e-4 * np.sqrt(x.size))
            y = DeviceArray.empty(rt, shape, np.float32)
            eng.irfft2(X, y)
            _close(y.get(), x, 1e-4)
            print("fft", shape, mapping, f"{err:.1e}", flush=True)
        # three planes in one call (joint colour): every pass launched once for the stack
        x3 = rng.standard_normal((3,) + shape)
        eng = DeviceFFT(rt, shape, np.float32)
        xd = DeviceArray.from_host(rt, x3.astype(np.float32))
        X = DeviceArray.empty(rt, (3,) + eng.spectrum_shape, np.complex64)
        eng.rfft2(xd, X)
        err = _close(X.get(), np.fft.rfft2(x3), 1e-4 * np.sqrt(x3.size))
        eng.irfft2(X, xd, overwrite_x=True)
        _close(xd.get(), x3, 1e-4)
        print("fft planes", (3,) + shape, f"{err:.1e}", flush=True)
    # every solver with the device FFT, a few iterations, against the numpy reference
    cam = clfza.Camera(pitch=0.01, shape=(32, 32), r1=0.16, z1=100.0, z2=3.0, mask="gzp")
    truth = rng.random((32, 32))
    y = clfza.simulate(truth, cam, object_width=cam.shape[1] * cam.pitch).y
    for method, opts in (("twist", {"mode": "paper"}), ("twist", {"mode": "efficient"}),
                         ("twist", {"mode": "paper", "reg": "l1"}),
                         ("fista", {"nonneg": True}), ("admm", {"nonneg": True})):
        kw = dict(iters=4, min_iters=4, stop="none", **opts)
        a = clfza.reconstruct(y, cam, method, backend="opencl", fft="device", **kw).image
        b = clfza.reconstruct(y, cam, method, backend="numpy", **kw).image
        err = _close(np.asarray(a, np.float64), np.asarray(b), 1e-4)
        print("solver", method, opts, f"{err:.1e}", flush=True)
    # joint colour (C = 3) on the device FFT
    yc = clfza.simulate(rng.random((32, 32, 3)), cam, object_width=cam.shape[1] * cam.pitch).y
    kw = dict(iters=4, min_iters=4, stop="none", colour="joint", mode="paper")
    a = clfza.reconstruct(yc, cam, "twist", backend="opencl", fft="device", **kw).image
    b = clfza.reconstruct(yc, cam, "twist", backend="numpy", **kw).image
    err = _close(np.asarray(a, np.float64), np.asarray(b), 1e-4)
    print("solver twist joint colour", f"{err:.1e}", flush=True)
    # a batch of frames (one launch per step for all): grey frames with their own tau, and
    # colour frames whose channels are planes of the batch, against one frame at a time
    from clfza.solvers import run_solver, run_solver_batch

    for frames in (np.stack([y, 0.5 * y[::-1], y[:, ::-1]]), np.stack([yc, yc[::-1]])):
        frames = frames - frames.mean(axis=(1, 2), keepdims=True)
        taus = [0.005, 0.01, 0.02][:len(frames)]
        kw = dict(iters=4, min_iters=4, stop="none", model="tf", fft="device",
                  backend="opencl")
        got = run_solver_batch(frames, cam, "admm", tau=taus, **kw)
        err = max(_close(g.image, run_solver(f, cam, "admm", tau=t, **kw).image, 1e-5)
                  for g, f, t in zip(got, frames, taus, strict=True))
        print("batched admm", frames.shape, f"{err:.1e}", flush=True)
    # the exact finite-aperture model (kernels/exact.cl): crop-split ADMM and FISTA
    cam = clfza.Camera(pitch=0.01, shape=(32, 32), r1=0.16, z1=100.0, z2=3.0, R=0.12,
                       mask="fza")
    y = clfza.simulate(truth, cam, sensor_plane=True).y
    for method, extra in (("admm", {}), ("fista", {}), ("admm", {"algorithm": "apg"})):
        kw = dict(iters=4, min_iters=4, stop="none", model="exact", **extra)
        a = clfza.reconstruct(y, cam, method, backend="opencl", fft="device", **kw).image
        b = clfza.reconstruct(y, cam, method, backend="numpy", **kw).image
        err = _close(np.asarray(a, np.float64), np.asarray(b), 1e-4)
        print("exact", method, *extra.values(), f"{err:.1e}", flush=True)
    return 0


def _fused_prox(rt, rng) -> None:
    """The CPU devices' one-pass TV proxes (kernels/tv_fused.cl: TwIST's Chambolle, FISTA's
    FGP), launched directly (the backend takes them on CPU devices only): windows over both
    image edges, a last work-item per row with fewer columns than the others, strips that
    overhang the last row."""
    import numpy as np

    import clfza
    from clfza.backends import get_backend
    from clfza.backends._base import ProxState
    from clfza.backends._opencl import (
        FUSED_FGP_COLUMNS,
        FUSED_PROX_COLUMNS,
        build_program,
    )
    from clfza.cl import DeviceArray

    kern = build_program(rt, "tv_fused", np.float32, 1).chambolle2_fused
    fpar1 = DeviceArray.from_host(rt, np.ones((1, 4), np.float32))  # one frame's factors
    for shape, strip in (((37, 29), 8), ((20, 48), 32)):
        cam = clfza.Camera(pitch=0.01, shape=shape, r1=0.2, z1=100.0, z2=3.0, mask="gzp")
        x = rng.standard_normal((1,) + shape)
        g = 0.1 * rng.standard_normal((1,) + shape)
        xd, gd = (DeviceArray.from_host(rt, a.astype(np.float32)) for a in (x, g))
        out = DeviceArray.from_host(rt, np.zeros((1,) + shape, np.float32))
        grid = (-(-shape[1] // FUSED_PROX_COLUMNS), -(-shape[0] // strip))
        lam = np.float32(2.0 / 0.005)
        # software prefetch on (3 rows ahead, stored rows too): its addresses stay inside
        kern(rt.queue, grid, None, out.buf, xd.buf, gd.buf, np.float32(0.5), lam,
             np.int32(strip), np.int32(3), np.int32(1), fpar1.buf, np.int32(shape[1]),
             np.int32(shape[0]))
        N = get_backend("numpy", cam)
        ref = N.empty()
        N.prox_step("tv", x, g, 0.5, 0.005, ref, 2, ProxState())
        err = _close(out.get().astype(np.float64), ref, 2e-5)
        print("fused prox", shape, f"{err:.1e}", flush=True)
    # FISTA's one-pass FGP (periodic windows over both edges, 7 warm-up rows that wrap)
    kern = build_program(rt, "tv_fused", np.float32, 1).fgp2_fused
    # the dual's rows padded (pitch > width, as dual_pitch pads widths that are multiples of 256)
    fpar = DeviceArray.from_host(rt, np.ones(4, np.float32))  # one frame: the factors 1
    for shape, strip, pq in (((37, 29), 8, 29), ((5, 48), 16, 48), ((9, 32), 8, 48)):
        cam = clfza.Camera(pitch=0.01, shape=shape, r1=0.2, z1=100.0, z2=3.0, mask="gzp")
        b = rng.standard_normal(shape)
        p = [0.3 * rng.standard_normal(shape) for _ in range(2)]
        padded = [np.pad(a, ((0, 0), (0, pq - shape[1])), constant_values=np.nan) for a in p]
        bd = DeviceArray.from_host(rt, b.astype(np.float32))
        p0, p1 = (DeviceArray.from_host(rt, a.astype(np.float32)) for a in padded)
        z = DeviceArray.from_host(rt, np.zeros(shape, np.float32))
        q0, q1 = (DeviceArray.from_host(rt, np.zeros((shape[0], pq), np.float32))
                  for _ in range(2))
        grid = (-(-shape[1] // FUSED_FGP_COLUMNS), -(-shape[0] // strip))
        contrib = DeviceArray.from_host(rt, np.zeros(2 * grid[0] * grid[1], np.float32))
        kern(rt.queue, grid, None, z.buf, q0.buf, q1.buf, bd.buf, p0.buf, p1.buf,
             np.float32(0.3), np.int32(1), np.int32(strip), np.int32(3), np.int32(1),
             fpar.buf, contrib.buf, np.int32(shape[1]), np.int32(shape[0]), np.int32(pq))
        N = get_backend("numpy", cam)
        st = ProxState(warm=True)
        st.arrays["p"], st.valid = np.stack(p)[:, None], True
        ref = N.empty()
        N.fgp_prox("tv", ref, b[None], 0.3, 2, st, True)
        err = _close(z.get().astype(np.float64), ref[0], 2e-5)
        for q, qref in zip((q0, q1), st.arrays["p"], strict=True):  # the new dual, pad untouched
            _close(q.get()[:, :shape[1]].astype(np.float64), qref[0], 2e-5)
            assert not np.any(q.get()[:, shape[1]:])
        print("fused fgp", shape, pq, f"{err:.1e}", flush=True)



def _spectrum_rows(rt, rng) -> None:
    """The CPU devices' row-vector spectrum kernels (spectrum.cl: resid_grad_spec8 with and
    without the step, admm_solve_spec8; 8 frequencies per work-item), launched directly
    against their float64 formulas: a half-spectrum row of two vectors with the Nyquist
    column in the last lane (width 30) and one of two vectors and a 1-lane tail (width 18)."""
    import numpy as np

    from clfza.backends._opencl import SPEC_LANES, build_program
    from clfza.cl import DeviceArray

    prg = build_program(rt, "spectrum", np.float32, 1)
    for hs, w in ((6, 30), (5, 18)):
        ws = w // 2 + 1
        grid = (-(-ws // SPEC_LANES), hs)
        weight = np.full(ws, 2.0)
        weight[0] = weight[-1] = 1.0  # even widths: column 0 and the Nyquist column
        X, Y = (rng.standard_normal((hs, ws)) + 1j * rng.standard_normal((hs, ws))
                for _ in range(2))
        H, inv = rng.standard_normal((hs, ws)), rng.random((hs, ws))
        for name, new, extra in (("resid_grad_spec8", H * (Y - H * X), (np.int32(0),)),
                                 ("resid_grad_spec8", X + H * (Y - H * X), (np.int32(1),)),
                                 ("admm_solve_spec8", inv * X, (np.int32(1), np.int32(0)))):
            r = Y - H * (X if name == "resid_grad_spec8" else inv * X)
            total = float(np.sum(weight * np.abs(r) ** 2))
            xd = DeviceArray.from_host(rt, X.astype(np.complex64).view(np.float32))
            dev = [DeviceArray.from_host(rt, a.astype(np.float32))
                   for a in ((Y.astype(np.complex64).view(np.float32)), H, inv)]
            contrib = DeviceArray.from_host(rt, np.zeros(grid[0] * hs, np.float32))
            args = [xd.buf, dev[0].buf, dev[1].buf]
            args += [dev[2].buf] if name == "admm_solve_spec8" else []
            getattr(prg, name)(rt.queue, grid, None, *args, contrib.buf, *extra, np.int32(ws),
                               np.int32(hs), np.int32(1))
            got = xd.get().view(np.complex64).astype(np.complex128)
            err = _close(got.view(np.float64), new.view(np.float64), 2e-6)
            sums = float(contrib.get().astype(np.float64).sum())
            assert abs(sums - total) <= 1e-5 * total, (name, sums, total)
            print("spectrum rows", name, extra, (hs, w), f"{err:.1e}", flush=True)


def _crop_spec(rt, rng) -> None:
    """The CPU devices' x-update spectrum kernel of the crop split (exact.cl's crop_x_spec8, 8
    frequencies per work-item), launched directly against its float64 formula: spectra of 40
    frequencies (no tail) and of 43 (a last work-item with 3), one plane and three."""
    import numpy as np

    from clfza.backends._opencl import build_program
    from clfza.cl import DeviceArray

    for nc in (1, 3):
        kern = build_program(rt, "exact", np.float32, nc).crop_x_spec8
        for n in (40, 43):
            X, E = (rng.standard_normal((nc, n)) + 1j * rng.standard_normal((nc, n))
                    for _ in range(2))
            H = rng.standard_normal(n) + 1j * rng.standard_normal(n)
            inv, mu1 = rng.random(n), 0.7
            new_x = (X + mu1 * np.conj(H) * E) * inv
            new_e = new_x * H
            xd, ed, hd = (DeviceArray.from_host(rt, a.astype(np.complex64).view(np.float32))
                          for a in (X, E, H))
            ivd = DeviceArray.from_host(rt, inv.astype(np.float32))
            kern(rt.queue, (-(-n // 8),), None, xd.buf, ed.buf, hd.buf, ivd.buf,
                 np.float32(mu1), np.int32(n))
            err = max(_close(d.get().view(np.complex64).astype(np.complex128).view(np.float64),
                             want.view(np.float64), 2e-6)
                      for d, want in ((xd, new_x), (ed, new_e)))
            print("crop x spec8", nc, n, f"{err:.1e}", flush=True)


def _admm_rows(rt, rng) -> None:
    """The CPU devices' ADMM update with 16 columns per work-item (elementwise.cl's
    admm_update16, and admm_update_rhs16 with the next right-hand side), launched directly
    against the float64 reference: a row of one vector and a 13-column tail (width 29), a width
    below one vector (14), two full vectors (32), with nonneg."""
    import numpy as np

    import clfza
    from clfza.backends import get_backend
    from clfza.backends._opencl import build_program
    from clfza.cl import DeviceArray
    from clfza.solvers._admm_ops import AdmmOps

    kern = build_program(rt, "elementwise", np.float32, 1).admm_update16
    fpar = DeviceArray.from_host(rt, np.ones(4, np.float32))  # one frame, factors 1, running
    for shape in ((5, 29), (4, 14)):
        cam = clfza.Camera(pitch=0.01, shape=shape, r1=0.2, z1=100.0, z2=3.0, mask="gzp")
        h = [0.3 * rng.standard_normal((1,) + shape) for _ in range(7)]
        d = [DeviceArray.from_host(rt, a.astype(np.float32)) for a in h]
        grid = (-(-shape[1] // 16), shape[0])
        contrib = DeviceArray.from_host(rt, np.zeros(2 * grid[0] * grid[1], np.float32))
        kern(rt.queue, grid, None, *(a.buf for a in d), np.float32(0.1), np.int32(1),
             fpar.buf, contrib.buf, np.int32(shape[1]), np.int32(shape[0]))
        AdmmOps.for_backend(get_backend("numpy", cam)).update(*h, 0.1, True)
        err = max(_close(a.get().astype(np.float64), b, 2e-6) for a, b in zip(d, h, strict=True))
        print("admm rows", shape, f"{err:.1e}", flush=True)
    # the update with the next right-hand side (admm_update_rhs16): reads the old split, writes
    # the new one elsewhere, recomputes the neighbours' q (the row below wraps, the column right
    # of a row's last work-item wraps): no work-item may read what another writes
    kern = build_program(rt, "elementwise", np.float32, 1).admm_update_rhs16
    for shape in ((5, 29), (3, 32)):
        cam = clfza.Camera(pitch=0.01, shape=shape, r1=0.2, z1=100.0, z2=3.0, mask="gzp")
        N = get_backend("numpy", cam)
        y = rng.standard_normal(shape)
        N.set_measurement(y)
        h = [0.3 * rng.standard_normal((1,) + shape) for _ in range(7)]  # x u1 u2 q1 q2 v s
        d = [DeviceArray.from_host(rt, a.astype(np.float32)) for a in h]
        new = [DeviceArray.from_host(rt, np.zeros((1,) + shape, np.float32)) for _ in range(3)]
        b = DeviceArray.from_host(rt, N.b.astype(np.float32))
        grid = (-(-shape[1] // 16), shape[0])
        contrib = DeviceArray.from_host(rt, np.zeros(2 * grid[0] * grid[1], np.float32))
        kern(rt.queue, grid, None, d[0].buf, d[1].buf, d[2].buf, new[0].buf, new[1].buf,
             d[5].buf, d[6].buf, new[2].buf, b.buf, np.float32(0.1), np.int32(1),
             np.float32(0.7), np.float32(0.3), fpar.buf, contrib.buf, np.int32(shape[1]),
             np.int32(shape[0]))
        out = np.empty((1,) + shape)
        AdmmOps.for_backend(N).update_rhs(h[0], (h[1], h[2]), None, (h[3], h[4]), h[5], h[6],
                                          out, 0.1, True, 0.7, 0.3)
        err = max(_close(a.get().astype(np.float64), ref, 1e-5) for a, ref in
                  zip((new[0], new[1], d[5], d[6], new[2]), (h[1], h[2], h[5], h[6], out),
                      strict=True))
        print("admm update+rhs", shape, f"{err:.1e}", flush=True)



def _twist_rows(rt, rng) -> None:
    """The CPU devices' TwIST combination with 16 columns per work-item (elementwise.cl's
    twist_combine16), launched directly against the float64 reference: a 13-column tail
    (width 29) and a width below one vector (14), sparse, with TV."""
    import numpy as np

    import clfza
    from clfza import regularizers as R
    from clfza.backends import get_backend
    from clfza.backends._opencl import build_program
    from clfza.cl import DeviceArray
    from clfza.solvers._twist_ops import TwistOps

    kern = build_program(rt, "elementwise", np.float32, 1).twist_combine16
    for shape in ((5, 29), (4, 14)):
        cam = clfza.Camera(pitch=0.01, shape=shape, r1=0.2, z1=100.0, z2=3.0, mask="gzp")
        h = [rng.standard_normal((1,) + shape) for _ in range(2)]
        h.append(R.soft(rng.standard_normal((1,) + shape), 0.6))  # x_ist with exact zeros
        d = [DeviceArray.from_host(rt, a.astype(np.float32)) for a in h]
        out = DeviceArray.from_host(rt, np.zeros((1,) + shape, np.float32))
        grid = (-(-shape[1] // 16), shape[0])
        contrib = DeviceArray.from_host(rt, np.zeros(3 * grid[0] * grid[1], np.float32))
        kern(rt.queue, grid, None, out.buf, *(a.buf for a in d), np.float32(1 - 1.96),
             np.float32(1.96 - 3.92), np.float32(3.92), np.int32(1), np.int32(1),
             DeviceArray.from_host(rt, np.ones((1, 4), np.float32)).buf, contrib.buf,
             np.int32(shape[1]), np.int32(shape[0]))
        ref = np.empty((1,) + shape)
        sums = TwistOps.for_backend(get_backend("numpy", cam)).combine(ref, *h, 1.96, 3.92, True)
        err = _close(out.get().astype(np.float64), ref, 2e-6)
        got = contrib.get().astype(np.float64).reshape(3, -1).sum(axis=1)
        assert np.allclose(got, sums.get()[:3], rtol=1e-5), (shape, got, sums.get())
        print("twist rows", shape, f"{err:.1e}", flush=True)

if __name__ == "__main__":
    sys.exit(_child())
