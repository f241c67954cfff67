"""``clfza reconstruct FRAMES... --workers N | --scheduler ADDRESS [--resume]``.

The streaming/distributed path of ``reconstruct`` (:func:`clfza.distributed.reconstruct_many`):
taken when one of ``--workers``, ``--scheduler``, ``--resume`` or ``--stack-out`` is given, or
when an input is a folder, a stack (multi-page TIFF, ``.npy``/``.npz``) or a video. Plain
frame files without those options keep the single-process loop of
:mod:`clfza.cli._reconstruct`.
"""

from __future__ import annotations

import sys
import time
from pathlib import Path

import numpy as np
from tqdm import tqdm

from .. import __version__
from ..cl import get_runtime
from ..distributed import FramePrep, Job, prepare_source, reconstruct_many, require_dask
from ..errors import ClfzaError
from ..io import (
    STACK_SUFFIXES,
    VIDEO_SUFFIXES,
    expand_frames,
    refs_of_file,
    write_json,
    write_stack,
)
from ._common import load_camera, positive_int, progress_enabled
from ._options import check_method, command_line, solver_options, validate_options

# reconstruct's options this path implements; any other one set away from its default is
# refused with one line (rather than silently ignored)
HANDLED = {"raw", "camera", "dark", "flat", "bayer", "crop", "center", "bin", "z1",
           "object_mean", "method", "tau", "iters", "opt", "backend", "device", "out", "format",
           "scaling", "percentiles", "force", "quiet", "verbose", "debug", "func", "help",
           "workers", "scheduler", "resume", "retries", "stack_out", "fps", "pin_cpus"}


def add_batch_options(p) -> None:
    """Add the stream/distributed options to the ``reconstruct`` parser."""
    g = p.add_argument_group(
        "streams and Dask", "FRAMES may be folders, globs, multi-page TIFFs, .npy/.npz stacks "
        "or videos (imageio; mp4 and friends need imageio-ffmpeg)")
    w = g.add_mutually_exclusive_group()
    w.add_argument("--workers", type=positive_int, metavar="N",
                   help="run on a local Dask cluster of N worker processes (needs the 'dask' "
                   "extra)")
    w.add_argument("--scheduler", metavar="ADDRESS",
                   help="run on an existing Dask cluster (e.g. tcp://host:8786); workers must "
                   "see the same files")
    g.add_argument("--resume", action="store_true",
                   help="skip frames whose complete outputs exist in --out, redo partial ones")
    g.add_argument("--retries", type=int, default=2, metavar="N",
                   help="further attempts for a frame after a device error or a dead worker "
                   "(default 2)")
    g.add_argument("--stack-out", action="append", default=[], metavar="FILE",
                   help="also write the reconstructions in order as a multi-page TIFF (.tif), "
                   "GIF (.gif) or MP4 (.mp4); repeatable")
    g.add_argument("--fps", type=float, default=10.0, help="frame rate of --stack-out GIF/MP4")
    g.add_argument("--pin-cpus", action="store_true",
                   help="--workers: give each worker its own share of the cores")
    p.set_defaults(_batch_parser=p)


def _is_stream_input(text: str) -> bool:

    p = Path(text)
    if p.is_dir() or p.suffix.lower() in STACK_SUFFIXES + VIDEO_SUFFIXES:
        return True
    if p.is_file() and p.suffix.lower() in (".tif", ".tiff", ".npy"):
        refs = refs_of_file(p)
        return len(refs) > 1 or refs[0].index is not None
    return False


def wants_batch(args) -> bool:
    """Whether ``reconstruct`` takes this streaming/distributed path."""
    if (getattr(args, "workers", None) or getattr(args, "scheduler", None)
            or getattr(args, "resume", False) or getattr(args, "stack_out", None)):
        return True
    return any(_is_stream_input(t) for t in getattr(args, "raw", []))


def _check_unsupported(args) -> None:
    parser = getattr(args, "_batch_parser", None)
    if parser is None:
        return
    for act in parser._actions:
        if act.dest in HANDLED or act.dest.startswith("_") or not act.option_strings:
            continue
        if getattr(args, act.dest, act.default) not in (act.default, None, False, []):
            raise ClfzaError(f"{act.option_strings[-1]} is not supported with --workers, "
                             "--scheduler, --resume, --stack-out or stack/video inputs")


