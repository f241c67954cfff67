"""Pieces shared by the subcommands: argument types, the camera and frame preparation
options, the warnings for ignored options and whether progress bars show."""

from __future__ import annotations

import argparse
import logging
import sys
import time

from .. import errors
from ..backends import tuning_cache, tuning_key
from ..camera import Camera, plausibility
from ..cl import SCORES_FILE, get_runtime, read_cache
from ..cl.check import warm_up
from ..errors import ClfzaError
from ..io import parse_pair, warn_ignored

log = logging.getLogger("clfza")


# ----------------------------------------------------------------------------------------
# argument types (argparse turns ArgumentTypeError into one clear line)
# ----------------------------------------------------------------------------------------
def _argtype(check, number=errors.parse_number):
    """An argparse type from a :mod:`clfza.errors` validator (one message for both paths):
    the text parsed to a number by ``number`` first (the validators take numbers only)."""

    def parse(text: str):
        try:
            return check("value", number("value", text))
        except ClfzaError as exc:
            raise argparse.ArgumentTypeError(str(exc)) from None

    parse.__name__ = check.__name__
    return parse


positive_float = _argtype(errors.positive)
nonneg_float = _argtype(errors.nonnegative)
positive_int = _argtype(errors.positive_int, errors.parse_int)
nonneg_int = _argtype(lambda name, value: errors.positive_int(name, value, 0), errors.parse_int)


def pair(integer: bool):
    """argparse type for ``N`` or ``A,B``."""

    def parse(text: str):
        try:
            return parse_pair(text, "value", integer=integer)
        except ClfzaError as exc:
            raise argparse.ArgumentTypeError(str(exc).replace("value ", "")) from None

    parse.__name__ = "pair"
    return parse


def option_value(text: str) -> tuple[str, object]:
    """``KEY=VALUE`` with VALUE parsed as int, float, true/false/none, else a string."""
    if "=" not in text or not text.split("=", 1)[0].strip():
        raise argparse.ArgumentTypeError(f"expected KEY=VALUE, got {text!r}")
    k, v = (s.strip() for s in text.split("=", 1))
    low = v.lower()
    val: object
    if low in ("true", "yes", "on"):
        val = True
    elif low in ("false", "no", "off"):
        val = False
    elif low in ("none", "null"):
        val = None
    else:
        try:
            val = int(v)
        except ValueError:
            try:
                val = float(v)
            except ValueError:
                val = v
    return k, val


def progress_enabled(args) -> bool:
    """Progress bars only on a terminal and without --quiet."""
    return not getattr(args, "quiet", False) and sys.stderr.isatty()


# ----------------------------------------------------------------------------------------
# frame preparation: dark, flat, Bayer, crop, bin, y
# ----------------------------------------------------------------------------------------
def add_camera_option(p, required: bool = True) -> None:
    p.add_argument("--camera", required=required, metavar="CAMERA",
                   help="camera TOML file or preset name (simulation, experiment)")


