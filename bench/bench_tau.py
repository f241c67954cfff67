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
    p.add_argument("--exact", action="store_true", help="the exact-model protocol (issue 33): "
                   "see exact_main; writes tau_exact_<machine>.{json,md,png}")
    p.add_argument("--tag", default="", help="(with --exact) a suffix of the output name")
    p.add_argument("--before", default=None, help="(with --exact) a former "
                   "clfza/solvers/_tau_exact.py whose rule runs as the 'before' column")
    p.add_argument("--label", default="after", help="(with --exact) the name of this run's "
                   "tau='auto' columns (with --reuse-grid the earlier labels are kept)")
    a = p.parse_args(argv)
    if a.exact:
        return exact_main(a)
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


# --- the exact model's protocol (issue 33, item 2) -------------------------------------------

EXACT_NOISES = {"gauss1e-2": Noise(gaussian_var=1e-2), "gauss1e-3": Noise(gaussian_var=1e-3),
                "gauss1e-4": Noise(gaussian_var=1e-4), "clean": None}
EXACT_COARSE = [float(t) for t in np.logspace(-5, 1, 7)]  # 1 per decade, then refined
EXACT_REFINE = (1.0 / 3.0, 1.0 / 6.0)  # decades either side of the best so far


def exact_cameras() -> dict:
    """name -> (camera, reconstruct options) of the exact model: the simulation preset
    resampled to 256^2 at pitch 0.02 mm (no aperture: no high-pass) and the experiment preset
    binned to 300^2 (pitch 0.03 mm), with the default high-pass and without it."""
    exp = clfza.Camera.preset("experiment").with_shape((300, 300), 0.00375 * 8)
    return {"sim256": (clfza.Camera.preset("simulation").with_shape((256, 256), 0.02), {}),
            "exp300_hp": (exp, {}), "exp300_nohp": (exp, {"highpass": 0})}


def _exact_psnr(meas, cam, iters, opts, tau):
    t0 = time.perf_counter()
    r = clfza.reconstruct(meas.y, cam, "admm", model="exact", iters=iters, tau=tau, **opts)
    return r, compare(r.image, meas.truth)["psnr"], time.perf_counter() - t0


def exact_grid(meas, cam, iters, opts) -> dict:
    """The hindsight-best ``tau``: one per decade from 1e-5 to 10 (PSNR(tau) of the exact
    model is unimodal at these budgets), then 1/3 and 1/6 of a decade either side of the best
    so far; the oracle is the best point tried."""
    rows = {}

    def at(t):
        if t not in rows:
            rows[t] = _exact_psnr(meas, cam, iters, opts, t)[1]

    for t in EXACT_COARSE:
        at(t)
    for step in EXACT_REFINE:
        best = max(rows, key=rows.get)
        for sgn in (-1, 1):
            at(float(best * 10 ** (sgn * step)))
    best = max(rows, key=rows.get)
    return {"grid": [{"tau": t, "psnr": rows[t]} for t in sorted(rows)], "oracle_tau": best,
            "oracle_psnr": rows[best]}


def exact_diagnostics(meas, cam, opts) -> dict:
    """What a tau rule can read and what it should have found: the true noise, the frame's
    estimates (out-of-band spectrum where the camera has one, the Haar MAD), the frame's
    Haar scale ratio, and the high-pass's noise gain."""
    from clfza.models import default_halfwidth, noise_gain
    from clfza.solvers import estimate_noise, haar_mad_sigma
    from clfza.solvers._noise import haar_scale_ratio

    y = np.asarray(meas.y, dtype=np.float64)
    k = opts.get("highpass", default_halfwidth(cam, None))
    sig, method = estimate_noise(y - y.mean(), cam)
    return {"true_sigma": float(np.std(meas.y - meas.clean_y)), "frame_sigma": sig,
            "frame_sigma_method": method, "haar_sigma": haar_mad_sigma(y - y.mean()),
            "haar_ratio": haar_scale_ratio(y - y.mean()), "highpass_k": int(k),
            "noise_gain": noise_gain(k) if k else 1.0, "rms_y": float(np.std(y))}


def old_rule(path: str):
    """A former ``clfza/solvers/_tau_exact.py`` (``git show REV:clfza/solvers/_tau_exact.py``)
    loaded beside the current one, to run its ``exact_group`` as the "before" column."""
    import importlib.util
    import sys

    spec = importlib.util.spec_from_file_location("clfza.solvers._tau_exact_before", path)
    mod = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = mod
    spec.loader.exec_module(mod)
    return mod.exact_group