def _bar(args, total: int):

    if not progress_enabled(args):
        return None

    return tqdm(total=total, desc="reconstruct", unit="frame", file=sys.stderr,
                dynamic_ncols=True)


def _preflight(refs, camera, prep) -> None:
    """Validate before any solve: when every frame comes from one file (a stack, a video),
    prepare its first frame here; a frame that cannot fit the camera fails the whole input
    with one line instead of one line per page."""

    if len({getattr(r, "path", None) for r in refs}) != 1:
        return
    prepare_source(refs[0], Job(camera, prep=prep), {})


def run_batch(args) -> int:
    """Entry point of the streaming/distributed ``clfza reconstruct``."""

    _check_unsupported(args)
    if args.retries < 0:
        raise ClfzaError(f"--retries must be >= 0, got {args.retries}")
    camera = load_camera(args.camera, args.z1)
    options = solver_options(args)
    check_method(args.method, options)
    validate_options(args, camera)
    if args.workers or args.scheduler:

        require_dask()
    elif args.backend == "opencl":

        get_runtime(args.device)
    refs, missing = expand_frames(args.raw)
    if not refs and missing:  # nothing to do: the last reason is the error
        for pat, why in missing[:-1]:
            print(f"clfza: error: {pat!r}: {why}", file=sys.stderr)
        raise ClfzaError(f"{missing[-1][0]!r}: {missing[-1][1]}")
    for pat, why in missing:
        print(f"clfza: error: {pat!r}: {why}", file=sys.stderr)
    if not refs:
        raise ClfzaError("no frames to reconstruct")
    prep = FramePrep(args.dark, args.flat, args.bayer, args.crop and tuple(args.crop),
                     args.center and tuple(args.center), args.bin, args.object_mean)
    _preflight(refs, camera, prep)
    bar = _bar(args, len(refs))

    def progress(r) -> None:
        if not r.ok:
            line = f"clfza: error: {r.error}"
            (bar.write(line, file=sys.stderr) if bar is not None
             else print(line, file=sys.stderr, flush=True))
        if bar is not None:
            bar.update(1)

    try:
        res = reconstruct_many(
            refs, camera, args.method, workers=args.workers, scheduler=args.scheduler,
            out_dir=args.out, prep=prep, backend=args.backend, device=args.device,
            format=args.format, scaling=args.scaling, percentiles=tuple(args.percentiles),
            force=args.force, resume=args.resume, retries=args.retries,
            pin_cpus=args.pin_cpus, progress=progress, command=command_line(), **options)
    except KeyboardInterrupt:
        print("clfza: interrupted; finished frames are complete on disk: rerun with --resume",
              file=sys.stderr)
        raise
    finally:
        if bar is not None:
            bar.close()
    return _finish(args, res, missing, options)


def _finish(args, res, missing, options: dict) -> int:
    """Write stacks and the batch summary, print it; the exit status."""



    stacks, stack_errors = [], []
    for target in args.stack_out:
        try:
            imgs = [np.load(r.record["outputs"]["npy"]) for r in res.succeeded]
            stacks.append(str(write_stack(target, imgs, force=args.force, fps=args.fps)))
        except ClfzaError as exc:
            stack_errors.append(f"{target!r}: {exc}")
    summary = {"clfza_version": __version__, "date": time.strftime("%Y-%m-%d %H:%M:%S"),
               "command": " ".join(["clfza", *sys.argv[1:]]), "method": args.method,
               "parameters": options, **res.summary(), "stacks": stacks,
               "missing_inputs": [{"input": p, "error": w} for p, w in missing],
               "stack_errors": stack_errors}
    out = Path(args.out)
    n = 1
    while (out / f"batch-{n:03d}.json").exists():
        n += 1
    js = write_json(out / f"batch-{n:03d}.json", summary)
    nfail = len(res.failed) + len(missing) + len(stack_errors)
    if not args.quiet:
        t = res.summary()
        print(f"reconstructed {t['succeeded'] - t['skipped_complete']} of {t['frames']} frame(s)"
              f" ({t['skipped_complete']} already complete) in {res.wall_s:.1f} s on "
              f"{res.where}; summary: {js}")
        for r in res.failed:
            print(f"  failed: {r.input}: {r.error}")
        for s in stacks:
            print(f"  stack: {s}")
        for e in stack_errors:
            print(f"  stack failed: {e}")
    if nfail == 0:
        return 0
    return 1 if res.succeeded else 2
