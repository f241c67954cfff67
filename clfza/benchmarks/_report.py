"""Result files of the benchmarks: JSON, PNG plots (matplotlib, Agg) and markdown tables."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ..io import atomic_write_bytes, write_figure, write_json

COLORS = {"bp": "0.5", "twist-tv-paper": "C3", "twist-tv-efficient": "C1", "twist-l1": "C4",
          "fista-tv": "C2", "admm-tv": "C0", "fista-tv-auto": "C8", "admm-tv-auto": "C9",
          "default": "k"}


def _plt():
    import matplotlib  # lazy: matplotlib takes ~0.5 s to import; only plots need it

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt  # lazy: matplotlib takes ~0.5 s to import; only plots need it

    return plt


def _fmt_t(t: float | None) -> str:
    if t is None:
        return "not reached"
    if t < 1e-3:
        return f"{t * 1e6:.0f} us"
    if t < 1:
        return f"{t * 1e3:.1f} ms"
    return f"{t:.2f} s"


def machine_lines(machine: dict) -> list[str]:
    """Markdown bullet lines describing the machine, device, versions and date."""
    dev = machine.get("device", {})
    v = machine.get("versions", {})
    vs = ", ".join(f"{k} {val}" for k, val in v.items() if val)
    return [
        f"- Machine: {machine.get('cpu_model')} ({machine.get('cores_usable')} usable cores, "
        f"{machine.get('memory_gib')} GiB, {machine.get('cpu_simd')}); load average at start "
        f"{machine.get('load_average')} (shared machine: compare ratios within one run)",
        f"- OpenCL device: {dev.get('describe') or dev.get('error')}",
        f"- Versions: {vs}; Python {machine.get('python')}",
        f"- Date: {machine.get('date')}",
    ]


def _table(header: list[str], rows: list[list[str]]) -> list[str]:
    out = ["| " + " | ".join(header) + " |", "|" + "|".join("---" for _ in header) + "|"]
    out += ["| " + " | ".join(str(c) for c in r) + " |" for r in rows]
    return out


# ------------------------------------------------------------------------------------------
# time against error
# ------------------------------------------------------------------------------------------
def _group_rows(rows, scene, noise, size, backend):
    return [r for r in rows if "error" not in r and r["scene"] == scene and r["noise"] == noise
            and r["size"] == size and r["backend"] == backend]


def _plot_panel(ax, rows, title: str) -> None:
    ref = next((r for r in rows if r["key"] == "twist-tv-paper"), None)
    for r in rows:
        ts = [max(p["time_s"], 1e-4) for p in r["curve"]]
        ps = [p["psnr"] for p in r["curve"]]
        style = "o" if len(ts) == 1 else ".-"
        ax.plot(ts, ps, style, color=COLORS.get(r["key"]), label=r["label"], ms=4, lw=1.2)
    if ref is not None:
        ax.axhline(ref["final"]["psnr"], color="C3", ls=":", lw=1,
                   label="paper-mode final PSNR")
    ax.set_xscale("log")
    ax.set_xlabel("wall time (s)")
    ax.set_ylabel("PSNR (dB, affine fit)")
    ax.set_title(title, fontsize=9)
    ax.grid(True, which="both", alpha=0.3)


def plot_time_error(result: dict, path: Path, grid_path: Path | None = None) -> list[Path]:
    """Headline plot (the paper row per backend) and a grid of every scene/noise panel."""
    plt = _plt()
    rows = result["rows"]
    pr = result["paper_row"]
    written = []
    backends = [b for b in ("opencl", "numpy")
                if _group_rows(rows, pr["scene"], pr["noise"], pr["size"], b)]
    if not backends:  # e.g. the tiny profile: plot whatever exists
        r0 = next((r for r in rows if "error" not in r), None)
        if r0 is None:
            return written
        pr = {"scene": r0["scene"], "noise": r0["noise"], "size": r0["size"]}
        backends = [r0["backend"]]
    noises = [pr["noise"]] + [n for n in ("none",) if n != pr["noise"] and any(
        _group_rows(rows, pr["scene"], n, pr["size"], b) for b in backends)]
    fig, axes = plt.subplots(len(noises), len(backends),
                             figsize=(6.2 * len(backends), 4.2 * len(noises)), squeeze=False)
    for i, noise in enumerate(noises):
        for ax, b in zip(axes[i], backends, strict=True):
            g = _group_rows(rows, pr["scene"], noise, pr["size"], b)
            if not g:
                ax.axis("off")
                continue
            _plot_panel(ax, g, f"{pr['scene']}, noise {noise}, {pr['size']}^2 - {b} "
                               f"({g[0]['dtype']}) on {g[0].get('device', b)}")
    axes[0][0].legend(fontsize=7, loc="best")
    fig.suptitle("clfza: PSNR against wall time, the paper's Fig. 7 setup (dotted: final PSNR "
                 "of paper-mode TwIST-TV)", fontsize=10)
    fig.tight_layout()
    written.append(write_figure(path, fig, force=True))
    plt.close(fig)
    if grid_path is not None:
        keys = sorted({(r["scene"], r["noise"], r["size"], r["backend"]) for r in rows
                       if "error" not in r}, key=lambda k: (k[3] != "opencl", k[2], k[1], k[0]))
        if keys:
            ncol = 5
            nrow = (len(keys) + ncol - 1) // ncol
            fig, axes = plt.subplots(nrow, ncol, figsize=(4.2 * ncol, 3.4 * nrow),
                                     squeeze=False)
            for ax, k in zip(axes.flat, keys, strict=False):
                _plot_panel(ax, _group_rows(rows, *k), f"{k[0]} / {k[1]} / {k[2]}^2 / {k[3]}")
            for ax in list(axes.flat)[len(keys):]:
                ax.axis("off")
            axes.flat[0].legend(fontsize=6, loc="lower right")
            fig.tight_layout()
            written.append(write_figure(grid_path, fig, force=True))
            plt.close(fig)
    return written


def _time_error_head(result: dict, png_names: list[str]) -> list[str]:
    """The report's title, the machine and the run's settings, and its figures."""
    lines = ["# Time against error", ""]
    lines += machine_lines(result["machine"])
    lines += [f"- Profile: {result.get('profile')}; elapsed {result.get('elapsed_s', 0):.0f} s",
              f"- Metrics: {result['metrics_note']}",
              f"- Cameras: {result['camera_note']}",
              "- Noise: " + "; ".join(f"`{k}` = {v}" for k, v in result["noise_models"].items()),
              "- Times: the solver's own solve clock after a warm-up run (kernel builds and FFT "
              "planning excluded; checkpoint metrics excluded); each curve is one solve, of "
              f"{result.get('repeats', 1)} per method and case the one of median time.", ""]
    for name in png_names:
        lines += [f"![time against error]({name})", ""]
    return lines


def _time_to_paper(rows: list[dict], ttp: list[dict], pr: dict) -> list[str]:
    """Section: time to the paper's quality on the paper's scene, noise and size."""
    head = [t for t in ttp if t["scene"] == pr["scene"] and t["noise"] == pr["noise"]
            and t["size"] == pr["size"]]
    if not head:
        return []
    lines = [f"## Time to the paper's quality ({pr['scene']}, {pr['noise']}, "
             f"{pr['size']}^2)", "",
             "Target: the final PSNR of paper-mode TwIST-TV (tau = 0.005, 200 iterations, "
             "2 Chambolle iterations), the paper's Fig. 7 settings.", ""]
    body = []
    for t in sorted(head, key=lambda t: (t["backend"] != "opencl",
                                         t["time_to_target_s"] or 1e9)):
        r = next(r for r in rows if r["key"] == t["key"] and r["backend"] == t["backend"]
                 and r["scene"] == t["scene"] and r["noise"] == t["noise"]
                 and r["size"] == t["size"])
        body.append([t["label"], t["backend"], r["iterations"], f"{t['final_psnr']:.2f}",
                     f"{t['final_ssim']:.3f}", f"{t['target_psnr']:.2f}",
                     _fmt_t(t["time_to_target_s"]),
                     f"{t['speedup_vs_paper']:.1f}x" if t["speedup_vs_paper"] else "-"])
    lines += _table(["method", "backend", "iterations", "final PSNR", "final SSIM",
                     "target PSNR", "time to target", "speed-up vs paper mode"], body)
    lines.append("")
    return lines


def _time_to_paper_per_scene(ttp: list[dict]) -> list[str]:
    """Section (OpenCL, 512^2): time to reach the paper-mode PSNR of each scene and noise."""
    cols = sorted({(t["scene"], t["noise"]) for t in ttp if t["backend"] == "opencl"
                   and t["size"] == 512})
    if not cols:
        return []
    lines = ["## Time to the paper-mode PSNR per scene (OpenCL, 512^2)", "",
             "Each cell: the time a method needs to reach the final PSNR of paper-mode "
             "TwIST-TV on the same scene and noise (target in the header row).", ""]
    keys = []
    for t in ttp:
        if t["key"] not in keys:
            keys.append(t["key"])
    header = ["method"] + [f"{s} / {n}" for s, n in cols]
    target_row = ["target PSNR (dB)"]
    for s, n in cols:
        tt = next((t for t in ttp if t["scene"] == s and t["noise"] == n
                   and t["backend"] == "opencl" and t["size"] == 512), None)
        target_row.append(f"{tt['target_psnr']:.2f}" if tt else "-")
    body = [target_row]
    for k in keys:
        label = next(t["label"] for t in ttp if t["key"] == k)
        cells = [label]
        for s, n in cols:
            tt = next((t for t in ttp if t["scene"] == s and t["noise"] == n
                       and t["backend"] == "opencl" and t["size"] == 512
                       and t["key"] == k), None)
            cells.append("-" if tt is None else _fmt_t(tt["time_to_target_s"]))
        body.append(cells)
    lines += _table(header, body)
    lines.append("")
    return lines


def _cost_against_limit(rows: list[dict], pr: dict, lim: dict) -> list[str]:
    """Section: cost per iteration against the machine's limit (the paper's scene and noise)."""
    bw = lim.get("bandwidth_used_gb_per_s") or 0.0
    lines = ["## Cost per iteration against the machine's limit", "",
             f"Limit = FFT pairs x measured rfft2+irfft2 time (clfza.fft._host, same dtype and "
             f"size) + arrays touched x N^2 x itemsize / {bw:.1f} GB/s (best triad bandwidth "
             "of this run; see clfza/benchmarks/methods.py for the per-method array counts). "
             "For BP the whole reconstruction is one 'iteration'.",
             ""]
    body = []
    for r in sorted(rows, key=lambda r: (r["size"], r["scene"], r["noise"], r["backend"],
                                         r["key"])):
        if r["scene"] != pr["scene"] or r["noise"] != pr["noise"]:
            continue
        ev = r.get("evaluations_per_iter")
        body.append([r["label"], r["backend"], f"{r['size']}^2", r["dtype"],
                     f"{r['per_iter_s'] * 1e3:.2f}", f"{r['limit_per_iter_s'] * 1e3:.2f}",
                     f"{r['ratio_to_limit']:.1f}", r["work_model"],
                     "-" if ev is None else f"{ev:.2f}"])
    lines += _table(["method", "backend", "size", "dtype", "ms / iteration", "limit ms",
                     "ratio", "work model", "FFT evaluations / it"], body)
    return lines


def _all_runs(result: dict, rows: list[dict]) -> list[str]:
    """Section: every run, then the runs that raised a ClfzaError."""
    lines = ["", "## All runs", ""]
    body = []
    for r in rows:
        f = r["final"]
        body.append([r["scene"], r["noise"], f"{r['size']}^2", r["backend"], r["label"],
                     r["iterations"], r["stop_reason"], f"{f['psnr']:.2f}", f"{f['ssim']:.3f}",
                     f"{f['mse']:.2e}", _fmt_t(r["solve_s"]), f"{r['ratio_to_limit']:.1f}"])
    lines += _table(["scene", "noise", "size", "backend", "method", "iterations", "stop",
                     "PSNR", "SSIM", "MSE", "solve time", "x limit"], body)
    errs = [r for r in result["rows"] if "error" in r]
    if errs:
        lines += ["", "Runs that raised a ClfzaError:", ""]
        lines += [f"- {r['key']} {r['scene']}/{r['noise']}/{r['size']}/{r['backend']}: "
                  f"{r['error']}" for r in errs]
    return lines


def time_error_markdown(result: dict, png_names: list[str]) -> str:
    """The time-against-error report as Markdown: settings and figures, time to the paper's
    quality, per scene, cost per iteration against the machine's limit, and every run."""
    rows = [r for r in result["rows"] if "error" not in r]
    ttp = result.get("time_to_paper", [])
    pr = result["paper_row"]
    lines = _time_error_head(result, png_names)
    lines += _time_to_paper(rows, ttp, pr)
    lines += _time_to_paper_per_scene(ttp)
    lines += _cost_against_limit(rows, pr, result.get("limits", {}))
    lines += _all_runs(result, rows)
    return "\n".join(lines) + "\n"


