"""``clfza tune [--device SPEC] [--size small|large|all] [--json FILE]``: measure the kernel
variants on a device again (clfza.backends._tuning), replace the cached choices and print a
table."""

from __future__ import annotations

import json

from ..backends import OpenCLBackend, retune, tuning_cache_path, tuning_key, tuning_table
from ..cl import get_runtime
from ..reconstruction import usable_devices

NAME = "tune"
HELP = "measure kernel variants on a device, cache the fastest"
DESCRIPTION = (
    "Time the kernel variants (fused or three-kernel TV prox, strip height, "
    "rows per contribution, work-group shapes) on the device at 512^2 (images up to "
    "1024^2 pixels) and 2048^2 (larger ones), cache the fastest per device and driver "
    "version, and print the timings. Runs by itself at first use; this reruns it.")


def add_arguments(p) -> None:
    """The arguments of ``clfza tune`` (its parser made by the command line from
    :data:`NAME`, :data:`HELP` and :data:`DESCRIPTION`)."""
    p.add_argument("--device", default=None,
                   help="OpenCL device: gpu, cpu, P:D or a name (default: clfza's default)")
    p.add_argument("--all-devices", action="store_true", help="every usable device")
    p.add_argument("--size", choices=("small", "large", "all"), default="all",
                   help="size class to measure (default all)")
    p.add_argument("--json", default=None, metavar="FILE", help="also write the results here")
    p.set_defaults(func=run)
    return p


def run(args) -> int:

    if args.all_devices:
        specs = usable_devices()
    else:
        specs = [args.device]
    classes = ("small", "large") if args.size == "all" else (args.size,)
    out = {}
    for spec in specs:
        rt = get_runtime(spec)
        res = retune(rt, OpenCLBackend, classes)
        print(f"{rt.info.describe()}")
        for cls in classes:
            e = res[cls]
            ch = ", ".join(f"{k}={v}" for k, v in e["choices"].items())
            print(f"  {cls}: {ch}  ({e['seconds']:.1f} s)")
            print("\n".join(tuning_table(e)))
        out[tuning_key(rt)] = res
    print(f"cached in {tuning_cache_path()}")
    if args.json:
        with open(args.json, "w", encoding="utf-8") as f:
            json.dump(out, f, indent=1)
    return 0
