"""Per-kernel and per-iteration times of two (or more) kernel source trees, in the same run.

Usage::

    python bench/bench_kernels.py [--base REV] [--sizes 512 2048] [--rounds 7] [--solvers]
                                  [--out FILE.json]

Variants: ``base`` is ``kernels/*.cl`` at git revision REV (default HEAD), ``work`` the
working tree's ``kernels/``. Each variant gets its own OpenCL context (programs are cached per
context) with its sources read through ``CLFZA_KERNEL_DIR``. Every hot operation of
``clfza.cl.check.hot_ops`` (one kernel, or a few, plus the sum16 fold where it reduces) is
launched ``reps`` times and timed to the queue's end; rounds alternate between the variants
so that drift on a shared machine hits both alike; medians over rounds. ``--solvers`` adds
TwIST paper mode, FISTA and ADMM ms/iteration (median over rounds of 10-iteration solves
after a warm-up) per variant on the ``bench_solvers`` camera.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import statistics
import subprocess
import sys
import tempfile
import time
import warnings
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT / "bench"))


def export_kernels(rev: str, dest: Path) -> None:
    names = subprocess.run(["git", "ls-tree", "--name-only", rev, "kernels/"], cwd=ROOT,
                           check=True, capture_output=True, text=True).stdout.split()
    for n in names:
        if n.endswith(".cl"):
            src = subprocess.run(["git", "show", f"{rev}:{n}"], cwd=ROOT, check=True,
                                 capture_output=True, text=True).stdout
            (dest / Path(n).name).write_text(src)


def make_backend(n: int, kdir: str):
    from bench_solvers import camera

    from clfza.backends._opencl import OpenCLBackend
    from clfza.cl._runtime import Runtime

    os.environ["CLFZA_KERNEL_DIR"] = kdir
    rt = Runtime(None)
    return OpenCLBackend(camera(n), 1, runtime=rt)


def time_op(B, fn, reps: int) -> float:
    t = time.perf_counter()
    for _ in range(reps):
        fn()
    B.finish()
    return (time.perf_counter() - t) / reps


def solver_ms(kdir: str, saved: dict, m, cam, method, opts, iters: int) -> float:
    import clfza
    from clfza.cl import _runtime as runtime

    os.environ["CLFZA_KERNEL_DIR"] = kdir
    runtime._RUNTIMES.clear()
    runtime._RUNTIMES.update(saved.setdefault(kdir, {}))
    r = clfza.reconstruct(m.y, cam, method, backend="opencl", iters=iters, min_iters=iters,
                          stop="none", **opts)
    saved[kdir] = dict(runtime._RUNTIMES)
    return r.info.timings["solve"] / r.info.iterations * 1e3


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--base", default="HEAD", help="git revision of the base kernels")
    ap.add_argument("--sizes", type=int, nargs="+", default=[512, 2048])
    ap.add_argument("--rounds", type=int, default=7)
    ap.add_argument("--solvers", action="store_true")
    ap.add_argument("--no-kernels", action="store_true", help="only the solvers (--solvers)")
    ap.add_argument("--only", nargs="*", help="operation names to time (default: all)")
    ap.add_argument("--out")
    args = ap.parse_args()
    warnings.simplefilter("ignore")
    from clfza.cl.check import hot_ops

    tmp = tempfile.TemporaryDirectory(prefix="clfza-kernels-")
    base = Path(tmp.name)
    export_kernels(args.base, base)
    variants = {"base": str(base), "work": str(ROOT / "kernels")}
    res: dict = {"kernels": {}, "solvers": {}}
    dev = None
    for n in ([] if args.no_kernels else args.sizes):
        reps = max(2, int(round(20 * (512 / n) ** 2)))
        Bs = {v: make_backend(n, d) for v, d in variants.items()}
        ops = {v: dict(hot_ops(B)) for v, B in Bs.items()}
        dev = Bs["work"].rt.info
        names = [k for k in ops["work"] if not args.only or k in args.only]
        ts = {(v, k): [] for v in variants for k in names}
        for v in variants:  # warm-up: compile, first touch
            for k in names:
                time_op(Bs[v], ops[v][k], 1)
        for r in range(args.rounds):
            order = list(variants) if r % 2 == 0 else list(variants)[::-1]
            for k in names:
                for v in order:
                    ts[(v, k)].append(time_op(Bs[v], ops[v][k], reps))
        print(f"\n{n}^2  ({dev.name}, {dev.platform}; median of {args.rounds} rounds x "
              f"{reps} launches, ms)")
        print(f"{'operation':28s} {'base':>9s} {'work':>9s} {'speed-up':>9s}")
        for k in names:
            b = statistics.median(ts[("base", k)]) * 1e3
            w = statistics.median(ts[("work", k)]) * 1e3
            res["kernels"].setdefault(str(n), {})[k] = {"base_ms": b, "work_ms": w}
            print(f"{k:28s} {b:9.3f} {w:9.3f} {b / w:8.2f}x", flush=True)
        del Bs, ops
    if args.solvers:
        from bench_solvers import ARRAYS_TOUCHED, camera, machine_limit
        from skimage import data

        import clfza

        saved: dict = {}
        for n in args.sizes:
            cam = camera(n)
            m = clfza.simulate(data.camera(), cam, object_width=200.0)
            print(f"\n{n}^2 solvers (ms/iteration, median of {args.rounds} solves)")
            for label, method, opts in (("twist-paper", "twist", {"mode": "paper"}),
                                        ("fista-nonneg", "fista", {"nonneg": True}),
                                        ("admm", "admm", {})):
                t = {v: [] for v in variants}
                for d in variants.values():  # warm-up and compile
                    solver_ms(d, saved, m, cam, method, opts, 3)
                for r in range(args.rounds):
                    order = list(variants) if r % 2 == 0 else list(variants)[::-1]
                    for v in order:
                        t[v].append(solver_ms(variants[v], saved, m, cam, method, opts, 10))
                b, w = statistics.median(t["base"]), statistics.median(t["work"])
                # the machine limit (one FFT pair + the arrays the iteration must touch at
                # triad bandwidth) right after the row, best of 3 probes: a loaded moment
                # only ever makes a probe slower
                lims = [machine_limit(n) for _ in range(3)]
                fft = min(x["fft_pair_ms"] for x in lims)
                bw = max(x["triad_GBps"] for x in lims) * 1e9
                lim = fft + ARRAYS_TOUCHED[method] * n * n * 4 / bw * 1e3
                res["solvers"].setdefault(str(n), {})[label] = {
                    "base_ms": b, "work_ms": w, "limit_ms": lim, "fft_pair_ms": fft,
                    "triad_GBps": bw / 1e9, "base_x_limit": b / lim, "work_x_limit": w / lim}
                print(f"{label:16s} base {b:8.2f}  work {w:8.2f}  {b / w:5.2f}x   limit "
                      f"{lim:7.2f} ms: base x{b / lim:.2f}, work x{w / lim:.2f}", flush=True)
    os.environ.pop("CLFZA_KERNEL_DIR", None)
    if args.out:
        import pyopencl

        from clfza.cl import get_runtime

        rti = get_runtime().info
        res["info"] = {
            "date": time.strftime("%Y-%m-%d %H:%M:%S"), "base": args.base,
            "device": rti.name, "platform": rti.platform, "driver": rti.driver,
            "machine": platform.processor() or platform.machine(), "host": platform.node(),
            "cpus": os.cpu_count(), "load_average": os.getloadavg(),
            "pyopencl": pyopencl.VERSION_TEXT, "numpy": np.__version__,
            "rounds": args.rounds,
        }
        Path(args.out).parent.mkdir(parents=True, exist_ok=True)
        Path(args.out).write_text(json.dumps(res, indent=2))
        print("wrote", args.out)


if __name__ == "__main__":
    main()
