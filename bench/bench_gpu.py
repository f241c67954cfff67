"""Issue 13, item 5: the solvers and the device FFT on a GPU, with the vendor's FFT beside it.

Usage (on a machine with a GPU; ``tools/device_gpu_run.sh`` runs it on a lent one)::

    python bench/bench_gpu.py [--device P:D] [--sizes 2048] [--rounds 3] [--short 20]
                              [--long 120] [--psnr-iters 200]

Per size, on one OpenCL device (default: the first usable GPU; without one, the default
device, labelled a smoke run):

* **FFT pair**: clfza's device FFT (``fft="device"``, the OpenCL kernels the solvers use on
  GPUs), a real forward and inverse 2-D transform in float32 as the solvers run it (the inverse
  in its input's memory), median of ``--fft-reps`` pairs after a warm-up, each waited for. Next
  to it, in the same run, the vendor's FFT where one is importable: cuFFT through CuPy
  (``cupy.fft.rfft2``/``irfft2`` with CuPy's plan cache, synchronised on the stream).
  Target: clfza's pair at least 50 % of the vendor's speed (vendor ms / clfza ms >= 0.5).
* **Solvers**: TwIST paper mode, FISTA (non-negative) and ADMM on the ``bench_solvers`` camera
  (the paper's Fig. 7 simulation scaled to the grid) with the stopping rule off: steady state
  ``(T_long - T_short) / (long - short)`` and the ``--long`` run's mean, medians over rounds
  interleaved short/long (as ``bench_xlimit``). Target: TwIST paper mode <= 1 ms/iteration at
  2048^2.
* **Where an iteration's time goes**: per solver, kernel launches, waits for the queue and
  blocking reads to the host per iteration (counted over a short and a long solve: on a GPU an
  iteration is launches and round trips long before it is memory traffic).
* **Joint colour**: TwIST paper mode on an RGB scene (C = 3, the device FFT plane by plane),
  steady state as above.
* **ADMM time to PSNR**: one ``--psnr-iters`` ADMM solve with the ground truth checked at about
  24 iterations spaced geometrically (each check costs an SSIM on the host: at every iteration
  that was 159 s of a 2048^2 run): the time (checkpoint overhead removed) at the first check
  reaching TwIST paper mode's PSNR after the same number of iterations, and ADMM's own final
  PSNR minus 0.1 dB.

Writes ``bench/results/gpu_<device>.json``, ``.md`` and ``.png`` (``--out`` another folder).
"""

from __future__ import annotations

import argparse
import contextlib
import re
import statistics
import sys
import time
import warnings
from pathlib import Path

import numpy as np

import clfza

sys.path.insert(0, str(Path(__file__).resolve().parent))
from bench_solvers import camera  # noqa: E402

from clfza.benchmarks._machine import machine_record  # noqa: E402
from clfza.benchmarks._report import write_result_files  # noqa: E402
from clfza.reconstruction._device_choice import usable_devices  # noqa: E402

RESULTS = Path(__file__).resolve().parent / "results"
SOLVERS = (("twist-paper", "twist", {"mode": "paper"}),
           ("fista-nonneg", "fista", {"nonneg": True}), ("admm", "admm", {}))
TWIST_TARGET_MS = 1.0  # at 2048^2
FFT_TARGET = 0.5  # vendor ms / clfza ms


def pick_device(requested: str | None) -> tuple[str, bool]:
    """``(device, is_gpu)``: the requested device, else the first usable GPU, else the
    default device (a smoke run)."""
    from clfza.cl import get_runtime

    if requested:
        return requested, not get_runtime(requested).is_cpu
    devices = usable_devices()
    gpus = [d for d in devices if not get_runtime(d).is_cpu]
    if gpus:
        return gpus[0], True
    return get_runtime().info.index, False


