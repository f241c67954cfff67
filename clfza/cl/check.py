"""``python -m clfza.cl.check``: is there an OpenCL device that compiles and runs kernels?

Exit status 0 and the device's description when there is; 1 and the reason when not.

``python -m clfza.cl.check --remarks`` (PoCL only) compiles and launches every hot solver
kernel once at a small size and reports, per kernel, the LLVM remarks
that mean a kernel's work-item loop stayed scalar: a built-in function that was not inlined
("conflicting attributes": pip's PoCL 3.0 built its kernel library for another CPU than the
one it compiles for, so LLVM refuses to inline ``fabs``, ``fmax``, ``shuffle``, ``vload16``...)
and "loop not vectorized: call instruction cannot be vectorized". Exit status 0 when no hot
kernel has one, 2 when some do, 3 when the device is not PoCL's. It sets
``POCL_VECTORIZER_REMARKS=1`` and a fresh ``POCL_CACHE_DIR`` for itself (PoCL compiles a
kernel at its first launch, and only a cache miss prints remarks).

``python -m clfza.cl.check --warm`` checks the device, then compiles and tunes clfza's kernels
on it once (:func:`warm_up`), so that the first reconstruction does not wait for them:
``install.sh`` runs it for the default device.
"""

from __future__ import annotations

import os
import re
import subprocess
import sys
import tempfile
import time
import warnings

import numpy as np

from ..backends import ProxState, get_backend
from ..camera import Camera
from ..reconstruction import reconstruct
from ..solvers import AdmmOps, FistaOps, FourierSolve, TwistOps
from ._arrays import DeviceArray
from ._runtime import get_runtime, set_status_writer, status, stderr_status

# remarks that mean a hot loop stays scalar
BAD_REMARKS = ("conflicting attributes", "not vectorized: call instruction")


