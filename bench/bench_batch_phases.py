"""A batched call's host work by phase, before and after a change, in one run (issue 37).

    python bench/bench_batch_phases.py --base REV [--work REV] [--devices 1:0 0:0] [--n 512]
                                       [--frames 16] [--rounds 3]
                                       [--out bench/results/batch_phases_NAME]

Each round runs ``tools/profile_batch.py --phases`` (whole batched ADMM calls of ``--frames``
frames, 2 iterations each, split by phase, ms per frame, the median of 5 calls; with
``--host``, ``--host-phases``: set_measurement, frame_starts and check_finite alone, 15 calls
each, this checkout's tool on each tree's clfza) once per device
for the base revision (``git archive REV``, its kernels through ``CLFZA_KERNEL_DIR``) and for
the working tree (or ``--work REV``, exported the same way: the tree can change meanwhile), in
alternating order, each in its own process. Written: per device, the
median over rounds of each phase for both, with the load average around each run, to
``OUT_<impl>.json`` and ``.md`` (``impl`` from the device's platform).
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import re
import statistics
import subprocess
import sys
import tarfile
import tempfile
import time
from io import BytesIO
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def export_tree(rev: str, dest: Path) -> str:
    """``git archive rev`` into ``dest``; returns the commit's short hash."""
    data = subprocess.run(["git", "archive", rev], cwd=ROOT, check=True,
                          capture_output=True).stdout
    with tarfile.open(fileobj=BytesIO(data)) as t:
        t.extractall(dest, filter="data")
    return git("rev-parse", "--short", rev)


def git(*args: str) -> str:
    return subprocess.run(["git", *args], cwd=ROOT, check=True, capture_output=True,
                          text=True).stdout.strip()


def phases(tree: Path, device: str, n: int, frames: int, base: bool, host: bool = False
           ) -> dict:
    env = dict(os.environ)
    if base:
        env.update(PYTHONPATH=str(tree), CLFZA_KERNEL_DIR=str(tree / "kernels"))
    # --host: this checkout's tool (a base revision's may not have --host-phases) on the
    # tree's clfza
    tool = (ROOT if host else tree) / "tools" / "profile_batch.py"
    mode = ["--host-phases", "--reps", "15"] if host else ["--phases"]
    out = subprocess.run([sys.executable, str(tool), *mode,
                          "--device", device, "--n", str(n), "--frames", str(frames)],
                         env=env, cwd=tempfile.gettempdir(), check=True, capture_output=True,
                         text=True).stdout
    row = {}
    for line in out.splitlines():
        m = re.match(r"^\s{2}(\S.*?)\s+(-?\d+\.\d+)$", line)
        if m:
            # the base tool's label of the same phase
            row[m.group(1).replace("FourierSolve.setup (inverses)", "FourierSolve.setup")] = \
                float(m.group(2))
    return row


def cpu_model() -> str:
    try:
        with open("/proc/cpuinfo", encoding="utf-8") as f:
            for line in f:
                if line.startswith("model name"):
                    return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or platform.machine()


