"""What each planner skip saves at equal PSNR, and that it costs nothing where it does not apply.

Rows (issue 6, item 4):

* ``bin``: a band-limited camera (1/(2p) = 3.2 rho_c, like the paper's experiment) -- full-grid
  solve against the planned solve on the grid binned by 3 (tau / 3, Fourier upsampling back);
* ``grey-rgb``: a grey scene in an RGB frame -- three channel solves against one;
* ``discrepancy``: a noisy frame -- the solver's own stop (``iters`` or objective change)
  against the first iteration count (on a 1.25x grid of counts) whose residual
  ``||y - K x||^2`` is below ``N sigma_est^2`` (Morozov; the solvers do not yet stop on a
  callback, so the stop is applied here by running to that count);
* ``float32``: the OpenCL backend in float32 against float64 on the same problem;
* ``no-skip``: a full-band colour scene where no skip applies -- direct ``reconstruct`` against
  ``reconstruct_planned`` (the cost is the planner itself).

Times are medians of repeated runs (wall time of the call, planning included for the planned
side); PSNR after the affine fit of :func:`clfza.metrics.compare`. Writes
``bench/results/skips_<machine>.json``, ``.md`` and ``.png``.

Run: ``.venv/bin/python bench/bench_skips.py [--repeats 3] [--quick]``
"""

from __future__ import annotations

import argparse
import datetime as dt
import json
import platform
import statistics
import sys
import time
import warnings
from pathlib import Path

import numpy as np
from skimage import data
from skimage.transform import resize

import clfza
from clfza import Camera, Noise, reconstruct, simulate
from clfza.metrics import compare
from clfza.models._transfer import NumpyOperator
from clfza.reconstruction import make_plan, reconstruct_planned

RESULTS = Path(__file__).resolve().parent / "results"


def machine() -> tuple[dict, str]:
    try:
        from clfza.benchmarks._machine import machine_record, machine_slug

        rec = machine_record()
        return rec, machine_slug(rec)
    except Exception as exc:  # noqa: BLE001 - the record is best effort
        rec = {"platform": platform.platform(), "python": sys.version.split()[0],
               "numpy": np.__version__, "clfza": clfza.__version__,
               "date": dt.datetime.now().isoformat(timespec="seconds"), "note": str(exc)}
        return rec, platform.node() or "machine"


def timed(fn, repeats: int):
    fn()  # warm-up (kernel builds, FFT plans)
    ts, out = [], None
    for _ in range(repeats):
        t0 = time.perf_counter()
        out = fn()
        ts.append(time.perf_counter() - t0)
    return statistics.median(ts), ts, out


def _img(r):
    return r.image


def scene(n: int) -> np.ndarray:
    return resize(data.camera() / 255.0, (n, n), anti_aliasing=True)


def band_limited_camera(n: int) -> Camera:
    p = 0.005
    r1p = np.sqrt(3 * n) * p
    return Camera(pitch=p, shape=(n, n), r1=r1p / 1.15, z1=20.0, z2=3.0,
                  R=0.95 * n * p / 2 / 1.15, mask="gzp", name="band-limited")


def full_band_camera(n: int) -> Camera:
    p = 0.01
    r1p = np.sqrt(n) * p
    return Camera(pitch=p, shape=(n, n), r1=r1p / 1.15, z1=20.0, z2=3.0, R=n * p / 2 / 1.15,
                  mask="gzp", name="full-band")


