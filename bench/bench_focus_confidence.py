"""Calibrate the FZA autofocus's confidence rule (clfza.focus.focus_confidence) on measured
false-alarm and miss rates over scenes x noise levels x depths x search ranges.

Grid. The paper's simulation camera (the ``simulation`` preset: 512^2 of 10 um, GZP, r1 0.23
mm, z2 3 mm), frames simulated at 512^2 with Gaussian noise of variance 0, 0.003, 0.01 (the
paper's Fig. 7) and 0.03 on ``y``, then binned 2x2 (the search runs on binned frames); scenes
natural, text, usaf, points (clfza.benchmarks' built-ins), a flat grey square and no scene at
all (noise only: every confident answer is a false alarm); true depths 12, 20, 35, 55 mm;
ranges 10-60 and 10-1000 mm. Two independent noise draws: ``calibration`` (the threshold is
chosen on it) and ``validation`` (held out). Then the issue-34 camera (pitch 5.5 um, 1024^2,
r1 0.5 mm, z2 2 mm, R 4 mm; binned 4x4) at 150, 250 and 500 mm searched over 100-1000 mm,
where the depth of focus is as wide as the range, and the Fig. 7 case unbinned.

A search is right when ``|z1_best - z1_true|`` is within the depth of focus at the truth
(:func:`clfza.focus.depth_resolution` of the searched camera); a confident wrong answer is a
false alarm, a refused right answer a miss. For each locality window ``PEAK_WIDTH`` the
threshold is the smallest value (step 0.05) with no false alarm on the calibration draw plus
one step of margin; the window with the fewest calibration misses at its threshold is chosen
(clfza's MIN_ISOLATION and PEAK_WIDTH), then checked on the validation draw.

    .venv/bin/python bench/bench_focus_confidence.py [--quick]
    .venv/bin/python bench/bench_focus_confidence.py --from bench/results/focus_confidence_grid.json

``--from`` re-applies the rule (with clfza's current constants) to the curves a run saved.

Writes bench/results/focus_confidence_<machine>.json, .md and .png.
"""

from __future__ import annotations

import argparse
import json
import math
import platform
import time
import warnings
from pathlib import Path

import numpy as np

from clfza import Camera, Noise, simulate
from clfza.benchmarks._scenes import measurement
from clfza.focus import autofocus, depth_resolution
from clfza.focus._search import MIN_ISOLATION, PEAK_WIDTH, focus_evidence

OUT = Path(__file__).resolve().parent / "results"
SCENES = ("natural", "text", "usaf", "points", "flat", "none")
NOISES = (0.0, 0.003, 0.01, 0.03)
DEPTHS = (12.0, 20.0, 35.0, 55.0)
RANGES = ((10.0, 60.0), (10.0, 1000.0))
THRESHOLDS = tuple(round(0.05 * i, 2) for i in range(0, 21))
PEAK_WIDTHS = (2.0, 3.0, 4.0, 6.0, 8.0)
#: the searched cameras by key (rows name theirs; the rule is re-applied from the saved curves)
CAMERAS = {
    "simulation/2": Camera.preset("simulation").with_shape((256, 256), 0.02),
    "fza-test": Camera(pitch=0.01, shape=(256, 256), r1=0.14, z1=30.0, z2=3.0, R=1.1,
                       mask="fza"),
    "issue34/4": Camera(pitch=0.022, shape=(256, 256), r1=0.5, z1=250.0, z2=2.0, R=4.0,
                        mask="fza"),
}


def _bin(a: np.ndarray, b: int) -> np.ndarray:
    h, w = a.shape[0] // b, a.shape[1] // b
    return a[:h * b, :w * b].reshape(h, b, w, b).mean(axis=(1, 3))


def _frame(scene: str, cam: Camera, var: float, seed: int) -> np.ndarray | None:
    """The observation y of one shot (None: no scene and no noise, nothing to search)."""
    noise = Noise(gaussian_var=var, seed=seed) if var else None
    if scene == "none":
        if not var:
            return None
        rng = np.random.default_rng(seed)
        return rng.normal(0.0, math.sqrt(var), cam.shape)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        if scene == "flat":
            width = 0.6 * cam.shape[1] * cam.pitch / cam.magnification
            return simulate(np.full((256, 256), 0.5), cam, object_width=width, noise=noise).y
        return measurement(scene, cam, noise=noise).measurement.y


