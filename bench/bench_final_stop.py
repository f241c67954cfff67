"""Issue 33: the stop of the default route's final solve on Eq. 17, in one run.

Usage::

    python bench/bench_final_stop.py [--n 512] [--scenes camera astronaut text brick]
                                     [--rounds 2] [--device SPEC] [--out bench/results]

On the ``simulation`` preset (the paper's Fig. 7 camera) at ``--n``^2, each scene at Gaussian
noise variance 1e-3 and 1e-2 and at 1e3 and 1e4 photons (the frames where the default route
takes Eq. 17), ``clfza.reconstruct(y, cam)`` with its default final stop (after the
discrepancy search: the spread of the objective over ``FINAL_STOP_WINDOW`` iterations at
``FINAL_TOL``, :func:`clfza.solvers._tau.final_options`) against the same call with
``tol=1e-6`` (the one-step objective rule the final solve used before). The two run
interleaved per case and round, the order alternating; the search is the same in both (its
stages do not read the final stop). Reported: PSNR against the truth (the affine fit of
:func:`clfza.metrics.compare`), the final solve's iterations, and the wall seconds of the call
(medians over the rounds) and their ratio. Writes ``bench/results/final_stop_<machine>.json``
/ ``.md`` / ``.png``.
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
from bench_tau import revision  # noqa: E402

import clfza  # noqa: E402
from clfza.benchmarks._machine import machine_record, machine_slug  # noqa: E402
from clfza.benchmarks._report import write_result_files  # noqa: E402
from clfza.metrics import compare  # noqa: E402
from clfza.solvers._tau import FINAL_STOP_WINDOW, FINAL_TOL  # noqa: E402

RESULTS = Path(__file__).resolve().parent / "results"
NOISES = {"gauss1e-3": {"gaussian_var": 1e-3}, "gauss1e-2": {"gaussian_var": 1e-2},
          "photons1e3": {"photons": 1e3}, "photons1e4": {"photons": 1e4}}
VARIANTS = {"default": {}, "one-step 1e-6": {"tol": 1e-6}}


def scene(name: str) -> np.ndarray:
    from skimage import color, data

    img = getattr(data, name)()
    return color.rgb2gray(img) if img.ndim == 3 else img / 255.0


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--n", type=int, default=512)
    p.add_argument("--scenes", nargs="+", default=["camera", "astronaut", "text", "brick"])
    p.add_argument("--rounds", type=int, default=2)
    p.add_argument("--device", default=None, help="OpenCL device spec (default: clfza's)")
    p.add_argument("--out", default=str(RESULTS))
    a = p.parse_args(argv)
    warnings.simplefilter("ignore")
    cam = clfza.Camera.preset("simulation")
    if a.n != cam.shape[0]:
        cam = cam.with_shape((a.n, a.n))
    cases = []
    for sc in a.scenes:
        for nz, kw in NOISES.items():
            m = clfza.simulate(scene(sc), cam, object_width=20.0, noise=clfza.Noise(**kw, seed=1))
            cases.append({"scene": sc, "noise": nz, "meas": m, "runs": {v: [] for v in VARIANTS}})
    clfza.reconstruct(cases[0]["meas"].y, cam, device=a.device)  # warm-up: kernel builds
    for rnd in range(a.rounds):
        for i, c in enumerate(cases):
            order = list(VARIANTS) if (rnd + i) % 2 == 0 else list(VARIANTS)[::-1]
            for v in order:
                t0 = time.perf_counter()
                rec = clfza.reconstruct(c["meas"].y, cam, device=a.device, **VARIANTS[v])
                wall = time.perf_counter() - t0
                c["runs"][v].append({
                    "wall_s": wall, "psnr": compare(rec.image, c["meas"].truth)["psnr"],
                    "iterations": rec.info.iterations, "model": rec.info.params["model"],
                    "stop_reason": rec.info.stop_reason,
                    "search_s": rec.info.timings.get("tau_search", 0.0),
                    "solve_s": rec.info.timings.get("solve", 0.0)})
            print(f"round {rnd}: {c['scene']:10s} {c['noise']:11s} " + "  ".join(
                f"{v}: {c['runs'][v][-1]['psnr']:.2f} dB {c['runs'][v][-1]['iterations']:3d} it "
                f"{c['runs'][v][-1]['wall_s']:.3f} s" for v in VARIANTS), flush=True)
    rows = []
    for c in cases:
        r = {"scene": c["scene"], "noise": c["noise"], "runs": c["runs"]}
        for v in VARIANTS:
            runs = c["runs"][v]
            r[v] = {"psnr": runs[-1]["psnr"], "iterations": runs[-1]["iterations"],
                    "model": runs[-1]["model"],
                    "wall_s": statistics.median(x["wall_s"] for x in runs),
                    "solve_s": statistics.median(x["solve_s"] for x in runs)}
        rows.append(r)
    res = {"machine": machine_record(a.device), "revision": revision(), "n": a.n,
           "rounds": a.rounds, "final_stop_window": FINAL_STOP_WINDOW, "final_tol": FINAL_TOL,
           "rows": rows}
    text = markdown(res)
    write_result_files(Path(a.out) / f"final_stop_{machine_slug(res['machine'])}", res, text,
                       plot)
    print(text)
    return 0


def markdown(res: dict) -> str:
    m = res["machine"]
    d = [r["default"]["psnr"] - r["one-step 1e-6"]["psnr"] for r in res["rows"]]
    wr = [r["default"]["wall_s"] / r["one-step 1e-6"]["wall_s"] for r in res["rows"]]
    it = [r["default"]["iterations"] / r["one-step 1e-6"]["iterations"] for r in res["rows"]]
    lines = [
        f"# The default route's final stop on Eq. 17 ({res['n']}^2 simulation preset)", "",
        f"{m.get('cpu_model', '')}, {(m.get('device') or {}).get('describe', '')}; "
        f"{m.get('date', '')}; revision {(res['revision']['commit'] or '?')[:7]}"
        f"{' (clfza modified)' if res['revision']['clfza_modified'] else ''}; "
        f"{res['rounds']} interleaved rounds, "
        "wall medians. `default`: the spread of the objective over "
        f"{res['final_stop_window']} iterations at {res['final_tol']:g}; `one-step 1e-6`: "
        "`tol=1e-6` (the rule before). Produced by `bench/bench_final_stop.py`.", "",
        f"PSNR change mean {np.mean(d):+.3f} dB, worst {min(d):+.3f} dB; final iterations "
        f"x{np.mean(it):.2f} (mean ratio); wall x{statistics.median(wr):.2f} (median ratio, "
        f"range {min(wr):.2f}-{max(wr):.2f}).", "",
        "| scene | noise | model | PSNR default | PSNR one-step | its default | its one-step "
        "| wall default | wall one-step | ratio |", "|---|---|---|---|---|---|---|---|---|---|"]
    for r, ratio in zip(res["rows"], wr, strict=True):
        a, b = r["default"], r["one-step 1e-6"]
        lines.append(f"| {r['scene']} | {r['noise']} | {a['model']} | {a['psnr']:.2f} | "
                     f"{b['psnr']:.2f} | {a['iterations']} | {b['iterations']} | "
                     f"{a['wall_s']:.3f} | {b['wall_s']:.3f} | {ratio:.2f} |")
    return "\n".join(lines) + "\n"


def plot(res: dict, path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(6.4, 4.2))
    for k, nz in enumerate(NOISES):
        rs = [r for r in res["rows"] if r["noise"] == nz]
        ax.plot([r["default"]["wall_s"] / r["one-step 1e-6"]["wall_s"] for r in rs],
                [r["default"]["psnr"] - r["one-step 1e-6"]["psnr"] for r in rs], "o",
                color=f"C{k}", label=nz)
    ax.axhline(0, color="grey", lw=1)
    ax.axvline(1, color="grey", lw=1)
    ax.set_xlabel("wall time, default / one-step rule")
    ax.set_ylabel("PSNR change (dB)")
    ax.set_title(f"final stop: window {res['final_stop_window']}, tol {res['final_tol']:g}",
                 fontsize=9)
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


if __name__ == "__main__":
    sys.exit(main())
