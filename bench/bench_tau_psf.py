"""``tau="auto"`` on measured-PSF frames against the best ``tau`` in hindsight (issue 33 item 2).

Frames: :func:`clfza.simulation.simulate_psf_capture` (a point-source capture through a
finite-aperture zone plate on an 8-bit sensor with photon and read noise, the scene at the
capture's depth), the PSF read with ``load_psf(..., background="border", center="centroid")``
and ``y = frame - mean``. Grid: 3 scenes (camera, astronaut in grey, text) x 2 noise levels
(the capture default, 20000 photons at full scale, and 2000) x 2 sizes (256^2, 320^2; one
process per size side by side, then ``--merge``). For every
case ADMM (400 iterations, ``clfza.reconstruct``'s measured-PSF route) at

* a half-decade ``tau`` grid (``GRID``; the hindsight best is its best point),
* ``tau="auto"`` (the rule in :mod:`clfza.solvers._tau_exact`),
* ``tau="auto"`` with the rule before (``PLAIN_TAU_FACTOR (p / r1') sigma``, the placeholder
  ``r1'`` of a measured-PSF camera), run beside it by patching ``PSF_TAU_FACTOR``,
* the fixed ``PSF_DEFAULT_TAU`` (3e-5, the measured-PSF default before; a grid point),

with PSNR after the positive-gain affine fit of :func:`clfza.metrics.compare`. ``tau`` is in the
solver's scale-free units (unit-sum PSF, frame divided by its RMS). The known noise of a case is
the sensor model's: per-pixel variance ``frame * 255 / full_well + (read * 255 / full_well)^2 +
1/12`` DN^2 (photon, read and quantisation noise), averaged, over the RMS of ``y``; the JSON
has it beside the auto rule's estimate (the Haar MAD of the pilot's residual).

Writes ``bench/results/tau_psf_<machine>.json``, ``.md`` and ``.png``.

    .venv/bin/python bench/bench_tau_psf.py --sizes 256 --tag _256 &
    .venv/bin/python bench/bench_tau_psf.py --sizes 320 --tag _320
    .venv/bin/python bench/bench_tau_psf.py --merge bench/results/tau_psf_*_{256,320}.json
"""

from __future__ import annotations

import argparse
import json
import math
import time
import warnings
from pathlib import Path
from unittest import mock

import numpy as np

import clfza
from clfza.benchmarks import _scenes as scenes
from clfza.benchmarks._machine import machine_record, machine_slug
from clfza.metrics import compare
from clfza.models import load_psf
from clfza.simulation import Noise, simulate_psf_capture

RESULTS = Path(__file__).parent / "results"
ROOT = Path(__file__).resolve().parents[1]
FIXED_DEFAULT = 3e-5  # PSF_DEFAULT_TAU before this bench: on the grid
GRID = [FIXED_DEFAULT * 10 ** (k / 2) for k in range(-1, 5)]  # half a decade apart
PHOTONS = (20000.0, 2000.0)


def _scene(name: str) -> np.ndarray:
    from skimage import color, data

    if name == "camera":
        return data.camera()
    if name == "astronaut":
        return color.rgb2gray(data.astronaut())
    return scenes.text()


SCENES = ("camera", "astronaut", "text")


def known_noise(cap, photons: float, read: float = 2.0, exposure: float = 0.9) -> float:
    """The sensor model's noise RMS in the solver's units (over the RMS of ``y``)."""
    fw = photons / exposure
    var = float(np.mean(cap.frame)) * 255.0 / fw + (read * 255.0 / fw) ** 2 + 1.0 / 12.0
    return math.sqrt(var) / float(np.sqrt(np.mean(cap.y ** 2)))


def solve(cap, psf, iters: int, tau) -> tuple[float, float, dict | None, float]:
    t0 = time.perf_counter()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        rec = clfza.reconstruct(cap.y, cap.camera, "admm", psf=psf, iters=iters,
                                **({} if tau is None else {"tau": tau}))
    dt = time.perf_counter() - t0
    return (float(compare(rec.image, cap.truth)["psnr"]), float(rec.info.params["tau"]),
            rec.info.stats.get("tau_auto"), dt)


