"""``clfza reconstruct FRAMES... --camera CAMERA``: raw frames in, images and JSON records out.

FRAMES are frame files, folders, glob patterns, multi-page TIFFs, ``.npy``/``.npz`` stacks or
videos; a single frame is a batch of one. Every input goes the same way, through
:func:`clfza.distributed.reconstruct_many` (in this process, or on Dask with ``--workers`` /
``--scheduler``), so every option works on every kind of input: a measured ``--psf`` (loaded
once, used for every frame), the planner (``--plan``, ``--explain``), ``--model``,
``--margin``, ``--opt``, the calibration and output options, ``--force``.

For every frame ``NAME`` it writes ``OUT/NAME.png`` (or ``.tif``) scaled to 16 bits,
``OUT/NAME.npy`` (the float64 reconstruction) and ``OUT/NAME.json`` (parameters, camera,
version, device, timings, stop reason, output paths and the 16-bit scaling), all three or
none. Existing files are never overwritten without ``--force``. Several frames make a batch:
one progress bar, and one bad frame does not stop the others; the summary names every
failure and is also written to ``OUT/batch-NNN.json``.

Exit status: 0 when every frame was reconstructed, 1 when some failed, 2 when none succeeded
(or the camera, calibration frames or options are bad).
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from ..backends import BACKENDS
from ..cl import get_runtime
from ..distributed import FramePrep, Job, prepare_source, require_dask
from ..errors import ClfzaError
from ..io import expand_frames
from ..models import PSF, load_psf
from ..reconstruction import DEFAULT_WHITE_BALANCE, WHITE_BALANCES
from ..solvers import AUTO_METHODS, DEFAULT_BACKEND, DEFAULT_METHOD
from ._batch import add_batch_options, run_batch
from ._common import (
    add_camera_option,
    add_frame_options,
    load_camera,
    nonneg_float,
    nonneg_int,
    option_value,
    pair,
    positive_float,
    positive_int,
    warm_first_run,
)
from ._options import (
    FORMATS,
    check_method,
    expected_frame,
    solver_options,
    validate_options,
    warn_bin_crop,
)
from ._preflight import check_outputs

NAME = "reconstruct"
HELP = "reconstruct raw sensor frames"
DESCRIPTION = (
    "Reconstruct raw FZA frames (PNG/TIFF/NPY, mono, RGB or Bayer; folders, "
    "globs, stacks and videos) into images. Outputs: NAME.png|.tif (16-bit), NAME.npy "
    "(float) and NAME.json per frame.")


def add_arguments(p) -> None:
    """The arguments of ``clfza reconstruct`` (its parser made by the command line from
    :data:`NAME`, :data:`HELP` and :data:`DESCRIPTION`)."""
    p.add_argument("raw", nargs="+", metavar="FRAMES",
                   help="frame files, folders, glob patterns, stacks or videos")
    add_camera_option(p)
    add_frame_options(p)
    s = p.add_argument_group("solver")
    s.add_argument("--method", default=DEFAULT_METHOD,
                   help="auto (the default: ADMM with tau chosen from the frame, on the "
                   "forward model the camera and the frame's noise call for), bp "
                   "(back-propagation) or an iterative method from clfza.solvers (twist, "
                   "fista, admm, wiener)")
    s.add_argument("--tau", type=tau_value, help="regularisation weight, or 'auto' (chosen "
                   "from the frame's noise, clfza.solvers._tau; admm's default, and with "
                   f"--plan {', '.join(AUTO_METHODS)}'s); default: the method's")
    s.add_argument("--iters", type=positive_int, help="iterations (method default)")
    s.add_argument("--opt", type=option_value, action="append", default=[],
                   metavar="KEY=VALUE", help="further method option, repeatable "
                   "(e.g. --opt mode=paper)")
    s.add_argument("--backend", choices=BACKENDS, default=DEFAULT_BACKEND)
    s.add_argument("--device", default=None, help="OpenCL device: gpu, cpu, P:D or a name")
    s.add_argument("--model", choices=("auto", "tf", "exact"), default="auto",
                   help="forward model: exact finite-aperture convolution, the paper's transfer "
                        "function (Eq. 17), or auto (exact where Eq. 17 is not the camera's "
                        "map, unless the frame's noise swamps Eq. 17's error; the JSON notes "
                        "say which ran and why)")
    s.add_argument("--psf", metavar="FILE",
                   help="measured PSF (PNG/TIFF/NPY point-source capture; the documentation's "
                        "'Measured PSFs' page) as the operator instead of the camera's mask; "
                        "read once for all frames")
    s.add_argument("--psf-pitch", type=positive_float, metavar="MM",
                   help="pixel pitch of the PSF capture (default: the camera file's pitch)")
    s.add_argument("--psf-scale", type=psf_scale_value, metavar="auto|S",
                   help="magnify the --psf by S (a scene at another depth than the point "
                        "source's), or 'auto': search it on the first frame (clfza focus "
                        "--psf); recorded as psf.scale")
    s.add_argument("--white-balance", choices=WHITE_BALANCES, default=DEFAULT_WHITE_BALANCE,
                   help="colour frames: psf (the default: divide out the sensor's channel "
                        "gains that a colour --psf's channel sums give; grey-world without "
                        "one), grey (grey-world) or none (the sensor's colours); recorded "
                        "as white_balance")
    s.add_argument("--margin", type=nonneg_int, default=0, metavar="PX",
                   help="exact model: object pixels modelled around the sensor (scenes larger "
                        "than the sensor's footprint)")
    s.add_argument("--explain", action="store_true",
                   help="print the scene plan (binning, skips, noise, dtype, FOV) and why")
    s.add_argument("--plan", action="store_true",
                   help="apply the plan: bin, skip flat frames, solve grey RGB once, stop "
                        "early by the discrepancy principle")
    o = p.add_argument_group("output")
    o.add_argument("--out", default="clfza-out", metavar="DIR",
                   help="output folder (default clfza-out)")
    o.add_argument("--format", choices=tuple(FORMATS), default="png",
                   help="image format: 16-bit PNG (default), 16-bit TIFF or float32 TIFF")
    o.add_argument("--scaling", choices=("percentile", "minmax", "unit"), default="percentile",
                   help="16-bit mapping: percentile range (default), min..max, or [0, 1]")
    o.add_argument("--percentiles", type=pair(False), default=(0.1, 99.9), metavar="LO,HI",
                   help="percentiles for --scaling percentile (default 0.1,99.9)")
    o.add_argument("--force", action="store_true", help="overwrite existing outputs")
    o.add_argument("--orient", choices=("sensor", "upright"), default="sensor",
                   help="the pinhole geometry inverts the scene (Eq. 2): 'upright' rotates the "
                        "saved image by 180 degrees (recorded in the JSON)")
    o.add_argument("--roi", type=roi_arg, metavar="Y,X,H,W",
                   help="save only this region of the reconstruction (rows Y..Y+H, cols "
                        "X..X+W of the sensor grid, before --orient)")

    add_batch_options(p)
    p.set_defaults(func=run)
    return p


def roi_arg(text: str) -> tuple[int, int, int, int]:
    """``Y,X,H,W`` (non-negative integers, H and W > 0)."""
    try:
        vals = tuple(int(v) for v in text.split(","))
    except ValueError:
        vals = ()
    if len(vals) != 4 or min(vals) < 0 or vals[2] == 0 or vals[3] == 0:
        raise argparse.ArgumentTypeError(f"--roi must be Y,X,H,W integers (H, W > 0), got "
                                         f"{text!r}")
    return vals


def tau_value(text: str):
    """``--tau``: a number >= 0 or ``auto``."""
    if text.strip().lower() == "auto":
        return "auto"
    return nonneg_float(text)


def psf_scale_value(text: str):
    """``--psf-scale``: a number > 0 or ``auto``."""
    if text.strip().lower() == "auto":
        return "auto"
    return positive_float(text)


def load_psf_for(args, camera, refs=None, prep=None) -> PSF | None:
    """The measured PSF of ``--psf``, read once and resampled to the pitch every prepared
    frame will have (the crop, ``--bayer`` and ``--bin`` decide it; see
    :func:`clfza.cli._options.expected_frame`), magnified by ``--psf-scale`` (``auto``: the
    scale :func:`clfza.focus.find_psf_scale` finds on the first frame, its search in the
    PSF's record); None without ``--psf``."""
    scale = getattr(args, "psf_scale", None)
    if not args.psf:
        if scale is not None:
            raise ClfzaError("--psf-scale needs --psf")
        return None
    grid, frame_pitch = expected_frame(camera, args)
    psf = load_psf(args.psf, psf_pitch=args.psf_pitch or camera.pitch,
                   frame_pitch=frame_pitch, center="centroid")
    if scale is None:
        return psf
    from ..models import scale_psf  # lazy: only --psf-scale rescales

    search = None
    if scale == "auto":
        import warnings  # lazy: the auto search only

        from ..focus import PSFScaleWarning, find_psf_scale  # lazy: clfza.focus is heavy

        y, cam, _ = prepare_source(refs[0], Job(camera, prep=prep), {})
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", PSFScaleWarning)
            res = find_psf_scale(y, psf, camera=cam, warn=False)
        scale = res.scale
        ev = res.evidence
        search = {"frame": str(getattr(refs[0], "path", refs[0])), "scale": res.scale,
                  "confident": res.confident, "reason": ev["reason"],
                  "scale_uncertainty": res.scale_uncertainty, "depth_mm": res.depth,
                  "seconds": res.timings["total"]}
        if not res.confident:
            print(f"clfza: warning: the PSF scale {res.scale:.4g} found on "
                  f"{search['frame']} is not reliable: {ev['reason']}", file=sys.stderr)
        elif not args.quiet:
            print(f"PSF scale {res.scale:.4g} (found on {search['frame']}; {ev['reason']})")
    out = scale_psf(psf, scale, max_shape=(2 * grid[0] - 1, 2 * grid[1] - 1))
    if search is not None:
        out.info["scale_search"] = search
    return out


def _inputs(patterns: list[str]) -> tuple[list, list[tuple[str, str]]]:
    """The frames of FRAMES and the inputs that gave none (named on stderr); an error when
    there is nothing to do."""
    refs, missing = expand_frames(patterns)
    if not refs and missing:  # nothing to do: the last reason is the error
        for pat, why in missing[:-1]:
            print(f"clfza: error: {pat!r}: {why}", file=sys.stderr)
        raise ClfzaError(f"{missing[-1][0]!r}: {missing[-1][1]}")
    for pat, why in missing:
        print(f"clfza: error: {pat!r}: {why}", file=sys.stderr)
    if not refs:
        raise ClfzaError("no frames to reconstruct")
    return refs, missing


def _preflight(refs, camera, prep: FramePrep) -> None:
    """When several frames all come from one file (a stack, a video), prepare its first
    frame before any solve: a stack that cannot fit the camera fails with one line instead
    of one line per page."""

    if len(refs) < 2 or len({r.path for r in refs}) != 1:
        return
    prepare_source(refs[0], Job(camera, prep=prep), {})


def run(args) -> int:
    """Entry point of ``clfza reconstruct``: check everything that can be checked before a
    frame is read, then reconstruct every frame through
    :func:`clfza.distributed.reconstruct_many`."""

    camera = load_camera(args.camera, args.z1)
    options = solver_options(args)
    check_method(args.method, options)
    options["white_balance"] = args.white_balance  # reconstruct's, not the method's option
    validate_options(args, camera)
    if args.retries < 0:
        raise ClfzaError(f"--retries must be >= 0, got {args.retries}")
    if args.workers or args.scheduler:
        require_dask()
    out = Path(args.out)
    if out.exists() and not out.is_dir():
        raise ClfzaError(f"--out {str(out)!r} is a file, not a folder")
    refs, missing = _inputs(args.raw)
    prep = FramePrep(args.dark, args.flat, args.bayer, args.crop and tuple(args.crop),
                     args.center and tuple(args.center), args.bin, args.object_mean)
    warn_bin_crop(camera, args, prep)
    psf = load_psf_for(args, camera, refs, prep)
    grid, _ = expected_frame(camera, args)
    check_outputs(args, refs, grid if args.roi is None else tuple(args.roi[2:]))
    _preflight(refs, camera, prep)
    if not (args.workers or args.scheduler) and args.backend == "opencl":
        get_runtime(args.device)  # no usable device: one error, before any frame is solved
    warm_first_run(args)
    return run_batch(args, refs, missing, camera, prep, psf, options)
