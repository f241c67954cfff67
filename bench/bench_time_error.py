"""Time against error (issue 5, items 1-2): PSNR/SSIM/MSE against wall time per method,
backend, size, scene and noise, and each iteration's cost next to the machine's limit.

Writes ``time_error_<machine>.json/.png/.md`` (and ``_grid.png``) into ``--out``
(default ``bench/results``). Examples::

    python bench/bench_time_error.py --profile quick
    python bench/bench_time_error.py --profile full
    python bench/bench_time_error.py --scenes natural usaf --noises gauss0.01 --sizes 512 \\
        --backends opencl numpy --merge
"""

from __future__ import annotations

import argparse
from pathlib import Path

from clfza.benchmarks import _scenes as scenes
from clfza.benchmarks import _timeerror as timeerror
from clfza.benchmarks._methods import default_methods


def _at_least_one(text: str) -> int:
    """An argparse type: an integer >= 1."""
    try:
        value = int(text)
    except ValueError:
        value = 0
    if value < 1:
        raise argparse.ArgumentTypeError(f"must be an integer >= 1, got {text!r}")
    return value


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--profile", choices=("quick", "full", "tiny"), default="quick")
    p.add_argument("--scenes", nargs="+", choices=scenes.SCENES,
                   help="custom grid: scenes (overrides --profile)")
    p.add_argument("--noises", nargs="+", choices=list(timeerror.NOISES), default=["gauss0.01"])
    p.add_argument("--sizes", nargs="+", type=int, default=[512])
    p.add_argument("--backends", nargs="+", choices=("opencl", "numpy"), default=["opencl"])
    p.add_argument("--methods", nargs="+", choices=[s.key for s in default_methods()])
    p.add_argument("--iters", type=int, default=None, help="override every method's iterations")
    p.add_argument("--sparse", action="store_true", help="fewer checkpoints")
    p.add_argument("--device", default=None)
    p.add_argument("--repeats", type=_at_least_one, default=3,
                   help="solves per method and case; the run of median time is kept")
    p.add_argument("--out", default=str(Path(__file__).parent / "results"))
    p.add_argument("--label", default=None, help="file label (default: the machine)")
    p.add_argument("--merge", action="store_true",
                   help="keep rows of an existing result file that this run does not redo")
    a = p.parse_args(argv)
    cases = None
    if a.scenes:
        cases = [timeerror.Case(s, n, z, b, a.methods, a.iters, not a.sparse)
                 for z in a.sizes for b in a.backends for n in a.noises for s in a.scenes]
    r = timeerror.run(a.profile, a.out, a.device, cases=cases, label=a.label, merge=a.merge,
                      repeats=a.repeats)
    print()
    print("time to the paper-mode TwIST's final PSNR:")
    for t in r["time_to_paper"]:
        tt = t["time_to_target_s"]
        print(f"  {t['scene']:8s} {t['noise']:10s} {t['size']:5d} {t['backend']:6s} "
              f"{t['label']:20s} target {t['target_psnr']:6.2f} dB  "
              f"{'not reached' if tt is None else f'{tt:8.3f} s'}")
    print("wrote", ", ".join(str(v) for v in r["paths"].values()))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
