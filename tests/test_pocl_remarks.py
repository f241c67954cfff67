"""No built-in call left in a hot kernel's work-item loop on PoCL (clfza.cl.check --remarks).

pip's PoCL 3.0 compiles kernels for the running CPU with a kernel library built for another
one, and LLVM then inlines no library function ("conflicting attributes"): every fabs, fmax,
shuffle or vload16 stays a call and the loop is "not vectorized: call instruction" (3-6x
slower). kernels/common.cl writes them as clang built-ins on PoCL; this test compiles every
hot solver kernel in a child process with PoCL's vectoriser remarks on and an empty kernel
cache, and fails on those two remarks for any of them. Skipped where the default device is
not PoCL's (other compilers print no such remarks).
"""

from __future__ import annotations

import pytest

from clfza.cl.check import BAD_REMARKS, HOT_KERNELS, collect_remarks, parse_remarks

pytestmark = pytest.mark.agreement  # rerun on every OpenCL device (.ci/run)


def test_parse_remarks_attributes_each_remark_to_its_kernel():
    r = "<unknown>:0:0: "
    text = (r + "'_Z8_cl_fabsf' not inlined into 'soft_step' because it should never be "
            "inlined (cost=never): conflicting attributes"
            + r + "'_pocl_kernel_soft_step' inlined into '_pocl_kernel_soft_step_workgroup'"
            " with (cost=always): always inliner"
            + r + "loop not vectorized: call instruction cannot be vectorized"
            + r + "'_pocl_kernel_triad' inlined into '_pocl_kernel_triad_workgroup' with "
            "(cost=always): always inliner" + r + "vectorized loop (vectorization width: 16)")
    rem = parse_remarks(text)
    assert sorted(rem) == ["soft_step", "triad"]
    assert len(rem["soft_step"]) == 2 and rem["triad"] == []


def test_hot_kernels_have_no_call_in_their_loops(rt):
    if "portable computing language" not in rt.info.platform.lower():
        pytest.skip(f"remarks are PoCL's; the device is on {rt.info.platform}")
    try:
        rem = collect_remarks()
    except LookupError as exc:  # the child picked another device (PYOPENCL_CTX)
        pytest.skip(str(exc))
    missing = [k for k in HOT_KERNELS if k not in rem]
    assert not missing, f"not compiled (no remarks seen; PoCL without remarks?): {missing}"
    bad = {k: sorted(set(v)) for k, v in rem.items() if k in HOT_KERNELS and v}
    assert not bad, f"{BAD_REMARKS} in hot kernels: {bad}"
