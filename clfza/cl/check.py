"""``python -m clfza.cl.check``: is there an OpenCL device that compiles and runs kernels?

Exit status 0 and the device's description when there is; 1 and the reason when not.
"""

from __future__ import annotations

import sys


def main(argv: list[str] | None = None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    quiet = "--quiet" in argv
    try:
        import numpy as np

        from . import DeviceArray, get_runtime

        rt = get_runtime()
        a = DeviceArray.from_host(rt, np.arange(8, dtype=np.float32))
        k = rt.kernel("spectrum", "multiply_real", np.float32)
        h = DeviceArray.from_host(rt, np.full(8, 2.0, np.float32))
        c = DeviceArray.from_host(rt, np.ones(8, np.complex64))
        k(rt.queue, (4,), None, c.buf, h.buf, np.int32(4))
        ok = np.allclose(c.get()[:4], 2.0) and a.get()[7] == 7
    except Exception as exc:  # report any failure as "no usable device"
        if not quiet:
            print(f"clfza: no usable OpenCL device: {exc}", file=sys.stderr)
        return 1
    if not ok:
        if not quiet:
            print("clfza: the OpenCL device returned wrong results", file=sys.stderr)
        return 1
    if not quiet:
        print(f"clfza: OpenCL device OK: {rt.info.describe()}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
