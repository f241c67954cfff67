"""``clfza focus RAW --camera CAMERA --z-range ZMIN,ZMAX``: find the object distance.

Searches ``z1`` for the sharpest fast back-propagation (:func:`clfza.focus.autofocus`), prints
the best distance and writes ``OUT/NAME-focus.json`` (the focus curve, every depth tried, the
depth of focus and timings). Reconstruct at that depth with ``clfza reconstruct --z1 Z``.
"""

from __future__ import annotations

import logging
import shlex
import time
import warnings
from pathlib import Path

from .. import __version__
from ..backends import BACKENDS
from ..errors import ClfzaError
from ..focus import SEARCHES, FocusWarning, autofocus
from ..io import prepare_frame, write_json
from ..solvers import DEFAULT_BACKEND
from ._common import (
    add_camera_option,
    add_frame_options,
    load_camera,
    pair,
    positive_float,
    positive_int,
    warm_first_run,
)

NAME = "focus"
HELP = "find the object distance z1 (autofocus)"
DESCRIPTION = (
    "Autofocus: search the object distance z1 for the sharpest "
    "back-propagation of a raw frame.")


def add_arguments(p) -> None:
    """The arguments of ``clfza focus`` (its parser made by the command line from
    :data:`NAME`, :data:`HELP` and :data:`DESCRIPTION`)."""
    p.add_argument("raw", metavar="RAW", help="frame file (PNG/TIFF/NPY)")
    add_camera_option(p)
    p.add_argument("--z-range", type=pair(False), metavar="ZMIN,ZMAX",
                   help="search interval of z1 in mm (required without --psf)")
    p.add_argument("--metric", default="mix",
                   help="sharpness metric: gradient, tamura, laplacian or mix (default)")
    p.add_argument("--search", choices=SEARCHES, default="golden",
                   help="search strategy refining the coarse grid's best depth (default "
                   "golden)")
    p.add_argument("--coarse", type=positive_int, default=41, metavar="N",
                   help="coarse grid points, uniform in 1/z1 (default 41)")
    p.add_argument("--backend", choices=BACKENDS, default=DEFAULT_BACKEND,
                   help=f"back-propagation engine for the search (default {DEFAULT_BACKEND}, "
                   "as every command's)")
    p.add_argument("--device", default=None, help="OpenCL device for --backend opencl")
    add_frame_options(p)
    g = p.add_argument_group("measured PSF")
    g.add_argument("--psf", metavar="FILE",
                   help="measured PSF (PNG/TIFF/NPY point-source capture): search its "
                        "magnification for this frame instead of z1 (the scene's depth too "
                        "when the camera file gives psf_z1 and z2)")
    g.add_argument("--psf-pitch", type=positive_float, metavar="MM",
                   help="pixel pitch of the PSF capture (default: the camera file's pitch)")
    g.add_argument("--scale-range", type=pair(False), metavar="LO,HI",
                   help="magnifications searched with --psf (default 0.5,2; from just below "
                        "a scene at infinity's scale up to 2 when the camera knows its "
                        "depths)")
    p.add_argument("--out", default="clfza-out", metavar="DIR",
                   help="output folder (default clfza-out)")
    p.add_argument("--force", action="store_true", help="overwrite an existing record")
    p.set_defaults(func=run)
    return p


log = logging.getLogger("clfza")


def run(args) -> int:
    """Entry point of ``clfza focus``."""

    if args.psf:
        return run_psf(args)
    if args.psf_pitch or args.scale_range:
        raise ClfzaError("--psf-pitch and --scale-range go with --psf")
    if args.z_range is None:
        raise ClfzaError("give --z-range ZMIN,ZMAX (or --psf FILE to search a measured PSF's "
                         "scale)")
    zmin, zmax = args.z_range
    if not (0 < zmin < zmax):
        raise ClfzaError(f"--z-range must satisfy 0 < ZMIN < ZMAX, got {zmin:g},{zmax:g}")
    camera = load_camera(args.camera, args.z1)
    out = Path(args.out)
    target = out / f"{Path(args.raw).stem or 'frame'}-focus.json"
    if target.exists() and not args.force:
        raise ClfzaError(f"{str(target)!r} exists; pass --force to overwrite it")
    prep = prepare_frame(args.raw, camera, args)
    warm_first_run(args)
    t0 = time.perf_counter()
    with warnings.catch_warnings():  # the evidence is reported below, once
        warnings.simplefilter("ignore", FocusWarning)
        res = autofocus(prep.y, prep.camera, z_range=(zmin, zmax), metric=args.metric,
                        search=args.search, coarse=args.coarse, backend=args.backend,
                        device=args.device)
    wall = time.perf_counter() - t0
    d = res.to_dict() if hasattr(res, "to_dict") else dict(res)
    record = {"clfza_version": __version__, "date": time.strftime("%Y-%m-%d %H:%M:%S"),
              "input": str(args.raw), **prep.record, "camera": prep.camera.summary(),
              "camera_file": args.camera, "z_range": [zmin, zmax], "search": args.search,
              "backend": args.backend, "focus": d, "wall_s": wall}
    write_json(target, record, force=args.force)
    z = d.get("z1_best")
    ev = d.get("evidence") or {}
    if not d.get("confident", True):
        # no answer without evidence: the record says why, the exit status says it failed
        # (an error, so that -q shows it too)
        log.error("no reliable focus in %g..%g mm: %s; the record %s has the curve",
                    zmin, zmax, ev.get("reason", "the focus curve has no clear peak"), target)
        return 1
    if not args.quiet:
        dz = d.get("depth_resolution")
        extra = f" (depth of focus +/- {dz:.3g} mm)" if isinstance(dz, float) else ""
        print(f"best z1 = {z:.6g} mm{extra}; {ev.get('reason', '')}; wrote {target}")
        print(f"next: {next_command(args, z)}")
    return 0


