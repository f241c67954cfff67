#!/usr/bin/env bash
# Set up clfza in ./.venv with a working OpenCL CPU device (PoCL), then check it.
#
#   ./install.sh            # create .venv, install clfza + PoCL + test tools
#
# pip's PoCL (pocl-binary-distribution 3.0, LLVM 14) cannot compile for CPUs newer than
# LLVM 14 knows (e.g. AMD Zen 5). When the check finds no working device, the script installs
# the distribution's PoCL (Debian/Ubuntu: pocl-opencl-icd) if it can, and checks again.
set -euo pipefail
cd "$(dirname "$0")"
PYTHON=${PYTHON:-python3}

if [ ! -x .venv/bin/python ]; then
  "$PYTHON" -m venv .venv
fi
.venv/bin/python -m pip install --quiet --upgrade pip
.venv/bin/python -m pip install --quiet -e ".[pocl,test,dask,video]"

if ! .venv/bin/python -m clfza.cl.check --quiet; then
  echo "install.sh: pip's PoCL cannot compile kernels on this CPU; trying the system PoCL" >&2
  if command -v apt-get >/dev/null 2>&1; then
    SUDO=""
    [ "$(id -u)" -ne 0 ] && command -v sudo >/dev/null 2>&1 && SUDO="sudo"
    $SUDO apt-get update -qq >/dev/null || true
    DEBIAN_FRONTEND=noninteractive $SUDO apt-get install -y -qq pocl-opencl-icd >/dev/null
  else
    echo "install.sh: no apt-get here; install your distribution's PoCL (pocl-opencl-icd)" >&2
  fi
fi
.venv/bin/python -m clfza.cl.check
