"""``tau="auto"`` against the best ``tau`` in hindsight (issue 14), with Wiener and BP.

Grid: 4 scenes (natural, text, usaf, points) x 4 noise levels (noise-free, Gaussian variance
1e-3, the paper's Fig. 7 variance 1e-2, photon-limited with 1e4 photons at the brightest pixel)
x 2 cameras (the ``simulation`` preset on the transfer-function model; the ``experiment`` preset
binned to 300^2 on the exact finite-aperture model, where ``clfza.reconstruct`` runs the
crop-split ADMM, 400 iterations by default). For every case: ADMM over a dense ``tau`` grid
(``GRID``, 3 per decade from 1e-5 to 31.6; the oracle is the best grid point), ADMM with
``tau="auto"``, ``method="wiener"`` and BP. PSNR after the positive-gain affine fit of
:func:`clfza.metrics.compare`.

Headline (simulation preset, natural scene): the time each method needs to reach 30 dB on the
noise-free frame and 25 dB at the Fig. 7 noise, with the ``tau`` it needs (the fastest ``tau``
of the grid that gets there).

Writes ``bench/results/tau_<machine>.json`` and ``.png``; the machine record (CPU, cores, load
average, OpenCL device and implementation) and the git revision measured (at the start and the
end: the tree is shared) are in the JSON, with the summary per camera. ``--reuse-grid`` keeps
the oracle grid of an earlier run; ``--cameras experiment_bin8`` runs one camera.

    .venv/bin/python bench/bench_tau.py [--iters 100] [--reuse-grid]
"""

from __future__ import annotations

import argparse
import json
import time
import warnings
from pathlib import Path

import numpy as np

import clfza
from clfza.benchmarks import _scenes as scenes
from clfza.benchmarks._machine import machine_record, machine_slug
from clfza.metrics import compare
from clfza.simulation import Noise

RESULTS = Path(__file__).parent / "results"
ROOT = Path(__file__).resolve().parents[1]  # the repository
SCENES = ("natural", "text", "usaf", "points")
NOISES = {"clean": None, "gauss1e-3": Noise(gaussian_var=1e-3),
          "gauss1e-2": Noise(gaussian_var=1e-2), "photons1e4": Noise(photons=1e4)}
MODEL = ["tf"]  # the current camera's model (set in main)
GRID = [float(t) for t in np.logspace(-5, 1.5, 20)]  # 3 per decade


def revision(root: Path = ROOT) -> dict:
    """The code measured: HEAD and whether clfza/ differs from it (the tree is shared)."""
    import subprocess

    def git(*args):
        try:
            # in the repository's root: the pathspec "clfza" is relative to the working
            # directory (run from bench/ it named bench/clfza, and a modified clfza/ read as
            # unmodified)
            return subprocess.run(["git", *args], cwd=root, text=True, capture_output=True,
                                  timeout=30).stdout.strip()
        except (OSError, subprocess.SubprocessError):
            return None

    return {"commit": git("rev-parse", "HEAD"),
            "clfza_modified": bool(git("status", "--porcelain", "--", "clfza"))}


def cameras() -> dict:
    """name -> (camera, model, ADMM iterations: 50 on the transfer-function model, the exact
    model's default (400) there)."""
    from clfza.solvers import default_iters

    return {"simulation": (clfza.Camera.preset("simulation"), "tf", 50),
            "experiment_bin8": (clfza.Camera.preset("experiment").with_shape(
                (300, 300), 0.00375 * 8), "exact", default_iters("admm", "exact"))}


def _admm(y, cam, iters, **kw):
    last: dict = {}

    def keep(rec):
        last.update(rec)

    t0 = time.perf_counter()
    r = clfza.reconstruct(y, cam, "admm", backend="opencl", iters=iters, callback=keep,
                          model=MODEL[0], **kw)
    return r, time.perf_counter() - t0, last.get("residual_norm2")


def grid_case(cam, meas, iters: int) -> dict:
    rows = []
    for tau in GRID:
        r, t, res2 = _admm(meas.y, cam, iters, tau=tau)
        rows.append({"tau": tau, "psnr": compare(r.image, meas.truth)["psnr"],
                     "residual2": res2, "time_s": t, "iterations": r.info.iterations,
                     "stop_reason": r.info.stop_reason})
    best = max(rows, key=lambda d: d["psnr"])
    return {"grid": rows, "oracle_tau": best["tau"], "oracle_psnr": best["psnr"],
            "model": r.info.params["model"]}


