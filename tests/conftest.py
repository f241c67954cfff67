"""Shared fixtures: the OpenCL runtime (PoCL on CPU-only machines) and small cameras.

Which OpenCL implementation the tests run on: ``--cl-device SPEC`` or ``CLFZA_TEST_DEVICE``
(any device spec of :func:`clfza.cl.get_runtime`: ``"PoCL 3.0"`` for pip's PoCL, ``"PoCL 3.1"``
for Debian's, ``"Intel"`` for Intel's CPU runtime, ``"P:D"``) becomes ``PYOPENCL_CTX`` for the
whole session, so every backend and operator the tests create uses that device. Without
either, ``PYOPENCL_CTX`` as set, else clfza's default device. The header names the device.
"""

from __future__ import annotations

import logging
import os
import shutil
import subprocess
import sys
import warnings

import numpy as np
import pytest

from clfza import Camera


def pytest_addoption(parser):
    parser.addoption("--cl-device", default=None,
                     help="OpenCL device/implementation for the whole run (sets PYOPENCL_CTX; "
                          "e.g. 'PoCL 3.0', 'PoCL 3.1', 'Intel', '1:0')")
    parser.addoption("--agreement", action="store_true",
                     help="only the kernel/solver agreement tests (marker 'agreement'), which "
                          ".ci/run reruns on every further OpenCL device; the default marker "
                          "selection (no stress, slow or oclgrind tests) still applies")


def pytest_configure(config):
    # registered here, beside pyproject.toml's markers: the short pass runs by default, the
    # full one is also marked slow (tests/test_fuzz.py)
    config.addinivalue_line("markers", "fuzz: fuzzed readers and options (tools/fuzz_report.py;"
                            " the full pass: -m 'fuzz and slow')")
    spec = config.getoption("--cl-device") or os.environ.get("CLFZA_TEST_DEVICE")
    if spec:
        os.environ["PYOPENCL_CTX"] = spec


def pytest_collection_modifyitems(config, items):
    if not config.getoption("--agreement"):
        return
    keep, drop = [], []
    for it in items:
        (keep if it.get_closest_marker("agreement") else drop).append(it)
    config.hook.pytest_deselected(items=drop)
    items[:] = keep


def pytest_report_header(config):
    try:
        import clfza.reconstruction._reconstruct  # noqa: F401  (installs the default device's measurement)
        from clfza.cl import get_runtime

        return f"clfza OpenCL device: {get_runtime().info.describe()}"
    except Exception as exc:  # no device: the tests that need one say so
        return f"clfza OpenCL device: none ({exc})"


@pytest.fixture(scope="session")
def rt():
    """The default OpenCL runtime; tests needing it fail loudly if none is usable."""
    from clfza.cl import get_runtime

    return get_runtime()


@pytest.fixture
def rng():
    return np.random.default_rng(1234)


@pytest.fixture(scope="session")
def camera_toml() -> str:
    """The 64x64 test camera (``R = 0.6``) as a camera file's text, for the tests that write
    it, or variants of it, where the command line or ``Camera.load`` needs a file."""
    return """\
[camera]
pitch = 0.01
shape = [64, 64]
r1 = 0.07
z1 = 20.0
z2 = 3.0
R = 0.6
"""


@pytest.fixture
def critical_camera():
    """A 256x256 GZP camera at critical sampling r1'^2 = N p^2 with no aperture."""
    n, p = 256, 0.01
    z1, z2 = 20.0, 3.0
    r1p = np.sqrt(n) * p
    return Camera(pitch=p, shape=(n, n), r1=r1p / (1 + z2 / z1), z1=z1, z2=z2, R=None,
                  mask="gzp")


@pytest.fixture(autouse=True)
def _no_sampling_warnings_leak():
    with warnings.catch_warnings():
        warnings.simplefilter("default")
        yield


@pytest.fixture
def cli_logging():
    """clfza.cli.main installs a stderr handler on the root logger; drop it after the test."""
    yield
    root = logging.getLogger()
    for h in list(root.handlers):
        if getattr(h, "_clfza", False):
            root.removeHandler(h)


OCLGRIND_ICD_LIBS = ("/usr/lib/oclgrind/liboclgrind-rt-icd.so",
                     "/usr/lib/x86_64-linux-gnu/oclgrind/liboclgrind-rt-icd.so")


@pytest.fixture
def oclgrind(tmp_path):
    """``run(args, timeout=1800)``: a Python child (``sys.executable *args``) on Oclgrind, a
    simulated GPU with its data-race detection on (``OCLGRIND_DATA_RACES=1``), through an ICD
    vendors folder of its own; the test is skipped where Oclgrind is not installed."""
    lib = None if shutil.which("oclgrind") is None else next(
        (p for p in OCLGRIND_ICD_LIBS if os.path.exists(p)), None)
    if lib is None:
        pytest.skip("oclgrind is not installed (apt-get install oclgrind)")
    vendors = tmp_path / "oclgrind-vendors"
    vendors.mkdir()
    (vendors / "oclgrind.icd").write_text(lib + "\n")
    env = dict(os.environ, OCL_ICD_VENDORS=str(vendors), PYOPENCL_CTX="Oclgrind",
               OCLGRIND_DATA_RACES="1")

    def run(args, timeout: int = 1800) -> subprocess.CompletedProcess:
        return subprocess.run([sys.executable, *args], env=env, capture_output=True,
                              text=True, timeout=timeout)

    return run
