"""Issue 34 (seconds per real frame): the crop-split ADMM's TV penalty and iterations with a
measured PSF, before and after, in one run.

Settings (``rho / w``, default iterations of the final solve; ``tau="auto"``'s pilot passes
run at ``rho / w = 10`` in all of them, as its rule was fitted on them):

* ``before``: 10, 400 (the mask shadow's defaults, which measured PSFs had);
* ``after``: :data:`clfza.solvers._admm_crop.PSF_RHO_PER_WEIGHT`,
  :data:`~clfza.solvers._admm_crop.PSF_ITERS` (the shipped defaults);
* ``after_400``: the shipped penalty at 400 iterations.

Cases: the real-size simulated captures of ``bench_real_camera.py --psf-speed`` (488^2 RGB, PSF
1.6x the frame at the true scale, cut to its energy support as the default route does), and
the held-out PSF family of ``bench_tau_heldout.py`` (192^2 grey, 4 scenes x 3 photon levels).
Each case runs every setting back to back, ``--rounds`` times (time: the median; PSNR: the
runs agree to rounding), with ``clfza.reconstruct(y, camera, "admm", psf=psf)`` and the
setting's constants patched. PSNR after the affine fit (:func:`clfza.metrics.compare`).

    .venv/bin/python bench/bench_psf_penalty.py [--rounds 2] [--rgb-cases 3] [--no-family]

Writes ``bench/results/psf_penalty_<machine>.json`` / ``.md`` / ``.png``.
"""

from __future__ import annotations

import argparse
import statistics
import sys
import time
import warnings
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
import clfza  # noqa: E402
import clfza.solvers._admm_crop as crop  # noqa: E402
from clfza.benchmarks._machine import machine_record, machine_slug  # noqa: E402
from clfza.benchmarks._report import write_result_files  # noqa: E402
from clfza.metrics import compare  # noqa: E402

RESULTS = Path(__file__).resolve().parent / "results"
SHIPPED = (crop.PSF_RHO_PER_WEIGHT, crop.PSF_ITERS)
SETTINGS = {"before": (10.0, 400), "after": SHIPPED, "after_400": (SHIPPED[0], 400)}


def rgb_cases(n: int):
    """The 488^2 RGB captures (bench_real_camera's SPEED_CASES), PSF scaled to the truth and
    cut to its support."""
    from bench_real_camera import PSF_SCENES, SPEED_CASES

    from clfza.models import crop_to_support, load_psf, scale_psf
    from clfza.simulation import simulate_psf_capture

    for scene, z in SPEED_CASES[:n]:
        cap = simulate_psf_capture(PSF_SCENES[scene](), shape=(488, 488), scene_z1=z)
        psf = load_psf(cap.psf, center="centroid")
        p = crop_to_support(scale_psf(psf, cap.true_scale, max_shape=(975, 975)))
        yield {"set": "rgb488", "scene": scene, "z1": z}, cap, p


def family_cases():
    """bench_tau_heldout's measured-PSF family (192^2)."""
    from bench_tau_heldout import PSF_PHOTONS, PSF_SCENES, psf_capture

    for scene in PSF_SCENES:
        for ph in PSF_PHOTONS:
            cap, psf = psf_capture(scene, ph, 192)
            yield {"set": "psf192", "scene": scene, "photons": ph}, cap, psf


