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
    p.add_argument("--z-range", type=pair(False), required=True, metavar="ZMIN,ZMAX",
                   help="search interval of z1 in mm")
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
    p.add_argument("--out", default="clfza-out", metavar="DIR",
                   help="output folder (default clfza-out)")
    p.add_argument("--force", action="store_true", help="overwrite an existing record")
    p.set_defaults(func=run)
    return p


log = logging.getLogger("clfza")


def run(args) -> int:
    """Entry point of ``clfza focus``."""

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