def add_frame_options(p, z1_grid: bool = False) -> None:
    """Options that turn a raw frame into the observation y (``z1_grid``: ``--z1`` takes a
    grid of object distances, as ``clfza sweep`` does, instead of one)."""
    g = p.add_argument_group("frame preparation")
    g.add_argument("--dark", metavar="FILE", help="dark frame to subtract (same shape as RAW)")
    g.add_argument("--flat", metavar="FILE",
                   help="flat field to divide by, normalised to mean 1 (same shape as RAW)")
    g.add_argument("--bayer", type=str.upper, choices=("RGGB", "BGGR", "GRBG", "GBRG"),
                   help="RAW is a Bayer mosaic: demosaic by 2x2 superpixel binning (pitch "
                   "doubles)")
    g.add_argument("--crop", type=pair(True), metavar="N|H,W",
                   help="crop size in sensor pixels around the centre (default: the "
                   "camera's shape)")
    g.add_argument("--center", type=pair(False), metavar="Y,X",
                   help="crop centre in sensor pixels, row then column (Y,X, like numpy; "
                   "default: the frame's centre)")
    g.add_argument("--bin", default="1", metavar="B|auto",
                   help="sum BxB pixel blocks after the crop (pitch x B); 'auto' uses the "
                   "camera's suggested bin factor (default 1)")
    if z1_grid:
        g.add_argument("--z1", type=str, metavar="A:B:N|LIST",
                       help="object distances in mm: N linear from A to B, or a list V1,V2,...")
    else:
        g.add_argument("--z1", type=positive_float, metavar="MM",
                       help="object distance in mm (overrides the camera file; a calibrated "
                       "r1_shadow is rescaled by (1 + z2/Z1) / (1 + z2/z1))")
    g.add_argument("--object-mean", type=positive_float, default=0.5, metavar="M",
                   help="assumed mean of the object, sets the output scale (default 0.5)")


def load_camera(spec: str, z1: float | None = None) -> Camera:
    """The camera of ``--camera`` (a preset or a TOML file), at ``--z1`` when given: the
    plausibility errors of a camera file apply to the moved camera too (``--z1 1e-300``
    makes the shadow's constant overflow)."""
    cam = Camera.load(spec)
    if z1 is None:
        return cam
    cam = cam.at_depth(z1)
    errors, _ = plausibility(cam)
    if errors:
        raise ClfzaError(f"--z1 {z1:g}: {errors[0]}")
    return cam


def _given(args, name: str, default) -> bool:
    v = getattr(args, name, default)
    return v is not None and v != default and v is not False and v != []


def ignored_options(args) -> list[str]:
    """Options set on the command line that do nothing in this combination; each one is
    warned about (once) and listed in the JSON record. Frame-dependent ones (``--center`` on a
    frame that already has the crop's shape) are found in :func:`prepare_frame`."""
    out: list[str] = []
    backend = getattr(args, "backend", None)
    if backend == "numpy" and _given(args, "device", None):
        out.append("--device is ignored: --backend numpy runs on the host, not OpenCL")
    if _given(args, "psf_pitch", None) and not getattr(args, "psf", None):
        out.append("--psf-pitch is ignored: there is no --psf")
    fmt = getattr(args, "format", None)
    scaling = getattr(args, "scaling", "percentile")
    pct_given = tuple(getattr(args, "percentiles", (0.1, 99.9)) or ()) != (0.1, 99.9)
    if fmt == "tiff-float":
        if scaling != "percentile" or pct_given:
            out.append("--scaling/--percentiles are ignored: --format tiff-float writes the "
                       "reconstruction unscaled as float32")
    elif pct_given and scaling != "percentile":
        out.append(f"--percentiles is ignored: --scaling {scaling} does not use percentiles")
    if getattr(args, "model", "auto") == "tf" and _given(args, "margin", 0):
        out.append("--margin is ignored: only the exact model (--model exact or auto) models "
                   "object pixels around the sensor")
    if getattr(args, "sensor_plane", False):
        if _given(args, "object_width", None):
            out.append("--object-width is ignored: with --sensor-plane the scene is already "
                       "the sensor-plane object on the camera grid")
        if tuple(getattr(args, "object_offset", None) or (0.0, 0.0)) != (0.0, 0.0):
            out.append("--object-offset is ignored: with --sensor-plane the scene is not "
                       "projected")
    return [warn_ignored(args, m) for m in out]


def add_subcommand(subparsers, common, name: str, help: str, description: str):
    """Register the subcommand ``name`` on argparse's ``subparsers`` and return its parser.

    ``common`` is the parent parser that carries ``--quiet``, ``--verbose`` and ``--debug``
    (None: none); ``help`` is the one line ``clfza --help`` lists, ``description`` the text
    of ``clfza NAME --help``.
    """
    parents = [common] if common is not None else []
    return subparsers.add_parser(name, parents=parents, help=help, description=description)


