"""Per-kernel bandwidth of the solvers' hot kernels against the triad, per OpenCL implementation
(issue 13: per-kernel bandwidth ratios per implementation).

Usage::

    .venv/bin/python bench/bench_kernel_bandwidth.py [--devices 1:0 0:0 2:0]
                                                     [--sizes 512 2048] [--rounds 5]

Per device (default: every OpenCL device that compiles kernels) and size, on the backend a
solve would use there (tuned kernel variants, float32, one channel): each kernel is launched
``reps`` times back to back on the same arrays and timed to the queue's end, rounds
interleaving the kernels (a shared machine's drift hits all alike), medians over rounds. The
bytes a launch must move come from a stated model (:data:`KERNELS`: arrays read plus arrays
written, one array = N^2 float32 values; a half spectrum of complex64 values counts as one
array, the real transfer function or ADMM's inverse as half of one; neighbours' re-reads and
the partial sums are not counted). Reported per kernel: ms per launch, the effective bandwidth
(model bytes / time) and the ratio to the triad, ``time / (model bytes / triad bandwidth)``,
with the triad ``a = b + s c`` timed in the same rounds: 1.0 is as fast per byte as the triad;
kernels bound by arithmetic (the one-pass TV proxes with their sqrt-then-divide chains) sit
well above it. The arrays stay warm between launches (at 2048^2 they are 16 MiB each: the
triad measures the same way).

Writes ``bench/results/kernel_bandwidth_<machine>.json``, ``.md`` and ``.png``.
"""

from __future__ import annotations

import argparse
import statistics
import sys
import time
import warnings
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from bench_solvers import camera  # noqa: E402

from clfza.benchmarks._machine import machine_record, machine_slug  # noqa: E402
from clfza.benchmarks._report import write_result_files  # noqa: E402
from clfza.reconstruction._device_choice import usable_devices  # noqa: E402

RESULTS = Path(__file__).resolve().parent / "results"

# kernel: (arrays moved per launch by the model, what it reads and writes)
KERNELS = {
    "triad": (3, "read b, c; write a"),
    "lincomb3": (4, "read 3; write 1"),
    "soft_step (TwIST-l1 prox)": (3, "read x, g; write out"),
    "project_nonneg": (2, "read 1; write 1"),
    "twist_combine (+ 3 sums)": (4, "read x_{t-2}, x_{t-1}, x_ist; write x_{t+1}"),
    "fista_extrap": (3, "read two gradient steps; write b"),
    "admm_rhs": (6, "read K^T y, q1, q2, v, s; write rhs"),
    "admm_update (+ 2 sums)": (10, "read x, u1, u2, s; write u1, u2, q1, q2, v, s"),
    "admm_update_rhs (+ 2 sums)": (10, "read x, u1, u2, s, K^T y; write u1', u2', v, s, rhs"),
    "reg_contrib (TV, l1 sums)": (1, "read x"),
    "chambolle2_fused (paper prox)": (3, "read x, g; write x_ist"),
    "fgp2_fused (FISTA prox, + 2 sums)": (6, "read b, p0 (2); write z, p (2)"),
    "resid_grad_spec (+ sum)": (3.5, "read X, Y, H (0.5); write X"),
    "admm_solve_spec (+ sum)": (4, "read X, Y, H (0.5), inverse (0.5); write X"),
}


