"""Scaling (issue 5, item 3): time per iteration from 256^2 to 4096^2 against N^2 log N, next
to the machine's limit measured in the same run.

Writes ``scaling_<machine>.json/.png/.md`` into ``--out`` (default ``bench/results``)::

    python bench/bench_scaling.py --profile full
    python bench/bench_scaling.py --sizes 256 512 1024 --methods bp admm-tv --backends opencl
"""

from __future__ import annotations

import argparse
from pathlib import Path

from clfza.benchmarks import _scaling as scaling
from clfza.benchmarks._methods import default_methods


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--profile", choices=("quick", "full", "tiny"), default="full")
    p.add_argument("--sizes", nargs="+", type=int, default=None)
    p.add_argument("--methods", nargs="+", choices=[s.key for s in default_methods()])
    p.add_argument("--backends", nargs="+", choices=("opencl", "numpy"))
    p.add_argument("--device", default=None)
    p.add_argument("--out", default=str(Path(__file__).parent / "results"))
    p.add_argument("--label", default=None)
    a = p.parse_args(argv)
    r = scaling.run(a.profile, a.out, a.device, sizes=a.sizes, methods=a.methods,
                    backends=a.backends, label=a.label)
    print()
    print(f"{'method':22s} {'backend':7s} {'N':>11s} {'k (t~N^2k)':>10s} {'NlogN drift':>11s}")
    for f in r["fits"]:
        print(f"{f['label']:22s} {f['backend']:7s} {f['sizes'][0]:5d}-{f['sizes'][-1]:<5d} "
              f"{f['exponent_vs_N2']:10.2f} {f['nlogn_ratio']:11.2f}")
    print("wrote", ", ".join(str(v) for v in r["paths"].values()))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