def exact_auto(meas, cam, iters, opts, group=None) -> dict:
    """``tau="auto"`` with the current rule, or with ``group`` (:func:`old_rule`) in its
    place."""
    from unittest import mock

    import clfza.solvers._tau as tau_mod

    with mock.patch.object(tau_mod, "exact_group", group or tau_mod.exact_group):
        r, p, t = _exact_psnr(meas, cam, iters, opts, "auto")
    a = r.info.stats.get("tau_auto", {})
    return {"tau": r.info.params["tau"], "psnr": p, "time_s": t,
            "criterion": {k: v for k, v in a.items() if k != "stages"},
            "stages": a.get("stages")}


def exact_main(a) -> int:
    """The exact model's ``tau="auto"`` against the hindsight-best ``tau`` (issue 33, item
    2): 4 scenes x 4 noise levels (noise-free, Gaussian variance 1e-4, 1e-3 and Fig. 7's
    1e-2) x :func:`exact_cameras`, ADMM at the exact model's default budget (400) unless
    ``--iters``. ``--reuse-grid`` keeps the oracle of an earlier run and adds this run's
    ``tau="auto"`` under ``--label`` (so the old rule's and the new rule's choices are
    compared against the same oracle)."""
    from clfza.solvers import default_iters

    warnings.simplefilter("ignore")
    machine = machine_record()
    out = Path(a.out)
    out.mkdir(parents=True, exist_ok=True)
    stem = out / f"tau_exact_{machine_slug(machine)}{a.tag}"
    prev, runs = {}, {}
    if a.reuse_grid and stem.with_suffix(".json").exists():
        old = json.loads(stem.with_suffix(".json").read_text())
        prev = {(c["camera"], c["scene"], c["noise"]): c for c in old["cases"]}
        runs = old.get("runs", {})
    runs[a.label] = {"revision": revision(), "machine": machine}
    iters = a.iters or default_iters("admm", "exact")
    before = old_rule(a.before) if a.before else None
    if before is not None:
        runs["before"] = {"revision": {"file": a.before}, "machine": machine}
    cases = []
    for cname, (cam, opts) in exact_cameras().items():
        if a.cameras and cname not in a.cameras:
            continue
        for noise_name, noise in EXACT_NOISES.items():
            for scene in SCENES:
                meas = scenes.measurement(scene, cam, noise).measurement
                key = (cname, scene, noise_name)
                if prev and key not in prev:
                    continue  # --reuse-grid: only the cases with an oracle
                row = dict(prev.get(key, {}))
                row.update({"camera": cname, "scene": scene, "noise": noise_name,
                            "iters": iters, "options": opts})
                row.update(exact_diagnostics(meas, cam, opts))
                if "grid" not in row:
                    row.update(exact_grid(meas, cam, iters, opts))
                for lab, group in ((a.label, None), ("before", before)):
                    if lab == "before" and before is None:
                        continue
                    auto = exact_auto(meas, cam, iters, opts, group)
                    row.setdefault("auto", {})[lab] = auto
                    auto["gap_db"] = row["oracle_psnr"] - auto["psnr"]
                cases.append(row)
                (out / f".tau_exact_partial{a.tag}.json").write_text(json.dumps(cases))
                print(f"{cname:11s} {noise_name:9s} {scene:7s} oracle {row['oracle_psnr']:6.2f}"
                      f" (tau {row['oracle_tau']:.3g})  " + "  ".join(
                          f"{k} {v['psnr']:6.2f} (tau {v['tau']:.3g}, sigma "
                          f"{v['criterion'].get('sigma', float('nan')):.3g})"
                          for k, v in row["auto"].items())
                      + f"  sigma true {row['true_sigma']:.3g} frame {row['frame_sigma']:.3g}",
                      flush=True)
    result = {"machine": machine, "runs": runs, "iters": iters, "coarse": EXACT_COARSE,
              "refine_decades": EXACT_REFINE, "cases": cases,
              "summary": exact_summary(cases), "load_average_end":
              machine_record()["load_average"]}
    stem.with_suffix(".json").write_text(json.dumps(result, indent=1))
    stem.with_suffix(".md").write_text(exact_markdown(result))
    exact_plot(result, stem.with_suffix(".png"))
    (out / f".tau_exact_partial{a.tag}.json").unlink(missing_ok=True)
    print(json.dumps(result["summary"], indent=1))
    print("wrote", stem.with_suffix(".json"))
    return 0


