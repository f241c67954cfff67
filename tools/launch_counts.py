"""Kernel launches, waits and blocking reads per iteration of each solver (issue 37), on any
OpenCL device, optionally along the GPU code path on a CPU device.

    python tools/launch_counts.py [--device P:D] [--n 512] [--gpu-path] [--fft device]
                                  [--methods admm twist-paper fista-nonneg] [--frames 1 8]
                                  [--stop none|objective|step]

Counts as ``bench/bench_gpu.py`` does (``counting``: the difference between a 10- and a
30-iteration solve, divided by 20; reads are blocking copies to the host, started reads
waited for later are not), per solver and batch size (``--frames``: batched ADMM through
:func:`clfza.solvers.run_solver_batch`). ``--gpu-path`` makes the device report itself as a
GPU (``Runtime.is_cpu`` and ``zero_copy`` False, set before anything is built), so a CPU
device runs the kernels, work-group shapes and device-FFT mapping a GPU gets: the launch
counts of the GPU path without a GPU. Also prints ms per iteration from the same runs
(steady state over the 20 extra iterations; meaningless with ``--gpu-path``).
"""

from __future__ import annotations

import argparse
import sys
import warnings
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "bench"))

SOLVERS = {"admm": ("admm", {"tau": 0.005}), "twist-paper": ("twist", {"mode": "paper"}),
           "fista-nonneg": ("fista", {"nonneg": True})}


def pretend_gpu() -> None:
    """Every runtime built from now on reports a GPU (the GPU code paths on a CPU device)."""
    from clfza.cl import _runtime

    init = _runtime.Runtime.__init__

    def gpu_init(self, *a, **k):
        init(self, *a, **k)
        self.is_cpu = False
        self.zero_copy = False  # buffers of their own: reads are copies, as on a GPU

    _runtime.Runtime.__init__ = gpu_init


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--device", default=None)
    p.add_argument("--n", type=int, nargs="+", default=[512])
    p.add_argument("--methods", nargs="+", default=list(SOLVERS), choices=list(SOLVERS))
    p.add_argument("--frames", type=int, nargs="+", default=[1])
    p.add_argument("--fft", default="auto", choices=("auto", "device", "host"))
    p.add_argument("--gpu-path", action="store_true")
    p.add_argument("--stop", default="none", choices=("none", "objective", "step"),
                   help="the stopping rule (with a tolerance it never meets: its reads "
                        "are counted, the iterations all run)")
    a = p.parse_args(argv)
    warnings.simplefilter("ignore")
    if a.gpu_path:
        pretend_gpu()
    from bench_gpu import counting
    from bench_solvers import camera

    import clfza
    from clfza.cl import get_runtime
    from clfza.solvers import run_solver_batch

    rt = get_runtime(a.device)
    print(f"{rt.info.name} ({rt.info.platform}); code path: "
          f"{'CPU' if rt.is_cpu else 'GPU'}; fft={a.fft}", flush=True)
    rng = np.random.default_rng(0)
    for n in a.n:
        cam = camera(n)
        for label in a.methods:
            method, opts = SOLVERS[label]
            for F in a.frames:
                if F > 1 and method != "admm":
                    continue
                ys = rng.standard_normal((F, n, n))
                kw = dict(backend="opencl", device=a.device, stop=a.stop, model="tf",
                          fft=a.fft, **opts)
                if a.stop != "none":
                    kw["tol"] = 1e-30

                def run(it, ys=ys, method=method, kw=kw, cam=cam):
                    if len(ys) == 1:
                        r = clfza.reconstruct(ys[0], cam, method, iters=it, min_iters=it, **kw)
                        return r.info.timings["solve"]
                    out = run_solver_batch(ys, cam, method, iters=it, min_iters=it, **kw)
                    return out[0].info.stats["batch"]["solve_s"]

                run(3)
                per, ts = {}, {}
                for it in (10, 30):
                    with counting() as c:
                        ts[it] = run(it)
                    per[it] = dict(c)
                row = {k: (per[30][k] - per[10][k]) / 20 for k in per[30]}
                ms = (ts[30] - ts[10]) / 20 * 1e3
                print(f"  {n}^2 {label:13s} frames {F:3d}: {row['launches']:5.1f} launches, "
                      f"{row['finishes']:4.1f} waits, {row['reads']:4.1f} reads per "
                      f"iteration; {ms:8.3f} ms/iteration", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