def write_time_error(result: dict, out: Path, label: str) -> dict:
    out.mkdir(parents=True, exist_ok=True)
    png = out / f"time_error_{label}.png"
    grid_png = out / f"time_error_{label}_grid.png"
    pngs = plot_time_error(result, png, grid_png)
    md = out / f"time_error_{label}.md"
    js = out / f"time_error_{label}.json"
    paths = {"json": str(js), "md": str(md), "png": [str(p) for p in pngs]}
    result["paths"] = paths
    write_json(js, result, force=True)

    text = time_error_markdown(result, [p.name for p in pngs])
    atomic_write_bytes(md, text.encode("utf-8"), force=True)
    return paths


# ------------------------------------------------------------------------------------------
# scaling
# ------------------------------------------------------------------------------------------
def plot_scaling(result: dict, path: Path) -> Path:

    plt = _plt()
    fig, axes = plt.subplots(1, 2, figsize=(12, 4.4))
    ax, ax2 = axes
    series: dict[tuple[str, str], list] = {}
    for r in result["rows"]:
        if "error" in r:
            continue
        series.setdefault((r["key"], r["backend"]), []).append(r)
    for (key, backend), rs in sorted(series.items()):
        rs = sorted(rs, key=lambda r: r["size"])
        n = np.array([r["size"] for r in rs], float)
        t = np.array([r["per_iter_s"] for r in rs])
        ls = "-" if backend == "opencl" else "--"
        ax.loglog(n, t, "o" + ls, color=COLORS.get(key), label=f"{rs[0]['label']} ({backend})",
                  ms=4)
        norm = t / (n**2 * np.log2(n))
        ax2.semilogx(n, norm / norm[0], "o" + ls, color=COLORS.get(key), ms=4)
    lim = result.get("limit_rows", [])
    if lim:
        n = np.array([r["size"] for r in lim], float)
        ax.loglog(n, [r["fft_pair_f32_s"] for r in lim], "k:", label="FFT pair f32 (limit part)")
    nn = np.array(sorted({r["size"] for r in result["rows"] if "error" not in r}), float)
    if len(nn):
        ref = [r for r in result["rows"] if "error" not in r and r["key"] == "bp"
               and r["backend"] == "opencl"]
        t0 = min(ref, key=lambda r: r["size"])["per_iter_s"] if ref else 1e-3
        n0 = nn[0]
        ax.loglog(nn, t0 * (nn**2 * np.log2(nn)) / (n0**2 * np.log2(n0)), color="k", lw=0.8,
                  alpha=0.5, label="N^2 log N (from BP at the smallest N)")
    ax.set_xlabel("N (grid N x N)")
    ax.set_ylabel("seconds per iteration")
    ax.set_title("time per iteration", fontsize=9)
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=6)
    ax2.axhline(1.0, color="k", lw=0.8)
    ax2.set_xlabel("N")
    ax2.set_ylabel("t / (N^2 log2 N), normalised to the smallest N")
    ax2.set_title("against the N^2 log N expectation (flat = as expected)", fontsize=9)
    ax2.grid(True, which="both", alpha=0.3)
    fig.tight_layout()
    p = write_figure(path, fig, force=True)
    plt.close(fig)
    return p