def run_case(scene: str, photons: float, size: int, iters: int) -> dict:
    from clfza.solvers import _tau_exact

    noise = Noise(photons=photons, read_noise=2.0, bit_depth=8, exposure=0.9, seed=0)
    cap = simulate_psf_capture(_scene(scene), shape=(size, size), scene_z1=400.0,
                               psf_z1=400.0, noise=noise)
    psf = load_psf(cap.psf, background="border", center="centroid")
    sigma = known_noise(cap, photons)
    grid = []
    for t in GRID:
        p, _, _, dt = solve(cap, psf, iters, t)
        grid.append({"tau": t, "psnr": p, "seconds": dt})
    best = max(grid, key=lambda r: r["psnr"])
    p, tau, a, dt = solve(cap, psf, iters, "auto")
    auto = {"psnr": p, "tau": tau, "seconds": dt, "sigma": a["sigma"],
            "sigma_frame": a["sigma_frame"], "stages": a["stages"], "rule": a["rule"]}
    old = _tau_exact.PLAIN_TAU_FACTOR * cap.camera.pitch / cap.camera.r1p
    with mock.patch.object(_tau_exact, "PSF_TAU_FACTOR", old):
        p, tau, a, dt = solve(cap, psf, iters, "auto")
    before = {"psnr": p, "tau": tau, "seconds": dt, "factor": old}
    fixed = dict(grid[GRID.index(FIXED_DEFAULT)])
    row = {"scene": scene, "photons": photons, "size": size, "known_sigma": sigma,
           "grid": grid, "best_tau": best["tau"], "best_psnr": best["psnr"],
           "best_tau_over_sigma": best["tau"] / sigma,
           "best_at_grid_edge": best["tau"] in (GRID[0], GRID[-1]),
           "auto": auto, "auto_before": before,
           "fixed_3e-5": fixed,
           "sigma_ratio": auto["sigma"] / sigma, "auto_over_best": auto["tau"] / best["tau"]}
    print(f"{scene:9s} ph {photons:6.0f} {size}: best {best['psnr']:.2f} @ {best['tau']:.3g} "
          f"(tau/sigma {best['tau'] / sigma:.3g}) | auto {auto['psnr']:.2f} @ {auto['tau']:.3g} "
          f"| before {before['psnr']:.2f} @ {before['tau']:.3g} | 3e-5 {fixed['psnr']:.2f} | "
          f"sigma est/known "
          f"{auto['sigma'] / sigma:.3f}", flush=True)
    return row


def summary(rows: list[dict]) -> dict:
    def gaps(key):
        g = [r["best_psnr"] - r[key]["psnr"] for r in rows]
        return {"mean_gap_db": float(np.mean(g)), "worst_gap_db": float(np.max(g))}

    out = {k: gaps(k) for k in ("auto", "auto_before", "fixed_3e-5")}
    out["auto_minus_fixed_db"] = [r["auto"]["psnr"] - r["fixed_3e-5"]["psnr"] for r in rows]
    out["auto_over_best_tau"] = [r["auto_over_best"] for r in rows]
    out["sigma_est_over_known"] = [r["sigma_ratio"] for r in rows]
    out["best_tau_over_sigma_geomean"] = float(np.exp(np.mean(
        [math.log(r["best_tau_over_sigma"]) for r in rows])))
    return out


