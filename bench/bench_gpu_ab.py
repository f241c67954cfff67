"""Same-run A/B of the GPU path's variants: the device FFT's column kind and the paired folds.

Usage (``tools/device_gpu_run.sh`` with ``GPU_AB=1`` runs it on a lent GPU)::

    python bench/bench_gpu_ab.py [--device P:D] [--variants codelets:on passes:on codelets:off]
                                 [--ab-rounds 2] [--sizes 512 2048] [--rounds 3]

Each variant is ``COLUMNS:PAIRS``: the device FFT's columns (``codelets``, the generated
radix-up-to-64 codelets, or ``passes``, ``fft.cl``'s radix-2..8 passes:
``clfza.fft._stockham.LINES_COLUMNS``) and whether two reducers' deferred folds share one launch
(``on``/``off``: ``clfza.backends._opencl.PAIR_FOLDS``). Each variant runs as its own
``bench/bench_gpu.py`` process (no time to PSNR), the variants interleaved ``--ab-rounds``
times, so a drift of the machine falls on all of them alike. Reported per size: the FFT pair
and each solver's steady ms per iteration, the median over the rounds of each process's median,
and the ratio to the first variant (below 1: faster than it).

Writes ``bench/results/gpu_ab_<device>.json``, ``.md`` and ``.png`` (``--out`` another folder).
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
RESULTS = HERE / "results"
sys.path.insert(0, str(HERE))

from clfza.benchmarks._report import write_result_files  # noqa: E402


def run_variant(variant: str, args, tmp: Path, tag: str) -> dict:
    cols, pairs = variant.split(":")
    cmd = [sys.executable, str(HERE / "bench_gpu.py"), "--fft-cols", cols, "--fold-pairs",
           pairs, "--psnr-iters", "0", "--rounds", str(args.rounds), "--sizes",
           *map(str, args.sizes), "--out", str(tmp), "--tag", tag]
    if args.device:
        cmd += ["--device", args.device]
    subprocess.run(cmd, check=True, stdout=subprocess.DEVNULL)
    (path,) = tmp.glob(f"gpu_*{tag}.json")
    return json.loads(path.read_text())


def cells(res: dict) -> dict:
    """{size: {cell: ms}}: the FFT pair and each solver's steady state."""
    out = {}
    for n, r in res["sizes"].items():
        row = {"fft pair": r["fft"]["pair_ms"]}
        row.update({s: v["steady_ms"] for s, v in r["solvers"].items()})
        row["launches admm"] = r["solvers"]["admm"]["launches_per_iteration"]
        out[n] = row
    return out


def markdown(rec: dict) -> str:
    base = rec["variants"][0]
    lines = [f"# GPU path A/B on {rec['device_name']} ({rec['date']})", "",
             f"`bench/bench_gpu_ab.py --variants {' '.join(rec['variants'])} --ab-rounds "
             f"{rec['ab_rounds']} --rounds {rec['rounds']}`, revision "
             f"{rec['revision'].get('commit', '?')[:10]}"
             f"{' (modified)' if rec['revision'].get('clfza_modified') else ''}. "
             "Variant `COLUMNS:PAIRS`: the device FFT's column kind and paired folds. Cells: "
             "median over the rounds (ms; the FFT pair, solvers steady state per iteration), "
             f"in brackets the ratio to `{base}`.", ""]
    for n, table in rec["sizes"].items():
        names = list(table[base])
        lines += [f"## {n}^2", "", "| cell | " + " | ".join(rec["variants"]) + " |",
                  "|---" * (len(rec["variants"]) + 1) + "|"]
        for c in names:
            row = [f"{table[v][c]:.3f}" + ("" if v == base or c.startswith("launches") else
                                           f" ({table[v][c] / table[base][c]:.2f})")
                   for v in rec["variants"]]
            lines.append(f"| {c} | " + " | ".join(row) + " |")
        lines.append("")
    return "\n".join(lines) + "\n"


def plot(rec: dict, path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    sizes = list(rec["sizes"])
    fig, axes = plt.subplots(1, len(sizes), figsize=(5 * len(sizes), 4), squeeze=False)
    for ax, n in zip(axes[0], sizes, strict=True):
        table = rec["sizes"][n]
        names = [c for c in table[rec["variants"][0]] if not c.startswith("launches")]
        width = 0.8 / len(rec["variants"])
        for j, v in enumerate(rec["variants"]):
            ax.bar(np.arange(len(names)) + j * width, [table[v][c] for c in names], width,
                   label=v)
        ax.set_xticks(np.arange(len(names)) + 0.4 - width / 2)
        ax.set_xticklabels(names, rotation=20, fontsize=8)
        ax.set_ylabel("ms")
        ax.set_title(f"{rec['device_name']}, {n}^2")
        ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--device", default=None, help="OpenCL device P:D (default: first GPU)")
    p.add_argument("--variants", nargs="+",
                   default=["codelets:on", "passes:on", "codelets:off"])
    p.add_argument("--ab-rounds", type=int, default=2)
    p.add_argument("--sizes", type=int, nargs="+", default=[512, 2048])
    p.add_argument("--rounds", type=int, default=3)
    p.add_argument("--out", default=str(RESULTS))
    a = p.parse_args(argv)
    for v in a.variants:
        cols, _, pairs = v.partition(":")
        if cols not in ("codelets", "passes") or pairs not in ("on", "off"):
            p.error(f"variant {v!r}: COLUMNS:PAIRS with COLUMNS codelets|passes, PAIRS on|off")
    if a.ab_rounds < 1 or a.rounds < 1:
        p.error("--ab-rounds and --rounds >= 1")
    runs = {v: [] for v in a.variants}
    with tempfile.TemporaryDirectory() as tmp:
        for k in range(a.ab_rounds):
            for i, v in enumerate(a.variants):
                res = run_variant(v, a, Path(tmp), f"_ab{k}_{i}")
                runs[v].append(res)
                print(f"round {k + 1}/{a.ab_rounds} {v}: " + "; ".join(
                    f"{n}^2 " + ", ".join(f"{c} {ms:.3f}" for c, ms in t.items())
                    for n, t in cells(res).items()), flush=True)
    first = runs[a.variants[0]][0]
    rec = {"device_name": first["device_name"], "platform": first["platform"],
           "driver": first["driver"], "date": first["machine"]["date"],
           "machine": first["machine"], "revision": first["revision"],
           "variants": a.variants, "ab_rounds": a.ab_rounds, "rounds": a.rounds,
           "runs": {v: [cells(r) for r in rs] for v, rs in runs.items()}, "sizes": {}}
    for n in map(str, a.sizes):
        rec["sizes"][n] = {v: {c: float(np.median([cells(r)[n][c] for r in rs]))
                               for c in cells(rs[0])[n]} for v, rs in runs.items()}
    slug = "".join(ch if ch.isalnum() else "-" for ch in first["device_name"].lower()).strip("-")
    paths = write_result_files(Path(a.out) / f"gpu_ab_{slug}", rec, markdown(rec), plot)
    print(markdown(rec))
    print("wrote", *paths)
    return 0


if __name__ == "__main__":
    sys.exit(main())