def solve(cap, psf, setting: tuple[float, int]) -> dict:
    rho_w, iters = setting
    old = crop.PSF_RHO_PER_WEIGHT, crop.PSF_ITERS
    crop.PSF_RHO_PER_WEIGHT, crop.PSF_ITERS = rho_w, iters
    try:
        t0 = time.perf_counter()
        rec = clfza.reconstruct(cap.y, cap.camera, "admm", psf=psf)
        wall = time.perf_counter() - t0
    finally:
        crop.PSF_RHO_PER_WEIGHT, crop.PSF_ITERS = old
    t = rec.info.timings
    return {"psnr": float(compare(rec.image, cap.truth)["psnr"]), "wall_s": wall,
            "solve_s": t.get("solve", 0.0), "tau_search_s": t.get("tau_search", 0.0),
            "iterations": rec.info.iterations, "tau": rec.info.params["tau"]}


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--rounds", type=int, default=2)
    p.add_argument("--rgb-cases", type=int, default=3)
    p.add_argument("--no-family", action="store_true")
    p.add_argument("--out", default=str(RESULTS))
    a = p.parse_args(argv)
    warnings.simplefilter("ignore")
    machine = machine_record()
    cases = list(rgb_cases(a.rgb_cases)) + ([] if a.no_family else list(family_cases()))
    rows = []
    for meta, cap, psf in cases:
        runs = {k: [] for k in SETTINGS}
        for _ in range(a.rounds):
            for k, s in SETTINGS.items():
                runs[k].append(solve(cap, psf, s))
        row = dict(meta)
        for k, rs in runs.items():
            row[k] = {"psnr": rs[0]["psnr"], "tau": rs[0]["tau"],
                      "iterations": rs[0]["iterations"],
                      **{f: statistics.median(r[f] for r in rs)
                         for f in ("wall_s", "solve_s", "tau_search_s")}}
        rows.append(row)
        print(f"{meta['set']} {meta['scene']:10s} " + "  ".join(
            f"{k} {row[k]['psnr']:.2f} dB {row[k]['wall_s']:.2f} s" for k in SETTINGS),
            flush=True)
    machine_after = machine_record()
    res = {"machine": machine, "load_average_end": machine_after.get("load_average"),
           "settings": {k: {"rho_per_weight": v[0], "iters": v[1]} for k, v in
                        SETTINGS.items()}, "rounds": a.rounds, "rows": rows,
           "summary": summary(rows)}
    stem = Path(a.out) / f"psf_penalty_{machine_slug(machine)}"
    write_result_files(stem, res, markdown(res), plot)
    print(markdown(res))
    return 0


def summary(rows: list[dict]) -> dict:
    out = {}
    for s in sorted({r["set"] for r in rows}):
        rs = [r for r in rows if r["set"] == s]
        out[s] = {}
        for k in SETTINGS:
            if k == "before":
                continue
            d = [r[k]["psnr"] - r["before"]["psnr"] for r in rs]
            out[s][k] = {"psnr_change_mean_db": float(np.mean(d)),
                         "psnr_change_worst_db": float(min(d)),
                         "wall_ratio_median": float(np.median(
                             [r[k]["wall_s"] / r["before"]["wall_s"] for r in rs])),
                         "solve_ratio_median": float(np.median(
                             [r[k]["solve_s"] / r["before"]["solve_s"] for r in rs]))}
    return out


def markdown(res: dict) -> str:
    m = res["machine"]
    lines = ["# The crop split's penalty and iterations with a measured PSF (issue 34)", "",
             f"{m.get('cpu_model')}, {m.get('cores_usable')} cores usable; OpenCL "
             f"{(m.get('device') or {}).get('describe', '')}; versions {m.get('versions')}; "
             f"{m.get('date')}; load {m.get('load_average')} -> {res['load_average_end']}. "
             "Produced by `bench/bench_psf_penalty.py` (cases and settings in its docstring); "
             f"{res['rounds']} rounds, time medians. Settings (rho/w, iterations): " +
             ", ".join(f"{k} ({v['rho_per_weight']:g}, {v['iters']})"
                       for k, v in res["settings"].items()) + ".", "",
             "| set | scene | noise | " + " | ".join(
                 f"{k} dB | {k} s" for k in SETTINGS) + " |",
             "|---|---|---|" + "---|---|" * len(SETTINGS)]
    for r in res["rows"]:
        noise = f"{r['photons']:g} photons" if "photons" in r else f"z1 {r['z1']:g} mm"
        lines.append(f"| {r['set']} | {r['scene']} | {noise} | " + " | ".join(
            f"{r[k]['psnr']:.2f} | {r[k]['wall_s']:.2f}" for k in SETTINGS) + " |")
    lines += ["", "Against `before` (PSNR change, dB; wall and solve time ratios, medians):", ""]
    for s, by in res["summary"].items():
        for k, v in by.items():
            lines.append(f"- {s}, {k}: mean {v['psnr_change_mean_db']:+.2f} dB, worst "
                         f"{v['psnr_change_worst_db']:+.2f} dB; wall x{v['wall_ratio_median']:.2f}"
                         f", solve x{v['solve_ratio_median']:.2f}")
    return "\n".join(lines) + "\n"


def plot(res: dict, path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(6.4, 4.2))
    marks = {"before": "o", "after": "s", "after_400": "^"}
    for k in SETTINGS:
        ax.scatter([r[k]["wall_s"] / r["before"]["wall_s"] for r in res["rows"]],
                   [r[k]["psnr"] - r["before"]["psnr"] for r in res["rows"]],
                   marker=marks[k], label=k)
    ax.axhline(0, color="grey", lw=1)
    ax.axvline(1, color="grey", lw=1)
    ax.set_xlabel("wall time / before")
    ax.set_ylabel("PSNR - before (dB)")
    ax.legend()
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


if __name__ == "__main__":
    sys.exit(main())