def clfza_fft_ms(device: str, n: int, reps: int) -> dict:
    """clfza's device FFT pair at n x n: median ms of ``reps`` waited-for pairs."""
    from clfza.backends import get_backend

    B = get_backend("opencl", camera(n), device=device, fft="device")
    x = B.from_host(np.random.default_rng(0).standard_normal((1, n, n)))
    y = B.empty()
    for _ in range(3):
        B.fft.rfft2(x, B.X)
        B.fft.irfft2(B.X, y, overwrite_x=True)
    B.finish()
    ts = []
    for _ in range(reps):
        t = time.perf_counter()
        B.fft.rfft2(x, B.X)
        B.fft.irfft2(B.X, y, overwrite_x=True)
        B.finish()
        ts.append(time.perf_counter() - t)
    err = float(np.max(np.abs(B.to_host(y) - B.to_host(x))) / np.max(np.abs(B.to_host(x))))
    return {"engine": type(B.fft).__name__, "pair_ms": statistics.median(ts) * 1e3,
            "roundtrip_max_rel_error": err}


def vendor_fft_ms(n: int, reps: int) -> dict | None:
    """cuFFT through CuPy at n x n (float32 rfft2 + irfft2), or None when CuPy or a CUDA
    device is missing."""
    try:
        import cupy as cp

        cp.cuda.runtime.getDeviceCount()
    except Exception as e:  # noqa: BLE001 - any import or driver failure means "no vendor FFT"
        return {"available": False, "why": f"{type(e).__name__}: {e}"[:200]}
    x = cp.asarray(np.random.default_rng(0).standard_normal((n, n)), dtype=cp.float32)
    for _ in range(3):
        cp.fft.irfft2(cp.fft.rfft2(x), s=(n, n))
    cp.cuda.Stream.null.synchronize()
    ts = []
    for _ in range(reps):
        t = time.perf_counter()
        cp.fft.irfft2(cp.fft.rfft2(x), s=(n, n))
        cp.cuda.Stream.null.synchronize()
        ts.append(time.perf_counter() - t)
    props = cp.cuda.runtime.getDeviceProperties(0)
    return {"available": True, "library": f"cuFFT via CuPy {cp.__version__}",
            "cuda_device": props["name"].decode() if isinstance(props["name"], bytes)
            else str(props["name"]), "pair_ms": statistics.median(ts) * 1e3}


FFT_POLICY = "auto"  # --fft: the solvers' FFT (auto = the device FFT on GPUs)


def solve_s(y, cam, method, opts, iters, device, **kw):
    return clfza.reconstruct(y, cam, method, backend="opencl", device=device, iters=iters,
                             min_iters=iters, stop="none", fft=FFT_POLICY, **opts, **kw)


@contextlib.contextmanager
def counting():
    """Count, while active, kernel launches (every pyopencl kernel call goes through
    ``enqueue_nd_range_kernel``), waits for the queue (:meth:`clfza.cl._runtime.Runtime.finish`)
    and blocking copies to host memory (reads of sums and images). Yields the counter."""
    import pyopencl as cl

    from clfza.cl._runtime import Runtime

    counts = {"launches": 0, "finishes": 0, "reads": 0}
    launch, copy, finish = cl._cl.enqueue_nd_range_kernel, cl.enqueue_copy, Runtime.finish

    def counted_launch(*a, **k):
        counts["launches"] += 1
        return launch(*a, **k)

    def counted_copy(queue, dest, src, **k):
        counts["reads"] += isinstance(dest, np.ndarray) and k.get("is_blocking", True)
        return copy(queue, dest, src, **k)

    def counted_finish(self):
        counts["finishes"] += 1
        return finish(self)

    cl._cl.enqueue_nd_range_kernel, cl.enqueue_copy = counted_launch, counted_copy
    Runtime.finish = counted_finish
    try:
        yield counts
    finally:
        cl._cl.enqueue_nd_range_kernel, cl.enqueue_copy = launch, copy
        Runtime.finish = finish


