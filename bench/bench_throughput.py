"""Throughput of a frame stream: frames/s end to end (read, solve, write) on Dask vs one process.

For each size (512^2 and 2048^2 by default) and method (ADMM-TV, TwIST-TV paper mode; OpenCL,
50 iterations, model "tf"), a stream of simulated raw frames (uint16 .npy files) is
reconstructed by :func:`clfza.reconstruct_many` under these configurations:

* ``single``: the single-process batch, in a clean process of its own (spawned before any
  cluster; no Dask in it): this process hosts the LocalClusters' schedulers and nannies, and
  batches run here solved 512^2 ADMM frames in 123 ms where a worker took 89;
* ``dask-1``: a LocalCluster of 1 worker process (free to use every core);
* ``dask-2``: 2 worker processes, each free to use every core (PoCL and scipy.fft threads);
* ``dask-1-pinned``: 1 worker process on one core (the unit the 2-pinned run doubles);
* ``dask-2-pinned``: 2 worker processes, one core each (``pin_cpus=True``);
* ``...-before`` (512^2 only): the same with ``chunk=1, cache_backends=False``, i.e. one
  Dask task per frame and the solver set-up rebuilt per frame, as before issue 15's overhead
  work -- the before/after comparison, measured in the same run.

The machine is shared, so the clusters stay up for the whole run and every configuration is
run once per round, rounds interleaved (the order rotated each round); each row reports the
median over the rounds, the spread (min/max of frames/s) and the load average around its
runs. Each cluster is warmed up per size and method first (kernels compile once per worker
process; the compile time of a worker's first frame is reported separately).

Per frame, the time is split into the workers' own timings (read, prepare, compile, plan,
solve, write, and the rest of the task: records, JSON) and the distributed overhead,
scheduling + transfer: the workers' idle time per frame, ``(wall x workers - sum of task
times) / frames`` (for ``single``, the client loop's own overhead); a no-op task round trip is
measured too. A cost model projects N workers from these measurements (a projection, not a
measurement).

    .venv/bin/python bench/bench_throughput.py [--frames 16] [--sizes 512,2048] [--rounds 3]

Writes ``bench/results/throughput_<tag>.json`` and ``.png``; the tag defaults to the CPU's
name and core count (e.g. ``intel-xeon-2c``), see :func:`default_tag`.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import re
import subprocess
import tempfile
import time
from pathlib import Path

import numpy as np

import clfza
from clfza.distributed._batch import reconstruct_many
from clfza.distributed._cluster import open_client, pin_plugin
from clfza.io import write_array

RESULTS = Path(__file__).resolve().parent / "results"
# model "tf" (the FFT-grid operator) pinned, so that solves compare with the README's
METHODS = {"admm": {"stop": "none", "model": "tf"}, "twist": {"mode": "paper", "model": "tf"}}
PARTS = ("read", "prepare", "compile", "plan", "solve", "write", "task_other")
BEFORE = {"chunk": 1, "cache_backends": False}
AFTER = {"chunk": "auto", "cache_backends": True}
# (name, cluster, options); cluster None: this process
CONFIGS = [("single", None, AFTER), ("single-before", None, BEFORE),
           ("dask-1", "1", AFTER), ("dask-1-before", "1", BEFORE),
           ("dask-1-pinned", "1p", AFTER), ("dask-2", "2", AFTER),
           ("dask-2-pinned", "2p", AFTER), ("dask-2-pinned-before", "2p", BEFORE)]
# key: (workers, cores per worker: None = every core)
CLUSTERS = {"1": (1, None), "1p": (1, 1), "2": (2, None), "2p": (2, 1)}
# 2 workers against 1, per pair of configurations (see scaling())
SCALING = {"one_core_each": ("dask-2-pinned", "dask-1-pinned"),
           "every_core": ("dask-2", "dask-1")}


def cpu_name() -> str:
    """The CPU's model name (``/proc/cpuinfo``, else ``lscpu``, else ``platform``)."""
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.lower().startswith("model name"):
                return line.split(":", 1)[1].strip()
    except OSError:
        pass
    try:
        out = subprocess.run(["lscpu"], capture_output=True, text=True, timeout=10).stdout
        m = re.search(r"^Model name:\s*(.+)$", out, re.M)
        if m:
            return m.group(1).strip()
    except (OSError, subprocess.SubprocessError):
        pass
    return platform.processor() or platform.machine() or "cpu"


