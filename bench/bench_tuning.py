"""Kernel variants per OpenCL implementation (clfza.backends._tuning) and TwIST paper mode before
and after tuning, in the same run.

Usage::

    python bench/bench_tuning.py [--devices "PoCL 3.0" "PoCL 3.1" Intel] [--sizes 512 2048]
                                 [--rounds 7] [--iters 10] [--out bench/results/tuning_TAG]

Per implementation: the tuning measurement at both size classes (every candidate of every
parameter, interleaved rounds, best round per candidate: what ``clfza tune`` prints), then
TwIST paper mode ms/iteration at each size with the built-in defaults (``before``: the fixed
choices clfza had before tuning) and with the tuned choices (``after``), pinned through
``CLFZA_TUNE``; rounds alternate the order of the two; medians (with min/max) over rounds of
``iters``-iteration solves after a warm-up. The load average is recorded before and after each
implementation's block. Writes TAG.json and TAG.md.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import statistics
import sys
import time
import warnings
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT / "bench"))


def pin(t: dict) -> str:
    return ",".join(f"{k}={v}" for k, v in t.items())


def twist_ms(m, cam, device: str, tune: dict, iters: int) -> float:
    import clfza

    os.environ["CLFZA_TUNE"] = pin(tune)
    r = clfza.reconstruct(m.y, cam, "twist", mode="paper", backend="opencl", device=device,
                          iters=iters, min_iters=iters, stop="none")
    return r.info.timings["solve"] / r.info.iterations * 1e3


def run_device(spec: str, sizes, rounds: int, iters: int) -> dict:
    from bench_solvers import camera
    from skimage import data

    import clfza
    from clfza.backends import _tuning as tuning
    from clfza.backends._opencl import OpenCLBackend
    from clfza.cl import get_runtime

    os.environ.pop("CLFZA_TUNE", None)
    rt = get_runtime(spec)
    out = {"device": rt.info.name, "platform": rt.info.platform, "driver": rt.info.driver,
           "platform_version": rt.device.platform.version.strip(),
           "load_before": list(os.getloadavg()), "tuning": {}, "twist_paper": {}}
    print(f"\n== {rt.info.describe()}", flush=True)
    for cls in ("small", "large"):
        e = tuning.measure(rt, cls, OpenCLBackend)
        out["tuning"][cls] = e
        print("\n".join(tuning.table_lines(e)), flush=True)
    for n in sizes:
        cam = camera(n)
        m = clfza.simulate(data.camera(), cam, object_width=200.0)
        variants = {"before": dict(tuning.DEFAULTS),
                    "after": out["tuning"][tuning.size_class(n, n)]["choices"]}
        for t in variants.values():  # warm-up: compile, first touch
            twist_ms(m, cam, spec, t, 2)
        ts = {v: [] for v in variants}
        for r in range(rounds):
            for v in (list(variants) if r % 2 == 0 else list(variants)[::-1]):
                ts[v].append(twist_ms(m, cam, spec, variants[v], iters))
        row = {v: {"median_ms": statistics.median(x), "min_ms": min(x), "max_ms": max(x),
                   "all_ms": x} for v, x in ts.items()}
        row["after_choices"] = variants["after"]
        row["speedup_median"] = row["before"]["median_ms"] / row["after"]["median_ms"]
        out["twist_paper"][str(n)] = row
        print(f"TwIST paper {n}^2: before {row['before']['median_ms']:.2f} "
              f"[{row['before']['min_ms']:.2f}-{row['before']['max_ms']:.2f}] ms, after "
              f"{row['after']['median_ms']:.2f} [{row['after']['min_ms']:.2f}-"
              f"{row['after']['max_ms']:.2f}] ms ({row['speedup_median']:.2f}x)", flush=True)
    os.environ.pop("CLFZA_TUNE", None)
    out["load_after"] = list(os.getloadavg())
    return out


def markdown(res: dict) -> str:
    info = res["info"]
    lines = [f"# Kernel variants per implementation ({info['date']})", "",
             f"Machine: {info['cpu']} ({info['cpus']} CPUs, host {info['host']}); "
             f"pyopencl {info['pyopencl']}, numpy {info['numpy']}. Load average at start "
             f"{info['load_start']}, at end {info['load_end']} (a shared machine: other "
             "sessions' work runs alongside).", "",
             "Tuning tables: ms per call, best of the interleaved rounds per candidate "
             "(`clfza tune`); `*` the choice (a candidate replaces the built-in default only "
             f"when {100 * res['margin']:.0f}% faster). Operations timed per parameter: local1d "
             "lincomb3 + soft_step; local2d the three-kernel TV prox + reg_contrib; rows "
             "twist_combine; strip and prox the paper-mode TV prox.", ""]
    for d in res["devices"]:
        lines.append(f"## {d['platform']} {d['driver']} ({d['device']})")
        lines.append("")
        lines.append(f"Load average before {[round(x, 2) for x in d['load_before']]}, after "
                     f"{[round(x, 2) for x in d['load_after']]}.")
        lines.append("")
        for e in d["tuning"].values():
            lines.append(f"Tuning at {e['size']}^2 ({e['rounds']} rounds x {e['reps']} calls, "
                         f"{e['seconds']} s):")
            lines.append("")
            lines.append("| parameter | candidates (ms per call) | chosen |")
            lines.append("|---|---|---|")
            for p, med in e["ms"].items():
                ch = str(e["choices"][p])
                cells = ", ".join(f"{k}: {'**' if k == ch else ''}{v:.3f}"
                                  f"{'**' if k == ch else ''}" for k, v in med.items())
                lines.append(f"| {p} | {cells} | {ch} |")
            lines.append("")
        lines.append("TwIST paper mode, ms/iteration (median [min-max] of "
                     f"{res['info']['rounds']} interleaved solves of {res['info']['iters']} "
                     "iterations):")
        lines.append("")
        lines.append("| size | before (defaults) | after (tuned) | speed-up | tuned choices |")
        lines.append("|---|---|---|---|---|")
        for n, row in d["twist_paper"].items():
            b, a = row["before"], row["after"]
            lines.append(f"| {n}^2 | {b['median_ms']:.2f} [{b['min_ms']:.2f}-{b['max_ms']:.2f}]"
                         f" | {a['median_ms']:.2f} [{a['min_ms']:.2f}-{a['max_ms']:.2f}] | "
                         f"{row['speedup_median']:.2f}x | {pin(row['after_choices'])} |")
        lines.append("")
    return "\n".join(lines) + "\n"


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--devices", nargs="+", default=["PoCL 3.0", "PoCL 3.1", "Intel"])
    ap.add_argument("--sizes", type=int, nargs="+", default=[512, 2048])
    ap.add_argument("--rounds", type=int, default=7)
    ap.add_argument("--iters", type=int, default=10)
    ap.add_argument("--out", default=str(ROOT / "bench" / "results" / "tuning_intel-xeon-2c"))
    args = ap.parse_args()
    warnings.simplefilter("ignore")
    import numpy as np
    import pyopencl

    from clfza.backends import _tuning as tuning

    cpu = platform.processor() or platform.machine()
    try:
        cpu = next(ln.split(":", 1)[1].strip() for ln in open("/proc/cpuinfo")
                   if ln.startswith("model name"))
    except (OSError, StopIteration):
        pass
    res = {"info": {"date": time.strftime("%Y-%m-%d %H:%M:%S"), "cpu": cpu,
                    "cpus": os.cpu_count(), "host": platform.node(),
                    "pyopencl": pyopencl.VERSION_TEXT, "numpy": np.__version__,
                    "rounds": args.rounds, "iters": args.iters,
                    "load_start": [round(x, 2) for x in os.getloadavg()]},
           "margin": tuning.MARGIN, "devices": []}
    for spec in args.devices:
        res["devices"].append(run_device(spec, args.sizes, args.rounds, args.iters))
        res["info"]["load_end"] = [round(x, 2) for x in os.getloadavg()]
        Path(args.out + ".json").write_text(json.dumps(res, indent=1))
        Path(args.out + ".md").write_text(markdown(res))
    print("wrote", args.out + ".json", args.out + ".md")


if __name__ == "__main__":
    main()
