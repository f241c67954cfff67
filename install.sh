#!/usr/bin/env bash
# Set up clfza in ./.venv with working OpenCL CPU devices, then check one.
#
#   ./install.sh            # .venv with clfza + pip's PoCL + test tools; the distribution's
#                           # PoCL too where apt-get can install it (root or sudo)
#   ./install.sh --intel    # also Intel's CPU OpenCL runtime from PyPI (.[intel]), registered
#                           # in .venv/etc/OpenCL/vendors (python -m clfza.cl.intel_icd)
#   ./install.sh --no-warm  # skip compiling the kernels at the end (see below)
#
# Last, it checks the default OpenCL device and compiles and tunes clfza's kernels on it once
# (python -m clfza.cl.check --warm): the programs go to the implementation's on-disk cache
# (PoCL's, or pyopencl's), the tuning and the choice of the default device to ~/.cache/clfza,
# so the first `clfza demo` or reconstruction does not wait for them. About a minute on a
# 2-core CPU with three CPU implementations (each is measured once to choose the default,
# under its own status line: "clfza: measuring N CPU OpenCL devices to choose the default").
#
# pip's PoCL (pocl-binary-distribution 3.0, LLVM 14) cannot compile for CPUs newer than
# LLVM 14 knows (e.g. AMD Zen 5), and on others it may compile for a CPU its kernel library
# was not built for; the distribution's PoCL (Debian 12: 3.1, LLVM 15) is installed next to it
# where possible. `clfza info` lists every device; `--device`/PYOPENCL_CTX choose one.
set -euo pipefail
cd "$(dirname "$0")"
PYTHON=${PYTHON:-python3}
INTEL=0
WARM=1
for a in "$@"; do
  case "$a" in
    --intel) INTEL=1 ;;
    --no-warm) WARM=0 ;;
    *) echo "install.sh: unknown option $a (use --intel, --no-warm)" >&2; exit 2 ;;
  esac
done

if [ ! -x .venv/bin/python ]; then
  "$PYTHON" -m venv .venv
fi
.venv/bin/python -m pip install --quiet --upgrade pip
EXTRAS="pocl,test,dask,video"
[ "$INTEL" = 1 ] && EXTRAS="$EXTRAS,intel"
.venv/bin/python -m pip install --quiet -e ".[$EXTRAS]"

# the distribution's PoCL, where apt-get can install it (root, or sudo without a password)
if command -v apt-get >/dev/null 2>&1 && ! dpkg -s pocl-opencl-icd >/dev/null 2>&1; then
  SUDO=""
  if [ "$(id -u)" -ne 0 ]; then
    if command -v sudo >/dev/null 2>&1 && sudo -n true 2>/dev/null; then SUDO="sudo -n"
    else SUDO="none"; fi
  fi
  if [ "$SUDO" != "none" ]; then
    $SUDO apt-get update -qq >/dev/null || true
    DEBIAN_FRONTEND=noninteractive $SUDO apt-get install -y -qq pocl-opencl-icd >/dev/null \
      || echo "install.sh: could not install the distribution's PoCL (pocl-opencl-icd)" >&2
  elif ! .venv/bin/python -m clfza.cl.check --quiet; then
    echo "install.sh: pip's PoCL cannot compile kernels on this CPU; install the" \
         "distribution's PoCL as root: apt-get install pocl-opencl-icd" >&2
  fi
fi

if [ "$INTEL" = 1 ]; then
  .venv/bin/python -m clfza.cl.intel_icd >/dev/null
fi
if [ "$WARM" = 1 ]; then
  echo "install.sh: choosing the default OpenCL device (where there are several CPU" \
       "devices, each is measured once), then compiling and tuning clfza's kernels for it" \
       "(once; cached on disk)"
  .venv/bin/python -m clfza.cl.check --warm
else
  .venv/bin/python -m clfza.cl.check
fi