def _search(y: np.ndarray, cam: Camera, z_range, z_true: float) -> dict:
    fr = autofocus(y, cam, z_range, backend="numpy", warn=False)
    dof = depth_resolution(cam, z_true)
    ev = fr.evidence
    return {"z_best": round(fr.z1_best, 4), "dof": round(dof, 4),
            "right": bool(abs(fr.z1_best - z_true) <= dof),
            "confident": bool(fr.confident), "isolation": round(ev["isolation"], 4),
            "ratio": round(ev["ratio"], 3), "at_edge": bool(ev["at_edge"]),
            "resolution_fraction": ev["resolution_fraction"],
            "scores": [float(f"{v:.7g}") for v in fr.scores],
            "grid": [float(f"{v:.7g}") for v in fr.z_grid]}


def grid(draw: str, seed0: int, quick: bool) -> list[dict]:
    """Every (scene, noise, depth, range) of the preset camera, frames binned 2x2."""
    base = Camera.preset("simulation")
    rows = []
    depths = DEPTHS[1:3] if quick else DEPTHS
    for si, scene in enumerate(SCENES):
        for ni, var in enumerate(NOISES):
            for di, z in enumerate(depths):
                cam = base.at_depth(z)
                y = _frame(scene, cam, var, seed0 + 1000 * si + 100 * ni + di)
                if y is None:
                    continue
                yb = _bin(y, 2)
                cb = CAMERAS["simulation/2"]
                for z_range in RANGES:
                    r = _search(yb, cb, z_range, z)
                    if scene == "none":
                        r["right"] = False
                    r.update(draw=draw, camera="simulation/2", scene=scene, noise_var=var,
                             z_true=z, z_range=list(z_range))
                    rows.append(r)
            print(f"{draw:11s} {scene:8s} var {var:g}: {sum(r['confident'] for r in rows)} "
                  f"confident of {len(rows)} so far", flush=True)
    return rows


def fza_test(draw: str, seed0: int) -> list[dict]:
    """The FZA camera of tests/test_focus.py (256^2 of 10 um, r1 0.14 mm, R 1.1 mm), whose
    sharpness peaks are wider than the preset's: natural, text, no scene; noise 0 and 0.01;
    15, 20, 35 mm searched over 10-60 mm, unbinned."""
    cam0 = CAMERAS["fza-test"]
    rows = []
    for si, scene in enumerate(("natural", "text", "none")):
        for var in (0.0, 0.01):
            for z in (15.0, 20.0, 35.0):
                y = _frame(scene, cam0.at_depth(z), var, seed0 + 10 * si + int(z))
                if y is None:
                    continue
                r = _search(y, cam0, (10.0, 60.0), z)
                if scene == "none":
                    r["right"] = False
                r.update(draw=draw, camera="fza-test", scene=scene, noise_var=var, z_true=z,
                         z_range=[10.0, 60.0])
                rows.append(r)
    return rows


def issue_camera(quick: bool) -> list[dict]:
    """The issue-34 FZA camera, 1024^2 binned 4x4, searched over 100-1000 mm."""
    cam0 = Camera(pitch=0.0055, shape=(1024, 1024), r1=0.5, z1=250.0, z2=2.0, R=4.0,
                  mask="fza")
    cb = CAMERAS["issue34/4"]
    rows = []
    for scene in ("natural",) if quick else ("natural", "text"):
        for var in (0.0, 0.01):
            for z in (150.0, 250.0, 500.0):
                cam = cam0.at_depth(z)
                y = _bin(_frame(scene, cam, var, 7), 4)
                r = _search(y, cb, (100.0, 1000.0), z)
                r.update(draw="issue camera", camera="issue34/4", scene=scene, noise_var=var,
                         z_true=z, z_range=[100.0, 1000.0])
                rows.append(r)
    return rows


def fig7() -> list[dict]:
    """The paper's Fig. 7 case unbinned: natural scene at 20 mm, noise variance 0.01."""
    cam = Camera.preset("simulation")
    y = _frame("natural", cam, 0.01, 1)
    rows = []
    for z_range in RANGES:
        r = _search(y, cam, z_range, 20.0)
        r.update(draw="fig7 512^2", camera="simulation", scene="natural", noise_var=0.01,
                 z_true=20.0, z_range=list(z_range))
        rows.append(r)
    return rows


