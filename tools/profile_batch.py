"""Where a batched ADMM iteration's time goes (issue 37): each operation of one iteration timed
alone, for one frame and for a batch of P frames, per frame, on one device.

    python tools/profile_batch.py [--device P:D] [--n 2048] [--frames 16] [--reps 20]
                                  [--local2d auto 32x8] [--loop] [--host] [--call]
                                  [--phases] [--host-phases] [--model tf]

Operations (each the median of ``--reps`` launches, the queue finished around each block of
5): the forward and inverse FFT of the backend's engine, ADMM's Fourier x-update pass
(``admm_solve_spec``), and its split update with the next right-hand side
(``admm_update_rhs``), with the 2-D kernels' work-group shape ``--local2d`` (the batch adds
the frames as a third dimension of one).
"""

from __future__ import annotations

import argparse
import statistics
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "bench"))
from bench_solvers import camera  # noqa: E402

from clfza.backends import get_backend  # noqa: E402
from clfza.solvers import AdmmOps, FourierSolve  # noqa: E402


def timed(rt, fn, reps: int) -> float:
    fn()
    rt.finish()
    out = []
    for _ in range(max(1, reps // 5)):
        t0 = time.perf_counter()
        for _ in range(5):
            fn()
        rt.finish()
        out.append((time.perf_counter() - t0) / 5)
    return statistics.median(out)


def ops(B, frames: int) -> dict:
    rng = np.random.default_rng(0)
    y = rng.standard_normal((frames,) + B.shape)
    B.set_measurement(y)
    fs = FourierSolve.for_backend(B)
    fs.setup(np.full(frames, 0.05) if frames > 1 else 0.05,
             np.zeros(frames) if frames > 1 else 0.0)
    ad = AdmmOps.for_backend(B)
    x, o = B.from_host(y), B.empty()
    u = (B.zeros(), B.zeros())
    spare = (B.empty(), B.empty())
    v, s, q = B.zeros(), B.zeros(), (B.empty(), B.empty())
    ny, nx = B.shape
    return {
        "rfft2": lambda: B.fft.rfft2(x, B.X),
        "irfft2": lambda: B.fft.irfft2(B.X, o, overwrite_x=True),
        "admm_solve_spec": lambda: B.spec_pass("admm_solve_spec",
                                               (B.X.buf, B.Y.buf, B.op.H.buf, fs.inv.buf),
                                               (B.i32(0), fs.inv_frames)),
        "admm_update_rhs": lambda: ad.update_rhs(x, u, spare, q, v, s, o, 0.1, False, 0.5, 0.0,
                                                 want=False),
        "copy (bandwidth probe)": lambda: B.copy(o, x),
        "_bytes": ny * nx * 4 * frames,
    }


def loop(cam, device, P: int, iters: int = 50) -> dict:
    """The batched ADMM loop as run_batch runs it, in three timed parts: enqueueing the
    iterations (host), their completion (device), and stopping every frame (images back)."""
    from clfza.solvers import options_class
    from clfza.solvers._batch import BatchAdmmSolver
    from clfza.solvers._common import Monitor

    rng = np.random.default_rng(1)
    B = get_backend("opencl", cam, device=device, frames=P)
    B.set_measurement(rng.standard_normal((P,) + B.shape))
    opts = options_class("admm").from_options({"tau": 0.005, "iters": iters, "stop": "none"},
                                               method="admm", exact=False)
    solver = BatchAdmmSolver(B, opts, Monitor(B), np.full(P, opts.weight))
    solver.setup(B.b)
    solver.start()
    B.finish()
    t0 = time.perf_counter()
    for it in range(1, iters + 1):
        solver.step(it)
    t1 = time.perf_counter()
    B.finish()
    t2 = time.perf_counter()
    for f in range(P):
        solver.stop_frame(f)
    t3 = time.perf_counter()
    return {"enqueue_ms_per_it": (t1 - t0) / iters * 1e3,
            "total_ms_per_it": (t2 - t0) / iters * 1e3, "stop_all_ms": (t3 - t2) * 1e3}


def host_starts(cam, P: int, reps: int = 5) -> dict:
    """The host work of a batch's starts (each frame's noise estimate and Wiener ``lam``):
    one frame at a time (``channel_group`` and ``wiener_lam`` per frame, as before issue
    37's item 1) against the stack at once (``frame_starts``, one thread and all CPUs),
    interleaved, ms per frame (medians of ``reps``)."""
    from clfza.solvers._context import SolveContext
    from clfza.solvers._tau import channel_group, frame_starts
    from clfza.solvers._wiener import wiener_lam

    B = get_backend("opencl", cam)
    ctx = SolveContext(cam, 1.0, False)
    planes = np.random.default_rng(2).standard_normal((P,) + B.shape)

    def alone():
        for p in planes:
            g = channel_group(B, ctx, p[None])
            wiener_lam(B, g.y, g.sigma)

    fns = {"per frame": alone, "stack, 1 thread": lambda: frame_starts(B, ctx, planes, 1,
                                                                       workers=1),
           "stack, all CPUs": lambda: frame_starts(B, ctx, planes, 1)}
    times = {k: [] for k in fns}
    for _ in range(reps):
        for k, f in fns.items():
            t0 = time.perf_counter()
            f()
            times[k].append((time.perf_counter() - t0) / P * 1e3)
    return {k: statistics.median(v) for k, v in times.items()}


def host_phases(cam, device, P: int, reps: int = 15) -> dict:
    """The host phases of a batched call alone, ms per frame, interleaved, ``reps`` times
    each (the median and the minimum): ``set_measurement`` of a stack of ``P`` frames (on a
    CPU device with its host FFTs and kernels, the queue finished), ``frame_starts`` (each
    frame's noise and Wiener lam, over the CPUs) and ``check_finite`` of each frame's image.
    Fewer moving parts than :func:`call_phases`, so more repetitions fit: the instrument for
    a change to one of these functions on a shared machine."""
    from clfza.solvers._context import SolveContext
    from clfza.solvers._driver import check_finite
    from clfza.solvers._tau import frame_starts

    B = get_backend("opencl", cam, device=device, frames=P)
    ctx = SolveContext(cam, B.data_scale ** 2, False)
    rng = np.random.default_rng(3)
    ys = rng.standard_normal((P,) + tuple(cam.shape))
    imgs = list(rng.standard_normal((P, 1) + tuple(cam.shape)))

    def measure():
        B.set_measurement(ys)
        B.finish()

    fns = {"set_measurement": measure, "frame_starts": lambda: frame_starts(B, ctx, ys, 1),
           "check_finite": lambda: [check_finite("admm", a, 0.1) for a in imgs]}
    times: dict = {k: [] for k in fns}
    for f in fns.values():
        f()
    for _ in range(reps):
        for k, f in fns.items():
            t0 = time.perf_counter()
            f()
            times[k].append((time.perf_counter() - t0) / P * 1e3)
    out = {}
    for k, v in times.items():
        out[k] = statistics.median(v)
        out[k + " (min)"] = min(v)
    return out


def call_profile(cam, device, P: int, top: int = 25) -> None:
    """Where a whole batched call's time goes outside the iterations: a cProfile of one
    ``run_solver_batch`` call of ``P`` frames (ADMM-50, stopping rule off, after a warm-up
    call with the backends kept), the functions with the most own time."""
    import cProfile
    import pstats

    from clfza.backends import BackendCache, reuse_backends
    from clfza.solvers import run_solver_batch

    ys = np.random.default_rng(3).standard_normal((P,) + tuple(cam.shape))
    kw = dict(backend="opencl", device=device, iters=50, min_iters=50, stop="none",
              model="tf", tau=0.005)
    with reuse_backends(BackendCache(maxsize=2)):
        run_solver_batch(ys, cam, "admm", **kw)
        t0 = time.perf_counter()
        out = run_solver_batch(ys, cam, "admm", **kw)
        wall = time.perf_counter() - t0
        b = out[0].info.stats["batch"]
        print(f"{cam.shape[0]}^2, {P} frames: call {wall * 1e3:.1f} ms, solve "
              f"{b['solve_s'] * 1e3:.1f} ms, plan {b['plan_s'] * 1e3:.1f} ms; host "
              f"{(wall - b['solve_s']) / P * 1e3:.2f} ms per frame", flush=True)
        pr = cProfile.Profile()
        pr.enable()
        run_solver_batch(ys, cam, "admm", **kw)
        pr.disable()
    pstats.Stats(pr).sort_stats("tottime").print_stats(top)


def call_phases(cam, device, P: int, iters: int = 2, rounds: int = 5,
                model: str = "tf") -> dict:
    """A whole batched call's wall time split by phase, ms per frame (medians of ``rounds``
    calls, backends kept): each named step of :func:`clfza.solvers._batch._batched` timed by
    a wrapper. On a CPU device the host FFT's and the kernels' work fall in the phases that
    queue them (set_measurement, FourierSolve.solve, run_batch); on a GPU those are queued
    and the phases' own time is the host's."""
    import collections
    import functools

    import clfza.solvers._batch as bm
    from clfza.backends import BackendCache, reuse_backends
    from clfza.backends._opencl import OpenCLBackend
    from clfza.solvers import run_solver_batch
    from clfza.solvers._admm_ops import OpenCLFourierSolve

    acc: dict = collections.defaultdict(float)
    undo = []

    def wrap(owner, name, label):
        f = getattr(owner, name)

        @functools.wraps(f)
        def timed_call(*a, **k):
            t0 = time.perf_counter()
            try:
                return f(*a, **k)
            finally:
                acc[label] += time.perf_counter() - t0

        undo.append((owner, name, f))
        setattr(owner, name, timed_call)

    for name in ("method_model", "frame_starts", "run_batch", "check_finite", "record_group"):
        wrap(bm, name, name)
    wrap(OpenCLBackend, "set_measurement", "set_measurement")
    wrap(OpenCLFourierSolve, "setup", "FourierSolve.setup")
    wrap(OpenCLFourierSolve, "solve", "FourierSolve.solve (x0)")
    wrap(bm.BatchAdmmSolver, "images", "images (read back)")
    ys = np.random.default_rng(3).standard_normal((P,) + tuple(cam.shape))
    kw = dict(backend="opencl", device=device, iters=iters, min_iters=iters, stop="none",
              model=model, tau=0.005)
    rows: dict = collections.defaultdict(list)
    try:
        with reuse_backends(BackendCache(maxsize=2)):
            run_solver_batch(ys, cam, "admm", **kw)
            for _ in range(rounds):
                acc.clear()
                t0 = time.perf_counter()
                out = run_solver_batch(ys, cam, "admm", **kw)
                wall = time.perf_counter() - t0
                solve = out[0].info.stats["batch"]["solve_s"]
                rows["call"].append(wall)
                rows["call - solve"].append(wall - solve)
                for k, v in acc.items():
                    rows[k].append(v)
    finally:
        for owner, name, f in undo:
            setattr(owner, name, f)
    return {k: statistics.median(v) / P * 1e3 for k, v in rows.items()}


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--device", default=None)
    p.add_argument("--n", type=int, nargs="+", default=[2048])
    p.add_argument("--frames", type=int, default=16)
    p.add_argument("--reps", type=int, default=20)
    p.add_argument("--local2d", nargs="+", default=["auto"])
    p.add_argument("--loop", action="store_true", help="also time the solver's loop")
    p.add_argument("--host", action="store_true",
                   help="only time the host work of the starts (per frame against the stack)")
    p.add_argument("--call", action="store_true",
                   help="only profile one whole batched call (cProfile, own time)")
    p.add_argument("--phases", action="store_true",
                   help="only split whole batched calls (2 iterations) by phase, ms/frame")
    p.add_argument("--model", default="tf", help="the calls' model (--phases)")
    p.add_argument("--host-phases", action="store_true",
                   help="only time set_measurement, frame_starts and check_finite alone, "
                        "ms/frame (median and minimum of --reps)")
    a = p.parse_args(argv)
    for n in a.n:
        cam = camera(n)
        if a.call:
            call_profile(cam, a.device, a.frames)
            continue
        if a.host_phases:
            r = host_phases(cam, a.device, a.frames, a.reps)
            print(f"{n}^2, {a.frames} frames, host phases alone, ms/frame:")
            for k, v in r.items():
                print(f"  {k:32s} {v:9.3f}")
            sys.stdout.flush()
            continue
        if a.phases:
            r = call_phases(cam, a.device, a.frames, model=a.model)
            print(f"{n}^2, {a.frames} frames, whole call by phase, ms/frame (medians):")
            for k, v in r.items():
                print(f"  {k:32s} {v:9.3f}")
            sys.stdout.flush()
            continue
        if a.host:
            r = host_starts(cam, a.frames)
            print(f"{n}^2, {a.frames} frames, host starts ms/frame:",
                  {k: round(v, 3) for k, v in r.items()}, flush=True)
            continue
        if a.loop:
            for P in (1, a.frames):
                loop(cam, a.device, P, 5)
                print(f"{n}^2 loop, {P} frame(s):", {k: round(v, 4) for k, v in
                                                   loop(cam, a.device, P).items()}, flush=True)
        for lw in a.local2d:
            row = {}
            for P in (1, a.frames):
                B = get_backend("opencl", cam, device=a.device, frames=P)
                B.apply_tuning({**B.tune, "local2d": lw})
                fns = ops(B, P)
                nbytes = fns.pop("_bytes")
                row[P] = {k: timed(B.rt, f, a.reps) * 1e3 / P for k, f in fns.items()}
                row[P]["copy GB/s"] = 2 * nbytes / (row[P]["copy (bandwidth probe)"] * P
                                                    * 1e-3) / 1e9
            print(f"{n}^2, local2d {lw}: ms per frame, 1 frame | {a.frames} frames batched")
            for k in row[1]:
                print(f"  {k:24s} {row[1][k]:9.4f} | {row[a.frames][k]:9.4f}")
            sys.stdout.flush()
    return 0


if __name__ == "__main__":
    sys.exit(main())