def auto_case(cam, meas, iters: int) -> dict:
    r, t, _ = _admm(meas.y, cam, iters, tau="auto")
    a = r.info.stats.get("tau_auto", {})
    out = {"auto_tau": r.info.params["tau"], "auto_psnr": compare(r.image, meas.truth)["psnr"],
           "auto_time_s": t, "auto_iterations": r.info.iterations,
           "auto_stop_reason": r.info.stop_reason,
           "data_scale_factor": r.info.stats.get("data_scale_factor"),
           "auto_criterion": {k: v for k, v in a.items() if k != "stages"},
           "auto_stages": a.get("stages")}
    t0 = time.perf_counter()
    w = clfza.reconstruct(meas.y, cam, "wiener", backend="opencl")
    out["wiener_psnr"] = compare(w.image, meas.truth)["psnr"]
    out["wiener_time_s"] = time.perf_counter() - t0
    t0 = time.perf_counter()
    b = clfza.reconstruct(meas.y, cam, "bp", backend="opencl")
    out["bp_psnr"] = compare(b.image, meas.truth)["psnr"]
    out["bp_time_s"] = time.perf_counter() - t0
    return out


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--iters", type=int, default=None, help="ADMM iterations (default: 50 "
                   "on the simulation preset's Eq. 17 model, the solver's default (400) on "
                   "the exact model)")
    p.add_argument("--reuse-grid", action="store_true")
    p.add_argument("--skip-headline", action="store_true")
    p.add_argument("--cameras", nargs="+", default=None)
    p.add_argument("--out", default=str(RESULTS))
    a = p.parse_args(argv)
    warnings.simplefilter("ignore")
    machine = machine_record()
    rev = revision()
    out = Path(a.out)
    out.mkdir(parents=True, exist_ok=True)
    stem = out / f"tau_{machine_slug(machine)}"
    prev = {}
    if a.reuse_grid and stem.with_suffix(".json").exists():
        prev = {(c["camera"], c["scene"], c["noise"]): c
                for c in json.loads(stem.with_suffix(".json").read_text())["cases"]}
    cases = []
    for cname, (cam, model, iters) in cameras().items():
        if a.cameras and cname not in a.cameras:
            continue
        MODEL[0] = model
        iters = a.iters or iters
        for noise_name, noise in NOISES.items():
            for scene in SCENES:
                meas = scenes.measurement(scene, cam, noise).measurement
                key = (cname, scene, noise_name)
                row = {"camera": cname, "scene": scene, "noise": noise_name, "iters": iters,
                       "y_energy": float(np.sum(meas.y**2)), "pixels": int(meas.y.size),
                       "noise_energy": float(np.sum((meas.y - meas.clean_y) ** 2))}
                if key in prev and "grid" in prev[key]:
                    row.update({k: prev[key][k] for k in ("grid", "oracle_tau", "oracle_psnr",
                                                          "model")})
                else:
                    row.update(grid_case(cam, meas, iters))
                row.update(auto_case(cam, meas, iters))
                row["auto_gap_db"] = row["oracle_psnr"] - row["auto_psnr"]
                cases.append(row)
                (out / ".tau_partial.json").write_text(json.dumps(cases))  # progress
                print(f"{cname:16s} {noise_name:10s} {scene:8s} oracle {row['oracle_psnr']:6.2f} "
                      f"(tau {row['oracle_tau']:.3g})  auto {row['auto_psnr']:6.2f} "
                      f"(tau {row['auto_tau']:.3g}, {row['auto_time_s']:.2f} s)  wiener "
                      f"{row['wiener_psnr']:6.2f}  bp {row['bp_psnr']:6.2f}", flush=True)
    gaps = np.array([c["auto_gap_db"] for c in cases])
    summary = {"mean_gap_db": float(gaps.mean()), "max_gap_db": float(gaps.max()),
               "cases": len(cases), "within_1db": int((gaps <= 1).sum()),
               "worse_than_3db": int((gaps > 3).sum())}
    print("tau=auto vs oracle:", summary)
    summary["per_camera"] = per_camera(cases)
    print("per camera:", summary["per_camera"])
    rev["at_end"] = revision()  # the tree is shared: did the code change during the run?
    result = {"machine": machine, "revision": rev, "grid": GRID, "summary": summary,
              "cases": cases, "load_average_end": machine_record()["load_average"]}
    if not a.skip_headline:
        result["headline"] = headline()
    stem.with_suffix(".json").write_text(json.dumps(result, indent=1))
    plot(result, stem.with_suffix(".png"))
    (out / ".tau_partial.json").unlink(missing_ok=True)
    print("wrote", stem.with_suffix(".json"), stem.with_suffix(".png"))
    return 0


def per_camera(cases: list[dict]) -> dict:
    """Mean and worst gap per camera, the worst case named (scene/noise)."""
    out = {}
    for cam in dict.fromkeys(c["camera"] for c in cases):
        rows = [c for c in cases if c["camera"] == cam]
        worst = max(rows, key=lambda c: c["auto_gap_db"])
        out[cam] = {"mean_gap_db": float(np.mean([c["auto_gap_db"] for c in rows])),
                    "max_gap_db": worst["auto_gap_db"],
                    "worst": f"{worst['scene']}/{worst['noise']}",
                    "worst_tau": worst["auto_tau"], "worst_oracle_tau": worst["oracle_tau"],
                    "within_1db": sum(c["auto_gap_db"] <= 1 for c in rows),
                    "worse_than_3db": sum(c["auto_gap_db"] > 3 for c in rows)}
    return out


