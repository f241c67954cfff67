"""``python -m clfza.cl.intel_icd``: register Intel's CPU OpenCL runtime from PyPI.

``pip install "clfza[intel]"`` (``intel-opencl-rt`` + ``intel-cmplr-lib-rt``) puts
``libintelocl.so.<version>`` into ``<venv>/lib`` but registers it nowhere. This writes the
ICD folder ``<venv>/etc/OpenCL/vendors``: ``intel-cpu.icd`` holding the library's absolute path
and links to the system's ICDs (``/etc/OpenCL/vendors/*.icd``: the distribution's PoCL, GPU
drivers), since the ICD loader reads one folder. clfza points the loader there by itself
(``OCL_ICD_VENDORS``, when unset) before its first platform query; other programs need the
environment it prints::

    python -m clfza.cl.intel_icd            # write the folder, print the environment to use
    python -m clfza.cl.intel_icd --env      # only print it (shell syntax; eval "$(...)")
    python -m clfza.cl.intel_icd --remove   # drop the folder (back to the system's ICDs)

pip's PoCL (pyopencl's bundled ICD) is found by pyopencl's own loader whatever the folder.
Exit status 1 when the runtime is not installed.
"""

from __future__ import annotations

import glob
import os
import shutil
import sys

from ._runtime import SYSTEM_VENDORS, venv_vendors_dir

ICD_NAME = "intel-cpu.icd"


def find_library(prefix: str | None = None) -> str | None:
    """Absolute path of ``<prefix>/lib/libintelocl.so.<version>`` (the real file), or None."""
    lib = os.path.join(prefix or sys.prefix, "lib")
    hits = sorted(glob.glob(os.path.join(lib, "libintelocl.so.*")), key=len)
    hits = [h for h in hits if not h.endswith(".py")] or glob.glob(
        os.path.join(lib, "libintelocl.so"))
    return os.path.realpath(hits[0]) if hits else None


def environment(prefix: str | None = None) -> dict[str, str]:
    """The variables other programs need to see the folder (clfza sets the first itself)."""
    lib = os.path.join(prefix or sys.prefix, "lib")
    ld = os.environ.get("LD_LIBRARY_PATH", "")
    return {"OCL_ICD_VENDORS": venv_vendors_dir(),
            "LD_LIBRARY_PATH": lib + (":" + ld if ld and lib not in ld.split(":") else "")}


def register(prefix: str | None = None, vendors: str | None = None,
             system: str = SYSTEM_VENDORS) -> str:
    """Write the vendors folder (default ``<sys.prefix>/etc/OpenCL/vendors``) for the library
    under ``prefix`` (default ``sys.prefix``); returns the library's path. Raises
    FileNotFoundError when the runtime is not installed there."""
    path = find_library(prefix)
    if path is None:
        raise FileNotFoundError(
            f"no libintelocl.so* in {os.path.join(sys.prefix, 'lib')}; install Intel's CPU "
            "runtime first: pip install \"clfza[intel]\" (intel-opencl-rt, intel-cmplr-lib-rt)")
    d = vendors or venv_vendors_dir()
    os.makedirs(d, exist_ok=True)
    # (pip's intel-opencl-rt ships an intel-cpu.icd naming a conda build prefix, which no
    # loader can open: it is overwritten here with the real path)
    with open(os.path.join(d, ICD_NAME), "w", encoding="utf-8") as f:
        f.write(path + "\n")
    if os.path.isdir(system):
        for name in sorted(os.listdir(system)):
            dst = os.path.join(d, name)
            if name.endswith(".icd") and name != ICD_NAME and not os.path.lexists(dst):
                os.symlink(os.path.join(system, name), dst)
    return path


def main(argv: list[str] | None = None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    env = environment()
    if "--remove" in argv:
        shutil.rmtree(venv_vendors_dir(), ignore_errors=True)
        print(f"removed {venv_vendors_dir()}", file=sys.stderr)
        return 0
    if "--env" not in argv:
        try:
            path = register()
        except FileNotFoundError as exc:
            print(f"clfza: {exc}", file=sys.stderr)
            return 1
        print(f"registered {path} in {venv_vendors_dir()}; clfza uses it from now on. "
              "For other OpenCL programs:", file=sys.stderr)
    for k, v in env.items():
        print(f"export {k}={v}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
