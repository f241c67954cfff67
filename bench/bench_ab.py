"""Same-run A/B of per-iteration solve time between two revisions of clfza (issue 12: a
refactor must leave the per-iteration cost unchanged within noise).

The base revision is checked out in a git worktree (``/tmp/clfza-ab-<rev>``); each round runs
one fresh process per revision, alternating A, B, A, B, ... so that both see the same load,
and each process times every method after a warm-up (compile and plan excluded: the solve
clock of ``info.timings["solve"]`` over its iterations). Reported: the median over rounds
of ms/iteration per revision and their ratio (head / base), and the same for the minimum
(the least-disturbed run: on a shared machine the median moves with the load). Writes
``bench/results/ab_<base>_<head>.json``.

    .venv/bin/python bench/bench_ab.py --base 995264f [--head WORKTREE] [--rounds 5] [--n 512]
                                       [--tag pocl31]   # with PYOPENCL_CTX=... for a device
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import statistics
import subprocess
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]

CASES = {  # name: (method, options) on the paper's simulation preset scaled to n x n
    "twist-paper": ("twist", {"mode": "paper", "iters": 30, "stop": "none"}),
    "fista": ("fista", {"iters": 50, "stop": "none", "model": "tf"}),
    "admm": ("admm", {"iters": 50, "stop": "none", "model": "tf"}),
    "admm-exact": ("admm", {"iters": 50, "stop": "none", "model": "exact", "adapt": False}),
}

CHILD = r"""
import json, sys, warnings
import numpy as np
warnings.simplefilter("ignore")
import clfza
from clfza import Camera, simulate
from skimage import data
from skimage.transform import resize
n = int(sys.argv[1]); cases = json.loads(sys.argv[2])
cam = Camera.preset("simulation")
cam = cam.with_shape((n, n), cam.pitch * cam.shape[0] / n)
y = simulate(resize(data.camera() / 255.0, (n, n)), cam).y
out = {"clfza_file": clfza.__file__}
from clfza.solvers import option_names
for name, (method, opts) in cases.items():
    if opts.get("model") == "exact" and "average" in (option_names(method) or ()):
        opts = dict(opts, average=False)  # the same iteration as before the mean existed
    clfza.reconstruct(y, cam, method, **dict(opts, iters=3))  # compile, plan, warm caches
    _, info = clfza.reconstruct(y, cam, method, **opts)
    out[name] = 1e3 * info.timings["solve"] / info.iterations
print(json.dumps(out))
"""


def worktree(rev: str) -> Path:
    path = Path(f"/tmp/clfza-ab-{rev}")
    if not path.exists():
        subprocess.run(["git", "-C", str(ROOT), "worktree", "add", "--detach", str(path), rev],
                       check=True, capture_output=True)
    return path


def run_once(tree: Path, n: int, cases: dict) -> dict:
    # the kernels too: clfza.kernels is package data mapped by the editable install, which
    # would otherwise give the base revision the head's .cl files
    # (the tree first, then any path already set: e.g. carried wheels on a device machine)
    path = os.pathsep.join(p for p in (str(tree), os.environ.get("PYTHONPATH", "")) if p)
    env = dict(os.environ, PYTHONPATH=path, CLFZA_KERNEL_DIR=str(tree / "kernels"))
    res = subprocess.run([sys.executable, "-c", CHILD, str(n), json.dumps(cases)], env=env,
                         capture_output=True, text=True, cwd=str(tree))
    if res.returncode:
        raise SystemExit(f"the child in {tree} failed:\n{res.stderr[-3000:]}")
    out = json.loads(res.stdout.strip().splitlines()[-1])
    if not out.pop("clfza_file").startswith(str(tree)):
        raise SystemExit(f"the child imported clfza from outside {tree}")
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--base", required=True, help="base revision (a commit)")
    ap.add_argument("--head", default=str(ROOT), help="head tree (default: this checkout)")
    ap.add_argument("--base-tree", default=None,
                    help="an existing checkout of the base (e.g. from `git archive` on a "
                         "machine without the repository's history) instead of a worktree")
    ap.add_argument("--rounds", type=int, default=5)
    ap.add_argument("--n", type=int, default=512)
    ap.add_argument("--cases", default=",".join(CASES))
    ap.add_argument("--out", default=str(ROOT / "bench" / "results"))
    ap.add_argument("--tag", default="", help="appended to the file name (e.g. the device)")
    a = ap.parse_args()
    cases = {k: CASES[k] for k in a.cases.split(",")}
    base = Path(a.base_tree).resolve() if a.base_tree else worktree(a.base)
    head = Path(a.head)
    load0 = os.getloadavg()
    runs: dict[str, list[dict]] = {"base": [], "head": []}
    for r in range(a.rounds):
        for side, tree in (("base", base), ("head", head)) if r % 2 == 0 else \
                (("head", head), ("base", base)):
            runs[side].append(run_once(tree, a.n, cases))
        print(f"round {r + 1}/{a.rounds} done", flush=True)
    rows = []
    print(f"{'case':12s} {'base ms/it':>11s} {'head ms/it':>11s} {'head/base':>10s} "
          f"{'min ratio':>10s}")
    for name in cases:
        b = statistics.median(x[name] for x in runs["base"])
        h = statistics.median(x[name] for x in runs["head"])
        bmin = min(x[name] for x in runs["base"])
        hmin = min(x[name] for x in runs["head"])
        rows.append({"case": name, "base_ms": round(b, 3), "head_ms": round(h, 3),
                     "ratio": round(h / b, 3), "base_min_ms": round(bmin, 3),
                     "head_min_ms": round(hmin, 3), "min_ratio": round(hmin / bmin, 3),
                     "base_all": [round(x[name], 3) for x in runs["base"]],
                     "head_all": [round(x[name], 3) for x in runs["head"]]})
        print(f"{name:12s} {b:11.2f} {h:11.2f} {h / b:10.3f} {hmin / bmin:10.3f}")
    head_rev = subprocess.run(["git", "-C", str(head), "rev-parse", "--short", "HEAD"],
                              capture_output=True, text=True).stdout.strip() or "head"
    dirty = bool(subprocess.run(["git", "-C", str(head), "status", "--porcelain", "clfza"],
                                capture_output=True, text=True).stdout.strip())
    from clfza.cl import get_runtime

    rt = get_runtime()
    rec = {"benchmark": "ab_per_iteration", "base": a.base, "head": head_rev,
           "head_dirty": dirty, "n": a.n, "rounds": a.rounds, "cases": rows,
           "device": rt.info.name, "platform": rt.info.platform,
           "machine": platform.processor() or platform.machine(),
           "load_average": {"start": load0, "end": os.getloadavg()},
           "date": time.strftime("%Y-%m-%dT%H:%M:%S"),
           "method": "median over rounds of the solve clock / iterations, one process per "
                     "revision per round, alternating order"}
    out = Path(a.out)
    out.mkdir(parents=True, exist_ok=True)
    path = out / f"ab_{a.base}_{head_rev}{'_' + a.tag if a.tag else ''}.json"
    path.write_text(json.dumps(rec, indent=1))
    print(f"wrote {path}")


if __name__ == "__main__":
    main()