def rates(rows: list[dict], min_isolation: float = MIN_ISOLATION,
          peak_width: float = PEAK_WIDTH) -> dict:
    """The rule with these thresholds applied to the rows' curves: false alarms (confident
    and wrong), misses (right but refused), successes (confident and right, or refused)."""
    fa = miss = conf_right = n_right = 0
    for r in rows:
        cam = CAMERAS.get(r["camera"])
        if cam is not None:
            ok = focus_evidence(np.asarray(r["scores"]), np.asarray(r["grid"]), camera=cam,
                                min_isolation=min_isolation,
                                peak_width=peak_width)["confident"]
        else:
            ok = r["confident"]
        n_right += r["right"]
        fa += ok and not r["right"]
        miss += (not ok) and r["right"]
        conf_right += ok and r["right"]
    n = len(rows)
    return {"min_isolation": min_isolation, "peak_width": peak_width, "runs": n, "right": n_right,
            "false_alarms": fa, "misses": miss, "confident_right": conf_right,
            "false_alarm_rate": fa / n if n else math.nan,
            "miss_rate": miss / n_right if n_right else math.nan,
            "success_rate": (n - fa) / n if n else math.nan}


def _cpu() -> str:
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or platform.machine()


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="two depths, one issue scene")
    ap.add_argument("--tag", default=None, help="file name tag (default grid, or quick)")
    ap.add_argument("--from", dest="source", default=None, metavar="JSON",
                    help="re-apply the rule to the curves of an earlier run's record")
    args = ap.parse_args()
    t0 = time.perf_counter()
    if args.source:
        old = json.loads(Path(args.source).read_text())
        rows, wall, args.quick = old["rows"], old["wall_s"], old["quick"]
        cal, val, issue, f7 = ([r for r in rows if r["draw"] == d] for d in
                               ("calibration", "validation", "issue camera", "fig7 512^2"))
        for r in rows:  # the verdict of clfza's current rule
            cam = CAMERAS.get(r["camera"], Camera.preset("simulation"))
            ev = focus_evidence(np.asarray(r["scores"]), np.asarray(r["grid"]), camera=cam)
            r.update(confident=bool(ev["confident"]), isolation=round(ev["isolation"], 4),
                     at_edge=bool(ev["at_edge"]))
    else:
        cal = grid("calibration", 0, args.quick) + fza_test("calibration", 0)
        val = grid("validation", 50000, args.quick) + fza_test("validation", 50000)
        issue = issue_camera(args.quick)
        f7 = fig7()
        wall = round(time.perf_counter() - t0, 1)
    table = [rates(cal, t, w) for w in PEAK_WIDTHS for t in THRESHOLDS]
    picks = []
    for w in PEAK_WIDTHS:
        clean = [t["min_isolation"] for t in table
                 if t["peak_width"] == w and t["false_alarms"] == 0]
        if clean:
            th = min(min(clean) + 0.05, 1.0)
            picks.append(rates(cal, round(th, 2), w))
    best = min(picks, key=lambda t: (t["misses"], t["min_isolation"]))
    summary = {
        "chosen": {"min_isolation": best["min_isolation"], "peak_width": best["peak_width"]},
        "constants": {"min_isolation": MIN_ISOLATION, "peak_width": PEAK_WIDTH},
        "calibration": rates(cal), "validation": rates(val),
        "issue_camera": rates(issue), "fig7": rates(f7),
        "all": rates(cal + val + issue + f7)}
    chosen = best["min_isolation"]
    for r in cal + val + issue + f7:
        r["scores"] = [float(f"{v:.7g}") for v in r["scores"]]
        r["grid"] = [float(f"{v:.7g}") for v in r["grid"]]
    machine = _cpu()
    tag = args.tag or ("quick" if args.quick else "grid")
    rec = {"bench": "focus_confidence", "date": time.strftime("%Y-%m-%d %H:%M:%S"),
           "machine": machine, "implementation": "numpy backend (float32 scipy.fft)",
           "wall_s": wall, "summary": summary,
           "threshold_table": table, "quick": args.quick,
           "rows": cal + val + issue + f7}
    OUT.mkdir(exist_ok=True)
    stem = OUT / f"focus_confidence_{tag}"
    stem.with_suffix(".json").write_text(json.dumps(rec, indent=1))
    stem.with_suffix(".md").write_text(markdown(rec))
    plot(stem.with_suffix(".png"), [t for t in table if t["peak_width"] == PEAK_WIDTH],
         cal + val, chosen)
    print(markdown(rec))


