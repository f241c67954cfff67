"""The ``clfza`` command line: ``demo``, ``info``, ``reconstruct``, ``simulate``, ``focus``,
``calibrate``, ``bench``, ``sweep`` and ``tune`` (all but the first two live in
:mod:`clfza.cli._commands`).

Errors: a :class:`~clfza.errors.ClfzaError` (bad files, parameters, cameras, devices) prints one
line ``clfza: error: ...`` on stderr and exits with 2; so do argument errors (no usage dump),
out-of-memory and OpenCL runtime errors. Anything unexpected prints one line and exits with 1.
``--debug`` re-raises with the full traceback.

Logging: warnings (Python ``warnings`` included) go to stderr as one line each;
``--verbose`` adds progress details, ``--quiet`` keeps only errors and hides progress bars
(which also stay hidden when stderr is not a terminal).

First run: the commands that solve on OpenCL, once their arguments and inputs are checked,
compile and tune the kernels on a device where that was never done
(:func:`clfza.cli._common.warm_first_run`, :func:`clfza.cl.check.warm_up`), under one status
line on stderr
(``clfza: compiling OpenCL kernels for DEVICE (first run on this device; cached afterwards)
... done in 12.3 s``; nothing where it takes under a second, none with ``--quiet``). Nothing
from the OpenCL compiler reaches stderr: its warnings are logged at INFO (``--verbose``), its
whole logs at DEBUG (``--verbose --debug``).
"""

from __future__ import annotations

import argparse
import logging
import re
import sys

from .. import __version__
from ..backends import BACKENDS, tuning_report
from ..camera import Camera
from ..cl import (
    choice_report,
    device_problems,
    get_runtime,
    list_devices,
    set_status_writer,
    stderr_status,
)
from ..errors import ClfzaError, report_exception
from ..fft import describe_policy
from ..solvers import DEFAULT_BACKEND
from ._commands import register_all
from ._common import warm_first_run
from ._demo import run_demo

__all__ = ["main", "build_parser", "report_exception", "setup_logging"]

log = logging.getLogger("clfza")


class ArgumentParser(argparse.ArgumentParser):
    """An ArgumentParser whose errors are one line on stderr (exit status 2)."""

    def error(self, message: str):  # noqa: D401 - argparse API
        self.exit(2, f"clfza: error: {' '.join(message.split())} "
                     f"(see '{self.prog} --help')\n")


def common_options(top: bool = False) -> ArgumentParser:
    """``--quiet``, ``--verbose``, ``--debug``: on the top-level parser (with defaults) and on
    every subcommand (``SUPPRESS``, so a subcommand's absence does not reset them)."""
    p = ArgumentParser(add_help=False)
    kw = {} if top else {"default": argparse.SUPPRESS}
    p.add_argument("-q", "--quiet", action="store_true", help="errors only, no progress bars",
                   **kw)
    p.add_argument("-v", "--verbose", action="store_true", help="log details", **kw)
    p.add_argument("--debug", action="store_true", help="show tracebacks", **kw)
    return p


#: a captured Python warning as :func:`warnings.formatwarning` writes it: "FILE:LINE:
#: CATEGORY: MESSAGE" and the source line below
_PY_WARNING = re.compile(r"^.*?:\d+: \w+: (?P<msg>.*?)\n(?:[ \t].*)?$", re.DOTALL)


class _OneLine(logging.Formatter):
    def format(self, record: logging.LogRecord) -> str:
        text = record.getMessage()
        if record.name == "py.warnings":  # the message alone, without file, line and source
            m = _PY_WARNING.match(text)
            if m:
                text = m["msg"]
        msg = " ".join(text.split())
        if record.levelno >= logging.WARNING:
            return f"clfza: {record.levelname.lower()}: {msg}"
        return f"clfza: {msg}"


def setup_logging(args) -> None:
    """Route clfza's logging and Python warnings to stderr, one line per record."""
    level = logging.WARNING
    if getattr(args, "verbose", False):
        level = logging.DEBUG if getattr(args, "debug", False) else logging.INFO
    if getattr(args, "quiet", False):
        level = logging.ERROR
    root = logging.getLogger()
    for h in list(root.handlers):
        if getattr(h, "_clfza", False):
            root.removeHandler(h)
    handler = logging.StreamHandler(sys.stderr)
    handler._clfza = True  # type: ignore[attr-defined]
    handler.setFormatter(_OneLine())
    root.addHandler(handler)
    root.setLevel(level)
    # Third-party readers log their own complaints about corrupt files; clfza turns those
    # files into one error line, so their logs show only with --verbose.
    for noisy in ("matplotlib", "PIL", "pyopencl", "pytools", "tifffile", "imageio"):
        logging.getLogger(noisy).setLevel(logging.WARNING if level <= logging.INFO
                                          else logging.CRITICAL + 1)
    logging.captureWarnings(True)
    logging.getLogger("py.warnings").setLevel(level if level > logging.WARNING else
                                              logging.WARNING)
    # slow first-run steps (compile, device measurement): one line each, unless --quiet
    set_status_writer(None if getattr(args, "quiet", False) else stderr_status)


