"""Shared fixtures: the OpenCL runtime (PoCL on CPU-only machines) and small cameras."""

from __future__ import annotations

import warnings

import numpy as np
import pytest

from clfza import Camera


@pytest.fixture(scope="session")
def rt():
    """The default OpenCL runtime; tests needing it fail loudly if none is usable."""
    from clfza.cl import get_runtime

    return get_runtime()


@pytest.fixture
def rng():
    return np.random.default_rng(1234)


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