def row(name, scene_desc, applies, base_t, skip_t, base_psnr, skip_psnr, **extra):
    return {"skip": name, "scene": scene_desc, "applies": applies,
            "baseline_s": base_t, "planned_s": skip_t,
            "saved_s": base_t - skip_t, "speedup": base_t / skip_t if skip_t > 0 else None,
            "baseline_psnr": base_psnr, "planned_psnr": skip_psnr,
            "dpsnr": skip_psnr - base_psnr, **extra}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser()
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--quick", action="store_true", help="smaller grids")
    args = ap.parse_args(argv)
    warnings.simplefilter("ignore")
    from clfza.solvers import _run as solvers

    method = next((m for m in ("fista", "admm", "twist") if m in solvers.METHODS), "bp")
    iterative = method != "bp"
    solver_note = (f"iterative solver '{method}' (clfza.solvers.METHODS = {solvers.METHODS})"
                   if iterative else "no iterative solver registered: back-propagation only")
    print(f"bench_skips: {solver_note}")
    R = args.repeats
    n_bl = 240 if args.quick else 480
    n_fb = 128 if args.quick else 256
    base_opts = {"tau": 0.003, "iters": 100, "stop": "none"} if iterative else {}
    rows = []

    # --- binning on a band-limited camera ---------------------------------------------
    cam = band_limited_camera(n_bl)
    m = simulate(scene(n_bl // 2), cam, noise=Noise(gaussian_var=1e-4, seed=1))
    tb, _, full = timed(lambda: reconstruct(m.y, cam, method, backend="numpy", **base_opts), R)
    ts, _, plan_out = timed(lambda: reconstruct_planned(m.y, cam, method, backend="numpy",
                                                        discrepancy=False, **base_opts), R)
    plan = plan_out.info.plan
    rows.append(row("bin", f"{cam.name} {n_bl}^2, 1/(2p) = "
                    f"{0.5 / cam.pitch / cam.band_limit:.2f} rho_c", True, tb, ts,
                    compare(full.image, m.truth)["psnr"], compare(_img(plan_out),
                                                                  m.truth)["psnr"],
                    bin=plan.bin, work_shape=list(plan.work_camera.shape)))

    # --- grey scene in an RGB frame ---------------------------------------------------
    cam = full_band_camera(n_fb)
    m = simulate(scene(n_fb // 2), cam, noise=Noise(gaussian_var=1e-4, seed=1))
    rng = np.random.default_rng(5)
    gains = (0.9, 1.0, 1.15)
    y3 = np.stack([g * m.clean_y + rng.normal(0, 0.01, cam.shape) for g in gains], -1)
    truth3 = np.stack([g * m.truth for g in gains], -1)
    tb, _, full = timed(lambda: reconstruct(y3, cam, method, backend="numpy", **base_opts), R)
    ts, _, out = timed(lambda: reconstruct_planned(y3, cam, method, backend="numpy",
                                                   discrepancy=False, **base_opts), R)
    rows.append(row("grey-rgb", f"{cam.name} {n_fb}^2 x 3, grey scene, gains {gains}",
                    out.info.plan.grey, tb, ts, compare(full.image, truth3)["psnr"],
                    compare(_img(out), truth3)["psnr"]))

    # --- early stopping by the discrepancy principle ----------------------------------
    if iterative:
        cam = full_band_camera(n_fb)
        m = simulate(scene(n_fb // 2), cam, noise=Noise(gaussian_var=4e-3, seed=2))
        plan = make_plan(m.y, cam, method=method)
        op = NumpyOperator(cam, warn=False)
        kmax = 200
        opts = {"tau": 0.01, "stop": "none"}
        k_stop, res_at = kmax, None
        k = 4
        while k < kmax:
            x = reconstruct(m.y, cam, method, backend="numpy", iters=k, **opts).image
            r2 = float(np.sum((m.y - op.forward(x)) ** 2))
            if r2 <= plan.discrepancy_target:
                k_stop, res_at = k, r2
                break
            k = max(k + 1, int(round(k * 1.25)))
        tb, _, full = timed(lambda: reconstruct(m.y, cam, method, backend="numpy",
                                                iters=kmax, **opts), R)
        ts, _, early = timed(lambda: reconstruct(m.y, cam, method, backend="numpy",
                                                 iters=k_stop, **opts), R)
        rows.append(row("discrepancy", f"{cam.name} {n_fb}^2, noise var 4e-3 "
                        f"(sigma_est {plan.sigma:.3g})", k_stop < kmax, tb, ts,
                        compare(full.image, m.truth)["psnr"],
                        compare(early.image, m.truth)["psnr"], iters_baseline=kmax,
                        iters_planned=k_stop, target=plan.discrepancy_target,
                        residual_at_stop=res_at))

    # --- float32 against float64 on OpenCL --------------------------------------------
    try:
        from clfza.cl import get_runtime

        rt = get_runtime()
        cam = full_band_camera(n_fb * 2)
        m = simulate(scene(n_fb), cam, noise=Noise(gaussian_var=1e-4, seed=3))
        plan = make_plan(m.y, cam, method=method)
        if rt.has_fp64:
            tb, _, r64 = timed(lambda: reconstruct(m.y, cam, method, backend="opencl",
                                                   dtype=np.float64, **base_opts), R)
            ts, _, r32 = timed(lambda: reconstruct(m.y, cam, method, backend="opencl",
                                                   dtype=np.float32, **base_opts), R)
            rows.append(row("float32", f"{cam.name} {2 * n_fb}^2 on {rt.info.name}",
                            plan.dtype == "float32", tb, ts,
                            compare(r64.image, m.truth)["psnr"],
                            compare(r32.image, m.truth)["psnr"]))
    except Exception as exc:  # noqa: BLE001 - report, do not fail the other rows
        print(f"float32 row skipped: {exc}")

    # --- zero cost where nothing applies ----------------------------------------------
    cam = full_band_camera(n_fb)
    col = np.stack([scene(n_fb // 2), np.roll(scene(n_fb // 2), 17, axis=1),
                    scene(n_fb // 2)[::-1]], -1)
    m = simulate(col, cam, noise=Noise(gaussian_var=1e-4, seed=4))
    tb, _, base = timed(lambda: reconstruct(m.y, cam, method, backend="numpy", **base_opts), R)
    ts, _, out = timed(lambda: reconstruct_planned(m.y, cam, method, backend="numpy",
                                                   discrepancy=False, **base_opts), R)
    applied = [d.name for d in out.info.plan.decisions if d.active and d.saving > 0]
    rows.append(row("no-skip", f"{cam.name} {n_fb}^2 colour scene", bool(applied), tb, ts,
                    compare(base.image, m.truth)["psnr"], compare(_img(out), m.truth)["psnr"],
                    plan_s=out.info.plan.timings.get("plan")))

    rec, slug = machine()
    result = {"benchmark": "skips", "solver": solver_note, "method": method,
              "options": base_opts, "repeats": R, "machine": rec,
              "date": dt.datetime.now().isoformat(timespec="seconds"), "rows": rows}
    RESULTS.mkdir(parents=True, exist_ok=True)
    base_path = RESULTS / f"skips_{slug}"
    base_path.with_suffix(".json").write_text(json.dumps(result, indent=2, default=str))
    md = [f"# Planner skips ({solver_note}; medians of {R} runs)", "",
          "| skip | scene | applies | baseline s | planned s | speed-up | PSNR base | "
          "PSNR planned | dPSNR |", "|---|---|---|---|---|---|---|---|---|"]
    for r in rows:
        md.append(f"| {r['skip']} | {r['scene']} | {r['applies']} | {r['baseline_s']:.3f} | "
                  f"{r['planned_s']:.3f} | {r['speedup']:.2f}x | {r['baseline_psnr']:.2f} | "
                  f"{r['planned_psnr']:.2f} | {r['dpsnr']:+.2f} |")
    md.append("")
    md.append(f"Machine: {rec.get('cpu', rec.get('platform', ''))}; date {result['date']}.")
    base_path.with_suffix(".md").write_text("\n".join(md) + "\n")
    print("\n".join(md))
    try:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt

        fig, ax = plt.subplots(1, 2, figsize=(10, 3.8))
        names = [r["skip"] for r in rows]
        xs = np.arange(len(rows))
        ax[0].bar(xs - 0.2, [r["baseline_s"] for r in rows], 0.4, label="baseline")
        ax[0].bar(xs + 0.2, [r["planned_s"] for r in rows], 0.4, label="planned")
        ax[0].set_xticks(xs, names)
        ax[0].set_ylabel("time (s, median)")
        ax[0].set_yscale("log")
        ax[0].legend()
        ax[1].bar(xs, [r["dpsnr"] for r in rows], color="tab:green")
        ax[1].axhline(-0.2, color="r", ls="--", lw=1)
        ax[1].set_xticks(xs, names)
        ax[1].set_ylabel("PSNR planned - baseline (dB)")
        fig.suptitle(f"clfza planner skips, {method}")
        fig.tight_layout()
        fig.savefig(base_path.with_suffix(".png"), dpi=110)
    except Exception as exc:  # noqa: BLE001
        print(f"plot skipped: {exc}")
    print(f"wrote {base_path}.json/.md/.png")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
