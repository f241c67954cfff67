"""``clfza reconstruct RAW... --camera CAMERA``: raw frames in, images and JSON records out.

For every input ``NAME.ext`` it writes ``OUT/NAME.png`` (or ``.tif``) scaled to 16 bits,
``OUT/NAME.npy`` (the float64 reconstruction) and ``OUT/NAME.json`` (parameters, camera,
version, device, timings, stop reason, output paths and the 16-bit scaling). Existing files are
never overwritten without ``--force``. Several files or glob patterns make a batch: one
progress bar, and one bad file does not stop the others; the summary names every failure and
is also written to ``OUT/batch-NNN.json``.

Exit status: 0 when every file was reconstructed, 1 when some failed, 2 when none succeeded
(or the camera, calibration frames or options are bad).
"""

from __future__ import annotations

import argparse
import logging
import platform
import sys
import time
from contextlib import contextmanager
from pathlib import Path

from tqdm import tqdm

from .. import __version__
from ..cl import get_runtime
from ..errors import ClfzaError, report_exception
from ..io import (
    atomic_write_many,
    encode_image,
    encode_json,
    load_calibration_frame,
    prepare_frame,
    write_json,
)
from ..models import choose_model, load_psf
from ..reconstruction import make_plan, reconstruct, reconstruct_planned
from ..solvers import AUTO_METHODS, default_iters
from ._batch import add_batch_options, run_batch, wants_batch
from ._common import (
    add_camera_option,
    add_frame_options,
    expand_inputs,
    load_camera,
    nonneg_float,
    nonneg_int,
    option_value,
    pair,
    positive_float,
    positive_int,
    progress,
    progress_enabled,
)
from ._options import (
    FORMATS,
    check_method,
    check_roi,
    command_line,
    solver_options,
    validate_options,
)

log = logging.getLogger("clfza")




def add_parser(subparsers, common=None):
    """Register ``reconstruct`` on an argparse subparsers object."""
    parents = [common] if common is not None else []
    p = subparsers.add_parser(
        "reconstruct", parents=parents, help="reconstruct raw sensor frames",
        description="Reconstruct raw FZA frames (PNG/TIFF/NPY, mono, RGB or Bayer) into "
        "images. Outputs: NAME.png|.tif (16-bit), NAME.npy (float) and NAME.json per input.")
    p.add_argument("raw", nargs="+", metavar="RAW", help="frame files or glob patterns")
    add_camera_option(p)
    add_frame_options(p)
    s = p.add_argument_group("solver")
    s.add_argument("--method", default="bp",
                   help="bp (back-propagation) or an iterative method from clfza.solvers "
                   "(twist, fista, admm when available); default bp")
    s.add_argument("--tau", type=tau_value, help="regularisation weight, or 'auto' (chosen "
                   "from the frame's noise, clfza.solvers._tau; the default with --plan for "
                   f"{', '.join(AUTO_METHODS)}); default: the method's")
    s.add_argument("--iters", type=positive_int, help="iterations (method default)")
    s.add_argument("--opt", type=option_value, action="append", default=[],
                   metavar="KEY=VALUE", help="further method option, repeatable "
                   "(e.g. --opt mode=paper)")
    s.add_argument("--backend", choices=("opencl", "numpy"), default="opencl")
    s.add_argument("--device", default=None, help="OpenCL device: gpu, cpu, P:D or a name")
    s.add_argument("--model", choices=("auto", "tf", "exact"), default="auto",
                   help="forward model: exact finite-aperture convolution, the paper's transfer "
                        "function (Eq. 17), or auto (exact where Eq. 17 is not the camera's "
                        "map; the JSON notes say which ran and why)")
    s.add_argument("--psf", metavar="FILE",
                   help="measured PSF (PNG/TIFF/NPY point-source capture, see the README) as "
                        "the operator instead of the camera's mask")
    s.add_argument("--psf-pitch", type=positive_float, metavar="MM",
                   help="pixel pitch of the PSF capture (default: the camera file's pitch)")
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


def finish_image(img, args) -> tuple:
    """Apply --roi and --orient to a reconstruction; returns it and what was done."""
    done: dict = {"orient": args.orient}
    if args.roi is not None:
        check_roi(args.roi, img.shape[:2])
        y, x, h, w = args.roi
        img = img[y:y + h, x:x + w]
        done["roi"] = list(args.roi)
    if args.orient == "upright":
        img = img[::-1, ::-1]
    return img, done