def steady_rows(y, cam, method, opts, device, rounds, short, long, **kw) -> dict:
    """Steady-state and run ms per iteration (interleaved short and long solves, medians),
    then launches, waits and blocking reads per iteration from one counted pair."""
    solve_s(y, cam, method, opts, 3, device, **kw)  # compile, tune, warm up
    rows = {"short": [], "long": []}
    for r in range(rounds):
        for k in (("short", "long") if r % 2 == 0 else ("long", "short")):
            it = short if k == "short" else long
            rows[k].append(solve_s(y, cam, method, opts, it, device, **kw).info.timings["solve"])
    steady = [(tl - ts) / (long - short) for ts, tl in zip(rows["short"], rows["long"],
                                                            strict=True)]
    per = {}
    for it in (short, long):
        with counting() as c:
            solve_s(y, cam, method, opts, it, device, **kw)
        per[it] = c
    out = {"method": method, "steady_ms": statistics.median(steady) * 1e3,
           "run_ms": statistics.median(rows["long"]) / long * 1e3}
    out.update({f"{k}_per_iteration": (per[long][k] - per[short][k]) / (long - short)
                for k in per[long]})
    return out


def solver_rows(m, cam, device, rounds, short, long) -> dict:
    out = {}
    for label, method, opts in SOLVERS:
        out[label] = r = steady_rows(m.y, cam, method, opts, device, rounds, short, long)
        print(f"  {label:13s} steady {r['steady_ms']:8.3f} ms/iteration, {long}-iteration run "
              f"{r['run_ms']:8.3f}; per iteration {r['launches_per_iteration']:.1f} launches, "
              f"{r['finishes_per_iteration']:.1f} waits, {r['reads_per_iteration']:.1f} reads",
              flush=True)
    return out


def colour_row(cam, device, rounds, short, long) -> dict:
    """Joint-colour TwIST paper mode (C = 3) on an RGB scene, as :func:`steady_rows`."""
    from skimage import data

    m = clfza.simulate(data.astronaut() / 255.0, cam, object_width=200.0)
    r = steady_rows(m.y, cam, "twist", {"mode": "paper"}, device, rounds, short, long,
                    colour="joint")
    print(f"  twist-paper joint colour steady {r['steady_ms']:8.3f} ms/iteration", flush=True)
    return r


def admm_time_to_psnr(m, cam, device, iters: int) -> dict:
    from clfza.metrics import compare

    twist = solve_s(m.y, cam, "twist", {"mode": "paper"}, iters, device)
    target_twist = compare(twist.image, m.truth)["psnr"]
    curve = []
    checks = sorted({int(k) for k in np.geomspace(1, iters, 24).round()})
    r = solve_s(m.y, cam, "admm", {}, iters, device, truth=m.truth, checkpoints=checks,
                callback=lambda rec: curve.append((rec["time"], rec["psnr"])))
    final = compare(r.image, m.truth)["psnr"]

    def first(target):
        return next((t for t, p in curve if p >= target), None)

    return {"iterations": iters, "checked_iterations": checks,
            "twist_paper_psnr": target_twist, "admm_final_psnr": final,
            "admm_time_to_twist_psnr_s": first(target_twist),
            "admm_time_to_final_minus_0.1dB_s": first(final - 0.1),
            "admm_solve_s": r.info.timings["solve"],
            "checkpoint_overhead_s": r.info.timings["checkpoint_overhead"]}