def operations(B) -> dict:
    """The callables launching each kernel of :data:`KERNELS` on backend ``B`` (the sums'
    folds included where the kernel reduces; results are not read back)."""
    from clfza.backends._base import ProxState
    from clfza.solvers._admm_ops import AdmmOps, FourierSolve
    from clfza.solvers._fista_ops import FistaOps
    from clfza.solvers._twist_ops import TwistOps

    rng = np.random.default_rng(0)
    n = B.shape

    def arr(scale=1.0):
        return B.from_host(rng.standard_normal((1,) + tuple(n)) * scale)

    x, g, y, z, o, o2, s = arr(), arr(0.1), arr(), arr(), B.empty(), B.empty(), arr()
    u1, u2, q1, q2, v = arr(0.1), arr(0.1), arr(0.1), arr(0.1), arr()
    spare = (B.empty(), B.empty())
    tw, fi, ad = TwistOps.for_backend(B), FistaOps.for_backend(B), AdmmOps.for_backend(B)
    fs = FourierSolve.for_backend(B)
    fs.setup(0.5, 1.0)  # mu = 1: the inverse <= 1, so repeated launches stay bounded
    B.fft.rfft2(x, B.X)  # a spectrum for the spectral passes (overwritten in place: bounded)
    spec = (B.X.buf, B.Y.buf, B.op.H.buf)
    state = ProxState(warm=True)
    return {
        "triad": lambda: B.triad(o, x, y, 2.0),
        "lincomb3": lambda: B.lincomb(o, 1.0, x, 0.5, y, 0.25, z),
        "soft_step (TwIST-l1 prox)": lambda: B.prox_step("l1", x, g, 0.5, 0.1, o, 0,
                                                         ProxState()),
        "project_nonneg": lambda: B.project_nonneg(o, x),
        "twist_combine (+ 3 sums)": lambda: tw.combine(o, x, y, z, 1.9, 1.2, True),
        "fista_extrap": lambda: fi.extrap(o, 1.3, x, -0.3, y),
        "admm_rhs": lambda: ad.rhs(o, q1, q2, v, s, 2.0, 0.5),
        "admm_update (+ 2 sums)": lambda: ad.update(x, u1, u2, q1, q2, o2, s, 0.3, True),
        # the split read from (u1, u2) and written to the spare pair on CPU devices (bounded)
        "admm_update_rhs (+ 2 sums)": lambda: ad.update_rhs(x, (u1, u2), spare, (q1, q2), o2,
                                                            s, o, 0.3, True, 2.0, 0.5)[0],
        "reg_contrib (TV, l1 sums)": lambda: B.reg_value(x),
        "chambolle2_fused (paper prox)": lambda: B.prox_step("tv", x, g, 0.5, 0.01, o, 2,
                                                             ProxState()),
        "fgp2_fused (FISTA prox, + 2 sums)": lambda: B.fgp_prox("tv", o, x, 0.05, 2, state,
                                                                True),
        "resid_grad_spec (+ sum)": lambda: B.spec_pass("resid_grad_spec", spec,
                                                       (B.i32(0),)).reduce(),
        "admm_solve_spec (+ sum)": lambda: B.spec_pass(
            "admm_solve_spec", spec + (fs.inv.buf,), (B.i32(1), B.i32(0))).reduce(planes=1),
    }


def measure(device: str, n: int, rounds: int) -> dict:
    from clfza.backends import get_backend
    from clfza.backends._base import ProxState

    B = get_backend("opencl", camera(n), device=device)
    ops = operations(B)
    reps = max(2, int(20 * (512 / n) ** 2) + 2)
    for f in ops.values():  # compile and warm up
        f()
    B.finish()
    times = {k: [] for k in ops}
    for _ in range(rounds):
        for k, f in ops.items():
            B.finish()
            t0 = time.perf_counter()
            for _ in range(reps):
                f()
            B.finish()
            times[k].append((time.perf_counter() - t0) / reps)
    array_bytes = n * n * 4
    t_triad = statistics.median(times["triad"])
    triad_bw = KERNELS["triad"][0] * array_bytes / t_triad
    rows = {}
    for k, ts in times.items():
        t = statistics.median(ts)
        nbytes = KERNELS[k][0] * array_bytes
        rows[k] = {"ms": t * 1e3, "ms_min": min(ts) * 1e3, "arrays": KERNELS[k][0],
                   "GBps": nbytes / t / 1e9, "x_triad": t / (nbytes / triad_bw)}
    return {"reps": reps, "triad_GBps": triad_bw / 1e9, "tuning": dict(B.tune),
            "fused_prox": B.prox_is_fused("tv", 2, ProxState()),
            "fused_fgp": B.fgp_is_fused("tv", 2), "kernels": rows}


