"""``clfza sweep RAW --camera CAMERA --tau A:B:N --z1 A:B:N``: which tau and depth to choose.

One reconstruction per grid point (z1 outer, tau inner), as Dask tasks with ``--workers N``
or ``--scheduler ADDRESS``, else in this process. Writes ``OUT/sweep-NNN/sweep.png`` (a
contact sheet of the reconstructions with their parameters; the suggested point framed in
red), ``sweep.json`` and ``sweep.csv`` (per point: z1, tau, iterations, solve time, TV,
focus score, final objective; with ``--truth`` also PSNR and SSIM). ``--tau`` is log-spaced
(``1e-4:1e-1:9``), ``--z1`` linear (``250:350:11``); both also take lists ``V1,V2,...``.
``--method`` defaults to a search's (back-propagation, :data:`clfza.solvers.SEARCH_METHOD`)
and ``--backend`` to every command's (OpenCL, :data:`clfza.solvers.DEFAULT_BACKEND`): a
``--tau`` grid names an iterative method, e.g. ``--method admm``.
"""

from __future__ import annotations

import json
import logging
import sys
import time

from tqdm import tqdm

from ..backends import BACKENDS
from ..distributed import FramePrep, edge_warning, parse_values, sweep, write_sweep
from ..errors import ClfzaError
from ..io import new_run_dir
from ..solvers import DEFAULT_BACKEND, SEARCH_METHOD, check_options
from ._common import (
    add_camera_option,
    add_frame_options,
    load_camera,
    option_value,
    positive_int,
    progress_enabled,
    warm_first_run,
)

log = logging.getLogger("clfza")

NAME = "sweep"
HELP = "reconstruct one frame over a tau / depth grid"
DESCRIPTION = (
    "Reconstruct RAW for every tau and object distance z1 of a grid; write a "
    "contact sheet PNG and the metrics as JSON and CSV.")


def add_arguments(p) -> None:
    """The arguments of ``clfza sweep`` (its parser made by the command line from
    :data:`NAME`, :data:`HELP` and :data:`DESCRIPTION`)."""
    p.add_argument("raw", metavar="RAW", help="raw frame file")
    add_camera_option(p)
    add_frame_options(p, z1_grid=True)
    g = p.add_argument_group("grid")
    g.add_argument("--tau", metavar="A:B:N|LIST",
                   help="regularisation weights: N log-spaced from A to B, or a list")
    g.add_argument("--method", default=SEARCH_METHOD,
                   help=f"reconstruction method (default {SEARCH_METHOD}, one FFT pair a point; "
                   "a --tau grid needs an iterative one, e.g. admm)")
    g.add_argument("--iters", type=positive_int, help="iterations (method default)")
    g.add_argument("--opt", type=option_value, action="append", default=[],
                   metavar="KEY=VALUE", help="further method option, repeatable")
    g.add_argument("--truth", metavar="FILE", help="ground truth image: adds PSNR and SSIM")
    g.add_argument("--backend", choices=BACKENDS, default=DEFAULT_BACKEND)
    g.add_argument("--device", default=None, help="OpenCL device: gpu, cpu, P:D or a name")
    w = p.add_argument_group("Dask").add_mutually_exclusive_group()
    w.add_argument("--workers", type=positive_int, metavar="N",
                   help="run the grid on a local Dask cluster of N processes")
    w.add_argument("--scheduler", metavar="ADDRESS", help="run on an existing Dask cluster")
    p.add_argument("--out", default="clfza-out", metavar="DIR",
                   help="base output folder (default clfza-out); writes DIR/sweep-NNN/")
    p.set_defaults(func=run)
    return p


def _z1_values(text: str | None, camera) -> list[float]:
    """``--z1``: a grid ``A:B:N`` / list ``V1,V2``, one distance, or the camera's z1."""

    if text is None:
        return [camera.z1]
    return parse_values(text, "--z1", log=False)


def run(args) -> int:
    """Entry point of ``clfza sweep``."""

    camera = load_camera(args.camera)
    z1s = _z1_values(args.z1, camera)
    taus = parse_values(args.tau, "--tau", log=True) if args.tau else [None]
    if args.dark or args.flat:
        raise ClfzaError("clfza sweep does not apply --dark/--flat; calibrate the frame first")
    options = dict(args.opt)
    if args.iters is not None:
        options["iters"] = args.iters

    if args.method == "bp" and (options or args.tau):
        raise ClfzaError("back-propagation (--method bp, the default) takes no --tau, --iters "
                         "or --opt; name an iterative method, e.g. --method admm")
    check_options(args.method, options)  # one line before the grid starts
    warm_first_run(args)
    prep = FramePrep(None, None, args.bayer, args.crop and tuple(args.crop),
                     args.center and tuple(args.center), args.bin, args.object_mean)

    bar = None
    if progress_enabled(args):

        bar = tqdm(total=len(z1s) * len(taus), desc="sweep", unit="point", file=sys.stderr)
    t0 = time.perf_counter()
    try:
        points = sweep(args.raw, camera, taus, z1s, args.method, prep=prep, truth=args.truth,
                       backend=args.backend, device=args.device, workers=args.workers,
                       scheduler=args.scheduler,
                       progress=(lambda _: bar.update(1)) if bar else None, **options)
    finally:
        if bar is not None:
            bar.close()
    d = new_run_dir(args.out, "sweep")
    meta = {"raw": args.raw, "method": args.method, "options": options, "taus": taus,
            "z1s": z1s, "truth": args.truth, "wall_s": time.perf_counter() - t0,
            "camera": camera.summary(), "command": " ".join(["clfza", *sys.argv[1:]])}
    paths = write_sweep(d, points, taus, z1s, meta)
    s = json.loads(paths["json"].read_text())["suggested"]
    edge = edge_warning(s, taus, z1s)
    if edge is not None:
        log.warning("%s", edge)
    if not args.quiet:
        print(f"swept {len(points)} point(s) in {meta['wall_s']:.1f} s; suggested z1 = "
              f"{s['z1']:.4g} mm, tau = {s['tau']} (by {s['by']})")
        for k in ("png", "json", "csv"):
            print(f"wrote {paths[k]}")
    return 0
