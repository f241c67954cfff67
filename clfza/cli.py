"""The ``clfza`` command line: ``demo`` and ``info`` (more commands join in clfza.commands)."""

from __future__ import annotations

import argparse
import sys

from . import __version__
from .errors import ClfzaError


def _cmd_demo(args) -> int:
    from .demo import run_demo

    print("clfza demo: the paper's simulation setup (512x512, p = 10 um, r1 = 0.23 mm, "
          "z1 = 20 mm, z2 = 3 mm) on scikit-image's 'camera'")
    s = run_demo(args.out, backend=args.backend, device=args.device,
                 gaussian_var=args.noise, quiet=args.quiet)
    print(f"wrote {s['paths']['png']}")
    print(f"wrote {s['paths']['json']}")
    return 0


def _cmd_info(args) -> int:
    from .camera import Camera
    from .cl.runtime import get_runtime, list_devices, probe_device

    try:
        devs = list_devices()
    except ClfzaError as exc:
        print(f"OpenCL: {exc}")
        devs = []
    print(f"clfza {__version__}")
    print("OpenCL devices:")
    for d in devs:
        pi, di = (int(v) for v in d.index.split(":"))
        from .cl.runtime import _all_devices

        dev = next(x[3] for x in _all_devices() if x[0] == pi and x[1] == di)
        why = probe_device(pi, di, dev)
        print(f"  {d.describe()}" + ("" if why is None else f"  [unusable: {why}]"))
    if devs:
        try:
            rt = get_runtime(args.device)
            print(f"selected: {rt.info.describe()}")
            try:
                from .fft import describe_policy

                print(f"FFT: {describe_policy(rt)}")
            except ImportError:
                print("FFT: host scipy.fft" + (" (zero-copy)" if rt.zero_copy else
                                               " (copies through the host)"))
        except ClfzaError as exc:
            print(f"selected: none ({exc})")
    if args.camera:
        cam = Camera.load(args.camera)
        print(f"camera {cam.name}:")
        for k, v in cam.summary().items():
            print(f"  {k:26s} {v}")
    return 0


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="clfza", description="FZA lensless camera reconstruction "
                                "on OpenCL (Wu et al., Light Sci. Appl. 9, 53, 2020)")
    p.add_argument("--version", action="version", version=f"clfza {__version__}")
    p.add_argument("--debug", action="store_true", help="show tracebacks")
    sub = p.add_subparsers(dest="command", required=True)
    d = sub.add_parser("demo", help="simulate the paper's setup and reconstruct it")
    d.add_argument("--out", default="clfza-out", help="base output folder (default clfza-out)")
    d.add_argument("--backend", choices=("opencl", "numpy"), default="opencl")
    d.add_argument("--device", default=None, help="OpenCL device: gpu, cpu, P:D or a name")
    d.add_argument("--noise", type=float, default=0.0, help="Gaussian noise variance")
    d.add_argument("--quiet", action="store_true")
    d.set_defaults(func=_cmd_demo)
    i = sub.add_parser("info", help="OpenCL devices, FFT path and camera optics")
    i.add_argument("--device", default=None)
    i.add_argument("--camera", default=None, help="preset name or camera TOML file")
    i.set_defaults(func=_cmd_info)
    return p


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    try:
        return int(args.func(args) or 0)
    except ClfzaError as exc:
        if args.debug:
            raise
        print(f"clfza: error: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("clfza: interrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
