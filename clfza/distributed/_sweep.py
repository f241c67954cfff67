"""Parameter sweeps: one raw frame reconstructed over a grid of ``tau`` and object distance.

:func:`sweep` runs one task per grid point -- in this process, or as Dask tasks on the
workers of :func:`clfza.distributed._cluster.open_client` (the frame travels as a path; each worker
reads it once) -- and returns the metrics and a thumbnail per point, in grid order. Metrics: with a
ground truth PSNR/SSIM after an affine fit (:func:`clfza.metrics.compare`); always the final
objective, the image's total variation and a focus score (Tamura coefficient of the gradient
on the central 70 %, :func:`clfza.focus.tamura`, scale invariant so comparable across tau).
:func:`contact_sheet` draws the thumbnails with their parameters; :func:`write_sweep` writes
the sheet, a JSON and a CSV.
"""

from __future__ import annotations

import csv
import io
import math
from pathlib import Path

import numpy as np

from ..backends import reuse_backends
from ..camera import Camera
from ..errors import ClfzaError, parse_int, parse_number, positive, positive_int
from ..focus import central_mask, tamura
from ..io import FrameInfo, FrameRef, atomic_write_many, encode_json, prepare_frame, read_ref
from ..metrics import compare
from ..reconstruction import reconstruct
from ..solvers import DEFAULT_BACKEND, SEARCH_METHOD
from ._batch import FramePrep, batch_backend_cache, worker_backend_cache
from ._cluster import open_client

THUMB = 160  # longest side of a thumbnail, pixels
_FRAMES: dict = {}  # per worker process: raw frames and truths by path


def parse_values(text: str, name: str, log: bool) -> list[float]:
    """``a:b:n`` (n values, log-spaced for ``log``, else linear) or ``v1,v2,...``."""
    t = str(text).strip()

    def value(v: str) -> float:
        return positive(name, parse_number(name, v))

    try:
        if ":" in t:
            a, b, n = t.split(":")
            lo, hi = value(a), value(b)
            k = positive_int(f"{name} count", parse_int(f"{name} count", n))
            if k == 1:
                return [lo]
            vals = (np.geomspace(lo, hi, k) if log else np.linspace(lo, hi, k)).tolist()
            return [float(f"{v:.6g}") for v in vals]
        return [value(v) for v in t.split(",") if v.strip()] or [value("")]
    except ValueError as exc:
        raise ClfzaError(f"{name} must be A:B:N or a list V1,V2,...; {exc}") from None


def _read(path: str) -> np.ndarray:

    if path not in _FRAMES:
        _FRAMES[path] = read_ref(FrameRef(path))[0]
    return _FRAMES[path]


def total_variation(x: np.ndarray) -> float:
    """Isotropic TV, the sum of ``|grad x|`` with forward differences (channels summed)."""
    a = np.asarray(x, np.float64)
    gx = np.diff(a, axis=1, append=a[:, -1:])
    gy = np.diff(a, axis=0, append=a[-1:, :])
    return float(np.sum(np.sqrt(gx * gx + gy * gy)))


def thumbnail(img: np.ndarray, side: int = THUMB) -> np.ndarray:
    """Block-mean downsampling to at most ``side`` pixels, scaled to [0, 1] (0.5-99.5 %)."""
    a = np.asarray(img, np.float64)
    b = max(1, math.ceil(max(a.shape[:2]) / side))
    h, w = a.shape[0] // b, a.shape[1] // b
    t = a[:h * b, :w * b].reshape(h, b, w, b, *a.shape[2:]).mean(axis=(1, 3))
    lo, hi = np.percentile(t, [0.5, 99.5])
    return np.clip((t - lo) / (hi - lo if hi > lo else 1.0), 0, 1).astype(np.float32)


