"""``clfza reconstruct``'s options, checked before any frame is read and turned into solver
options (:mod:`clfza.cli._reconstruct`, which runs every input through
:func:`clfza.distributed.reconstruct_many`).
"""

from __future__ import annotations

import sys

from ..distributed import check_roi
from ..errors import ClfzaError
from ..io import (
    bin_crop_note,
    bin_factor,
    check_output_options,
    check_reconstruct,
    warn_ignored,
)
from ..solvers import AUTO_METHODS, METHOD_NAMES, check_options, resolve_method
from ._common import ignored_options

FORMATS = {"png": ".png", "tiff": ".tif", "tiff-float": ".tif"}


def command_line() -> str:
    """The command as typed, for the records (``clfza ARGS``)."""
    return " ".join(["clfza", *sys.argv[1:]])


def solver_options(args) -> dict:
    """Method options from --tau, --iters and --opt (only those given)."""
    opts: dict = dict(args.opt)
    if args.tau is not None:
        opts["tau"] = args.tau
    elif getattr(args, "plan", False) and args.method in AUTO_METHODS \
            and "weight" not in opts:
        opts["tau"] = "auto"  # --plan chooses tau from the frame unless one is given
    if args.iters is not None:
        opts["iters"] = args.iters
    return opts


def expected_frame(camera, args) -> tuple[tuple[int, int], float]:
    """The grid a frame is reconstructed on and its pitch (mm), from the options alone
    (before any frame is read): the crop (or the camera's shape), halved by --bayer, divided
    by --bin; the pitch grows to match.

    Examples
    --------
    >>> expected_frame(Camera.preset("experiment"), args)  # --bayer RGGB --bin 2
    ...                                                     # doctest: +SKIP
    ((600, 600), 0.0075)
    """

    crop, pitch, b = _before_bin(camera, args)
    return (crop[0] // b, crop[1] // b), pitch * b


def _before_bin(camera, args) -> tuple[tuple[int, int], float, int]:
    """The grid and pitch --bin applies to (the crop, halved by --bayer) and the factor."""
    crop = tuple(args.crop) if args.crop else tuple(camera.shape)
    pitch = camera.pitch
    if args.bayer:
        crop = ((crop[0] - crop[0] % 2) // 2, (crop[1] - crop[1] % 2) // 2)
        pitch *= 2
    return crop, pitch, bin_factor(args.bin, camera.with_shape(crop, pitch))


def warn_bin_crop(camera, args, prep) -> None:
    """Warn, before any frame is read, when --bin forces a crop (sides no multiple of the
    factor); ``prep`` remembers it, so that no frame says it again."""
    crop, _, b = _before_bin(camera, args)
    note = bin_crop_note(crop, b)
    if note is not None:
        warn_ignored(prep, note)


def validate_options(args, camera) -> None:
    """Every option and combination that can be checked without the frame, checked before
    any frame is read or any FFT runs: output format, scaling and percentiles, --roi against
    the grid, --plan against --psf/--margin, the memory of the solve; and a warning for each
    option that does nothing in this combination (:func:`ignored_options`)."""

    check_output_options(f"x{FORMATS[args.format]}", args.scaling, tuple(args.percentiles))
    if args.plan and (args.psf or args.margin):
        raise ClfzaError("--plan bins for the camera's own mask model; give --psf or "
                         "--margin without --plan")
    if args.psf and args.model == "tf":
        raise ClfzaError("--psf is used through the exact model; give --model exact or auto")
    if args.psf and getattr(args, "z1", None) is not None:
        raise ClfzaError("--z1 does nothing with --psf: a measured PSF is the operator at the "
                         "depth it was captured at (rescale it with --psf-pitch); drop --z1")
    if getattr(args, "bin", None) is not None:
        grid, _ = expected_frame(camera, args)
        check_roi(getattr(args, "roi", None), grid)
        check_reconstruct(grid, 1, args.method, model=args.model)
    args._ignored = ignored_options(args)


def check_method(method: str, options: dict) -> None:
    """Fail early on an unknown method or options given to back-propagation."""

    available = METHOD_NAMES
    if method not in available:
        raise ClfzaError(f"unknown method {method!r}; available in this build: "
                         f"{', '.join(available)}")
    method, options, _ = resolve_method(method, options)  # "auto": ADMM, tau="auto"
    if method == "bp" and options:
        raise ClfzaError(f"method 'bp' takes no options (got {', '.join(sorted(options))}); "
                         "choose an iterative --method for --tau/--iters")
    check_options(method, options)  # --opt nonneg=maybe: one line, before any frame is read
