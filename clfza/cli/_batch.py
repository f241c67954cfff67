"""How ``clfza reconstruct`` runs its frames and reports them.

The stream and Dask options (``--workers``, ``--scheduler``, ``--resume``, ``--retries``,
``--stack-out``, ``--fps``, ``--pin-cpus``), and :func:`run_batch`: every invocation, one
frame or many, goes through :func:`clfza.distributed.reconstruct_many` with all of
``reconstruct``'s options; this module shows its progress (a bar for several frames, one
line per failed frame, ``--explain``'s text), then writes the stacks and the batch summary
and chooses the exit status.
"""

from __future__ import annotations

import logging
import sys
import time
from pathlib import Path

import numpy as np
from tqdm import tqdm

from .. import __version__
from ..distributed import reconstruct_many
from ..errors import ClfzaError
from ..io import write_json, write_stack
from ._common import positive_int, progress_enabled
from ._options import command_line

log = logging.getLogger("clfza")


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
    g.add_argument("--frames-per-solve", type=_frames_per_solve, default="auto", metavar="N",
                   help="consecutive frames solved together, one kernel launch per step for "
                   "all (ADMM, FISTA and TwIST with TV on the transfer-function model); auto "
                   "(default): "
                   "sized per device and frame size; 1: each frame alone")


def _frames_per_solve(text: str):
    return "auto" if text.strip().lower() == "auto" else positive_int(text)


def _reporter(args, total: int):
    """The progress callback of a batch (errors, ``--explain``, the verbose log line, the
    bar) and the bar (None off a terminal, with --quiet or for a single frame)."""
    bar = None
    if total > 1 and progress_enabled(args):
        bar = tqdm(total=total, desc="reconstruct", unit="frame", file=sys.stderr,
                   dynamic_ncols=True)

    def say(line: str, file=None) -> None:
        if bar is not None:
            bar.write(line, file=file)
        else:
            print(line, file=file, flush=True)

    def report(r) -> None:
        if not r.ok:
            say(f"clfza: error: {r.error}", file=sys.stderr)
        elif not r.skipped:
            rec = r.record
            log.info("%s -> %s (%s, %.2f s, %s)", r.input, rec.get("outputs", {}).get("image"),
                     rec.get("device"), rec.get("timings_s", {}).get("reconstruct", 0.0),
                     rec.get("stop_reason"))
        if r.explain is not None:
            say(f"plan for {r.input}:\n{r.explain}")
        if bar is not None:
            bar.update(1)

    return report, bar


def run_batch(args, refs: list, missing: list[tuple[str, str]], camera, prep, psf,
              options: dict) -> int:
    """Reconstruct ``refs`` (:class:`clfza.io.FrameRef`, from FRAMES) with every option of
    ``args``; write the stacks and the summary; returns the exit status."""
    local = not (args.workers or args.scheduler)
    single = len(refs) == 1 and not missing
    report, bar = _reporter(args, len(refs))
    try:
        res = reconstruct_many(
            refs, camera, args.method, workers=args.workers, scheduler=args.scheduler,
            out_dir=args.out, prep=prep, backend=args.backend, device=args.device,
            model=args.model, psf=psf, margin=args.margin, plan=args.plan,
            explain=args.explain, roi=args.roi, orient=args.orient, format=args.format,
            scaling=args.scaling, percentiles=tuple(args.percentiles), force=args.force,
            resume=args.resume, retries=args.retries, pin_cpus=args.pin_cpus,
            progress=report, command=command_line(),
            record={"camera_file": args.camera,
                    "ignored_options": list(getattr(args, "_ignored", []))},
            raise_errors=bool(getattr(args, "debug", False)),
            iteration_bar=single and local and progress_enabled(args),
            frames_per_solve=args.frames_per_solve, **options)
    except KeyboardInterrupt as exc:
        print("clfza: interrupted; finished frames are complete on disk (a frame is written "
              "whole or not at all): rerun with --resume", file=sys.stderr)
        exc.clfza_reported = True  # type: ignore[attr-defined]  # main() says it no more
        raise
    finally:
        if bar is not None:
            bar.close()
    return _finish(args, res, missing, options, single)


def _stacks(args, res) -> tuple[list[str], list[str]]:
    """``--stack-out``: the reconstructions in input order as TIFF/GIF/MP4 stacks."""
    stacks, errors = [], []
    for target in args.stack_out:
        try:
            imgs = [np.load(r.record["outputs"]["npy"]) for r in res.succeeded]
            stacks.append(str(write_stack(target, imgs, force=args.force, fps=args.fps)))
        except ClfzaError as exc:
            errors.append(f"{target!r}: {exc}")
    return stacks, errors


def _finish(args, res, missing, options: dict, single: bool) -> int:
    """Write stacks and (for several frames) the batch summary, print what was done; the
    exit status: 0 all done, 1 some failed, 2 none succeeded."""
    stacks, stack_errors = _stacks(args, res)
    nfail = len(res.failed) + len(missing) + len(stack_errors)
    if single and not stacks and not stack_errors:
        r = res.results[0]
        if r.ok and not args.quiet:
            o = r.record["outputs"]
            print(f"skipped {r.input}: its outputs are complete ({o['json']})" if r.skipped
                  else f"wrote {o['image']}, {o['npy']}, {o['json']}")
        return 0 if r.ok else 2
    summary = {"clfza_version": __version__, "date": time.strftime("%Y-%m-%d %H:%M:%S"),
               "command": command_line(), "method": args.method,
               "parameters": options, **res.summary(), "stacks": stacks,
               "missing_inputs": [{"input": p, "error": w} for p, w in missing],
               "stack_errors": stack_errors}
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    n = 1
    while (out / f"batch-{n:03d}.json").exists():
        n += 1
    js = write_json(out / f"batch-{n:03d}.json", summary)
    if not args.quiet:
        t = res.summary()
        print(f"reconstructed {t['succeeded'] - t['skipped_complete']} of {t['frames']} frame(s)"
              f" ({t['skipped_complete']} already complete) in {res.wall_s:.1f} s on "
              f"{res.where}; summary: {js}")
        for r in res.failed:
            print(f"  failed: {r.input}: {r.error}")
        for s in stacks:
            print(f"  stack: {s}")
    for e in stack_errors:  # errors show under --quiet too
        print(f"clfza: error: stack {e}", file=sys.stderr)
    if nfail == 0:
        return 0
    return 1 if res.succeeded else 2