def scaling_markdown(result: dict, png_name: str) -> str:
    lines = ["# Scaling: time per iteration against N^2 log N", ""]
    lines += machine_lines(result["machine"])
    lines += ["", f"![scaling]({png_name})", "",
              "Exponent k of t ~ (N^2)^k fitted by least squares in log-log (k = 1 plus a "
              "little for the log N factor of the FFT is the expectation; the N^2 log N column "
              "is t / (N^2 log2 N) at the largest N divided by the same at the smallest).", ""]
    body = [[f["label"], f["backend"], f"{f['sizes'][0]}-{f['sizes'][-1]}",
             f"{f['exponent_vs_N2']:.2f}", f"{f['nlogn_ratio']:.2f}",
             f"{f['ratio_to_limit_range'][0]:.1f}-{f['ratio_to_limit_range'][1]:.1f}"]
            for f in result["fits"]]
    lines += _table(["method", "backend", "N", "exponent k (t ~ N^2k)", "N^2 log N drift",
                     "x limit"], body)
    lines += ["", "## Per size", ""]
    body = [[r["label"], r["backend"], f"{r['size']}^2", f"{r['per_iter_s'] * 1e3:.2f}",
             f"{r['limit_per_iter_s'] * 1e3:.2f}", f"{r['ratio_to_limit']:.1f}"]
            for r in sorted(result["rows"], key=lambda r: (r["key"], r["backend"], r["size"]))
            if "error" not in r]
    lines += _table(["method", "backend", "size", "ms / iteration", "limit ms", "ratio"], body)
    if result.get("limit_rows"):
        lines += ["", "## Machine limit parts", ""]
        body = [[f"{r['size']}^2", f"{r['fft_pair_f32_s'] * 1e3:.2f}",
                 f"{r['fft_pair_f64_s'] * 1e3:.2f}"] for r in result["limit_rows"]]
        lines += _table(["size", "FFT pair f32 (ms)", "FFT pair f64 (ms)"], body)
        lines += ["", f"Triad bandwidth used: {result['limits']['bandwidth_used_gb_per_s']:.1f}"
                      " GB/s"]
    return "\n".join(lines) + "\n"