def markdown(res: dict) -> str:
    mach = res["machine"]
    names = [d["name"] for d in res["devices"].values()]
    lines = [f"# Hot kernels against the triad per OpenCL implementation ({mach['date']})", "",
             f"Machine: {mach['cpu_model']} ({mach['cores_usable']} usable cores), load "
             f"average at start "
             f"{res['load_start']}, at end {res['load_end']}. `bench/bench_kernel_bandwidth.py "
             f"--rounds {res['rounds']}`, revision {res['revision']}.", "",
             "Per kernel: ms per launch (median of interleaved rounds of back-to-back "
             "launches, arrays warm), the bytes it must move by the model (arrays read + "
             "written; one array = N^2 float32), the effective GB/s and x triad = time / "
             "(model bytes at the triad's bandwidth, same rounds). 1.0 = as fast per byte as "
             "the triad; the one-pass TV proxes are bound by their arithmetic.", ""]
    for n in res["sizes"]:
        lines += [f"## {n}^2", "",
                  "| kernel | arrays | " + " | ".join(f"{nm}: ms / GB/s / x triad"
                                                       for nm in names) + " |",
                  "|---|---|" + "---|" * len(names)]
        for k in KERNELS:
            cells = []
            for d in res["devices"].values():
                r = d["results"][str(n)]["kernels"][k]
                cells.append(f"{r['ms']:.3f} / {r['GBps']:.1f} / x{r['x_triad']:.2f}")
            lines.append(f"| {k} | {KERNELS[k][0]:g} | " + " | ".join(cells) + " |")
        tri = ", ".join(f"{d['name']} {d['results'][str(n)]['triad_GBps']:.1f} GB/s"
                        for d in res["devices"].values())
        lines += ["", f"Triad: {tri}.", ""]
    lines += ["Byte model per kernel:", ""]
    lines += [f"- {k}: {a:g} arrays ({what})" for k, (a, what) in KERNELS.items()]
    return "\n".join(lines) + "\n"


def plot(res: dict, path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    devs = list(res["devices"].values())
    names = [k for k in KERNELS if k != "triad"]
    fig, axes = plt.subplots(1, len(res["sizes"]), figsize=(7 * len(res["sizes"]), 5),
                             squeeze=False)
    width = 0.8 / len(devs)
    for ax, n in zip(axes[0], res["sizes"], strict=True):
        for j, d in enumerate(devs):
            ys = [d["results"][str(n)]["kernels"][k]["x_triad"] for k in names]
            ax.bar(np.arange(len(names)) + j * width, ys, width, label=d["name"])
        ax.axhline(1.0, color="k", linestyle="--", linewidth=0.8)
        ax.set_xticks(np.arange(len(names)) + 0.4 - width / 2)
        ax.set_xticklabels([k.split(" ")[0] for k in names], rotation=60, ha="right",
                           fontsize=7)
        ax.set_yscale("log")
        ax.set_ylabel("time / (model bytes at triad bandwidth)")
        ax.set_title(f"{n}^2 (dashed: the triad)")
        ax.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--devices", nargs="+", default=None)
    p.add_argument("--sizes", type=int, nargs="+", default=[512, 2048])
    p.add_argument("--rounds", type=int, default=5)
    p.add_argument("--out", default=str(RESULTS))
    a = p.parse_args(argv)
    if a.rounds < 1 or any(n < 16 for n in a.sizes):
        p.error("--rounds must be at least 1 and every size at least 16")
    warnings.simplefilter("ignore")
    from bench_tau import revision

    from clfza.cl import get_runtime

    mach = machine_record()
    res = {"machine": mach, "revision": revision(), "sizes": a.sizes, "rounds": a.rounds,
           "load_start": mach["load_average"], "devices": {}}
    for dev in a.devices or usable_devices():
        info = get_runtime(dev).info
        name = f"{info.platform} {info.driver}"
        print(f"[{dev}] {name}", flush=True)
        res["devices"][dev] = {"name": name, "device": info.name, "results": {}}
        for n in a.sizes:
            r = measure(dev, n, a.rounds)
            res["devices"][dev]["results"][str(n)] = r
            print(f"  {n}^2 triad {r['triad_GBps']:.1f} GB/s: " + ", ".join(
                f"{k.split(' ')[0]} x{v['x_triad']:.2f}" for k, v in r["kernels"].items()),
                flush=True)
    res["load_end"] = machine_record()["load_average"]
    paths = write_result_files(Path(a.out) / f"kernel_bandwidth_{machine_slug(mach)}", res,
                               markdown(res), plot)
    print(markdown(res))
    print("wrote", *paths)
    return 0


if __name__ == "__main__":
    sys.exit(main())
