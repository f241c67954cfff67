"""Issue 37: frames per second against the batch size (many frames per launch).

Usage::

    python bench/bench_batch.py [--device P:D] [--sizes 512 2048] [--batches 1 2 4 8]
                                [--iters 50] [--rounds 3] [--methods admm fista twist]
                                [--out bench/results]

On one OpenCL device (default: the first usable GPU, else the default device), per size, the
``bench_solvers`` camera (the paper's Fig. 7 simulation scaled to the grid) and distinct noisy
frames of scikit-image's camera scene (Gaussian noise of variance 0.01, the paper's), each batch
size solved as one batch (:func:`clfza.solvers.run_solver_batch`) with a fixed number of
iterations (``--iters``, the stopping rule off), backends reused between calls as a stream of
frames reuses them (:func:`clfza.backends.reuse_backends`). Batch size 1 is the one-frame
path (:func:`clfza.solvers.run_solver`). Batch sizes are interleaved round by round (the
machine is shared and noisy) and every figure is a median over ``--rounds``.

Per row:

* **frames/s (solve)**: frames over the batch's solve time (the iterations);
* **frames/s (call)**: frames over the whole call (noise estimates, Wiener starts, the
  measurement's spectra, the images back to the host), what a stream of frames sees;
* **ms/iteration** of the whole batch, and per frame;
* **host ms/frame**: the call's time outside the iterations, per frame (call minus solve);
* **launches, waits and blocking reads per iteration**, counted over a short and a long run
  (``bench_gpu.counting``);
* the speed-up over batch size 1, from the same rounds.

``--methods`` (default ``admm twist``): the batched methods measured (``admm``, ``fista``:
MFISTA-TV with its default options, tau as ADMM's; ``twist``: TwIST paper mode, tau as ADMM's,
which runs ``--iters`` + 1 iterations as the reference counts them, the same at every batch
size; each method's batch sizes interleaved in the same rounds).

Writes ``bench/results/batch_<device>.json``, ``.md`` and ``.png`` (frames/s against the batch
size, per size and solver).
"""

from __future__ import annotations

import argparse
import re
import statistics
import sys
import time
import warnings
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from bench_gpu import counting, pick_device  # noqa: E402
from bench_solvers import camera  # noqa: E402

import clfza  # noqa: E402
from clfza.backends import BackendCache, reuse_backends  # noqa: E402
from clfza.benchmarks._machine import machine_record  # noqa: E402
from clfza.benchmarks._report import write_result_files  # noqa: E402
from clfza.solvers import run_solver, run_solver_batch  # noqa: E402

RESULTS = Path(__file__).resolve().parent / "results"
NOISE_VAR = 0.01
TAU = 0.005  # ADMM's default tau


DISTINCT = 8  # frames simulated (with distinct noise); larger batches repeat them


def frames_for(cam, k: int) -> np.ndarray:
    """``k`` noisy frames of the camera scene (``DISTINCT`` noise draws, repeated), DC
    removed."""
    from skimage import data

    out = []
    for i in range(min(k, DISTINCT)):
        y = clfza.simulate(data.camera(), cam, object_width=200.0,  # as bench_gpu
                           noise=clfza.Noise(gaussian_var=NOISE_VAR, seed=i)).y
        out.append(y - y.mean())
    return np.stack([out[i % len(out)] for i in range(k)])


def solve(ys, cam, method, iters: int, device: str, **opts):
    """One call as a stream makes it: returns (wall seconds, solve seconds)."""
    kw = dict(backend="opencl", device=device, iters=iters, min_iters=iters, stop="none",
              model="tf", **opts)
    t0 = time.perf_counter()
    if len(ys) == 1:
        rec = run_solver(ys[0], cam, method, **kw)
        wall = time.perf_counter() - t0
        return wall, rec.info.timings["solve"]
    out = run_solver_batch(ys, cam, method, **kw)
    wall = time.perf_counter() - t0
    batch = out[0].info.stats["batch"]
    if batch["frames"] != len(ys):
        raise RuntimeError(f"{method} did not batch: {batch}")
    return wall, batch["solve_s"]


def counts(ys, cam, method, device, short: int, long: int, **opts) -> dict:
    per = {}
    for it in (short, long):
        with counting() as c:
            solve(ys, cam, method, it, device, **opts)
        per[it] = dict(c)
    return {k: (per[long][k] - per[short][k]) / (long - short) for k in per[long]}


BATCHED = ("admm", "fista", "twist")  # --methods measured against the batch size