def load_psf_for(args, camera, frame_camera):
    """The measured PSF of ``--psf`` on the frame's pitch (loaded once per run)."""
    if not args.psf:
        return None
    cached = getattr(args, "_psf", None)
    if cached is not None and cached[0] == frame_camera.pitch:
        return cached[1]

    psf = load_psf(args.psf, psf_pitch=args.psf_pitch or camera.pitch,
                   frame_pitch=frame_camera.pitch, center="centroid")
    args._psf = (frame_camera.pitch, psf)
    return psf


def tau_value(text: str):
    """``--tau``: a number >= 0 or ``auto``."""
    if text.strip().lower() == "auto":
        return "auto"
    return nonneg_float(text)


def _stems(files: list[Path]) -> list[str]:
    seen: dict[str, int] = {}
    out = []
    for f in files:
        s = f.stem or "frame"
        n = seen.get(s, 0) + 1
        seen[s] = n
        out.append(s if n == 1 else f"{s}-{n}")
    return out


def _message(exc: BaseException, path: Path) -> str:

    msg = report_exception(exc)[0].removeprefix("clfza: error: ")
    return msg if str(path) in msg else f"{str(path)!r}: {msg}"


def _model_kind(args, camera, options: dict, psf) -> str | None:
    """The model kind ``reconstruct`` will choose (its default iteration count differs)."""
    if args.method == "bp":
        return None

    return choose_model(camera, args.model, method=args.method,
                        mode=options.get("mode", "paper"), psf=psf is not None)[0]


