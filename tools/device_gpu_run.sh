#!/usr/bin/env bash
# Issue 13, item 5 in one call on a lent GPU machine (the workplace's `device` tool), from the
# repository root:
#
#   run(command="bash tools/device_gpu_run.sh", carry=[".whl"], timeout_s=600)
#
# The machine's image has Python 3.12, numpy, scipy, scikit-image, matplotlib and CuPy (cuFFT,
# the vendor FFT) but no pyopencl and no OpenCL loader registration. Prepare the wheels here
# once (they are git-ignored and travel with `carry`):
#
#   python3 -m pip download --no-deps --only-binary=:all: --python-version 3.12 \
#     --implementation cp --platform manylinux_2_28_x86_64 --platform manylinux_2_17_x86_64 \
#     -d .whl pyopencl pytools platformdirs siphash24 imagecodecs
#
# (imagecodecs only for the whole suite: its LZW TIFF tests; the image has tifffile without it.)
#
# Then, within one command's 10 minutes: install them into /tmp/site, register NVIDIA's
# OpenCL library with pyopencl's ICD loader (OCL_ICD_VENDORS), show `clfza info`, run
# bench/bench_gpu.py (GPU measurements first: TwIST paper mode at 2048^2, clfza's device FFT
# against cuFFT, ADMM time to PSNR) and then the kernel/solver agreement tests on the GPU (as
# .ci/run runs them on each further device). Everything lands in $OUT (logs and the bench's
# JSON/MD/PNG); copy the bench files into bench/results/ afterwards. PY overrides the Python
# (a dry run here: PY=.venv/bin/python OUT=/tmp/x bash tools/device_gpu_run.sh). Knobs:
# BATCH=1 (bench/bench_batch.py first, with BATCH_ARGS: frames/s against the batch size),
# BENCH_ARGS, SKIP_BENCH=1, TEST_ARGS (instead of the agreement tests), SKIP_AGREE=1,
# FULL_SUITE=1 (the whole default suite after them), *_TIMEOUT (seconds per step), FORCE_TESTS=1 (tests
# without a GPU, for a dry run), PROFILE="fista:512 twist-paper:2048 ..." (tools/profile_solve.py
# per case, after the bench), AB_BASE_TREE=<folder with `git archive` of a base revision>
# (carried: e.g. .device/ab_base) with AB_SIZES, AB_ROUNDS, AB_CASES (bench/bench_ab.py on the GPU),
# DNCNN=1 (bench/bench_dncnn.py first, with DNCNN_ARGS: the learned prior's time per call),
# GPU_AB=1 (bench/bench_gpu_ab.py with GPU_AB_ARGS: FFT column kinds and paired folds, same run),
# PHASES=1 (tools/profile_batch.py --phases with PHASES_ARGS: a batched call's time by phase).
set -u
cd "$(dirname "$0")/.."
PY=${PY:-python3}
OUT=${OUT:?OUT must name the folder for the results}
export PYTHONUNBUFFERED=1
log() { echo "== $*" | tee -a "$OUT/run.log"; }