# ----------------------------------------------------------------------------------------
# demo and info
# ----------------------------------------------------------------------------------------
def _cmd_demo(args) -> int:

    print("clfza demo: the paper's simulation setup (512x512, p = 10 um, r1 = 0.23 mm, "
          "z1 = 20 mm, z2 = 3 mm) on scikit-image's 'camera'")
    first = warm_first_run(args)
    s = run_demo(args.out, backend=args.backend, device=args.device,
                 gaussian_var=args.noise, quiet=args.quiet, first_run=first)
    print(f"wrote {s['paths']['png']}")
    print(f"wrote {s['paths']['json']}")
    return 0


def _fft_path(rt) -> str:
    try:
        pass
    except ImportError:
        return "host scipy.fft" + (" (zero-copy)" if rt.zero_copy else
                                   " (copies through the host)")
    return str(describe_policy(rt))


def _fmt_mm(v: float) -> str:
    if v != v or v in (float("inf"), float("-inf")):
        return str(v)
    return f"{v * 1000:.2f} um" if abs(v) < 1 else f"{v:.3f} mm"


def camera_report(cam) -> list[str]:
    """Human-readable optics of a camera: regime, resolution, FOV, band limit, binning."""
    s = cam.summary()
    reg = cam.regime
    lines = [
        f"camera {cam.name}: {cam.shape[0]}x{cam.shape[1]} pixels of {_fmt_mm(cam.pitch)}, "
        f"{cam.mask.upper()} r1 = {cam.r1:g} mm (shadow r1' = {cam.r1p:.4f} mm), "
        f"z1 = {cam.z1:g} mm, z2 = {cam.z2:g} mm, R = {cam.R if cam.R is not None else 'none'}",
        f"  sampling regime      {reg.name} (r1'^2 / (N p^2) = {reg.ratio:.3f})"
        + ("" if reg.is_critical else f": {reg.advice}"),
        f"  resolution (sensor)  {_fmt_mm(s['resolution_sensor_mm'])}",
        f"  resolution (object)  {_fmt_mm(s['resolution_object_mm'])} at z1 = {cam.z1:g} mm "
        f"(magnification {s['magnification']:.4g})",
        f"  field of view        {s['field_of_view_deg']:.1f} deg",
        f"  band limit           {s['band_limit_cyc_per_mm']:.2f} cycles/mm (pixel Nyquist "
        f"{s['pixel_nyquist_cyc_per_mm']:.2f})",
        f"  suggested bin factor {s['suggested_bin']}",
    ]
    return lines


def _cmd_info(args) -> int:

    cam = Camera.load(args.camera) if args.camera else None  # bad camera: fail first
    print(f"clfza {__version__}")
    try:
        devs = list_devices()
    except ClfzaError as exc:
        print(f"OpenCL: {exc}")
        devs = []
    print("OpenCL devices:" if devs else "OpenCL devices: none")
    problems = device_problems() if devs else {}
    for d in devs:
        why = problems.get(d.index)
        line = f"  {d.describe()}"
        if why is not None:
            line += f"  [unusable: {why}]"
        else:
            try:
                drt = get_runtime(d.index)
                line += f"\n      FFT path: {_fft_path(drt)}"
                line += "\n" + "\n".join(tuning_report(drt))
            except ClfzaError as exc:
                line += f"  [unusable: {exc}]"
        print(line)
    if devs:
        try:
            rt = get_runtime(args.device)
            print("\n".join(choice_report()))
            print(f"selected: {rt.info.describe()}")
            print(f"FFT: {_fft_path(rt)}")
        except ClfzaError as exc:
            print(f"selected: none ({exc})")
    if cam is not None:
        print("\n".join(camera_report(cam)))
    return 0


# ----------------------------------------------------------------------------------------
# parser and entry point
# ----------------------------------------------------------------------------------------
def build_parser() -> ArgumentParser:

    common = common_options()
    p = ArgumentParser(prog="clfza", parents=[common_options(top=True)],
                       description="FZA lensless camera reconstruction on OpenCL "
                       "(Wu et al., Light Sci. Appl. 9, 53, 2020)")
    p.add_argument("--version", action="version", version=f"clfza {__version__}")
    sub = p.add_subparsers(dest="command", required=True, metavar="COMMAND")
    d = sub.add_parser("demo", parents=[common],
                       help="simulate the paper's setup and reconstruct it")
    d.add_argument("--out", default="clfza-out", help="base output folder (default clfza-out)")
    d.add_argument("--backend", choices=BACKENDS, default=DEFAULT_BACKEND)
    d.add_argument("--device", default=None, help="OpenCL device: gpu, cpu, P:D or a name")
    d.add_argument("--noise", type=float, default=0.0, help="Gaussian noise variance")
    d.set_defaults(func=_cmd_demo)
    i = sub.add_parser("info", parents=[common],
                       help="OpenCL devices, FFT path and a camera's optics")
    i.add_argument("--device", default=None, help="OpenCL device to select")
    i.add_argument("--camera", default=None, help="preset name or camera TOML file")
    i.set_defaults(func=_cmd_info)
    register_all(sub, common)
    return p


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    setup_logging(args)
    try:
        return int(args.func(args) or 0)
    except KeyboardInterrupt as exc:
        if not getattr(exc, "clfza_reported", False):  # said once, where it was caught first
            print("clfza: interrupted", file=sys.stderr)
        return 130
    except Exception as exc:
        if args.debug:
            raise
        msg, code = report_exception(exc)
        print(msg, file=sys.stderr)
        return code


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
