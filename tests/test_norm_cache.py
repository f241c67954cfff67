"""The exact model's operator norm, measured once per operator (:attr:`ExactModel.norm`): kept
by content in memory and in clfza's cache folder, read back by another model of the same
operator (the power iteration is seeded, so the value read is the value measured), and measured
again for any other kernel or geometry."""

from __future__ import annotations

import json

import numpy as np
import pytest

from clfza.models import _exact
from clfza.models._exact import ExactModel, operator_norm


@pytest.fixture
def fresh(monkeypatch, tmp_path):
    """An empty cache folder and an empty in-memory cache; a counter of power iterations."""
    monkeypatch.setenv("CLFZA_CACHE_DIR", str(tmp_path))
    monkeypatch.setattr(_exact, "_NORMS", {})
    runs = []

    def counted(normal, shape, **kw):
        runs.append(shape)
        return operator_norm(normal, shape, **kw)

    monkeypatch.setattr(_exact, "operator_norm", counted)
    return tmp_path, runs


def kernel(seed: int, n: int = 9) -> np.ndarray:
    return np.random.default_rng(seed).random((n, n))


def test_the_norm_is_measured_once_per_operator(fresh):
    folder, runs = fresh
    a = ExactModel(kernel(0), (24, 24))
    assert a.norm == pytest.approx(np.sqrt(np.max(np.abs(np.fft.rfft2(a.kernel_grid))) ** 2),
                                   rel=0.2)  # below the circulant bound, not far
    assert runs == [a.shape]
    assert ExactModel(kernel(0), (24, 24)).norm == a.norm  # the same operator: read, equal
    assert len(runs) == 1
    _exact._NORMS.clear()  # a later process: from the cache folder
    assert ExactModel(kernel(0), (24, 24)).norm == a.norm and len(runs) == 1
    on_disk = json.loads((folder / _exact.NORM_CACHE).read_text())
    assert on_disk["_order"] == [a._norm_key()] and on_disk[a._norm_key()] == a.norm


@pytest.mark.parametrize("other", [lambda: ExactModel(kernel(1), (24, 24)),
                                   lambda: ExactModel(kernel(0), (24, 28)),
                                   lambda: ExactModel(kernel(0), (24, 24), margin=2)])
def test_another_kernel_or_geometry_is_measured_again(fresh, other):
    _, runs = fresh
    first, second = ExactModel(kernel(0), (24, 24)), other()
    assert first.norm > 0 and second.norm > 0 and first.norm != second.norm
    assert len(runs) == 2


def test_the_cache_keeps_the_latest_entries_and_ignores_a_bad_value(fresh, monkeypatch):
    folder, runs = fresh
    monkeypatch.setattr(_exact, "NORM_CACHE_SIZE", 2)
    models = [ExactModel(kernel(s), (16, 16)) for s in range(3)]
    assert all(m.norm > 0 for m in models)
    on_disk = json.loads((folder / _exact.NORM_CACHE).read_text())
    assert on_disk["_order"] == [m._norm_key() for m in models[1:]]
    assert models[0]._norm_key() not in on_disk
    on_disk[models[2]._norm_key()] = "not a number"
    (folder / _exact.NORM_CACHE).write_text(json.dumps(on_disk))
    _exact._NORMS.clear()
    assert ExactModel(kernel(2), (16, 16)).norm == models[2].norm  # measured again
    assert len(runs) == 4


def _dense(model: ExactModel) -> np.ndarray:
    """The operator as a matrix (its columns: the images of the grid's unit vectors)."""
    cols = []
    for i in range(int(np.prod(model.shape))):
        e = np.zeros(model.shape)
        e.flat[i] = 1.0
        cols.append(model.forward(e).ravel())
    return np.array(cols).T


@pytest.mark.parametrize("gain", [1.0, 1e-25, 1e25])  # a PSF in any units: no float32 range
def test_the_single_precision_power_iteration_measures_the_largest_singular_value(fresh, gain):
    model = ExactModel(kernel(3) * gain, (16, 16))
    exact = np.linalg.norm(_dense(model), 2)  # the float64 SVD
    assert exact / _exact.NORM_SAFETY <= model.norm <= exact * (1 + 1e-5)
    assert np.isfinite(model.norm)
    float64 = operator_norm(model.normal, model.shape)  # the reference's own operator
    assert model.norm == pytest.approx(float64, rel=1e-4)
