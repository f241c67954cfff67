"""Issue 34 (seconds per real frame): the coarse pilot of measured-PSF frames against the
full-size pilot passes, in one run.

Usage::

    python bench/bench_coarse_pilot.py [--size 384] [--rounds 2] [--out bench/results]
                                       [--no-rgb] [--no-family]

``clfza.reconstruct(y, cam, "admm", psf=psf)`` (the defaults: ``tau="auto"``) with the coarse
pilot (clfza.reconstruction's ``_coarse_pilot``: the frame and the PSF binned 2x and solved,
the image upsampled as the start, ``tau="auto"`` reading the noise from its residual) and
without it (``COARSE_PILOT_MIN_SIDE`` raised past the frame: the full-size pilot passes), the
two interleaved per case and round (the order alternating), wall seconds (medians over the
rounds) and PSNR against the truth (the affine fit of :func:`clfza.metrics.compare`):

* ``family``: grey captures at ``--size`` (``bench_tau_heldout``'s measured-PSF family:
  camera, text, astronaut in grey, USAF bars; 50000, 5000 and 500 photons at the brightest
  pixel, read noise 2, 8 bits; and noise-free), the PSF captured at the scene's depth;
* ``rgb``: the 488^2 RGB captures of ``bench_real_camera.py --psf-speed`` (PSF 1.6x the frame,
  the scale known, cut to its energy support), the issue's <= 6 s case.

Writes ``bench/results/coarse_pilot_<machine>.json`` / ``.md`` / ``.png``.
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
from clfza.reconstruction import _reconstruct  # noqa: E402

RESULTS = Path(__file__).resolve().parent / "results"
FAMILY_SCENES = ("camera", "text", "astronaut", "usaf")
FAMILY_PHOTONS = (50000.0, 5000.0, 500.0, None)  # None: noise-free


def family_case(scene: str, photons: float | None, size: int):
    from bench_tau_heldout import psf_capture

    from clfza.models import crop_to_support, load_psf
    from clfza.simulation import simulate_psf_capture

    if photons is None:
        from bench_tau_psf import _scene

        from clfza.benchmarks import _scenes as scenes

        img = scenes.usaf_target()[0] if scene == "usaf" else _scene(scene)
        cap = simulate_psf_capture(img, shape=(size, size), scene_z1=400.0, psf_z1=400.0,
                                   noise=None)
        psf = load_psf(cap.psf, background="border", center="centroid")
    else:
        cap, psf = psf_capture(scene, photons, size)
    return cap.y, cap.camera, crop_to_support(psf), cap.truth


def rgb_case(scene: str, z: float):
    from bench_real_camera import PSF_SCENES

    from clfza.models import crop_to_support, load_psf, scale_psf
    from clfza.simulation import simulate_psf_capture

    cap = simulate_psf_capture(PSF_SCENES[scene](), shape=(488, 488), scene_z1=z)
    psf = load_psf(cap.psf, center="centroid")
    psf = crop_to_support(scale_psf(psf, cap.true_scale, max_shape=(975, 975)))
    return cap.y, cap.camera, psf, cap.truth


def solve(y, cam, psf, truth, coarse: bool) -> dict:
    saved = _reconstruct.COARSE_PILOT_MIN_SIDE
    if not coarse:
        _reconstruct.COARSE_PILOT_MIN_SIDE = 10**9
    try:
        t0 = time.perf_counter()
        rec = clfza.reconstruct(y, cam, "admm", psf=psf)
        wall = time.perf_counter() - t0
    finally:
        _reconstruct.COARSE_PILOT_MIN_SIDE = saved
    stats = rec.info.stats.get("channels", [rec.info.stats])
    return {"wall_s": wall, "psnr": compare(rec.image, truth)["psnr"],
            "rule": [s.get("tau_auto", {}).get("rule") for s in stats],
            "coarse_used": [bool(s.get("coarse_pilot", {}).get("used")) for s in stats],
            "pilot_iterations": [s.get("tau_auto", {}).get("stage_iterations_total")
                                 for s in stats]}


def run_case(label: str, kind: str, data, rounds: int) -> dict:
    y, cam, psf, truth = data
    runs = {"coarse": [], "fine": []}
    solve(y, cam, psf, truth, True)  # warm-up: kernels, the device's first solve
    for r in range(rounds):
        for which in (("coarse", "fine") if r % 2 == 0 else ("fine", "coarse")):
            runs[which].append(solve(y, cam, psf, truth, which == "coarse"))
    row = {"case": label, "kind": kind, "shape": list(np.shape(y))}
    for which, rs in runs.items():
        row[which] = dict(rs[-1], wall_s=statistics.median(r["wall_s"] for r in rs),
                          walls=[r["wall_s"] for r in rs])
    row["psnr_change_db"] = row["coarse"]["psnr"] - row["fine"]["psnr"]
    row["wall_ratio"] = row["coarse"]["wall_s"] / row["fine"]["wall_s"]
    print(f"{label:28s} fine {row['fine']['psnr']:6.2f} dB {row['fine']['wall_s']:6.2f} s | "
          f"coarse {row['coarse']['psnr']:6.2f} dB {row['coarse']['wall_s']:6.2f} s "
          f"(used {row['coarse']['coarse_used']}) | change {row['psnr_change_db']:+.2f} dB, "
          f"wall x{row['wall_ratio']:.2f}", flush=True)
    return row


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--size", type=int, default=384)
    p.add_argument("--rounds", type=int, default=2)
    p.add_argument("--no-rgb", action="store_true")
    p.add_argument("--no-family", action="store_true")
    p.add_argument("--out", default=str(RESULTS))
    a = p.parse_args(argv)
    warnings.simplefilter("ignore")
    machine = machine_record()
    rows = []
    if not a.no_rgb:
        from bench_real_camera import SPEED_CASES

        for scene, z in SPEED_CASES:
            rows.append(run_case(f"rgb488 {scene}", "rgb", rgb_case(scene, z), a.rounds))
    if not a.no_family:
        for photons in FAMILY_PHOTONS:
            for scene in FAMILY_SCENES:
                label = f"grey{a.size} {scene} " + (f"{photons:g} ph" if photons else "clean")
                rows.append(run_case(label, "family", family_case(scene, photons, a.size),
                                     a.rounds))
    summary = {}
    for kind in ("rgb", "family"):
        rs = [r for r in rows if r["kind"] == kind]
        if rs:
            ch = [r["psnr_change_db"] for r in rs]
            summary[kind] = {"cases": len(rs), "mean_psnr_change_db": float(np.mean(ch)),
                             "worst_psnr_change_db": float(min(ch)),
                             "median_wall_ratio": float(np.median([r["wall_ratio"]
                                                                   for r in rs])),
                             "median_wall_coarse_s": float(np.median(
                                 [r["coarse"]["wall_s"] for r in rs])),
                             "median_wall_fine_s": float(np.median(
                                 [r["fine"]["wall_s"] for r in rs]))}
    machine["load_average_end"] = list(machine_record()["load_average"])
    res = {"benchmark": "coarse_pilot", "machine": machine, "rounds": a.rounds,
           "revision": revision(),  # bench_tau's: HEAD and whether clfza/ differs
           "size": a.size, "rows": rows, "summary": summary}
    stem = Path(a.out) / f"coarse_pilot_{machine_slug(machine)}"
    write_result_files(stem, res, markdown(res), plot)
    print(markdown(res))
    return 0


def markdown(res: dict) -> str:
    m = res["machine"]
    lines = ["# The coarse pilot of measured-PSF frames against full-size pilot passes", "",
             f"`bench/bench_coarse_pilot.py` (its docstring: the cases and the two routes). "
             f"{m.get('cpu_model')}, {m.get('cores_usable')} cores usable (shared VM); OpenCL "
             f"{(m.get('device') or {}).get('describe', '')}; versions {m.get('versions')}; "
             f"{m.get('date', '')}; load average {m.get('load_average')} -> "
             f"{m.get('load_average_end')}; {res['rounds']} rounds, interleaved, wall medians; "
             f"revision {_rev(res.get('revision'))}. PSNR after the affine fit "
             f"(clfza.metrics.compare); 'fine' = the full-size pilot passes.",
             "", "| case | fine PSNR | fine s | coarse PSNR | coarse s | change dB | wall ratio "
             "| coarse used | rule (coarse) |", "|---|---|---|---|---|---|---|---|---|"]
    for r in res["rows"]:
        c, f = r["coarse"], r["fine"]
        lines.append(f"| {r['case']} | {f['psnr']:.2f} | {f['wall_s']:.2f} | {c['psnr']:.2f} | "
                     f"{c['wall_s']:.2f} | {r['psnr_change_db']:+.2f} | x{r['wall_ratio']:.2f} | "
                     f"{'/'.join('y' if u else 'n' for u in c['coarse_used'])} | "
                     f"{'/'.join(str(x) for x in c['rule'])} |")
    lines += ["", "| cases | n | mean change dB | worst dB | median wall ratio | median s "
              "(coarse / fine) |", "|---|---|---|---|---|---|"]
    for k, s in res["summary"].items():
        lines.append(f"| {k} | {s['cases']} | {s['mean_psnr_change_db']:+.2f} | "
                     f"{s['worst_psnr_change_db']:+.2f} | x{s['median_wall_ratio']:.2f} | "
                     f"{s['median_wall_coarse_s']:.2f} / {s['median_wall_fine_s']:.2f} |")
    return "\n".join(lines) + "\n"


def _rev(r) -> str:
    if not isinstance(r, dict):  # a run before the revision was a dict
        return str(r)
    return (r.get("commit") or "?")[:7] + (" (clfza modified)" if r.get("clfza_modified")
                                            else "")


def plot(res: dict, path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(6.4, 4.2))
    for kind, mk in (("rgb", "o"), ("family", "s")):
        rs = [r for r in res["rows"] if r["kind"] == kind]
        ax.scatter([r["wall_ratio"] for r in rs], [r["psnr_change_db"] for r in rs],
                   marker=mk, label=kind)
    ax.axhline(0, color="grey", lw=1)
    ax.axvline(1, color="grey", lw=1)
    ax.set_xlabel("wall time, coarse pilot / full-size passes")
    ax.set_ylabel("PSNR change, dB")
    ax.legend()
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


if __name__ == "__main__":
    raise SystemExit(main())