if ! "$PY" -c "import pyopencl" 2>/dev/null; then
  ls .whl/*.whl >/dev/null 2>&1 || { log "no .whl/ wheels: prepare them (see the header)"; exit 2; }
  "$PY" -m pip install -q --no-index --no-deps --no-compile --no-cache-dir --upgrade \
    --target /tmp/site .whl/*.whl || { log "pip install of .whl/ failed"; exit 2; }
  export PYTHONPATH=/tmp/site${PYTHONPATH:+:$PYTHONPATH}
fi
# clfza runs from this checkout (not installed): its kernels from kernels/
export PYTHONPATH=$PWD${PYTHONPATH:+:$PYTHONPATH}
export CLFZA_KERNEL_DIR=$PWD/kernels

# NVIDIA's OpenCL library by absolute path (OCL_ICD_VENDORS overrides /etc/OpenCL/vendors,
# whose entry, if any, may name a library the loader cannot find), with its folder (libcuda)
# on the library path
lib=$(ls /usr/local/nvidia/lib64/libnvidia-opencl.so.1 \
      /usr/lib/x86_64-linux-gnu/libnvidia-opencl.so.1 2>/dev/null | head -n 1)
[ -n "$lib" ] || lib=$(find / -xdev -name 'libnvidia-opencl.so.1' 2>/dev/null | head -n 1)
if [ -n "$lib" ]; then
  mkdir -p /tmp/icd && echo "$lib" > /tmp/icd/nvidia.icd
  export OCL_ICD_VENDORS=/tmp/icd
  export LD_LIBRARY_PATH=$(dirname "$lib")${LD_LIBRARY_PATH:+:$LD_LIBRARY_PATH}
  log "registered $lib"
else
  log "no libnvidia-opencl.so.1 found: the system's OpenCL registration as it is"
fi
command -v nvidia-smi >/dev/null && nvidia-smi -L | tee -a "$OUT/run.log"

log "clfza info"
timeout -k 5 120 "$PY" -m clfza info 2>&1 | tee "$OUT/info.txt"
GPU=$("$PY" - <<'PY'
from clfza.cl import get_runtime
from clfza.reconstruction import usable_devices
print(next((d for d in usable_devices() if not get_runtime(d).is_cpu), ""))
PY
)
if [ -z "$GPU" ]; then
  log "no usable OpenCL GPU: bench on the default device only (a smoke run)"
fi

# the learned prior (issue 38): time per denoiser call on the GPU
if [ -n "${DNCNN:-}" ]; then
  log "bench/bench_dncnn.py on ${GPU:-the default device}"
  timeout -k 5 ${DNCNN_TIMEOUT:-180} "$PY" bench/bench_dncnn.py ${GPU:+--device "$GPU"} \
    --out "$OUT" ${DNCNN_ARGS:-} 2>&1 | tee "$OUT/dncnn.log"
fi

# same-run A/B of the GPU path's variants (device FFT columns, paired folds), then where a
# batched call's time goes by phase
if [ -n "${GPU_AB:-}" ]; then
  log "bench/bench_gpu_ab.py on ${GPU:-the default device}"
  timeout -k 5 ${GPU_AB_TIMEOUT:-240} "$PY" bench/bench_gpu_ab.py ${GPU:+--device "$GPU"} \
    --out "$OUT" ${GPU_AB_ARGS:-} 2>&1 | tee "$OUT/gpu_ab.log"
fi
if [ -n "${PHASES:-}" ]; then
  log "tools/profile_batch.py --phases on ${GPU:-the default device}"
  timeout -k 5 ${PHASES_TIMEOUT:-90} "$PY" tools/profile_batch.py --phases \
    ${GPU:+--device "$GPU"} ${PHASES_ARGS:-} 2>&1 | tee "$OUT/phases.log"
fi

# frames per launch (issue 37): frames/s against the batch size
if [ -n "${BATCH:-}" ]; then
  log "bench/bench_batch.py on ${GPU:-the default device}"
  timeout -k 5 ${BATCH_TIMEOUT:-240} "$PY" bench/bench_batch.py ${GPU:+--device "$GPU"} \
    --out "$OUT" ${BATCH_ARGS:-} 2>&1 | tee "$OUT/batch.log"
fi

if [ -z "${SKIP_BENCH:-}" ]; then
  log "bench/bench_gpu.py on ${GPU:-the default device}"
  timeout -k 5 ${BENCH_TIMEOUT:-240} "$PY" bench/bench_gpu.py ${GPU:+--device "$GPU"} \
    --out "$OUT" ${BENCH_ARGS:-} 2>&1 | tee "$OUT/bench.log"
  # the tuning the bench's sizes chose (small / large size classes), after it
  { echo; echo "== after the bench"; timeout -k 5 60 "$PY" -m clfza info; } >> "$OUT/info.txt" 2>&1
fi

# host-side profiles of single solves: where the time between kernels goes
for case in ${PROFILE:-}; do
  m=${case%%:*}; n=${case##*:}; extra=()
  [ "$m" = twist-paper ] && { m=twist; extra=(--mode paper); }
  log "profile $case"
  timeout -k 5 ${PROFILE_TIMEOUT:-60} "$PY" tools/profile_solve.py --method "$m" --n "$n" \
    "${extra[@]}" ${GPU:+--device "$GPU"} --iters 100 --top 25 2>&1 | tee -a "$OUT/profile.log"
done
# same-run A/B of this tree against a base tree, per size
if [ -n "${AB_BASE_TREE:-}" ]; then
  for n in ${AB_SIZES:-512 2048}; do
    log "bench_ab at $n against $AB_BASE_TREE"
    PYOPENCL_CTX=${GPU:-} timeout -k 5 ${AB_TIMEOUT:-150} "$PY" bench/bench_ab.py \
      --base "$(cat "$AB_BASE_TREE/.rev" 2>/dev/null || echo base)" --base-tree "$AB_BASE_TREE" \
      --rounds ${AB_ROUNDS:-3} --n "$n" --cases ${AB_CASES:-twist-paper,fista,admm} \
      --out "$OUT" --tag "gpu$n" 2>&1 | tee -a "$OUT/ab.log"
  done
fi

if { [ -n "$GPU" ] || [ -n "${FORCE_TESTS:-}" ]; } && [ -z "${SKIP_AGREE:-}" ]; then
  log "agreement tests on ${GPU:-the default device}"
  timeout -k 5 ${TEST_TIMEOUT:-270} "$PY" -m pytest -q -p no:cacheprovider --maxfail=20 \
    ${GPU:+--cl-device "$GPU"} ${TEST_ARGS:---agreement} > "$OUT/pytest.log" 2>&1
  log "pytest exit $?: $(tail -n 1 "$OUT/pytest.log")"
fi
# FULL_SUITE=1: then the whole default suite on the GPU, one line per test (-v: what ran
# survives a timeout), with the slowest tests listed
if [ -n "${FULL_SUITE:-}" ] && { [ -n "$GPU" ] || [ -n "${FORCE_TESTS:-}" ]; }; then
  log "whole default suite on ${GPU:-the default device}"
  timeout -k 5 ${FULL_TIMEOUT:-300} "$PY" -m pytest -v -rfE -p no:cacheprovider \
    --maxfail=100 --durations=15 ${GPU:+--cl-device "$GPU"} > "$OUT/pytest_full.log" 2>&1
  log "pytest (whole suite) exit $?: $(tail -n 1 "$OUT/pytest_full.log")"
fi