def markdown(rec: dict) -> str:
    s = rec["summary"]
    lines = [f"# FZA autofocus confidence ({rec['date']}, {rec['implementation']}, "
             f"{rec['wall_s']} s)", "",
             f"Chosen on the calibration draw (per window: the smallest threshold with no false "
             f"alarm plus 0.05; the window with the fewest misses): "
             f"min_isolation {s['chosen']['min_isolation']}, peak_width "
             f"{s['chosen']['peak_width']}; clfza's MIN_ISOLATION, PEAK_WIDTH: "
             f"{s['constants']['min_isolation']}, {s['constants']['peak_width']}.", "",
             "| set | runs | right | confident & right | false alarms | misses | "
             "success (right or refused) |", "|---|---|---|---|---|---|---|"]
    for k in ("calibration", "validation", "issue_camera", "fig7", "all"):
        r = s[k]
        lines.append(f"| {k} | {r['runs']} | {r['right']} | {r['confident_right']} | "
                     f"{r['false_alarms']} ({100 * r['false_alarm_rate']:.1f}%) | "
                     f"{r['misses']} ({100 * r['miss_rate']:.1f}% of right) | "
                     f"{100 * r['success_rate']:.1f}% |")
    lines += ["", "Calibration draw, by threshold (peak_width: false alarms / misses):", ""]
    widths = sorted({t["peak_width"] for t in rec["threshold_table"]})
    lines += ["| min_isolation | " + " | ".join(f"w {w:g}" for w in widths) + " |",
              "|---" * (len(widths) + 1) + "|"]
    for th in sorted({t["min_isolation"] for t in rec["threshold_table"]}):
        cells = [f"{t['false_alarms']} / {t['misses']}" for w in widths
                 for t in rec["threshold_table"]
                 if t["peak_width"] == w and t["min_isolation"] == th]
        lines.append(f"| {th:.2f} | " + " | ".join(cells) + " |")
    lines += ["", "Issue camera and Fig. 7 rows:", "",
              "| set | scene | var | z true | range | z found | dof | right | confident |",
              "|---|---|---|---|---|---|---|---|---|"]
    for r in rec["rows"]:
        if r["draw"] in ("issue camera", "fig7 512^2"):
            lines.append(f"| {r['draw']} | {r['scene']} | {r['noise_var']:g} | {r['z_true']:g} "
                         f"| {r['z_range'][0]:g}-{r['z_range'][1]:g} | {r['z_best']:.4g} | "
                         f"{r['dof']:.3g} | {r['right']} | {r['confident']} |")
    return "\n".join(lines) + "\n"


def plot(path: Path, table: list[dict], rows: list[dict], chosen: float) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, (a, b) = plt.subplots(1, 2, figsize=(11, 4))
    t = [r["min_isolation"] for r in table]
    a.plot(t, [r["false_alarm_rate"] for r in table], "r.-", label="false alarms / runs")
    a.plot(t, [r["miss_rate"] for r in table], "b.-", label="misses / right answers")
    a.axvline(chosen, color="k", ls=":", label=f"chosen {chosen}")
    a.set_xlabel("min_isolation")
    a.set_ylabel("rate (calibration draw)")
    a.legend()
    for right, c, lab in ((True, "g", "right"), (False, "r", "wrong")):
        sel = [r for r in rows if r["right"] == right and not r["at_edge"]]
        b.scatter([r["ratio"] for r in sel], [r["isolation"] for r in sel], s=10, c=c,
                  label=lab)
    b.axhline(MIN_ISOLATION, color="k", ls=":")
    b.axvline(6.0, color="gray", ls="--", label="former ratio test (6x)")
    b.set_xscale("log")
    b.set_xlabel("peak / curve noise (former statistic)")
    b.set_ylabel("isolation")
    b.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=100)


if __name__ == "__main__":
    main()