def markdown(res: dict) -> str:
    lines = [f"# Solvers and FFT on {res['device_name']} ({res['machine']['date']})", "",
             f"OpenCL: {res['platform']}, driver {res['driver']}; "
             f"{'GPU' if res['is_gpu'] else 'no GPU here: a smoke run on a CPU device'}. "
             f"`bench/bench_gpu.py --rounds {res['rounds']} --short {res['short']} --long "
             f"{res['long']}`, revision {res['revision']}; device FFT columns "
             f"`{res.get('fft_columns')}`, fold pairs {res.get('fold_pairs')}.", ""]
    for n, r in res["sizes"].items():
        f, v = r["fft"], r["vendor_fft"]
        ratio = r.get("fft_vendor_over_clfza")
        lines += [f"## {n}^2", "", "| FFT pair (float32 rfft2 + irfft2) | ms |", "|---|---|",
                  f"| clfza {f['engine']} (round trip within "
                  f"{f['roundtrip_max_rel_error']:.1e} of the input) | {f['pair_ms']:.3f} |"]
        if v.get("available"):
            lines.append(f"| {v['library']} on {v['cuda_device']} | {v['pair_ms']:.3f} |")
            lines += ["", f"clfza at {ratio:.0%} of the vendor FFT's speed (target >= "
                      f"{FFT_TARGET:.0%}: {'met' if ratio >= FFT_TARGET else 'not met'})."]
        else:
            lines += ["", f"No vendor FFT here ({v['why']})."]
        lines += ["", f"Solvers with FFT policy `{res['solver_fft']}` (per iteration: kernel "
                  "launches, waits for the queue, blocking reads to the host):", "",
                  "| solver | steady ms/iteration | run ms/iteration | launches | waits | reads |",
                  "|---|---|---|---|---|---|"]
        rows = list(r["solvers"].items())
        if "colour" in r:
            rows.append(("twist-paper, joint colour (C = 3)", r["colour"]))
        for label, s in rows:
            lines.append(f"| {label} | {s['steady_ms']:.3f} | {s['run_ms']:.3f} | "
                         f"{s['launches_per_iteration']:.1f} | {s['finishes_per_iteration']:.1f}"
                         f" | {s['reads_per_iteration']:.1f} |")
        if n == "2048":
            ms = r["solvers"]["twist-paper"]["steady_ms"]
            lines += ["", f"TwIST paper mode target <= {TWIST_TARGET_MS} ms/iteration: "
                      f"{'met' if ms <= TWIST_TARGET_MS else 'not met'} ({ms:.3f} ms)."]
        a = r.get("admm_psnr")
        if a is None:
            lines.append("")
            continue
        lines += ["", f"ADMM time to PSNR ({a['iterations']} iterations, checked at "
                  f"{len(a.get('checked_iterations', []))} of them): TwIST paper mode's "
                  f"{a['twist_paper_psnr']:.2f} dB reached after "
                  f"{_s(a['admm_time_to_twist_psnr_s'])}, its own final {a['admm_final_psnr']:.2f}"
                  f" dB - 0.1 dB after {_s(a['admm_time_to_final_minus_0.1dB_s'])} (solve "
                  f"{a['admm_solve_s']:.2f} s, checkpoint overhead removed).", ""]
    return "\n".join(lines) + "\n"


def _s(t) -> str:
    return "never" if t is None else f"{t:.3f} s"