def exact_summary(cases: list[dict]) -> dict:
    """Per run label and camera: mean and worst gap (dB), the worst case named, and the cases
    whose noisy frame got a tau below a tenth of its oracle's."""
    out: dict = {}
    labels = dict.fromkeys(k for c in cases for k in c.get("auto", {}))
    for lab in labels:
        out[lab] = {}
        for cam in dict.fromkeys(c["camera"] for c in cases):
            rows = [c for c in cases if c["camera"] == cam and lab in c["auto"]]
            if not rows:
                continue
            gaps = [c["auto"][lab]["gap_db"] for c in rows]
            worst = rows[int(np.argmax(gaps))]
            out[lab][cam] = {
                "mean_gap_db": float(np.mean(gaps)), "max_gap_db": float(np.max(gaps)),
                "worst": f"{worst['scene']}/{worst['noise']}",
                "noisy_tau_below_tenth_of_oracle": sum(
                    c["noise"] != "clean" and c["auto"][lab]["tau"] < 0.1 * c["oracle_tau"]
                    for c in rows), "cases": len(rows)}
    return out


def exact_markdown(result: dict) -> str:
    m = result["machine"]
    dev = m.get("device") or {}
    lines = ["# tau='auto' on the exact model against the hindsight-best tau (issue 33)", "",
             f"{m['cpu_model']}, {m['cores_usable']} cores, OpenCL {dev.get('platform', '?')}"
             f" ({dev.get('name', '?')}); ADMM (crop split), {result['iters']} iterations; "
             f"runs: " + ", ".join(f"{k} at {v['revision'].get('commit', '?')[:7]}"
                                   f"{' (modified)' if v['revision'].get('clfza_modified') else ''}"
                                   for k, v in result["runs"].items()), "",
             "## Summary (gap = oracle PSNR - tau='auto' PSNR, dB)", "",
             "| run | camera | mean gap | worst gap | worst case | noisy tau < oracle/10 |",
             "|---|---|---|---|---|---|"]
    for lab, per in result["summary"].items():
        for cam, s in per.items():
            lines.append(f"| {lab} | {cam} | {s['mean_gap_db']:.2f} | {s['max_gap_db']:.2f} | "
                         f"{s['worst']} | {s['noisy_tau_below_tenth_of_oracle']} of "
                         f"{s['cases']} |")
    labels = list(result["summary"])
    lines += ["", "## Cases", "", "| camera | noise | scene | sigma true | frame est. | oracle "
              "tau | oracle dB | " + " | ".join(f"{lab} tau | {lab} dB" for lab in labels) +
              " |", "|---" * (7 + 2 * len(labels)) + "|"]
    for c in result["cases"]:
        cells = []
        for lab in labels:
            v = c["auto"].get(lab)
            cells += ([f"{v['tau']:.3g}", f"{v['psnr']:.2f}"] if v else ["-", "-"])
        lines.append(f"| {c['camera']} | {c['noise']} | {c['scene']} | {c['true_sigma']:.3g} |"
                     f" {c['frame_sigma']:.3g} | {c['oracle_tau']:.3g} | "
                     f"{c['oracle_psnr']:.2f} | " + " | ".join(cells) + " |")
    return "\n".join(lines) + "\n"


def exact_plot(result: dict, path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    cams = list(dict.fromkeys(c["camera"] for c in result["cases"]))
    labels = list(result["summary"])
    fig, axes = plt.subplots(2, len(cams), figsize=(6 * len(cams), 7), squeeze=False)
    for j, cam in enumerate(cams):
        rows = [c for c in result["cases"] if c["camera"] == cam]
        xs = np.arange(len(rows))
        ax, bx = axes[0][j], axes[1][j]
        ax.plot(xs, [r["oracle_psnr"] for r in rows], "o", label="best tau (hindsight)")
        bx.plot(xs, [1.0] * len(rows), "k-", lw=0.5)
        for lab, mk in zip(labels, "sx^v", strict=False):
            ok = [i for i, r in enumerate(rows) if lab in r["auto"]]
            ax.plot(ok, [rows[i]["auto"][lab]["psnr"] for i in ok], mk,
                    label=f"tau=auto ({lab})")
            bx.semilogy(ok, [rows[i]["auto"][lab]["tau"] / rows[i]["oracle_tau"] for i in ok],
                        mk, label=lab)
        for x in (ax, bx):
            x.set_xticks(xs, [f"{r['noise']}\n{r['scene']}" for r in rows], rotation=90,
                         fontsize=6)
            x.grid(alpha=0.3)
        ax.set_title(f"{cam} ({result['iters']} ADMM iterations)")
        ax.set_ylabel("PSNR (dB)")
        bx.set_ylabel("tau / best tau")
    axes[0][0].legend(fontsize=7)
    axes[1][0].legend(fontsize=7)
    m = result["machine"]
    fig.suptitle(f"exact model: tau=auto vs the best tau in hindsight; {m['cpu_model']}, "
                 f"load {m['load_average']}", fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)


if __name__ == "__main__":
    raise SystemExit(main())