@contextmanager
def _iteration_bar(args, options: dict, y, model: str | None = None):
    """Options with a progress callback for an iterative method on a terminal.

    The bar appears only for a single frame (a batch has its own bar), on a terminal and
    without --quiet; it asks the solver for a checkpoint every ~2 % of the iterations.
    """
    if (args.method == "bp" or not getattr(args, "_iteration_bar", False)
            or "callback" in options or "checkpoints" in options):
        yield options
        return


    iters = int(options.get("iters") or default_iters(args.method, model) or 1)
    chans = 1 if y.ndim == 2 else y.shape[2]
    bar = tqdm(total=iters * chans, desc=args.method, unit="it", file=sys.stderr,
               dynamic_ncols=True, leave=False)

    def cb(rec: dict) -> None:
        done = int(rec.get("iteration", 0)) + iters * int(rec.get("channel") or 0)
        bar.update(max(0, min(done, bar.total) - bar.n))

    try:
        yield {**options, "checkpoints": max(1, iters // 50), "callback": cb}
    finally:
        bar.close()


def _output_paths(args, stem: str) -> tuple[Path, Path, Path]:
    """The image, NPY and JSON paths of one frame, refused when one exists without --force."""
    out = Path(args.out)
    paths = (out / f"{stem}{FORMATS[args.format]}", out / f"{stem}.npy", out / f"{stem}.json")
    if not args.force:
        for t in paths:
            if t.exists():
                raise ClfzaError(f"{str(t)!r} exists; pass --force to overwrite it")
    return paths


def _solve(prep, camera, args, options: dict) -> tuple:
    """Plan (--explain, --plan) and reconstruct one prepared frame; returns the
    reconstruction, the plan (None without --explain/--plan) and the measured PSF (or None)."""

    plan = None
    check_roi(args.roi, prep.camera.shape)
    if args.plan and (args.psf or args.margin):
        raise ClfzaError("--plan bins for the camera's own mask model; give --psf or "
                         "--margin without --plan")
    if args.explain or args.plan:

        plan = make_plan(prep.y, prep.camera, method=args.method, kind="y",
                         iters=options.get("iters"))
    psf = load_psf_for(args, camera, prep.camera)
    model_kw = {"model": args.model, "margin": args.margin}
    if psf is not None:
        model_kw["psf"] = psf.array
    if args.plan:

        rec = reconstruct_planned(prep.y, prep.camera, args.method, plan=plan,
                                  backend=args.backend, device=args.device,
                                  model=args.model, **options)
        plan = rec.info.plan
    else:
        with _iteration_bar(args, options, prep.y, _model_kind(args, prep.camera, options,
                                                               psf)) as run_opts:
            rec = reconstruct(prep.y, prep.camera, args.method, backend=args.backend,
                              device=args.device, **model_kw, **run_opts)
    return rec, plan, psf


def _record(path: Path, prep, args, options: dict, info, psf, timings: dict, scaling,
            finish: dict, paths: tuple[Path, Path, Path], ran: dict) -> dict:
    """The JSON record of one reconstructed frame (``paths``: image, NPY, JSON)."""
    img, npy, json_path = paths
    record = {
        "clfza_version": __version__,
        "date": time.strftime("%Y-%m-%d %H:%M:%S"),
        "command": command_line(),
        "input": str(path),
        **prep.record,
        "camera": prep.camera.summary(),
        "camera_file": args.camera,
        "method": info.method,
        "parameters": {**options, **info.params},
        "backend": info.backend,
        "device": info.device,
        "dtype": info.dtype,
        "iterations": info.iterations,
        "stop_reason": info.stop_reason,
        "notes": list(info.notes),
        "timings_s": timings,
        "scaling": scaling,
        "output_geometry": finish,
        "psf": None if psf is None else {"file": args.psf, **psf.info},
        "outputs": {"image": str(img), "npy": str(npy), "json": str(json_path)},
        "machine": {"platform": platform.platform(), "python": platform.python_version()},
    }
    record.update(ran)  # the grid, bin factor, iterations and stop rule that actually ran
    ignored = list(getattr(args, "_ignored", [])) + list(prep.record.get("ignored_options", []))
    if ignored:
        record["ignored_options"] = ignored
    if info.objective:
        record["objective_last"] = info.objective[-1]
    if info.stats.get("tau_auto"):  # tau=auto: the chosen tau and the criterion's values
        record["tau_auto"] = info.stats["tau_auto"]
    if info.stats.get("returned"):  # exact-model ADMM: which candidate was returned, and why
        record["returned"] = {"image": info.stats["returned"],
                              "objective_mean": info.stats["objective_mean"],
                              "objective_last": info.stats["objective_last"]}
    return record


def reconstruct_one(path: Path, stem: str, camera, args, cal: dict, options: dict) -> dict:
    """Prepare, reconstruct and write one frame; returns its JSON record."""

    paths = img_path, npy_path, json_path = _output_paths(args, stem)
    t0 = time.perf_counter()
    prep = prepare_frame(path, camera, args, cal)
    t1 = time.perf_counter()
    rec, plan, psf = _solve(prep, camera, args, options)
    t2 = time.perf_counter()
    info = rec.info
    image, finish = finish_image(rec.image, args)
    npy_bytes, _ = encode_image(npy_path, image)
    img_bytes, scaling = encode_image(img_path, image, scaling=args.scaling,
                                      percentiles=tuple(args.percentiles),
                                      tiff_float=args.format == "tiff-float")
    t3 = time.perf_counter()
    ran = what_ran(prep, plan if args.plan else None, info)
    if args.explain:
        print(f"plan for {path}:\n{explain_ran(plan, ran, applied=args.plan)}")
    timings = {"prepare": t1 - t0, "reconstruct": t2 - t1, "write": t3 - t2,
               "solver": dict(info.timings)}
    record = _record(path, prep, args, options, info, psf, timings, scaling, finish, paths,
                     ran)
    # the whole record or nothing: image, NPY and JSON appear together (JSON last)
    atomic_write_many([(npy_path, npy_bytes), (img_path, img_bytes),
                       (json_path, encode_json(record))], force=args.force)
    return record


def what_ran(prep, plan, info) -> dict:
    """The facts of the run for the JSON record, from the run itself: the bin factor and grid
    the solve ran on (frame preparation x the plan), iterations and the stop rule that fired."""
    b_prep = int(prep.record.get("bin", 1))
    b_plan = int(plan.bin) if plan is not None else 1
    work = plan.work_camera.shape if plan is not None else prep.camera.shape
    if plan is not None and plan.skip_solve:
        b_plan, work = 1, prep.camera.shape
    stop = str(info.stop_reason)
    params = info.params.get("plan") or {}
    rule = params.get("stop_rule_fired") if isinstance(params, dict) else None
    return {"bin": b_prep * b_plan, "bin_prepare": b_prep, "bin_plan": b_plan,
            "solve_shape": [int(v) for v in work], "iterations": int(info.iterations),
            "stop_reason": stop, "stop_rule_fired": rule or stop}


def explain_ran(plan, ran: dict, applied: bool) -> str:
    """``--explain``: the plan, then what actually ran (from the run's own record)."""
    text = plan.explain() if plan is not None else "  (no plan)"
    head = "" if applied else "  (advice only: the plan was not applied; add --plan)\n"
    return (head + text + f"\n  ran: {ran['iterations']} iteration(s) on "
            f"{ran['solve_shape'][0]}x{ran['solve_shape'][1]} (bin {ran['bin']}: "
            f"{ran['bin_prepare']} at preparation x {ran['bin_plan']} by the plan), stop: "
            f"{ran['stop_rule_fired']}")


def _error_printer(bar_on: bool):
    """A function printing ``clfza: error: MSG`` to stderr (through tqdm while a bar runs)."""

    def say_error(msg: str) -> None:
        line = f"clfza: error: {msg}"
        if bar_on:

            tqdm.write(line, file=sys.stderr)
        else:
            print(line, file=sys.stderr, flush=True)

    return say_error


def _write_summary(args, out: Path, options: dict, done: list[dict], failures: list[dict],
                   wall: float) -> None:
    """Write a batch's summary to ``OUT/batch-NNN.json`` (the next free number); print it."""

    summary = {
        "clfza_version": __version__,
        "date": time.strftime("%Y-%m-%d %H:%M:%S"),
        "command": command_line(),
        "method": args.method,
        "parameters": options,
        "succeeded": [{"input": r["input"], **r["outputs"]} for r in done],
        "failed": failures,
        "wall_s": wall,
    }
    out.mkdir(parents=True, exist_ok=True)
    n = 1
    while (out / f"batch-{n:03d}.json").exists():
        n += 1
    js = write_json(out / f"batch-{n:03d}.json", summary)
    if not args.quiet:
        total = len(done) + len(failures)
        print(f"reconstructed {len(done)} of {total} file(s) in {wall:.1f} s; summary: {js}")
        for fl in failures:
            print(f"  failed: {fl['input']}: {fl['error']}")


def run(args) -> int:
    """Entry point of ``clfza reconstruct``."""

    if wants_batch(args):  # --workers/--scheduler/--resume/--stack-out, stacks, videos
        return run_batch(args)

    camera = load_camera(args.camera, args.z1)
    options = solver_options(args)
    check_method(args.method, options)
    validate_options(args, camera)
    if args.backend == "opencl":  # no usable device: one error, before the batch starts

        get_runtime(args.device)
    cal = {"dark": load_calibration_frame(args.dark, "dark frame"),
           "flat": load_calibration_frame(args.flat, "flat field")}
    files, missing = expand_inputs(args.raw)
    out = Path(args.out)
    if out.exists() and not out.is_dir():
        raise ClfzaError(f"--out {str(out)!r} is a file, not a folder")
    failures: list[dict] = [{"input": pat, "error": f"{pat!r}: {why}"} for pat, why in missing]
    done: list[dict] = []
    batch = len(files) + len(missing) > 1
    t0 = time.perf_counter()
    bar_on = progress_enabled(args)
    say_error = _error_printer(bar_on)
    for f in failures:
        say_error(f["error"])
    args._iteration_bar = bar_on and not batch
    jobs = list(zip(files, _stems(files), strict=True))
    for path, stem in progress(jobs, args, desc="reconstruct", unit="frame",
                               disable=not (bar_on and batch)):
        try:
            rec = reconstruct_one(path, stem, camera, args, cal, options)
        except KeyboardInterrupt:
            raise
        except Exception as exc:
            if getattr(args, "debug", False):
                raise
            msg = _message(exc, path)
            failures.append({"input": str(path), "error": msg})
            say_error(msg)
            continue
        done.append(rec)
        log.info("%s -> %s (%s, %.2f s, %s)", path, rec["outputs"]["image"], rec["device"],
                 rec["timings_s"]["reconstruct"], rec["stop_reason"])
        if not args.quiet and not batch:
            print(f"wrote {rec['outputs']['image']}, {rec['outputs']['npy']}, "
                  f"{rec['outputs']['json']}")
    if batch:
        _write_summary(args, out, options, done, failures, time.perf_counter() - t0)
    if not failures:
        return 0
    return 1 if done else 2