def plot(res: dict, path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    sizes = list(res["sizes"])
    fig, ax = plt.subplots(figsize=(7, 4))
    labels = [s for s, _, _ in SOLVERS] + ["FFT pair (clfza)", "FFT pair (vendor)"]
    width = 0.8 / len(sizes)
    for j, n in enumerate(sizes):
        r = res["sizes"][n]
        v = r["vendor_fft"]
        vals = [r["solvers"][s]["steady_ms"] for s, _, _ in SOLVERS] + [
            r["fft"]["pair_ms"], v["pair_ms"] if v.get("available") else 0.0]
        ax.bar(np.arange(len(labels)) + j * width, vals, width, label=f"{n}^2")
    ax.set_xticks(np.arange(len(labels)) + 0.4 - width / 2)
    ax.set_xticklabels(labels, rotation=20, fontsize=8)
    ax.set_ylabel("ms (steady state per iteration; per FFT pair)")
    ax.set_title(res["device_name"])
    ax.legend()
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--device", default=None, help="OpenCL device P:D (default: first GPU)")
    p.add_argument("--sizes", type=int, nargs="+", default=[2048])
    p.add_argument("--rounds", type=int, default=3)
    p.add_argument("--short", type=int, default=20)
    p.add_argument("--long", type=int, default=120)
    p.add_argument("--fft-reps", type=int, default=50)
    p.add_argument("--fft", choices=("auto", "device", "host"), default="auto",
                   help="the solvers' FFT (auto: the device FFT on GPUs, host scipy on CPUs)")
    p.add_argument("--psnr-iters", type=int, default=200)
    p.add_argument("--fft-cols", choices=("codelets", "passes"), default=None,
                   help="the device FFT's column passes on GPUs (clfza.fft._stockham."
                        "LINES_COLUMNS; default: as the package sets it)")
    p.add_argument("--fold-pairs", choices=("on", "off"), default=None,
                   help="two reducers' deferred folds per launch (clfza.backends._opencl."
                        "PAIR_FOLDS; default: as the package sets it)")
    p.add_argument("--tag", default="", help="appended to the file names")
    p.add_argument("--out", default=str(RESULTS))
    a = p.parse_args(argv)
    from clfza.backends import _opencl
    from clfza.fft import _stockham

    if a.fft_cols:
        _stockham.LINES_COLUMNS = a.fft_cols
    if a.fold_pairs:
        _opencl.PAIR_FOLDS = a.fold_pairs == "on"
    if not 0 < a.short < a.long:
        p.error("--short must be positive and below --long")
    if min(a.sizes) < 16 or a.rounds < 1 or a.fft_reps < 1 or a.psnr_iters < 0:
        p.error("sizes >= 16, rounds and fft-reps >= 1, psnr-iters >= 0 (0: no time to PSNR)")
    warnings.simplefilter("ignore")
    global FFT_POLICY
    FFT_POLICY = a.fft
    from bench_tau import revision
    from skimage import data

    from clfza.cl import get_runtime

    device, is_gpu = pick_device(a.device)
    info = get_runtime(device).info
    print(f"[{device}] {info.name} ({info.platform} {info.driver})"
          f"{'' if is_gpu else ': no GPU, smoke run'}", flush=True)
    res = {"machine": machine_record(device), "revision": revision(), "device": device,
           "device_name": info.name, "platform": info.platform, "driver": info.driver,
           "is_gpu": is_gpu, "fft_columns": _stockham.LINES_COLUMNS,
           "fold_pairs": _opencl.PAIR_FOLDS,
           "solver_fft": a.fft, "rounds": a.rounds, "short": a.short,
           "long": a.long, "sizes": {}}
    for n in a.sizes:
        cam = camera(n)
        m = clfza.simulate(data.camera(), cam, object_width=200.0)
        fft = clfza_fft_ms(device, n, a.fft_reps)
        vendor = vendor_fft_ms(n, a.fft_reps)
        rec = {"fft": fft, "vendor_fft": vendor}
        if vendor.get("available"):
            rec["fft_vendor_over_clfza"] = vendor["pair_ms"] / fft["pair_ms"]
        print(f"  {n}^2 FFT pair: clfza {fft['pair_ms']:.3f} ms, vendor "
              f"{vendor['pair_ms'] if vendor.get('available') else 'n/a'}", flush=True)
        rec["solvers"] = solver_rows(m, cam, device, a.rounds, a.short, a.long)
        rec["colour"] = colour_row(cam, device, a.rounds, a.short, a.long)
        if a.psnr_iters:
            rec["admm_psnr"] = admm_time_to_psnr(m, cam, device, a.psnr_iters)
        res["sizes"][str(n)] = rec
    slug = re.sub(r"[^a-z0-9]+", "-", info.name.lower()).strip("-")[:40] or "device"
    paths = write_result_files(Path(a.out) / f"gpu_{slug}{a.tag}", res, markdown(res), plot)
    print(markdown(res))
    print("wrote", *paths)
    return 0


if __name__ == "__main__":
    sys.exit(main())