def next_command(args, z: float) -> str:
    """``clfza reconstruct`` at the depth found, with every frame option of this run (the
    same crop, centre, calibration frames, Bayer pattern, binning and object mean)."""

    parts = ["clfza", "reconstruct", args.raw, "--camera", args.camera, "--z1", f"{z:.6g}"]
    for opt, val in (("--dark", args.dark), ("--flat", args.flat), ("--bayer", args.bayer)):
        if val:
            parts += [opt, str(val)]
    if args.crop:
        parts += ["--crop", ",".join(str(v) for v in args.crop)]
    if args.center:
        parts += ["--center", ",".join(f"{v:g}" for v in args.center)]
    if str(args.bin) != "1":
        parts += ["--bin", str(args.bin)]
    if args.object_mean != 0.5:
        parts += ["--object-mean", f"{args.object_mean:g}"]
    return " ".join(shlex.quote(p) for p in parts)


def run_psf(args) -> int:
    """``clfza focus RAW --camera CAMERA --psf PSF``: the measured PSF's magnification that
    fits the frame (:func:`clfza.focus.find_psf_scale`); the record ``OUT/NAME-focus.json``
    (``psf_scale``: the scale, its confidence and evidence, the depth, every scale tried) and
    the curve ``OUT/NAME-focus.png``."""
    from ..focus import PSFScaleWarning, find_psf_scale  # lazy: the --psf path only
    from ..models import load_psf  # lazy: the --psf path only

    if args.z_range is not None or getattr(args, "z1", None) is not None:
        raise ClfzaError("--z-range and --z1 do not go with --psf: the search is over the "
                         "PSF's magnification (--scale-range)")
    camera = load_camera(args.camera, None)
    out = Path(args.out)
    stem = Path(args.raw).stem or "frame"
    target, figure = out / f"{stem}-focus.json", out / f"{stem}-focus.png"
    for path in (target, figure):
        if path.exists() and not args.force:
            raise ClfzaError(f"{str(path)!r} exists; pass --force to overwrite it")
    prep = prepare_frame(args.raw, camera, args)
    psf = load_psf(args.psf, psf_pitch=args.psf_pitch or camera.pitch,
                   frame_pitch=prep.camera.pitch, center="centroid")
    t0 = time.perf_counter()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", PSFScaleWarning)
        res = find_psf_scale(prep.y, psf, args.scale_range, camera=prep.camera, warn=False)
    wall = time.perf_counter() - t0
    d = res.to_dict()
    record = {"clfza_version": __version__, "date": time.strftime("%Y-%m-%d %H:%M:%S"),
              "input": str(args.raw), **prep.record, "camera": prep.camera.summary(),
              "camera_file": args.camera,
              "psf": {"file": str(args.psf), **{k: v for k, v in psf.info.items()
                                                if k != "source"}},
              "psf_scale": d, "wall_s": wall}
    write_json(target, record, force=args.force)
    _plot_scale_curve(res, figure, args.force)
    ev = d["evidence"]
    if not res.confident:
        log.error("no reliable PSF scale: best %.4g, %s; the record %s has the curve",
                  res.scale, ev["reason"], target)
        return 1
    if not args.quiet:
        depth = (f"; scene depth {res.depth:.4g} mm" if res.depth is not None else "")
        print(f"PSF scale = {res.scale:.4g} (+/- {100 * res.scale_uncertainty:.2g} %){depth}; "
              f"{ev['reason']}; wrote {target}")
        print("next: " + " ".join(shlex.quote(p) for p in [
            "clfza", "reconstruct", args.raw, "--camera", args.camera, "--psf", args.psf,
            *(["--psf-pitch", f"{args.psf_pitch:g}"] if args.psf_pitch else []),
            "--psf-scale", f"{res.scale:.5g}"]))
    return 0


def _plot_scale_curve(res, path: Path, force: bool) -> None:
    """The scale search's curves (each level's scores against the scale) as a PNG."""
    import matplotlib  # lazy: the figure only

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt  # lazy: the figure only

    from ..io import write_figure  # lazy: with matplotlib, for the figure only

    fig, ax = plt.subplots(figsize=(6.4, 3.6))
    for lv in res.levels:
        label = f"bin {lv['bin']}" + (" (range)" if lv.get("background") else "")
        ax.plot(lv["scales"], lv["scores"], "." if lv.get("background") else "-",
                label=label, lw=1)
    ax.axvline(res.scale, color="k", ls="--", lw=0.8)
    ax.set_xscale("log")
    ax.set_xlabel("PSF magnification")
    ax.set_ylabel("score (sharpness over null frames)")
    ax.set_title(f"scale {res.scale:.4g}, {'confident' if res.confident else 'not confident'}")
    handles, labels = ax.get_legend_handles_labels()
    uniq = dict(zip(labels, handles, strict=True))
    ax.legend(uniq.values(), uniq.keys(), fontsize=7)
    write_figure(path, fig, force=force)
    plt.close(fig)