def measure(cam, device: str, batches: list[int], iters: int, rounds: int,
            methods: tuple = ("admm", "twist")) -> dict:
    ys_all = frames_for(cam, max(batches))
    if len(batches) < 2:
        raise SystemExit("at least two batch sizes fit --max-mpx at this size")
    batched = [m for m in BATCHED if m in methods]
    cache = BackendCache(maxsize=len(batches) + 2)
    rows = {(m, b): {"wall": [], "solve": []} for m in batched for b in batches}
    res = {}
    with reuse_backends(cache):
        for m in batched:
            for b in batches:  # compile, tune, warm the cache
                solve(ys_all[:b], cam, m, 3, device, tau=TAU)
        for r in range(rounds):
            for m in batched:
                for b in (batches if r % 2 == 0 else batches[::-1]):
                    wall, sol = solve(ys_all[:b], cam, m, iters, device, tau=TAU)
                    rows[m, b]["wall"].append(wall)
                    rows[m, b]["solve"].append(sol)
        for m in batched:
            res[m] = _rows_of(rows, m, ys_all, cam, device, batches, iters)
    return res


def _rows_of(rows: dict, m: str, ys_all, cam, device: str, batches: list[int], iters: int
             ) -> dict:
    """Method ``m``'s row per batch size from the rounds' times (medians) and counts."""
    out = {}
    for b in batches:
        wall = statistics.median(rows[m, b]["wall"])
        sol = statistics.median(rows[m, b]["solve"])
        c = counts(ys_all[:b], cam, m, device, 10, 30, tau=TAU)
        out[str(b)] = {
            "frames_per_s_solve": b / sol, "frames_per_s_call": b / wall,
            "ms_per_iteration": sol / iters * 1e3,
            "ms_per_iteration_per_frame": sol / iters / b * 1e3,
            # the call's work outside the iterations, per frame (noise estimates, Wiener
            # starts, transfers, records): what batching the host work shrinks
            "host_ms_per_frame": statistics.median(
                (w - s) / b * 1e3 for w, s in zip(rows[m, b]["wall"], rows[m, b]["solve"],
                                                  strict=True)),
            "solve_s": rows[m, b]["solve"], "call_s": rows[m, b]["wall"],
            **{f"{k}_per_iteration": v for k, v in c.items()}}
    one = out[str(batches[0])]
    for b in batches:
        o = out[str(b)]
        o["speedup_solve"] = o["frames_per_s_solve"] / one["frames_per_s_solve"]
        o["speedup_call"] = o["frames_per_s_call"] / one["frames_per_s_call"]
        print(f"  {m}-{iters} batch {b:3d}: {o['frames_per_s_solve']:8.1f} frames/s "
              f"(solve), {o['frames_per_s_call']:8.1f} (call); {o['ms_per_iteration']:.3f} "
              f"ms/iteration; {o['launches_per_iteration']:.1f} launches, "
              f"{o['reads_per_iteration']:.1f} reads per iteration; x"
              f"{o['speedup_solve']:.2f} / x{o['speedup_call']:.2f}; host "
              f"{o['host_ms_per_frame']:.2f} ms/frame", flush=True)
    return out


def markdown(res: dict) -> str:
    lines = [f"# Frames per second against the batch size on {res['device_name']} "
             f"({res['machine'].get('date', '')})", "",
             f"OpenCL: {res['platform']}, driver {res['driver']}; "
             f"{'GPU' if res['is_gpu'] else 'CPU device'}. `bench/bench_batch.py --iters "
             f"{res['iters']} --rounds {res['rounds']}`, revision {res['revision']}.", "",
             f"{' and '.join(m.upper() for m in BATCHED if m in res.get('methods', ['admm']))}"
             f" (tau {TAU}, {res['iters']} iterations, stopping rule off) on the Fig. 7 "
             f"simulation (noise variance {NOISE_VAR}), medians of {res['rounds']} rounds "
             "with the batch sizes interleaved. *solve*: the iterations; *call*: the whole "
             "call (noise estimates, Wiener starts, images back).", ""]
    for n, rec in res["sizes"].items():
        lines += [f"## {n}^2", ""]
        for m in BATCHED:
            if m not in rec:
                continue
            lines += [f"{m.upper()}-{res['iters']}:", "",
                      "| batch | frames/s (solve) | frames/s (call) | ms/iteration (batch) | "
                      "ms/iteration per frame | launches/iteration | reads/iteration | x "
                      "batch 1 (solve / call) | host ms/frame (call - solve) |",
                      "|---|---|---|---|---|---|---|---|---|"]
            for b, o in rec[m].items():
                lines.append(
                    f"| {b} | {o['frames_per_s_solve']:.1f} | {o['frames_per_s_call']:.1f}"
                    f" | {o['ms_per_iteration']:.3f} | {o['ms_per_iteration_per_frame']:.3f}"
                    f" | {o['launches_per_iteration']:.1f} | {o['reads_per_iteration']:.1f}"
                    f" | {o['speedup_solve']:.2f} / {o['speedup_call']:.2f}"
                    f" | {o.get('host_ms_per_frame', float('nan')):.2f} |")
            lines.append("")
        t = rec.get("twist_paper_one_at_a_time")
        if t is not None:
            lines += [f"TwIST paper mode, one frame at a time: {t['frames_per_s_solve']:.1f} "
                      f"frames/s (solve), {t['ms_per_iteration']:.3f} ms/iteration, "
                      f"{t['launches_per_iteration']:.1f} launches and "
                      f"{t['reads_per_iteration']:.1f} blocking reads per iteration.", ""]
    return "\n".join(lines) + "\n"


