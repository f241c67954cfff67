"""``clfza calibrate FRAME --pitch P --z1 Z1 --z2 Z2``: fit a camera to a point-source shot.

Fits the shadow constant ``r1'^2``, the pattern's centre, the aperture's shadow ``R'``, the
mask type and the phase to a capture of a point source (or a PSF image) with
:func:`clfza.camera._calibrate.calibrate`, prints one line per parameter and writes a camera TOML
(``r1_shadow_squared``, ``R = R' / (1 + z2/z1)``, ``mask``, ``mask_center``, ``pitch``,
``shape``) that ``clfza reconstruct --camera`` reads, and the calibration's record beside it
(``.json``: every fitted value with its error bar, and ``undetermined``: the parameters the
frame does not determine, with why). When the frame does not determine ``R'`` (the aperture's
shadow reaches past the sensor), one line says so and the camera file gets ``--R`` or no
``R``, never the fitted value. A progress bar shows on a terminal. An existing file is kept
unless ``--force``; a low-confidence fit is reported, nothing is written and the exit status
is 2.
"""

from __future__ import annotations

import sys
import time
from pathlib import Path

from tqdm import tqdm

from .. import __version__
from .. import io as fio
from ..camera import calibrate, camera_toml
from ..errors import ClfzaError
from ..io import atomic_write_bytes
from ._common import positive_float, positive_int, progress_enabled


def _z1(text: str) -> float:
    if text.strip().lower() in ("inf", "infinity"):
        return float("inf")
    return positive_float(text)


NAME = "calibrate"
HELP = "fit a camera to a point-source frame"
DESCRIPTION = (
    "Fit r1'^2, the mask centre, the aperture's shadow R', the mask type and "
    "the phase to a point-source capture or PSF image; write a camera TOML.")


def add_arguments(p) -> None:
    """The arguments of ``clfza calibrate`` (its parser made by the command line from
    :data:`NAME`, :data:`HELP` and :data:`DESCRIPTION`)."""
    p.add_argument("frame", metavar="POINT_SOURCE_FRAME", help="frame file (PNG/TIFF/NPY)")
    p.add_argument("--pitch", type=positive_float, required=True, metavar="MM",
                   help="pixel pitch of the frame in mm")
    p.add_argument("--z1", type=_z1, required=True, metavar="MM",
                   help="distance of the point source from the mask in mm (or inf)")
    p.add_argument("--z2", type=positive_float, required=True, metavar="MM",
                   help="mask-to-sensor distance in mm")
    p.add_argument("--r1", type=positive_float, metavar="MM",
                   help="the mask's r1 in mm (default r1' / (1 + z2/z1))")
    p.add_argument("--R", type=positive_float, default=None, metavar="MM", dest="R",
                   help="the mask's aperture radius in mm, written to the camera file when "
                   "the frame does not determine R' (its shadow reaches past the sensor); "
                   "default: no R then")
    p.add_argument("--mask", choices=("auto", "fza", "gzp"), default="auto",
                   help="mask type; auto decides from the third harmonic (default)")
    p.add_argument("--bin", type=positive_int, default=1, metavar="B",
                   help="sum BxB pixel blocks before fitting (default 1)")
    p.add_argument("--dark", metavar="FILE", help="dark frame to subtract")
    p.add_argument("--name", default=None, help="camera name (default: the frame's stem)")
    p.add_argument("--out", default=None, metavar="TOML",
                   help="camera file to write (default FRAME-camera.toml)")
    p.add_argument("--force", action="store_true", help="overwrite an existing camera file")
    p.set_defaults(func=run)
    return p


def run(args) -> int:
    """Entry point of ``clfza calibrate``."""

    src = Path(args.frame)
    target = Path(args.out) if args.out else Path(f"{src.stem or 'frame'}-camera.toml")
    if target.exists() and not args.force:
        raise ClfzaError(f"{str(target)!r} exists; pass --force to overwrite it")
    frame, _ = fio.read_frame(src)
    if args.dark:
        dark, _ = fio.read_frame(args.dark, name=f"dark frame {args.dark!r}")
        frame = fio.subtract_dark(frame, dark)
    bar = None
    if progress_enabled(args):
        bar = tqdm(desc="calibrate", unit="eval", file=sys.stderr, dynamic_ncols=True)

    def progress(stage: str, evaluations: int) -> None:
        if bar is not None:
            bar.set_description(f"calibrate {stage}", refresh=False)
            bar.update(evaluations - bar.n)

    try:
        cal = calibrate(frame, args.pitch, z1=args.z1, z2=args.z2, r1=args.r1,
                        mask=args.mask, bin=args.bin, progress=progress)
    finally:
        if bar is not None:
            bar.close()
    for line in cal.summary_lines():
        print(line)
    if not cal.confident:
        raise ClfzaError("low-confidence calibration, camera file not written: "
                         + "; ".join(cal.warnings))
    comment = (f"clfza {__version__} calibrate {src.name} "
               f"({time.strftime('%Y-%m-%d %H:%M:%S')}, {cal.timings['total_s']:.2f} s)")
    r_note = r_source(cal, args.R)
    if r_note is not None:
        print(f"R' not determined, {r_note[1]}: {cal.undetermined['R_shadow']}")
        comment += f"\nR: {r_note[1]}"
    text = camera_toml(cal, args.z1, args.z2, args.r1, args.name or src.stem or "calibrated",
                       comment, R=args.R)
    record = {"clfza_version": __version__, "date": time.strftime("%Y-%m-%d %H:%M:%S"),
              "input": str(src), "camera_file": str(target), "z1": args.z1, "z2": args.z2,
              "r1_given": args.r1, "R_given": args.R,
              "R_source": "measured" if r_note is None else r_note[0],
              "calibration": cal.to_dict()}
    atomic_write_bytes(target, text.encode("utf-8"), force=args.force)
    rec_path = target.with_suffix(".json")
    fio.write_json(rec_path, record, force=True)
    if not args.quiet:
        print(f"wrote {target} and {rec_path.name}")
    return 0


def r_source(cal, R: float | None) -> tuple[str, str] | None:
    """Where the camera file's ``R`` comes from when the frame does not determine ``R'``:
    ``("given", line)`` or ``("omitted", line)``; None when it was measured (or the
    calibration names no reason)."""
    if cal.R_shadow is not None or "R_shadow" not in cal.undetermined:
        return None
    if R is not None:
        return "given", f"the camera file keeps --R {R:g} mm"
    return "omitted", "the camera file has no R (pass --R with the mask's aperture radius)"