HEADLINE_TAUS = (0.003, 0.01, 0.03, 0.1, 0.3, 1.0)
HEADLINE_METHODS = (("admm", "auto", {}), ("admm", "tf", {}), ("fista", "auto", {}),
                    ("twist", "auto", {"mode": "efficient"}), ("twist", "auto", {"mode": "paper"}))


def _time_to(rec, target: float, offset: float = 0.0):
    for c in rec.info.checkpoints:
        if c.get("psnr") is not None and c["psnr"] >= target:
            return offset + c["time"], c["iteration"]
    return None, None


def headline(iters: int = 200) -> list[dict]:
    """Time to 30 dB noise-free and to 25 dB at the Fig. 7 noise (simulation preset, natural
    scene, OpenCL float32), per method with the fastest tau of HEADLINE_TAUS and with
    tau="auto" (its search counted), and Wiener (one solve)."""
    cam = clfza.Camera.preset("simulation")
    rows = []
    for noise_name, noise, target in (("clean", None, 30.0), ("gauss1e-2", NOISES["gauss1e-2"],
                                                                25.0)):
        meas = scenes.measurement("natural", cam, noise).measurement
        for method, model, extra in HEADLINE_METHODS:
            label = method + (f"-{extra['mode']}" if extra else "") + f" (model {model})"
            best = None
            for tau in (*HEADLINE_TAUS, "auto"):
                t0 = time.perf_counter()
                try:
                    r = clfza.reconstruct(meas.y, cam, method, backend="opencl", tau=tau,
                                          iters=iters, model=model, truth=meas.truth,
                                          checkpoints=5, **extra)
                except clfza.ClfzaError as e:  # e.g. tau=auto for TwIST's paper mode
                    rows.append({"noise": noise_name, "method": label, "tau": tau,
                                 "error": str(e)})
                    continue
                wall = time.perf_counter() - t0
                offset = 0.0
                if tau == "auto":  # the search counts: wall time outside the final solve
                    offset = max(0.0, wall - r.info.timings["solve"]
                                 - r.info.timings.get("checkpoint_overhead", 0.0)
                                 - r.info.timings.get("compile", 0.0)
                                 - r.info.timings.get("plan", 0.0))
                t, it = _time_to(r, target, offset)
                final = r.info.checkpoints[-1]["psnr"] if r.info.checkpoints else None
                row = {"noise": noise_name, "target_db": target, "method": label,
                       "tau": r.info.params["tau"] if tau == "auto" else tau,
                       "tau_auto": tau == "auto", "time_to_target_s": t, "iteration": it,
                       "final_psnr": final, "model": r.info.params["model"]}
                rows.append(row)
                if tau != "auto" and t is not None and (best is None or t < best[0]):
                    best = (t, tau)
            print(f"headline {noise_name:9s} {label:28s} fastest tau {best}", flush=True)
        t0 = time.perf_counter()
        w = clfza.reconstruct(meas.y, cam, "wiener", backend="opencl")
        wt = time.perf_counter() - t0
        wp = compare(w.image, meas.truth)["psnr"]
        rows.append({"noise": noise_name, "target_db": target, "method": "wiener",
                     "tau": None, "lam": w.info.stats["lam"], "final_psnr": wp,
                     "time_to_target_s": w.info.timings["solve"] if wp >= target else None,
                     "wall_s": wt})
    return rows


def plot(result: dict, path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    cams = sorted({c["camera"] for c in result["cases"]})
    fig, axes = plt.subplots(1, len(cams), figsize=(6.5 * len(cams), 4.5), squeeze=False)
    for ax, cam in zip(axes[0], cams, strict=True):
        rows = [c for c in result["cases"] if c["camera"] == cam]
        xs = np.arange(len(rows))
        for key, lab, mk in (("oracle_psnr", "ADMM, best tau (grid)", "o"),
                             ("auto_psnr", "ADMM, tau=auto", "s"),
                             ("wiener_psnr", "Wiener", "^"), ("bp_psnr", "BP", "x")):
            ax.plot(xs, [r[key] for r in rows], mk, label=lab)
        ax.set_xticks(xs, [f"{r['noise']}\n{r['scene']}" for r in rows], rotation=90,
                      fontsize=6)
        ax.set_ylabel("PSNR (dB)")
        ax.set_title(f"{cam} ({rows[0]['iters']} ADMM iterations)")
        ax.grid(alpha=0.3)
    axes[0][0].legend(fontsize=7)
    m = result["machine"]
    dev = m.get("device") or {}
    fig.suptitle(f"tau=auto vs the best tau in hindsight; {m['cpu_model']}, "
                 f"{m['cores_usable']} cores, OpenCL {dev.get('platform', '?')} "
                 f"({dev.get('name', '?')}), load {m['load_average']}", fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


if __name__ == "__main__":
    raise SystemExit(main())