#: the commands that solve on OpenCL: they compile and tune the kernels first on a device's
#: first run (warm_up), under one status line, so that no solve is charged for it
WARM_COMMANDS = ("demo", "reconstruct", "focus", "bench", "sweep")


def warm_first_run(args) -> dict | None:
    """:func:`clfza.cl.check.warm_up` on the command's device, for :data:`WARM_COMMANDS` on
    the OpenCL backend: each command calls it once its arguments and inputs are checked, so
    that a bad option is reported at once, not after a first-run compile. A device that
    cannot be used is left to the command to report.

    Returns
    -------
    dict or None
        The first run's times (:func:`first_run`), for the command's record (the demo's and
        the benchmarks' ``setup`` / ``first_run``); None where nothing ran (another command,
        the numpy backend, a device that cannot be used).
    """
    if (getattr(args, "command", None) not in WARM_COMMANDS
            or getattr(args, "backend", "opencl") != "opencl"):
        return None
    try:
        return first_run(getattr(args, "device", None))
    except ClfzaError:
        return None


def first_run(device: str | None = None) -> dict:
    """Open ``device`` and warm it (:func:`clfza.cl.check.warm_up`), timing each first-run step
    where it happens, so that a record can hold them apart from the solves.

    Parameters
    ----------
    device : str, optional
        OpenCL device spec (:func:`clfza.cl.get_runtime`; None: the default device).

    Returns
    -------
    dict
        ``device`` (its description); ``device_s``: seconds to open it, which on a machine's
        first run holds the measurement of the CPU devices that chooses the default (each
        compiles and tunes its kernels); ``devices_measured``: how many were measured then
        (0: cached); ``compiled``: whether the device was compiled and tuned now (False: its
        programs and tuning were cached); ``warm_up_s`` and ``compile_s``: that step's seconds
        and the part spent building programs (0 when cached); ``tuning_s``: seconds the
        device's kernel-variant tuning took in that step (the tuner's own clock, part of
        ``warm_up_s``; the measurement's tuning is in ``device_s``); ``seconds``:
        ``device_s + warm_up_s``.
    """
    scores0 = read_cache(SCORES_FILE)
    t0 = time.perf_counter()
    rt = get_runtime(device)
    device_s = time.perf_counter() - t0
    measured = len(set(read_cache(SCORES_FILE)) - set(scores0))
    key = tuning_key(rt)
    before = tuning_cache().get(key, {})
    done = warm_up(device)
    after = tuning_cache().get(key, {})
    tuning_s = sum((float(e.get("seconds", 0.0)) for cls, e in after.items()
                    if isinstance(e, dict) and before.get(cls) != e), 0.0)
    warm_s = done["seconds"] if done else 0.0
    return {"device": rt.info.describe(), "device_s": device_s, "devices_measured": measured,
            "compiled": done is not None, "warm_up_s": warm_s,
            "compile_s": done["compile_s"] if done else 0.0, "tuning_s": tuning_s,
            "seconds": device_s + warm_s}


def first_run_line(record: dict | None) -> str | None:
    """The demo's and the benchmarks' line for a :func:`first_run` record: what the first run
    on this machine or device spent before any solve (None when it spent nothing worth a
    line: devices and kernels cached)."""
    if not record or not (record["compiled"] or record["devices_measured"]):
        return None
    parts = []
    if record["devices_measured"]:
        n = record["devices_measured"]
        parts.append(f"measuring {n} CPU device{'s' * (n > 1)} {record['device_s']:.1f} s")
    if record["compiled"]:
        parts.append(f"compiling and tuning {record['warm_up_s']:.1f} s (OpenCL builds "
                     f"{record['compile_s']:.1f} s, tuning {record['tuning_s']:.1f} s)")
    return f"first run (not timed below) {record['seconds']:.1f} s: " + ", ".join(parts)