def device_info(device: str) -> tuple[str, str]:
    from clfza.cl import get_runtime

    info = get_runtime(device).info
    plat, ver = info.platform, info.driver or ""
    if "portable" in plat.lower():
        impl = "pocl30" if ver.startswith("3.0") else "pocl31"
    elif "intel" in plat.lower():
        impl = "intel"
    else:
        impl = re.sub(r"\W+", "-", plat.lower()).strip("-")
    return impl, f"{plat} {ver} ({info.name})".replace("  ", " ")


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--base", required=True, help="the revision to compare against")
    p.add_argument("--work", default=None,
                   help="the revision to measure (default: the working tree)")
    p.add_argument("--devices", nargs="+", default=["1:0", "0:0"])
    p.add_argument("--n", type=int, default=512)
    p.add_argument("--frames", type=int, default=16)
    p.add_argument("--rounds", type=int, default=3)
    p.add_argument("--host", action="store_true",
                   help="the host phases alone (profile_batch.py --host-phases: "
                        "set_measurement, frame_starts, check_finite, 15 calls each per run)")
    p.add_argument("--out", default=str(ROOT / "bench" / "results" / "batch_phases_host"))
    a = p.parse_args(argv)
    with tempfile.TemporaryDirectory(prefix="clfza-base-") as tmp:
        base = Path(tmp) / "base"
        base_rev = export_tree(a.base, base)
        if a.work is None:
            work, work_exported = ROOT, False
            head = git("rev-parse", "--short", "HEAD")
            dirty = bool(git("status", "--porcelain", "--untracked-files=no"))
        else:
            work, work_exported = Path(tmp) / "work", True
            head, dirty = export_tree(a.work, work), False
        runs = {d: {"base": [], "work": [], "load": []} for d in a.devices}
        for r in range(a.rounds):
            for d in a.devices:
                order = [("base", base, True), ("work", work, work_exported)]
                for name, tree, is_base in (order if r % 2 == 0 else order[::-1]):
                    load = os.getloadavg()[0]
                    row = phases(tree, d, a.n, a.frames, is_base, a.host)
                    runs[d][name].append(row)
                    runs[d]["load"].append(round(load, 2))
                    print(f"round {r} {d} {name} load {load:.2f}: call "
                          f"{row.get('call', float('nan')):.2f} ms/frame", flush=True)
    for d in a.devices:
        impl, plat = device_info(d)
        keys = list(runs[d]["work"][0])
        med, low = ({v: {k: fn([x[k] for x in runs[d][v] if k in x]) for k in keys
                         if any(k in x for x in runs[d][v])} for v in ("base", "work")}
                    for fn in (statistics.median, min))
        rec = {"bench": "batch_phases", "date": time.strftime("%Y-%m-%d"),
               "machine": f"{cpu_model()}, {os.cpu_count()} CPUs", "device": d, "platform": plat,
               "n": a.n, "frames": a.frames, "rounds": a.rounds, "base": base_rev,
               "work": head + ("+" if dirty else ""), "load_avg_1min": runs[d]["load"],
               "medians_ms_per_frame": med, "min_ms_per_frame": low,
               "runs": {v: runs[d][v] for v in ("base", "work")}}
        out = Path(f"{a.out}_{impl}")
        out.with_suffix(".json").write_text(json.dumps(rec, indent=1))
        work_arg = (f" --work {a.work}" if a.work else "") + (" --host" if a.host else "")
        what = (f"the host phases alone (`tools/profile_batch.py --host-phases`: a stack of "
                f"{a.frames} frames of {a.n}^2; each run's figures the median, and the minimum "
                "as '(min)', of 15 interleaved calls)" if a.host else
                f"whole batched ADMM calls of {a.frames} frames of {a.n}^2 (2 iterations each), "
                "split by phase (`tools/profile_batch.py --phases`, each round's figure the "
                "median of 5 calls)")
        lines = [f"# A batched call's host work by phase: {rec['base']} against {rec['work']} "
                 f"({plat}, device {d})", "",
                 f"`bench/bench_batch_phases.py --base {a.base}{work_arg} --devices {d} "
                 f"--n {a.n} "
                 f"--frames {a.frames} --rounds {a.rounds}` on {rec['machine']}, "
                 f"{rec['date']}: {what}, ms per frame over {a.rounds} rounds (base and work "
                 "alternating, each in its own process). 1-minute load averages at the runs' "
                 "starts: "
                 f"{', '.join(map(str, runs[d]['load']))}.", "",
                 "The minimum over rounds is the less load-bound figure on a shared machine.",
                 "", "```", f"{'':32s} {'median over rounds':>29s}   {'minimum over rounds':>29s}",
                 f"{'phase':32s} " + "   ".join([f"{'base':>9s} {'work':>9s} {'ratio':>9s}"] * 2)]
        nan = float("nan")
        for k in med["work"]:
            cells = []
            for t in (med, low):
                b, w = t["base"].get(k, nan), t["work"][k]
                cells.append(f"{b:9.3f} {w:9.3f} " + (f"{w / b:9.2f}" if b > 0 else f"{'':9s}"))
            lines.append(f"{k:32s} " + "   ".join(cells))
        lines += ["```", ""]
        out.with_suffix(".md").write_text("\n".join(lines))
        print("\n".join(lines))
    return 0


if __name__ == "__main__":
    sys.exit(main())