def default_tag(name: str | None = None, cores: int | None = None) -> str:
    """A file tag from the CPU: vendor and family words of its model name and the core count,
    e.g. ``"Intel(R) Xeon(R) Processor"`` on 2 cores -> ``intel-xeon-2c``, ``"AMD EPYC 7B13
    64-Core Processor"`` -> ``amd-epyc-7b13-2c``."""
    name = cpu_name() if name is None else name
    cores = (len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity")
             else os.cpu_count() or 1) if cores is None else cores
    s = re.sub(r"\((r|tm|c)\)|@.*$|\bcpu\b|\bprocessor\b|\d+-core\b", " ", name.lower())
    words = [w for w in re.split(r"[^a-z0-9]+", s) if w][:3] or ["cpu"]
    return "-".join(words + [f"{cores}c"])


def make_frames(d: Path, n: int, size: int) -> tuple[list[Path], clfza.Camera]:
    """``n`` simulated raw frames (uint16 .npy) of the paper's camera at ``size``^2."""
    from skimage import data, transform

    cam = clfza.Camera.preset("simulation")
    if size != cam.shape[0]:
        cam = cam.with_shape((size, size), cam.pitch * cam.shape[0] / size)
    base = data.camera().astype(float) / 255
    rng = np.random.default_rng(0)
    files = []
    for i in range(n):
        scene = np.roll(base, (8 * i, 5 * i), axis=(0, 1))
        scene = transform.resize(scene, (size // 4, size // 4)) + 0.01 * rng.random((size // 4,
                                                                                      size // 4))
        f = clfza.simulate(scene, cam, object_width=20.0).frame
        files.append(write_array(d / f"frame{i:03d}.npy",
                                 np.round(f / f.max() * 60000).astype(np.uint16)))
    return files, cam


def noop(i: int) -> int:
    return i


def round_trip(client, n: int = 200) -> float:
    """Seconds per no-op task, submitted and gathered like the batch (scheduling + transfer)."""
    client.gather([client.submit(noop, i, pure=False) for i in range(4)])
    t0 = time.perf_counter()
    client.gather([client.submit(noop, i, pure=False) for i in range(n)])
    return (time.perf_counter() - t0) / n


def _split(res, wall: float, workers: int, t0_unix: float, t1_unix: float) -> dict:
    """Mean seconds per frame: the workers' parts, and scheduling + transfer (the workers'
    idle time per frame) split by when it happens: ``head`` (batch start to each worker's
    first frame), ``gaps`` (between consecutive frames on a worker: the round trips between
    tasks; within a chunk only the loop), ``tail`` (each worker's last frame to the batch's
    end: the imbalance of the last tasks and the result's way back)."""
    ok = [r for r in res.results if r.ok]
    n = max(len(ok), 1)
    per = {}
    for k in PARTS[:-1] + ("task",):
        per[k] = float(np.mean([r.timings.get(k, 0.0) for r in ok]))
    per["task_other"] = max(per["task"] - sum(per[k] for k in PARTS[:-1]), 0.0)
    idle = (wall * workers - sum(r.timings["task"] for r in ok)) / n
    per["sched_transfer"] = max(idle, 0.0)
    by: dict = {}
    for r in ok:
        by.setdefault(r.record["worker"]["pid"], []).append(
            (r.timings["start_unix"], r.timings["end_unix"]))
    head = gaps = tail = 0.0
    for spans in by.values():
        spans.sort()
        head += spans[0][0] - t0_unix
        gaps += sum(b[0] - a[1] for a, b in zip(spans, spans[1:], strict=False))
        tail += t1_unix - spans[-1][1]
    idle_workers = max(workers - len(by), 0) * wall  # a worker that got no frame
    per["sched_head"], per["sched_gaps"] = head / n, gaps / n
    per["sched_tail"] = (tail + idle_workers) / n
    return per


def run_stream(files, cam, method: str, iters: int, out: Path, client, opts: dict) -> dict:
    """One timed pass over the stream; per-frame split and the tasks' chunk sizes."""
    load0 = os.getloadavg()[0]
    t0u, t0 = time.time(), time.perf_counter()
    kw = {"client": client} if client is not None else {}
    res = reconstruct_many(files, cam, method, out_dir=out, iters=iters, **kw, **opts,
                           **METHODS[method])
    wall = time.perf_counter() - t0
    t1u = time.time()
    assert not res.failed, [r.error for r in res.failed]
    workers = res.n_workers if client is not None else 1
    return {"wall_s": wall, "frames_per_s": len(files) / wall, "workers": workers,
            "per_frame_s": _split(res, wall, workers, t0u, t1u),
            "load_1min": [load0, os.getloadavg()[0]],
            "iterations": res.results[0].record["iterations"],
            "device": res.results[0].record["device"]}


def warm_single(files, cam, method: str, iters: int, out: Path) -> float:
    """The clean process's first frames (compile, plan); returns the compile time."""
    res = reconstruct_many(files, cam, method, out_dir=out, iters=iters, **METHODS[method])
    return max(r.timings.get("compile", 0.0) for r in res.results)


def _median_row(name: str, runs: list[dict]) -> dict:
    fps = [r["frames_per_s"] for r in runs]
    per = {k: float(np.median([r["per_frame_s"][k] for r in runs]))
           for k in runs[0]["per_frame_s"]}
    loads = [v for r in runs for v in r["load_1min"]]
    return {"config": name, "rounds": len(runs), "frames_per_s": float(np.median(fps)),
            "frames_per_s_min_max": [min(fps), max(fps)],
            "spread_pct": 100 * (max(fps) - min(fps)) / float(np.median(fps)),
            "wall_s": float(np.median([r["wall_s"] for r in runs])), "per_frame_s": per,
            "overhead_vs_solve_pct": 100 * per["sched_transfer"] / max(per["solve"], 1e-9),
            "overhead_pct_per_round": [100 * r["per_frame_s"]["sched_transfer"]
                                       / max(r["per_frame_s"]["solve"], 1e-9) for r in runs],
            "load_1min_min_max": [min(loads), max(loads)],
            "iterations": runs[0]["iterations"], "device": runs[0]["device"],
            "workers": runs[0]["workers"]}


def project(rows: list[dict], cores: int) -> dict:
    """Cost model: N single-core workers run independent frames, so frames/s(N) =
    N / (t_task + t_sched) while N <= cores (and memory bandwidth holds); beyond, flat."""
    pinned = next((r for r in rows if r["config"] == "dask-2-pinned"), None)
    if pinned is None:
        return {}
    t = pinned["per_frame_s"]["task"] + pinned["per_frame_s"]["sched_transfer"]
    return {"model": "fps(N) = min(N, cores) / (t_task_1core + t_sched)",
            "t_task_1core_s": pinned["per_frame_s"]["task"],
            "t_sched_s": pinned["per_frame_s"]["sched_transfer"],
            "projected_fps": {str(n): min(n, cores) / t for n in (1, 2, 4, 8, 16)},
            "note": "PROJECTION from the dask-2-pinned measurements, not measured; assumes "
                    "one core per worker, no memory-bandwidth limit (2 workers share one "
                    "here), a file system that keeps up and a scheduler that is not the "
                    "bottleneck (measured no-op round trip per task; tasks carry chunks)"}


def scaling(rows: list[dict]) -> dict:
    """frames/s of 2 workers over 1, measured: one core each (Dask's scaling, what the
    projection multiplies) and free to use every core (what a user of this machine gets: one
    worker already runs PoCL's and scipy.fft's threads on both cores)."""
    fps = {r["config"]: r["frames_per_s"] for r in rows}
    return {k: fps[a] / fps[b] for k, (a, b) in SCALING.items() if a in fps and b in fps}


def machine() -> dict:
    import dask
    import distributed

    from clfza.cl import get_runtime

    rt = get_runtime()
    try:
        commit = subprocess.run(["git", "rev-parse", "--short", "HEAD"], capture_output=True,
                                text=True, cwd=Path(__file__).parent, timeout=10).stdout.strip()
    except (OSError, subprocess.SubprocessError):
        commit = ""
    return {"cpu": cpu_name(), "tag": default_tag(), "platform": platform.platform(),
            "cpus": os.cpu_count(), "python": platform.python_version(),
            "clfza": clfza.__version__, "git_commit": commit, "dask": dask.__version__,
            "distributed": distributed.__version__, "numpy": np.__version__,
            "device": rt.info.describe(), "load_average_1_5_15_at_save": list(os.getloadavg())}


def plot(report: dict, path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    rows = report["rows"]
    cases = sorted({(r["size"], r["method"]) for r in rows})
    fig, axes = plt.subplots(2, len(cases), figsize=(4.6 * len(cases), 8), squeeze=False)
    for j, (size, method) in enumerate(cases):
        sub = [r for r in rows if (r["size"], r["method"]) == (size, method)]
        names = [r["config"] for r in sub]
        ax = axes[0][j]
        fps = np.array([r["frames_per_s"] for r in sub])
        lo = fps - np.array([r["frames_per_s_min_max"][0] for r in sub])
        hi = np.array([r["frames_per_s_min_max"][1] for r in sub]) - fps
        ax.bar(names, fps, yerr=[lo, hi], color="C0", capsize=3)
        ax.set_title(f"{method.upper()} {size}^2, {sub[0]['iterations']} it", fontsize=9)
        ax.set_ylabel("frames/s end to end (median, min-max)")
        ax.tick_params(axis="x", rotation=45, labelsize=7)
        ax = axes[1][j]
        bottom = np.zeros(len(sub))
        for k, part in enumerate(PARTS + ("sched_transfer",)):  # sched_*: its split
            v = np.array([r["per_frame_s"][part] * 1e3 for r in sub])
            ax.bar(names, v, bottom=bottom, label=part, color=f"C{k}")
            bottom += v
        ax.set_ylabel("ms per frame (per worker)")
        ax.tick_params(axis="x", rotation=45, labelsize=7)
    axes[1][0].legend(fontsize=7)
    m = report["machine"]
    fig.suptitle(f"clfza stream throughput; {m['cpu']}, {m['cpus']} cores; {m['device'][:50]}; "
                 f"dask {m['dask']}; medians of {report['rounds']} interleaved rounds",
                 fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--frames", type=int, default=16, help="frames per stream at 512^2 "
                    "(2048^2: a quarter, at least 4)")
    ap.add_argument("--frames-large", type=int, default=None,
                    help="frames per stream above 512^2 (default: --frames / 4, at least 4)")
    ap.add_argument("--sizes", default="512,2048", help="comma list")
    ap.add_argument("--iters", type=int, default=50)
    ap.add_argument("--methods", default="admm,twist")
    ap.add_argument("--rounds", type=int, default=3, help="interleaved rounds per configuration")
    ap.add_argument("--configs", default=",".join(c[0] for c in CONFIGS),
                    help="comma list of configurations (default: all)")
    ap.add_argument("--before-max-size", type=int, default=512,
                    help="run the '-before' configurations up to this size")
    ap.add_argument("--tag", default=None, help="results file tag (default: from the CPU, "
                    f"here {default_tag()!r})")
    args = ap.parse_args()
    args.tag = args.tag or default_tag()
    args.configs = [c.strip() for c in args.configs.split(",") if c.strip()]
    unknown = sorted(set(args.configs) - {c[0] for c in CONFIGS})
    if unknown:
        ap.error(f"unknown configuration(s) {unknown}")
    report = {"machine": machine(), "iters": args.iters, "rounds": args.rounds, "rows": [],
              "noop_round_trip_s": {}, "startup_s": {}, "compile_first_frame_s": {}}
    import multiprocessing
    from concurrent.futures import ProcessPoolExecutor

    with tempfile.TemporaryDirectory() as tmp, ProcessPoolExecutor(
            1, mp_context=multiprocessing.get_context("spawn")) as single:
        single.submit(noop, 0).result()  # started before any cluster touches the environment
        clients = {}
        ctxs = []
        try:
            used = {c[1] for c in CONFIGS if c[0] in args.configs} - {None}
            for key, (w, per) in CLUSTERS.items():
                if key not in used:
                    continue
                t0 = time.perf_counter()
                ctx = open_client(workers=w)
                clients[key] = ctx.__enter__()[0]
                if per is not None:  # pin_cores: worker k of n gets cores // n of them
                    clients[key].register_plugin(pin_plugin(max(w, (os.cpu_count() or 1)
                                                                // per)))
                ctxs.append(ctx)
                report["startup_s"][key] = time.perf_counter() - t0
                report["noop_round_trip_s"][key] = round_trip(clients[key])
            for size in (int(s) for s in args.sizes.split(",")):
                n = args.frames if size <= 512 else (args.frames_large
                                                      or max(4, args.frames // 4))
                files, cam = make_frames(Path(tmp) / f"in{size}", n, size)
                for method in args.methods.split(","):
                    _case(report, args, size, method, files, cam, clients, Path(tmp), single)
                    _save(report, args)  # partial results survive an interrupted run
        finally:
            for ctx in reversed(ctxs):
                ctx.__exit__(None, None, None)
    out = _save(report, args)
    print(f"wrote {out} and {out.with_suffix('.png')}")


def _case(report, args, size, method, files, cam, clients, tmp: Path, single) -> None:
    configs = [c for c in CONFIGS if c[0] in args.configs and not (
        c[0].endswith("-before") and size > args.before_max_size)]
    case = f"{size}-{method}"
    warm = {}
    warm["None"] = single.submit(warm_single, files[:1], cam, method, args.iters,
                                 tmp / f"warm-{case}-single").result()
    for key, c in clients.items():  # compile, plan, first frames
        res = reconstruct_many(files[:CLUSTERS[key][0]], cam, method,
                               out_dir=tmp / f"warm-{case}-{key}", client=c, iters=args.iters,
                               **METHODS[method])
        warm[str(key)] = max(r.timings.get("compile", 0.0) for r in res.results)
    report["compile_first_frame_s"][case] = warm
    runs: dict[str, list] = {c[0]: [] for c in configs}
    for rnd in range(args.rounds):
        k = rnd % len(configs)
        for name, key, opts in configs[k:] + configs[:k]:
            out = tmp / f"{case}-{name}-{rnd}"
            r = (single.submit(run_stream, files, cam, method, args.iters, out, None, opts)
                 .result() if key is None else
                 run_stream(files, cam, method, args.iters, out, clients[key], opts))
            runs[name].append(r)
            print(f"{size}^2 {method:6s} round {rnd} {name:21s} {r['frames_per_s']:6.2f} "
                  f"frames/s  solve {r['per_frame_s']['solve'] * 1e3:7.1f} ms  plan "
                  f"{r['per_frame_s']['plan'] * 1e3:5.1f} ms  sched+transfer "
                  f"{r['per_frame_s']['sched_transfer'] * 1e3:6.1f} ms (gaps "
                  f"{r['per_frame_s']['sched_gaps'] * 1e3:5.1f})  load "
                  f"{r['load_1min'][1]:.2f}", flush=True)
    for name, _, opts in configs:
        row = _median_row(name, runs[name])
        row.update(size=size, method=method, frames=len(files), options=opts,
                   runs=runs[name])
        report["rows"].append(row)


def _save(report: dict, args) -> Path:
    rows = report["rows"]
    report["projection"] = {f"{s}-{m}": project([r for r in rows
                                                 if (r["size"], r["method"]) == (s, m)],
                                                os.cpu_count() or 1)
                            for s, m in sorted({(r["size"], r["method"]) for r in rows})}
    report["scaling_2_over_1"] = {f"{s}-{m}": scaling([r for r in rows
                                                       if (r["size"], r["method"]) == (s, m)])
                                  for s, m in sorted({(r["size"], r["method"]) for r in rows})}
    report["machine"]["load_average_1_5_15_at_save"] = list(os.getloadavg())
    RESULTS.mkdir(exist_ok=True)
    out = RESULTS / f"throughput_{args.tag}.json"
    out.write_text(json.dumps(report, indent=2) + "\n")
    if rows:
        plot(report, out.with_suffix(".png"))
    return out


if __name__ == "__main__":
    main()
