"""Numerical stability stress report (issue 5, item 4): every case gives a finite image or a
clear error; counts of cases, NaN/Inf images, crashes, objective rises where monotonicity is
promised, and the largest float32/float64 gaps over 1000 iterations.

Writes ``stress_report.json/.md`` into ``--out`` (default ``bench/results``)::

    python bench/stress_report.py
    python bench/stress_report.py --level test --precision-size 64 --precision-iters 100
"""

from __future__ import annotations

import argparse
from pathlib import Path

from clfza.benchmarks import stability


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--level", choices=("report", "test"), default="report",
                   help="report: 128^2 cases; test: 64^2 and fewer iterations")
    p.add_argument("--precision-size", type=int, default=256)
    p.add_argument("--precision-iters", type=int, default=1000)
    p.add_argument("--categories", nargs="+", default=None)
    p.add_argument("--no-isolate", action="store_true",
                   help="run cases in this process (a native crash then ends the run)")
    p.add_argument("--out", default=str(Path(__file__).parent / "results"))
    a = p.parse_args(argv)
    r = stability.run(a.out, level=a.level, precision_size=a.precision_size,
                      precision_iters=a.precision_iters, categories=a.categories,
                      isolate=not a.no_isolate)
    print()
    for k, v in r["counts"].items():
        print(f"  {k:24s} {v}")
    print("wrote", ", ".join(str(v) for v in r["paths"].values()))
    bad = r["counts"]["nonfinite"] + r["counts"]["crashes"] + r["counts"]["monotone_violations"]
    return 1 if bad else 0


if __name__ == "__main__":
    raise SystemExit(main())
