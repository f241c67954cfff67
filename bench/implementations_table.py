"""Markdown tables from bench/results/kernels_builtins_*.json (bench/bench_kernels.py runs, one
per OpenCL implementation): per-kernel ms base -> work, solver ms/iteration and x-limit.

Usage: ``python bench/implementations_table.py FILE.json... > bench/results/X.md``
"""

from __future__ import annotations

import json
import sys


def main(paths: list[str]) -> None:
    runs = [(p, json.load(open(p, encoding="utf-8"))) for p in paths]
    short = {"Portable Computing Language": "PoCL", "Intel(R) OpenCL": "Intel"}
    names = [f"{short.get(r['info']['platform'], r['info']['platform'])} "
             f"{r['info']['driver']}" for _, r in runs]
    info = runs[0][1]["info"]
    print(f"Device: {info['device']} ({info['cpus']} CPUs); base = kernels at {info['base']}, "
          f"work = kernels after the clang built-ins; medians of {info['rounds']} "
          "interleaved rounds, same process per implementation.\n")
    for n in runs[0][1]["solvers"]:
        print(f"### Solvers at {n}^2: ms/iteration (x machine limit)\n")
        print("| solver | " + " | ".join(f"{nm} base | {nm} work" for nm in names) + " |")
        print("|---|" + "---|---|" * len(names))
        for s in runs[0][1]["solvers"][n]:
            cells = []
            for _, r in runs:
                v = r["solvers"][n][s]
                cells += [f"{v['base_ms']:.2f} (x{v['base_x_limit']:.2f})",
                          f"{v['work_ms']:.2f} (x{v['work_x_limit']:.2f})"]
            print(f"| {s} | " + " | ".join(cells) + " |")
        lims = ", ".join(f"{nm}: {r['solvers'][n]['twist-paper']['limit_ms']:.2f} ms"
                         for nm, (_, r) in zip(names, runs, strict=True))
        print(f"\nTwIST limit (FFT pair + 4 arrays at triad bandwidth): {lims}\n")
    for n in runs[0][1]["kernels"]:
        print(f"### Kernels at {n}^2: ms per launch, base -> work (speed-up)\n")
        print("| operation | " + " | ".join(names) + " |")
        print("|---|" + "---|" * len(names))
        for k in runs[0][1]["kernels"][n]:
            cells = []
            for _, r in runs:
                v = r["kernels"][n][k]
                cells.append(f"{v['base_ms']:.3f} -> {v['work_ms']:.3f} "
                             f"({v['base_ms'] / v['work_ms']:.2f}x)")
            print(f"| {k} | " + " | ".join(cells) + " |")
        print()


if __name__ == "__main__":
    main(sys.argv[1:])