def markdown(doc: dict) -> str:
    m, s = doc["machine"], doc["summary"]
    lines = [f"# tau=auto on measured-PSF frames ({doc['date']})", "",
             f"Machine: {m.get('cpu_model', '?')}, {m.get('cores', '?')} cores, load "
             f"{m.get('load_average')}; OpenCL "
             f"{m.get('device', {}).get('platform', '?')} / {m.get('device', {}).get('name', '?')};"
             f" revision {doc['revision']['start']}; ADMM {doc['iters']} iterations, PSNR "
             f"after the affine fit. tau in the solver's scale-free units (unit-sum PSF, "
             f"frame / RMS).", "",
             "| scene | photons | size | known sigma | est/known | best tau (grid) | best dB "
             "| auto tau | auto dB | auto before: tau | dB | fixed 3e-5 dB |",
             "|---|---|---|---|---|---|---|---|---|---|---|---|"]
    for r in doc["rows"]:
        lines.append(
            f"| {r['scene']} | {r['photons']:g} | {r['size']} | {r['known_sigma']:.4f} | "
            f"{r['sigma_ratio']:.3f} | {r['best_tau']:.3g} | {r['best_psnr']:.2f} | "
            f"{r['auto']['tau']:.3g} | {r['auto']['psnr']:.2f} | "
            f"{r['auto_before']['tau']:.3g} | {r['auto_before']['psnr']:.2f} | "
            f"{r['fixed_3e-5']['psnr']:.2f} |")
    lines += ["", "Gap to the hindsight-best grid tau (dB): "
              + "; ".join(f"{k}: mean {v['mean_gap_db']:.2f}, worst {v['worst_gap_db']:.2f}"
                          for k, v in s.items() if isinstance(v, dict)),
              "", f"Best tau / known sigma, geometric mean: "
              f"{s['best_tau_over_sigma_geomean']:.4f}.", ""]
    return "\n".join(lines)


def plot(doc: dict, path: Path) -> None:
    try:
        import matplotlib
        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except ImportError:
        return
    rows = doc["rows"]
    fig, axes = plt.subplots(1, 2, figsize=(12, 4.5))
    for ax, size in zip(axes, sorted({r["size"] for r in rows}), strict=False):
        for r in (r for r in rows if r["size"] == size):
            s = r["known_sigma"]
            x = [g["tau"] / s for g in r["grid"]]
            line, = ax.semilogx(x, [g["psnr"] for g in r["grid"]], "-",
                                label=f"{r['scene']} {r['photons']:g} ph")
            c = line.get_color()
            ax.plot(r["auto"]["tau"] / s, r["auto"]["psnr"], "o", color=c)
            ax.plot(r["auto_before"]["tau"] / s, r["auto_before"]["psnr"], "x", color=c)
            ax.plot(r["fixed_3e-5"]["tau"] / s, r["fixed_3e-5"]["psnr"], "s", color=c,
                    mfc="none")
        ax.set_title(f"{size}^2: o auto, x auto before, square fixed 3e-5")
        ax.set_xlabel("tau / known noise sigma (scale-free units)")
        ax.set_ylabel("PSNR (dB)")
        ax.grid(True, alpha=0.3)
        ax.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--sizes", type=int, nargs="+", default=[256, 320])
    ap.add_argument("--scenes", nargs="+", default=list(SCENES))
    ap.add_argument("--iters", type=int, default=400)
    ap.add_argument("--tag", default="")
    ap.add_argument("--merge", nargs="+", metavar="JSON",
                    help="write the combined result of earlier runs (e.g. one per size, run "
                         "side by side) instead of running")
    args = ap.parse_args()
    from bench_tau import revision  # bench/ is on the path when run as a script

    if args.merge:
        parts = [json.loads(Path(p).read_text()) for p in args.merge]
        doc = dict(parts[0])
        doc["rows"] = [r for p in parts for r in p["rows"]]
        doc["summary"] = summary(doc["rows"])
        doc["merged_from"] = [{"file": Path(p).name, "machine": q["machine"],
                               "revision": q["revision"]} for p, q in zip(args.merge, parts,
                                                                          strict=True)]
    else:
        rev0 = revision()
        rows = [run_case(sc, ph, n, args.iters) for n in args.sizes for sc in args.scenes
                for ph in PHOTONS]
        doc = {"date": time.strftime("%Y-%m-%d"), "machine": machine_record(),
               "revision": {"start": rev0, "end": revision()}, "iters": args.iters,
               "grid": GRID, "rows": rows, "summary": summary(rows)}
    RESULTS.mkdir(exist_ok=True)
    stem = RESULTS / f"tau_psf_{machine_slug(doc['machine'])}{args.tag}"
    stem.with_suffix(".json").write_text(json.dumps(doc, indent=1, default=str))
    stem.with_suffix(".md").write_text(markdown(doc))
    plot(doc, stem.with_suffix(".png"))
    print(json.dumps(doc["summary"], indent=1))
    print(f"wrote {stem}.json/.md/.png")


if __name__ == "__main__":
    main()
