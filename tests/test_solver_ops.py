"""The core backend and the per-solver operation families (clfza.backends._base.Ops): a family
written in one module (as a new solver's would be) runs on both backends, is made once per
backend, and the core interface holds no solver's operations."""

from __future__ import annotations

from abc import abstractmethod

import numpy as np
import pytest

from clfza import Camera
from clfza.backends import get_backend
from clfza.backends._base import Backend, Ops
from clfza.errors import ClfzaError

SHAPE = (24, 40)


class AxpyOps(Ops):
    """A new solver's family, in its own module: ``out = a x + y``."""

    @abstractmethod
    def axpy(self, out, a: float, x, y) -> None: ...


@AxpyOps.implements("numpy")
class NumpyAxpyOps(AxpyOps):
    def axpy(self, out, a, x, y):
        out[...] = a * x + y


@AxpyOps.implements("opencl")
class OpenCLAxpyOps(AxpyOps):
    KERNELS = (("elementwise", ("triad",)),)  # a = b + s c

    def axpy(self, out, a, x, y):
        self.B.launch1d("triad", out.buf, y.buf, x.buf, self.B.r(a))


class HostOnlyOps(Ops):
    @abstractmethod
    def nothing(self) -> None: ...


@HostOnlyOps.implements("numpy")
class NumpyHostOnlyOps(HostOnlyOps):
    def nothing(self):
        return None


@pytest.fixture(scope="module")
def backends():
    cam = Camera(pitch=0.01, shape=SHAPE, r1=0.2, z1=100.0, z2=3.0, mask="gzp")
    return get_backend("opencl", cam), get_backend("numpy", cam)


def test_a_family_in_one_module_runs_on_both_backends(backends):
    B, N = backends
    rng = np.random.default_rng(0)
    x, y = rng.standard_normal((2, 1) + SHAPE)
    out_b, out_n = B.empty(), N.empty()
    AxpyOps.for_backend(B).axpy(out_b, 0.5, B.from_host(x), B.from_host(y))
    AxpyOps.for_backend(N).axpy(out_n, 0.5, x, y)
    np.testing.assert_allclose(B.to_host(out_b), out_n, rtol=1e-6, atol=1e-6)
    assert isinstance(AxpyOps.for_backend(B), OpenCLAxpyOps)
    assert isinstance(B.ops(AxpyOps), OpenCLAxpyOps) and isinstance(N.ops(AxpyOps), NumpyAxpyOps)


def test_an_implementation_is_made_once_per_backend(backends):
    B, N = backends
    assert AxpyOps.for_backend(B) is AxpyOps.for_backend(B) is B.ops(AxpyOps)
    assert AxpyOps.for_backend(N) is not AxpyOps.for_backend(B)
    assert "triad" in B.k


def test_a_missing_implementation_is_named(backends):
    B, N = backends
    assert HostOnlyOps.for_backend(N).nothing() is None
    with pytest.raises(ClfzaError, match="HostOnlyOps has no implementation on the opencl"):
        HostOnlyOps.for_backend(B)
    assert AxpyOps.kinds is not HostOnlyOps.kinds  # one table per family


def test_kernel_names_do_not_clash_across_programs(backends):
    B, _ = backends
    with pytest.raises(ClfzaError, match="triad"):  # bench.cl's triad vs elementwise.cl's
        B.use_kernels(("bench", ("triad",)))


def test_the_core_interface_holds_no_solver_operations():
    core = {"empty", "from_host", "to_host", "copy", "finish", "set_measurement", "b",
            "resid_grad", "reg_value", "prox_step", "project_nonneg", "fgp_prox", "lincomb",
            "diffnorm", "dot"}
    assert set(Backend.__abstractmethods__) == core