def main(argv: list[str] | None = None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    if "--remarks" in argv:
        return remarks_main(argv)
    quiet = "--quiet" in argv
    if not quiet:  # the first run's steps (the default's measurement, the compile): one line
        set_status_writer(stderr_status)
    try:
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
        print(f"clfza: OpenCL device OK: {rt.info.describe()}", flush=True)
    if "--warm" in argv:
        done = warm_up(force=True)
        if not quiet:
            print(f"clfza: compiled and tuned the kernels in {done['seconds']:.1f} s (cached "
                  "on disk: the first reconstruction on this device does not wait for them)")
    return 0


# ----- the first run on a device ------------------------------------------------------------
#: what :func:`warm_up` runs: every method once at 512^2, so that each program of the solvers
#: is built, each kernel launched (PoCL compiles a kernel at its first launch) and the
#: device's tuning for small images measured
WARM_METHODS = (("bp", {}), ("twist", {"mode": "paper", "iters": 2}), ("fista", {"iters": 2}),
                ("admm", {"iters": 2, "model": "tf"}), ("admm", {"iters": 1, "model": "exact"}))


def compile_status(rt) -> str:
    """The status line of a device's first compile (:func:`warm_up`)."""
    return (f"compiling OpenCL kernels for {rt.info.name} ({rt.info.platform} "
            f"{rt.info.driver}) (first run on this device; cached afterwards)").replace("  ", " ")


def warm_up(device: str | None = None, *, force: bool = False) -> dict | None:
    """Compile and tune clfza's kernels on a device, once: its first run.

    The first solve on a device waits for the OpenCL compiler (seconds to half a minute on a
    2-core CPU: the programs are built from source, PoCL compiles each kernel again at its
    first launch) and for the measurement of its kernel variants (:mod:`clfza.backends`'
    tuning). Both are cached on disk (the implementation's program cache: PoCL's, or
    pyopencl's for the others; ``tuning.json`` in :func:`clfza.cl.cache_dir`), so this runs
    each method once at 512^2 under one status line (:func:`clfza.cl.status`), then records
    the device as warm (:meth:`clfza.cl.Runtime.mark_warm`). The command line calls it before
    its commands that solve; ``install.sh`` (``python -m clfza.cl.check --warm``) for the
    default device.

    Parameters
    ----------
    device : str, optional
        OpenCL device spec (:func:`clfza.cl.get_runtime`).
    force : bool
        Run even where the device is recorded as warm.

    Returns
    -------
    dict or None
        ``{"device", "seconds", "compile_s"}`` (the wall time, the part spent building
        programs), or None where the device was warm already.
    """
    rt = get_runtime(device)
    first = rt.first_run()
    if not (force or first):
        return None
    cam = Camera.preset("simulation")
    y = np.random.default_rng(0).random(cam.shape)
    t0, c0 = time.perf_counter(), rt.compile_seconds
    text = compile_status(rt) if first else compile_status(rt).split(" (first run")[0]
    with status(text), warnings.catch_warnings():
        warnings.simplefilter("ignore")  # the solves' advice on this made-up frame
        for method, opts in WARM_METHODS:
            reconstruct(y, cam, method, backend="opencl", device=device, **opts)
        rt.finish()
    rt.mark_warm()
    return {"device": rt.info.describe(), "seconds": time.perf_counter() - t0,
            "compile_s": rt.compile_seconds - c0}


# ----- vectoriser remarks of the hot kernels (PoCL) -------------------------------------------
def hot_ops(B):
    """(name, callable) for every hot solver kernel of the OpenCL backend ``B`` (one channel),
    each callable launching it (plus the sum16 fold where the operation reduces) through the
    backend's public methods and the solvers' operation families. Inputs are random and stay
    bounded when an operation repeats."""


    shape = B.shape
    rng = np.random.default_rng(0)

    def arr(scale=1.0):
        return B.from_host(rng.standard_normal((1,) + tuple(shape)) * scale)

    x, g, y, z, w, o, o2, s = arr(), arr(0.1), arr(), arr(), arr(), B.empty(), B.empty(), arr()
    u1, u2, q1, q2 = arr(0.1), arr(0.1), B.empty(), B.empty()
    warm = ProxState(warm=True)
    tw, fi, ad = TwistOps.for_backend(B), FistaOps.for_backend(B), AdmmOps.for_backend(B)
    fs = FourierSolve.for_backend(B)
    fs.setup(0.5, 0.1)
    B.prox_step("tv", x, g, 0.5, 0.01, o, 3, warm)  # a valid warm dual for the change kernel
    B.finish()
    return [
        ("triad", lambda: B.triad(o, x, y, 2.0)),
        ("lincomb3", lambda: B.lincomb(o, 1.0, x, 0.5, y, 0.25, z)),
        ("soft_step", lambda: B.prox_step("l1", x, g, 0.5, 0.1, o, 0, ProxState())),
        ("project_nonneg", lambda: B.project_nonneg(o, x)),
        ("shrink_vec", lambda: B.shrink(o, o2, x, y, 0.3)),
        ("twist_combine16", lambda: tw.combine(o, x, y, z, 1.9, 1.2, True).get()),
        ("twist_combine", lambda: B.launch_rows_reduce(  # colour frames and GPUs
            "twist_combine", o.buf, x.buf, y.buf, z.buf, B.r(0.1), B.r(0.5), B.r(0.4),
            B.i32(1), B.i32(1), B.fpar.buf, planes=3).get()),
        ("mask_past", lambda: tw.mask_past(y, z, x)),
        ("fista_extrap", lambda: fi.extrap(o, 1.3, x, -0.3, y)),
        ("admm_rhs", lambda: ad.rhs(o, q1, q2, w, s, 2.0, 0.5)),
        ("admm_update16", lambda: ad.update(x, u1, u2, q1, q2, o2, s, 0.3, 1).get()),
        ("admm_update_rhs16", lambda: ad.update_rhs(  # CPU devices; elsewhere the one below
            x, (u1, u2), (q1, q2), (y, z), o2, s, o, 0.3, True, 2.0, 0.5)[0].get()),
        ("admm_update", lambda: B.launch2d_reduce(  # colour frames and GPUs
            "admm_update", x.buf, u1.buf, u2.buf, q1.buf, q2.buf, o2.buf, s.buf, B.r(0.3),
            B.i32(1), B.fpar.buf).get()),
        ("dot_contrib", lambda: B.dot(x, y).get()),
        ("sum16x2", lambda: _fold_pair(B, x, y, o, o2)),
        ("diffnorm_contrib", lambda: B.diffnorm(x, y).get()),
        ("reg_contrib", lambda: B.reg_value(x).get()),
        ("chambolle_first/step/finish",
         lambda: B.prox_step("tv", x, g, 0.5, 0.01, o, 3, ProxState())),
        ("chambolle_step_change",
         lambda: B.prox_step("tv", x, g, 0.5, 0.01, o, 6, warm, tol=1e-9)),
        ("chambolle2_fused", lambda: B.prox_step("tv", x, g, 0.5, 0.01, o, 2, ProxState())),
        ("fgp_step/fgp_finish",
         lambda: B.fgp_prox("tv", o, x, 0.05, 3, ProxState(), True).get()),
        ("fgp2_fused", lambda: B.fgp_prox("tv", o, x, 0.05, 2, ProxState(), True).get()),
        ("resid_grad_spec8", lambda: B.resid_grad(x, o).get()),
        ("admm_solve_spec8", lambda: fs.solve(x, o, True).get()),
    ]


def _fold_pair(B, a, b, out_a, out_b) -> None:
    """One level of two deferred folds in one launch (reduce.cl's sum16x2, as
    ``OpenCLBackend.flush_folds`` pairs them), of one plane of ``a`` and one of ``b``: at the
    remarks' image size only one of the backend's reducers folds on the device, so the launch
    is made here."""
    i32 = np.int32
    n = a.size
    m = -(-n // 16)
    B.k["sum16x2"](B.rt.queue, (m, 2), None, a.buf, out_a.buf, i32(m), i32(n), b.buf,
                   out_b.buf, i32(m), i32(n), i32(1))
    B.finish()


def _dncnn(B) -> None:
    """One pass of the shipped 6-layer DnCNN (PnP's denoiser; on CPUs dncnn_mid between
    dncnn_first and dncnn_last) on a 64 x 64 image on ``B``'s device: for the remarks only
    (not a hot_ops entry, which Oclgrind and bench_kernels also run)."""
    from ..denoisers import DnCNNDevice, load_dncnn  # lazy: only the remarks child runs it

    img = np.random.default_rng(1).random((64, 64))
    DnCNNDevice(load_dncnn("6N"), B.rt)(img, 0.05)


def small_backend(shape=(128, 128)):  # > REDUCE_HOST pixels: sum16 runs

    cam = Camera(pitch=0.01, shape=shape, r1=0.2, z1=100.0, z2=3.0, mask="gzp")
    B = get_backend("opencl", cam)
    # the fused prox even where the device's tuning chose the three kernels: every hot
    # kernel must launch (PoCL compiles, and reports, at the first launch)
    B.apply_tuning({**B.tune, "prox": "fused", "fgp": "fused"})
    return B


# the kernels of the solvers' inner loops: none may keep a built-in call in its loop
HOT_KERNELS = ("triad", "lincomb3", "soft_step", "project_nonneg", "shrink_vec",
               "twist_combine", "twist_combine16", "mask_past", "fista_extrap", "admm_rhs",
               "admm_update", "admm_update16", "admm_update_rhs16", "sum16", "sum16x2",
               "dot_contrib", "diffnorm_contrib", "reg_contrib", "chambolle_first",
               "chambolle_step", "chambolle_step_change", "chambolle_finish",
               "chambolle2_fused", "fgp_step", "fgp_finish", "fgp2_fused", "resid_grad_spec8",
               "admm_solve_spec8", "dncnn_first", "dncnn_mid", "dncnn_last")


def _run_ops() -> int:
    """Child process: launch each hot operation once (PoCL compiles at the first launch)."""
    B = small_backend()
    if "portable computing language" not in B.rt.info.platform.lower():
        print(f"NOT-POCL {B.rt.info.platform}", file=sys.stderr)
        return 3
    for _name, fn in hot_ops(B):
        fn()
        B.finish()
    _dncnn(B)
    return 0


def collect_remarks(env: dict | None = None, timeout: float = 600) -> dict[str, list[str]]:
    """Per compiled kernel, its remarks of BAD_REMARKS (PoCL only): see :func:`parse_remarks`.

    Runs a child process with remarks on and an empty kernel cache. Raises RuntimeError when
    the child fails, LookupError when the device is not PoCL's.
    """
    with tempfile.TemporaryDirectory(prefix="clfza-pocl-cache-") as cache:
        e = dict(os.environ if env is None else env)
        e.update(POCL_VECTORIZER_REMARKS="1", POCL_CACHE_DIR=cache, POCL_KERNEL_CACHE="0")
        p = subprocess.run([sys.executable, "-m", "clfza.cl.check", "--remarks-child"],
                           env=e, capture_output=True, text=True, timeout=timeout)
    if p.returncode == 3:
        raise LookupError(p.stderr.strip().splitlines()[-1])
    if p.returncode != 0:
        raise RuntimeError(f"remarks child failed ({p.returncode}):\n{p.stderr[-3000:]}")
    return parse_remarks(p.stdout + p.stderr)


_REMARK = "<unknown>:0:0: "
_WG = re.compile(r"'_pocl_kernel_(\w+)' inlined into '_pocl_kernel_\1_workgroup'")
_NOT_INLINED = re.compile(r"'(\w+)' not inlined into '(\w+)'")


def _kernel_name(fn: str) -> str:
    return re.sub(r"_workgroup(_fast)?$", "", re.sub(r"^_pocl_kernel_", "", fn))


def parse_remarks(text: str) -> dict[str, list[str]]:
    """The remarks of BAD_REMARKS per kernel, from PoCL's remark stream (printed without
    newlines, each after ``<unknown>:0:0: ``). An inlining remark names its kernel; a loop
    vectoriser remark does not and belongs to the kernel whose work-group function PoCL built
    last ("'_pocl_kernel_K' inlined into '_pocl_kernel_K_workgroup'" starts each)."""
    out: dict[str, list[str]] = {}
    cur = "?"
    for rem in text.replace("\n", "").split(_REMARK):
        m = _WG.match(rem)
        if m:
            cur = m.group(1)
            out.setdefault(cur, [])
            continue
        if not any(b in rem for b in BAD_REMARKS):
            continue
        m = _NOT_INLINED.match(rem)
        k = _kernel_name(m.group(2)) if m else cur
        out.setdefault(k, []).append(rem.strip())
    return out


def remarks_main(argv: list[str]) -> int:
    if "--remarks-child" in argv:
        return _run_ops()
    try:
        rem = collect_remarks()
    except LookupError as exc:
        print(f"clfza: not a PoCL device ({exc}); remarks are PoCL's", file=sys.stderr)
        return 3
    bad = 0
    for name in sorted(rem):
        lines = rem[name]
        hot = name in HOT_KERNELS
        bad += bool(lines) and hot
        state = "OK" if not lines else f"{len(lines)} blocking remarks"
        print(f"{name:24s} {'hot ' if hot else '    '} {state}")
        for u in sorted(set(lines)):
            print(f"    {u}")
    missing = [k for k in HOT_KERNELS if k not in rem]
    if missing:
        print("not compiled (no work-group function seen): " + ", ".join(missing))
    return 2 if bad else 0


if __name__ == "__main__":
    if "--remarks-child" in sys.argv[1:]:
        sys.exit(_run_ops())
    sys.exit(main())
