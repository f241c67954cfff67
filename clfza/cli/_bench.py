"""``clfza bench --quick|--full --out DIR``: the benchmark suite (time against error,
throughput, stability), provided by :func:`clfza.benchmarks.run`."""

from __future__ import annotations

from pathlib import Path

from .. import benchmarks
from ..errors import ClfzaError
from ._common import first_run_line, warm_first_run

NAME = "bench"
HELP = "run the benchmarks"
DESCRIPTION = (
    "Run the benchmark suite and write JSON + PNG results to DIR.")


def add_arguments(p) -> None:
    """The arguments of ``clfza bench`` (its parser made by the command line from
    :data:`NAME`, :data:`HELP` and :data:`DESCRIPTION`)."""
    g = p.add_mutually_exclusive_group()
    g.add_argument("--quick", dest="profile", action="store_const", const="quick",
                   help="small grids, a few minutes (default)")
    g.add_argument("--full", dest="profile", action="store_const", const="full",
                   help="the paper's grids; long")
    p.add_argument("--out", default="bench-out", metavar="DIR",
                   help="results folder (default bench-out)")
    p.set_defaults(func=run, profile="quick")
    return p


def _runner():
    """``clfza.benchmarks.run``, looked up at call time (a build without it fails clearly)."""
    fn = getattr(benchmarks, "run", None)
    if not callable(fn):
        raise ClfzaError("benchmarks are not available in this build (clfza.benchmarks.run "
                         "is missing)")
    return fn


def run(args) -> int:
    """Entry point of ``clfza bench``."""
    out = Path(args.out)
    if out.exists() and not out.is_dir():
        raise ClfzaError(f"--out {str(out)!r} is a file, not a folder")
    first = warm_first_run(args)
    line = first_run_line(first)
    if line and not args.quiet:
        print(line)
    result = _runner()(args.profile, out, first_run=first)
    if not args.quiet:
        where = result if isinstance(result, (str, Path)) else out
        print(f"benchmarks ({args.profile}) written to {where}")
    return 0