def sweep_point(raw: str, camera: Camera, z1: float, tau: float | None, method: str,
                options: dict, prep, truth: str | None, backend: str = DEFAULT_BACKEND,
                device=None) -> dict:
    """Reconstruct ``raw`` at one (z1, tau) and measure it (a task; runs on a worker)."""

    frame = _read(raw)
    loaded = (frame, FrameInfo(raw, "file", "float64", frame.shape, None))
    p = prepare_frame(raw, camera.at_depth(z1), prep, {"dark": None, "flat": None},
                      loaded=loaded)
    opts = dict(options) if tau is None else {**options, "tau": tau}

    with reuse_backends(worker_backend_cache()):  # a tau sweep reuses the set-up of its depth
        rec = reconstruct(p.y, p.camera, method, backend=backend, device=device, **opts)
    img = rec.image
    grey = img if img.ndim == 2 else img.mean(axis=2)
    m = {"z1": z1, "tau": opts.get("tau"), "iterations": rec.info.iterations,
         "solve_s": rec.info.timings.get("solve", rec.info.timings.get("total", 0.0)),
         "tv": total_variation(grey),
         "focus": tamura(grey, central_mask(grey.shape)),
         "objective": _last(rec.info.objective)}
    if truth is not None:

        t = _read(truth)
        if t.shape != img.shape:
            raise ClfzaError(f"--truth has shape {t.shape} but the reconstruction {img.shape}")
        c = compare(img, t)
        m.update(psnr=c["psnr"], ssim=c["ssim"])
    return {"metrics": m, "thumb": thumbnail(img)}


def _last(obj) -> float | None:
    while isinstance(obj, list) and obj:
        obj = obj[-1]
    return float(obj) if isinstance(obj, (int, float, np.floating)) else None


def sweep(raw: str | Path, camera: Camera, taus: list[float | None], z1s: list[float],
          method: str = SEARCH_METHOD, *, prep=None, truth: str | Path | None = None,
          backend: str = DEFAULT_BACKEND, device=None, client=None, workers: int | None = None,
          scheduler: str | None = None, progress=None, **options) -> list[dict]:
    """Reconstruct ``raw`` for every (z1, tau) of the grid; results in row-major grid order
    (z1 outer, tau inner), each ``{"metrics": {...}, "thumb": array}``.

    ``method`` defaults to a search's (:data:`clfza.solvers.SEARCH_METHOD`,
    back-propagation) and ``backend`` to every entry point's
    (:data:`clfza.solvers.DEFAULT_BACKEND`): a sweep over ``tau`` names an iterative method
    (``method="admm"``). Runs in this process unless ``client``, ``workers`` or ``scheduler``
    is given (then one Dask task per point). ``prep`` is a
    :class:`clfza.distributed.FramePrep` (dark/flat are not applied here). ``progress`` is
    called once per finished point.

    Examples
    --------
    >>> pts = sweep("raw.tif", camera, [1e-3, 1e-2], [250.0, 300.0], "admm")  # doctest: +SKIP
    """

    if method == "bp" and any(t is not None for t in taus):
        raise ClfzaError("back-propagation (method 'bp', the default) has no tau; name an "
                         "iterative method to sweep tau (e.g. method='admm', --method admm)")
    prep = prep or FramePrep()
    args = [(str(raw), camera, z, t, method, options, prep,
             None if truth is None else str(truth), backend, device)
            for z in z1s for t in taus]
    if client is None and workers is None and scheduler is None:

        out = []
        with batch_backend_cache():
            for a in args:
                out.append(sweep_point(*a))
                if progress:
                    progress(out[-1])
        return out

    with open_client(client, workers, scheduler) as (c, _, _):
        futs = [c.submit(sweep_point, *a, pure=False, priority=-i) for i, a in enumerate(args)]
        if progress:
            from distributed import as_completed  # lazy: Dask is optional (clfza[dask])

            for _ in as_completed(futs, loop=c.loop):  # this client's loop, not the default's
                progress(None)
        return c.gather(futs)


