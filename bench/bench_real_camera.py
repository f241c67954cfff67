"""The paper's real camera (``experiment`` preset: binary FZA, R = 4.56 mm, 200 mm scene at
300 mm) reconstructed with the transfer-function model (the paper's, which returns a blob here)
and with the exact finite-aperture model (clfza.models._exact), noise-free and with sensor noise.

Error: object-footprint PSNR/SSIM after the affine fit of clfza.metrics.compare (the footprint
is the bounding box of the projected scene on the sensor). Time: wall time of the solve
(compile and plan reported apart). Writes bench/results/real_camera_<machine>.json and .png.

    .venv/bin/python bench/bench_real_camera.py [--bin 3] [--iters 200] [--scenes camera,...]
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import time
from pathlib import Path

import numpy as np
from skimage import data

import clfza
from clfza import Camera, Noise
from clfza.metrics import compare
from clfza.simulation import simulate

SCENES = {"camera": data.camera, "astronaut": lambda: data.astronaut().mean(axis=2) / 255.0,
          "text": data.text}
NOISE = Noise(photons=20000, read_noise=3.0, bit_depth=12, seed=1)


def footprint(truth: np.ndarray) -> tuple[slice, slice]:
    rows, cols = np.where(truth.any(1))[0], np.where(truth.any(0))[0]
    return slice(rows[0], rows[-1] + 1), slice(cols[0], cols[-1] + 1)


def score(img: np.ndarray, truth: np.ndarray) -> dict:
    fp = footprint(truth)
    m = compare(img[fp], truth[fp])
    return {"psnr": round(m["psnr"], 2), "ssim": round(m["ssim"], 4)}


def _iters(iters: int | None) -> dict:
    return {} if iters is None else {"iters": iters}


def run_planned(cam: Camera, scene: str, noisy: bool, iters: int | None, tau_noisy
                ) -> list[dict]:
    """Full-resolution frames: ADMM through the planner, which bins by the band limit (3x
    here) and runs the exact model's binned kernel; BP on the full frame. Both are scored on
    the binned grid against the pixel-binned truth: detail finer than the band limit is not
    in the frame for any method. ``tau`` with noise: ``"auto"`` (clfza.solvers._tau) or a number on
    the full grid (the planner divides it by the bin factor); noise-free the solver's
    default."""
    from clfza.models._exact import box_bin
    from clfza.reconstruction import reconstruct_planned

    meas = simulate(SCENES[scene](), cam, object_width=200.0, noise=NOISE if noisy else None)
    kw = {"tau": tau_noisy} if noisy else {}
    t0 = time.perf_counter()
    rec = reconstruct_planned(meas.y, cam, "admm", discrepancy=False, upsample=None,
                              **_iters(iters), **kw)
    wall = time.perf_counter() - t0
    b = rec.info.plan.bin
    truth = box_bin(meas.truth, b)
    img, info = clfza.reconstruct(meas.y, cam, "bp")
    rows = [_row(scene, noisy, "bp", "tf", info, box_bin(img, b), truth)]
    row = _row(scene, noisy, "admm (planned)", rec.info.params.get("model", "?"), rec.info,
               rec.image, truth)
    row.update(bin=b, tau=kw.get("tau"), tau_used=rec.info.params.get("tau"),
               wall_s=round(wall, 2))
    rows.append(row)
    return rows


def _row(scene, noisy, method, model, info, img, truth) -> dict:
    row = {"scene": scene, "noisy": noisy, "method": method, "model": model,
           "iterations": info.iterations, "solve_s": round(info.timings["solve"], 3),
           "tau_search_s": round(info.timings.get("tau_search", 0.0), 3),
           "plan_s": round(info.timings.get("plan", 0.0), 3),
           "compile_s": round(info.timings.get("compile", 0.0), 3), **score(img, truth)}
    print(f"{scene:10s} {'noisy' if noisy else 'clean':5s} {method:15s} {model:6s} "
          f"{row['iterations']:4d} it {row['solve_s']:7.2f} s  PSNR {row['psnr']:6.2f} dB "
          f"SSIM {row['ssim']:.3f}", flush=True)
    return row


def run(cam: Camera, scene: str, noisy: bool, iters: int | None, tau_noisy) -> list[dict]:
    meas = simulate(SCENES[scene](), cam, object_width=200.0, noise=NOISE if noisy else None)
    rows = []
    cases = [("bp", "tf", {}), ("bp", "exact", {}),
             ("admm", "tf", _iters(iters)),
             ("admm", "exact", {**_iters(iters), "tau": tau_noisy if noisy else 1e-3,
                                "checkpoints": [25, 50, 100, 200, 400],
                                "truth": meas.truth})]
    for method, model, kw in cases:
        img, info = clfza.reconstruct(meas.y, cam, method, model=model, **kw)
        row = {"scene": scene, "noisy": noisy, "method": method, "model": model,
               "iterations": info.iterations, "solve_s": round(info.timings["solve"], 3),
               "tau_search_s": round(info.timings.get("tau_search", 0.0), 3),
               "plan_s": round(info.timings.get("plan", 0.0), 3),
               "compile_s": round(info.timings.get("compile", 0.0), 3), **score(img, meas.truth),
               "tau": kw.get("tau"), "tau_used": info.params.get("tau")}
        if kw.get("checkpoints"):
            row["trace"] = [(c["iteration"], round(c["time"], 2)) for c in info.checkpoints]
        rows.append(row)
        print(f"{scene:10s} {'noisy' if noisy else 'clean':5s} {method:5s} {model:6s} "
              f"{row['iterations']:4d} it {row['solve_s']:7.2f} s  PSNR {row['psnr']:6.2f} dB "
              f"SSIM {row['ssim']:.3f}", flush=True)
    return rows


def check_targets(rows: list[dict]) -> list[dict]:
    """Issue 11's targets per scene: ADMM on the exact model >= 28 dB noise-free and >= BP + 10
    dB with sensor noise (BP on the transfer-function model, as the paper runs it), the solve
    (with ``tau="auto"``'s pilot passes or search) <= 20 s. Printed and recorded."""
    out = []
    for scene in dict.fromkeys(r["scene"] for r in rows):
        for noisy in (False, True):
            rs = [r for r in rows if r["scene"] == scene and r["noisy"] == noisy]
            bp = next((r for r in rs if r["method"] == "bp" and r["model"] == "tf"), None)
            ad = next((r for r in rs if r["method"].startswith("admm")
                       and r["model"] == "exact"), None)
            if bp is None or ad is None:
                continue
            need = bp["psnr"] + 10.0 if noisy else 28.0
            t = {"scene": scene, "noisy": noisy, "psnr": ad["psnr"], "required": need,
                 "met": ad["psnr"] >= need, "solve_s": ad["solve_s"],
                 "tau_search_s": ad.get("tau_search_s", 0.0)}
            t["time_met"] = t["solve_s"] + t["tau_search_s"] <= 20.0
            out.append(t)
            print(f"target {scene:10s} {'noisy' if noisy else 'clean':5s} PSNR {t['psnr']:6.2f}"
                  f" >= {need:6.2f}: {'met' if t['met'] else 'NOT met'}; solve "
                  f"{t['solve_s']:.1f} s + tau search {t['tau_search_s']:.1f} s <= 20 s: "
                  f"{'met' if t['time_met'] else 'NOT met'}")
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--bin", type=int, default=3, help="camera binning (3: 800^2)")
    ap.add_argument("--iters", type=int, default=None,
                    help="ADMM iterations (default: the solver's, 400 on the exact model)")
    ap.add_argument("--tau-noisy", default="auto",
                    help="tau with sensor noise: 'auto' or a number on the full grid "
                         "(binned camera: 1/bin of it on its grid)")
    ap.add_argument("--planned", action="store_true",
                    help="full-resolution frames through the planner (bins by --bin's "
                         "band-limit rule itself) instead of a binned camera")
    ap.add_argument("--scenes", default="camera,astronaut,text")
    ap.add_argument("--out", default="bench/results")
    a = ap.parse_args()
    cam0 = Camera.preset("experiment")
    n = cam0.shape[0] // a.bin
    cam = cam0.with_shape((n, n), cam0.pitch * a.bin)
    from clfza.cl import get_runtime

    rt = get_runtime()
    rows = []
    for scene in a.scenes.split(","):
        for noisy in (False, True):
            if a.planned:
                tau = a.tau_noisy if a.tau_noisy == "auto" else float(a.tau_noisy)
                rows.extend(run_planned(cam0, scene, noisy, a.iters, tau))
            else:
                tau = a.tau_noisy if a.tau_noisy == "auto" else float(a.tau_noisy) / a.bin
                rows.extend(run(cam, scene, noisy, a.iters, tau))
    machine = f"{platform.machine()}-{platform.processor() or 'cpu'}"
    targets = check_targets(rows)
    rec = {"benchmark": "real_camera",
           "camera": (cam0 if a.planned else cam).to_dict(), "bin": a.bin,
           "load_average": [round(v, 2) for v in os.getloadavg()], "targets": targets,
           "device": rt.info.name, "platform": rt.info.platform, "machine": machine,
           "python": platform.python_version(), "clfza": clfza.__version__,
           "noise": NOISE.__dict__, "date": time.strftime("%Y-%m-%d"), "rows": rows,
           "normalisation": "object footprint, affine fit a x + b (clfza.metrics.compare)"}
    out = Path(a.out)
    out.mkdir(parents=True, exist_ok=True)
    stem = out / ("real_camera_planned" if a.planned else f"real_camera_bin{a.bin}")
    stem.with_suffix(".json").write_text(json.dumps(rec, indent=1))
    _plot(rows, stem.with_suffix(".png"))
    print(f"wrote {stem}.json/.png")


def _plot(rows: list[dict], path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(7, 4))
    labels = [f"{r['scene']}\n{'noisy' if r['noisy'] else 'clean'}" for r in rows
              if r["method"] == "bp" and r["model"] == "tf"]
    x = np.arange(len(labels))
    kinds = sorted({(r["method"], r["model"]) for r in rows})
    width = 0.8 / len(kinds)
    for k, (method, model) in enumerate(kinds):
        vals = [r["psnr"] for r in rows if r["method"] == method and r["model"] == model]
        ax.bar(x + width * (k - (len(kinds) - 1) / 2), vals, width,
               label=f"{method} / {model}")
    ax.set_xticks(x, labels)
    ax.set_ylabel("footprint PSNR (dB)")
    ax.set_title("experiment preset: transfer-function vs exact model")
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=120)


if __name__ == "__main__":
    main()