def write_scaling(result: dict, out: Path, label: str) -> dict:

    out.mkdir(parents=True, exist_ok=True)
    png = plot_scaling(result, out / f"scaling_{label}.png")
    md = out / f"scaling_{label}.md"
    js = out / f"scaling_{label}.json"
    paths = {"json": str(js), "md": str(md), "png": str(png)}
    result["paths"] = paths
    write_json(js, result, force=True)
    atomic_write_bytes(md, scaling_markdown(result, png.name).encode("utf-8"), force=True)
    return paths


# ------------------------------------------------------------------------------------------
# stability
# ------------------------------------------------------------------------------------------
def stability_markdown(result: dict) -> str:
    c = result["counts"]
    lines = ["# Numerical stability stress report", ""]
    lines += machine_lines(result["machine"])
    lines += ["", "## Counts", ""]
    lines += _table(["quantity", "value"], [
        ["cases tried", c["cases"]],
        ["finite images", c["finite"]],
        ["clear errors (ClfzaError, expected)", c["clear_errors"]],
        ["NaN/Inf images produced", c["nonfinite"]],
        ["crashes (any other exception, or an unexpected ClfzaError)", c["crashes"]],
        ["objective rises where monotonicity is promised", c["monotone_violations"]],
        ["monotone runs checked", c["monotone_checked"]],
        ["largest float32/float64 PSNR gap (dB)", f"{c['max_psnr_gap_db']:.3g}"],
        ["largest float32/float64 relative objective gap", f"{c['max_objective_gap']:.3g}"],
    ])
    lines += ["", f"Monotonicity tolerance: a rise counts when f[k+1] > f[k] (1 + "
                  f"{result['monotone_rtol']['float32']:g}) in float32, "
                  f"{result['monotone_rtol']['float64']:g} in float64 (rounding of the "
                  "objective's own sums).", ""]
    gaps = result.get("precision", [])
    if gaps:
        lines += ["## float32 against float64", ""]
        body = [[g["label"], g["size"], g["iterations"], f"{g['psnr_f32']:.3f}",
                 f"{g['psnr_f64']:.3f}", f"{g['psnr_gap_db']:.2e}",
                 "-" if g["objective_gap"] is None else f"{g['objective_gap']:.2e}",
                 f"{g['image_rel_diff']:.2e}"] for g in gaps]
        lines += _table(["method", "size", "iterations", "PSNR f32", "PSNR f64",
                         "PSNR gap (dB)", "objective gap (rel)", "image rel. diff"], body)
        lines.append("")
    lines += ["## By category", ""]
    cats: dict[str, dict] = {}
    for r in result["cases"]:
        d = cats.setdefault(r["category"], {"n": 0, "finite": 0, "error": 0, "bad": 0})
        d["n"] += 1
        d["finite"] += r["outcome"] == "finite"
        d["error"] += r["outcome"] == "clear_error"
        d["bad"] += r["outcome"] in ("nonfinite", "crash")
    lines += _table(["category", "cases", "finite", "clear errors", "NaN/Inf or crash"],
                    [[k, v["n"], v["finite"], v["error"], v["bad"]] for k, v in cats.items()])
    lines += ["", "## Cases", ""]
    body = []
    for r in result["cases"]:
        detail = r.get("message") or ""
        if r.get("psnr") is not None:
            detail = f"PSNR {r['psnr']:.2f} dB" + (f"; {detail}" if detail else "")
        if r.get("monotone_violations"):
            detail += f"; {r['monotone_violations']} objective rise(s)"
        body.append([r["category"], r["name"], r["outcome"], detail.replace("|", "/")[:160]])
    lines += _table(["category", "case", "outcome", "detail"], body)
    return "\n".join(lines) + "\n"


def write_stability(result: dict, out: Path, stem: str = "stress_report") -> dict:

    out.mkdir(parents=True, exist_ok=True)
    js = out / f"{stem}.json"
    md = out / f"{stem}.md"
    paths = {"json": str(js), "md": str(md)}
    result["paths"] = paths
    write_json(js, result, force=True)
    atomic_write_bytes(md, stability_markdown(result).encode("utf-8"), force=True)
    return paths


def write_result_files(stem: Path, result: dict, markdown: str, plot) -> list[Path]:
    """A benchmark's result files, overwriting earlier ones: ``stem.json`` (``result``),
    ``stem.md`` (``markdown``) and ``stem.png`` (drawn by ``plot(result, path)``); the folder
    is made if missing. Returns the three paths."""
    paths = [stem.with_suffix(s) for s in (".json", ".md", ".png")]
    write_json(paths[0], result, force=True)
    atomic_write_bytes(paths[1], markdown.encode("utf-8"), force=True)
    plot(result, paths[2])
    return paths