def plot(res: dict, path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(6.4, 4.2))
    for n, rec in res["sizes"].items():
        for m in BATCHED:
            if m not in rec:
                continue
            bs = [int(b) for b in rec[m]]
            for key, style in (("frames_per_s_solve", "-o"), ("frames_per_s_call", "--s")):
                ax.plot(bs, [rec[m][str(b)][key] for b in bs], style,
                        label=f"{m.upper()}-{res['iters']} {n}^2 ({key.rsplit('_', 1)[1]})")
        if "twist_paper_one_at_a_time" in rec:
            ax.axhline(rec["twist_paper_one_at_a_time"]["frames_per_s_solve"], ls=":", lw=1,
                       color="grey")
    ax.set_xscale("log", base=2)
    ax.set_yscale("log")
    ax.set_xlabel("batch size (frames per launch)")
    ax.set_ylabel("frames/s")
    twist = any("twist_paper_one_at_a_time" in rec for rec in res["sizes"].values())
    ax.set_title(f"{res['device_name']}" + (" (dotted: TwIST paper, one at a time)" if twist
                                            else ""), fontsize=9)
    ax.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--device", default=None, help="OpenCL device P:D (default: first GPU)")
    p.add_argument("--sizes", type=int, nargs="+", default=[512])
    p.add_argument("--batches", type=int, nargs="+", default=None,
                   help="batch sizes (default: 1 2 4 8 on CPU devices, 1 4 16 64 on GPUs)")
    p.add_argument("--iters", type=int, default=50)
    p.add_argument("--rounds", type=int, default=3)
    p.add_argument("--methods", nargs="+", choices=BATCHED,
                   default=["admm", "twist"],
                   help="batched methods (admm, fista, twist: paper mode)")
    p.add_argument("--max-mpx", type=float, default=80.0,
                   help="largest batch in megapixels (larger batch sizes are left out at a "
                        "size: the host simulates and prepares every frame)")
    p.add_argument("--tag", default="", help="appended to the result files' name")
    p.add_argument("--fft-cols", choices=("codelets", "passes"), default=None,
                   help="the device FFT's column passes on GPUs (clfza.fft._stockham."
                        "LINES_COLUMNS; default: as the package sets it)")
    p.add_argument("--out", default=str(RESULTS))
    a = p.parse_args(argv)
    from clfza.fft import _stockham

    if a.fft_cols:
        _stockham.LINES_COLUMNS = a.fft_cols
    if a.iters < 31 or a.rounds < 1 or min(a.sizes) < 16:
        p.error("--iters >= 31 (the launch counts difference 10 and 30), rounds >= 1, "
                "sizes >= 16")
    warnings.simplefilter("ignore")
    from bench_tau import revision

    from clfza.cl import get_runtime

    device, is_gpu = pick_device(a.device)
    info = get_runtime(device).info
    batches = sorted(set(a.batches or ([1, 4, 16, 64] if is_gpu else [1, 2, 4, 8])))
    if batches[0] != 1:
        batches = [1] + batches
    print(f"[{device}] {info.name} ({info.platform} {info.driver})", flush=True)
    res = {"machine": machine_record(device), "revision": revision(), "device": device,
           "device_name": info.name, "platform": info.platform, "driver": info.driver,
           "is_gpu": is_gpu, "fft_columns": _stockham.LINES_COLUMNS,
           "iters": a.iters, "rounds": a.rounds, "batches": batches, "methods": a.methods,
           "sizes": {}}
    for n in a.sizes:
        print(f"{n}^2", flush=True)
        fits = [b for b in batches if b * n * n <= a.max_mpx * 1e6 or b == 1]
        res["sizes"][str(n)] = measure(camera(n), device, fits, a.iters, a.rounds,
                                       tuple(a.methods))
    # the implementation in the name: both PoCLs name the CPU alike
    impl = "gpu" if is_gpu else ("intel" if "intel" in info.platform.lower() else
                                 "pocl" + re.sub(r"[^0-9]", "", info.driver)[:2])
    slug = (re.sub(r"[^a-z0-9]+", "-", info.name.lower()).strip("-")[:40] or "device") \
        + f"_{impl}"
    stem = Path(a.out) / f"batch_{slug}{('_' + a.tag) if a.tag else ''}"
    paths = write_result_files(stem, res, markdown(res), plot)
    print(markdown(res))
    print("wrote", *paths)
    return 0


if __name__ == "__main__":
    sys.exit(main())
