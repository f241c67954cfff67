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
import re
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
             f"{rec['ab_rounds']} --rounds {rec['rounds']}`"
             + (f" (rounds merged from {', '.join(rec['merged_from'])})"
                if rec.get("merged_from") else "")
             + f"; samples per variant {rec['samples']}; revision "
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
    p.add_argument("--merge", nargs="+", default=None, metavar="FILE",
                   help="no run: merge the rounds of earlier runs on one machine (record JSONs "
                        "and this script's logs)")
    p.add_argument("--revision", default=None,
                   help="the code's commit, where the machine's own record of it is wrong "
                        "(a `git archive` snapshot run beside a stale .git)")
    p.add_argument("--out", default=str(RESULTS))
    a = p.parse_args(argv)
    for v in a.variants:
        cols, _, pairs = v.partition(":")
        if cols not in ("codelets", "passes") or pairs not in ("on", "off"):
            p.error(f"variant {v!r}: COLUMNS:PAIRS with COLUMNS codelets|passes, PAIRS on|off")
    if a.ab_rounds < 1 or a.rounds < 1:
        p.error("--ab-rounds and --rounds >= 1")
    if a.merge:
        runs, meta = merge(a.merge)
        variants = list(runs)
    else:
        runs, meta, variants = {v: [] for v in a.variants}, None, a.variants
        with tempfile.TemporaryDirectory() as tmp:
            for k in range(a.ab_rounds):
                for i, v in enumerate(a.variants):
                    res = run_variant(v, a, Path(tmp), f"_ab{k}_{i}")
                    runs[v].append(cells(res))
                    print(f"round {k + 1}/{a.ab_rounds} {v}: {round_line(runs[v][-1])}",
                          flush=True)
                    meta = meta or {"device_name": res["device_name"],
                                    "platform": res["platform"], "driver": res["driver"],
                                    "date": res["machine"]["date"], "machine": res["machine"],
                                    "revision": res["revision"], "ab_rounds": a.ab_rounds,
                                    "rounds": a.rounds}
                    # written after every process: a run cut short keeps what it measured
                    paths = write(record(meta, runs, variants), a.out)
    if a.revision:
        meta = dict(meta, revision={"commit": a.revision, "clfza_modified": False})
    rec = record(meta, runs, variants)
    paths = write(rec, a.out)
    print(markdown(rec))
    print("wrote", *paths)
    return 0


def round_line(table: dict) -> str:
    return "; ".join(f"{n}^2 " + ", ".join(f"{c} {ms:.3f}" for c, ms in t.items())
                     for n, t in table.items())


ROUND = re.compile(r"^round \d+/\d+ (\S+): (.*)$")


def merge(paths: list[str]) -> tuple[dict, dict]:
    """The rounds of earlier runs on one machine: record JSONs (their metadata and rounds) or
    this script's printed logs (their ``round k/K VARIANT: ...`` lines)."""
    runs, meta = {}, None
    for path in paths:
        text = Path(path).read_text()
        if path.endswith(".json"):
            rec = json.loads(text)
            meta = meta or {k: rec[k] for k in ("device_name", "platform", "driver", "date",
                                                "machine", "revision", "ab_rounds", "rounds")}
            for v, tables in rec["runs"].items():
                runs.setdefault(v, []).extend(tables)
            continue
        for line in text.splitlines():
            m = ROUND.match(line)
            if not m:
                continue
            table = {}
            for part in m.group(2).split("; "):
                n, _, rest = part.partition("^2 ")
                table[n] = {c: float(ms) for c, _, ms in
                            (cell.rpartition(" ") for cell in rest.split(", "))}
            runs.setdefault(m.group(1), []).append(table)
    if meta is None:
        raise SystemExit("--merge needs at least one record JSON (the machine's metadata)")
    meta = dict(meta, merged_from=[Path(p).name for p in paths],
                ab_rounds=max(len(t) for t in runs.values()))
    return runs, meta


def record(meta: dict, runs: dict, variants: list[str]) -> dict:
    done = [v for v in variants if runs.get(v)]
    rec = dict(meta, variants=done, runs={v: runs[v] for v in done},
               samples={v: len(runs[v]) for v in done}, sizes={})
    for n in runs[done[0]][0]:
        rec["sizes"][n] = {v: {c: float(np.median([t[n][c] for t in runs[v]]))
                               for c in runs[v][0][n]} for v in done}
    return rec


def write(rec: dict, out: str) -> list:
    name = rec["device_name"].lower()
    slug = "".join(ch if ch.isalnum() else "-" for ch in name).strip("-")
    return write_result_files(Path(out) / f"gpu_ab_{slug}", rec, markdown(rec), plot)


if __name__ == "__main__":
    sys.exit(main())