def best(points: list[dict], taus: list | None = None, z1s: list | None = None) -> dict:
    """The suggested point: the highest PSNR with a truth, else the sharpest (focus score).

    ``at_edge`` lists the grid parameters (``"tau"``, ``"z1"``) whose suggested value is the
    first or last of a grid of three or more values: the optimum may lie beyond the grid.
    """
    key = "psnr" if "psnr" in points[0]["metrics"] else "focus"
    i = int(np.nanargmax([p["metrics"][key] for p in points]))
    m = points[i]["metrics"]
    edge = [name for name, grid in (("tau", taus), ("z1", z1s))
            if grid is not None and len(grid) >= 3 and m[name] in (grid[0], grid[-1])]
    return {"by": key, **m, "at_edge": edge}


def edge_warning(suggested: dict, taus: list, z1s: list) -> str | None:
    """One line when the suggested point sits at the edge of its grid, else None."""
    parts = []
    for name, grid, opt in (("tau", taus, "--tau"), ("z1", z1s, "--z1")):
        if name in suggested.get("at_edge", []):
            side = "smallest" if suggested[name] == grid[0] else "largest"
            parts.append(f"{name} = {suggested[name]:.4g} is the {side} of its grid "
                         f"({grid[0]:.4g}..{grid[-1]:.4g}; extend {opt})")
    if not parts:
        return None
    return (f"the best point (by {suggested['by']}) lies at the edge of the sweep: "
            f"{'; '.join(parts)}: the optimum may lie beyond it")


def contact_sheet(points: list[dict], taus: list, z1s: list[float], suggested: dict):
    """A matplotlib figure: rows z1, columns tau, each thumbnail titled with its metrics."""
    import matplotlib  # lazy: matplotlib takes ~0.5 s to import; only plots need it

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt  # lazy: matplotlib takes ~0.5 s to import; only plots need it

    rows, cols = len(z1s), len(taus)
    fig, axes = plt.subplots(rows, cols, figsize=(1.9 * cols + 0.4, 2.25 * rows + 0.5),
                             squeeze=False)
    for k, p in enumerate(points):
        ax = axes[k // cols][k % cols]
        m = p["metrics"]
        ax.imshow(p["thumb"], cmap="gray" if p["thumb"].ndim == 2 else None)
        tau = "default" if m["tau"] is None else f"{m['tau']:.3g}"
        score = (f"PSNR {m['psnr']:.2f} dB" if "psnr" in m else f"focus {m['focus']:.3f}")
        ax.set_title(f"z1 {m['z1']:.4g}, tau {tau}\n{score}", fontsize=7)
        ax.set_xticks([])
        ax.set_yticks([])
        if m["z1"] == suggested["z1"] and m["tau"] == suggested["tau"]:
            for s in ax.spines.values():
                s.set_edgecolor("red")
                s.set_linewidth(2.5)
    fig.suptitle(f"sweep: suggested z1 = {suggested['z1']:.4g} mm, tau = {suggested['tau']} "
                 f"(by {suggested['by']}; red)", fontsize=9)
    fig.tight_layout()
    return fig


def write_sweep(out_dir: str | Path, points: list[dict], taus: list, z1s: list[float],
                meta: dict) -> dict[str, Path]:
    """Write ``sweep.png`` (contact sheet), ``sweep.json`` and ``sweep.csv`` into ``out_dir``
    (atomic; the folder is new, see :func:`clfza.io._outputs.new_run_dir`)."""
    import matplotlib.pyplot as plt  # lazy: matplotlib takes ~0.5 s to import; only plots need it


    d = Path(out_dir)
    sug = best(points, taus, z1s)
    fig = contact_sheet(points, taus, z1s, sug)
    pbuf = io.BytesIO()
    try:
        fig.savefig(pbuf, format="png", dpi=110, bbox_inches="tight")
    finally:
        plt.close(fig)
    rows = [p["metrics"] for p in points]
    buf = io.StringIO()
    keys = list(rows[0])
    w = csv.DictWriter(buf, fieldnames=keys)
    w.writeheader()
    w.writerows(rows)
    png, cs, js = d / "sweep.png", d / "sweep.csv", d / "sweep.json"
    # the whole record or nothing (JSON last)
    atomic_write_many([(png, pbuf.getvalue()), (cs, buf.getvalue().encode()),
                       (js, encode_json({**meta, "suggested": sug, "points": rows}))])
    return {"png": png, "json": js, "csv": cs}
