"""Autofocus, depth finding and focal stacks (issue 6) on simulated scenes at known depths.

Geometry with measurable depth sensitivity: z2 = 3 mm and z1 in 10-60 mm (the paper's
simulation has z1 = 20 mm), 256^2 pixels of 10 um, r1 = 0.14 mm (critical sampling at
z1 = 20 mm), aperture R' just inside the sensor.
"""

from __future__ import annotations

import warnings

import numpy as np
import pytest
from scipy.ndimage import gaussian_filter
from skimage import data
from skimage.transform import resize

from clfza import Camera, Noise, simulate
from clfza.focus import (
    METRICS,
    FastBP,
    autofocus,
    depth_resolution,
    find_depths,
    sharpness,
)
from clfza.reconstruction import focal_stack, reconstruct_autofocus


@pytest.fixture(scope="module")
def cam():
    return Camera(pitch=0.01, shape=(256, 256), r1=0.14, z1=30.0, z2=3.0, R=1.1, mask="fza")


def _sim(obj, camera, **kw):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return simulate(obj, camera, **kw)


@pytest.fixture(scope="module")
def scene():
    return resize(data.camera() / 255.0, (128, 128), anti_aliasing=True)


@pytest.mark.parametrize("metric", METRICS)
def test_metrics_prefer_sharp_images(metric, scene):
    blurred = gaussian_filter(scene, 3.0)
    assert sharpness(scene, metric) > sharpness(blurred, metric)


@pytest.mark.parametrize("z0", [15.0, 35.0])
@pytest.mark.parametrize("metric,search", [("mix", "golden"), ("tamura", "grid"),
                                           ("gradient", "golden")])
def test_autofocus_single_object_within_5_percent(cam, scene, z0, metric, search):
    m = _sim(scene, cam.at_depth(z0), noise=Noise(gaussian_var=1e-4, seed=1))
    fr = autofocus(m.y, cam, (10.0, 60.0), metric=metric, search=search)
    assert abs(fr.z1_best / z0 - 1) < 0.05, (fr.z1_best, z0)
    assert fr.timings["evaluations"] >= 41
    assert fr.r1p_best == pytest.approx(cam.at_depth(fr.z1_best).r1p)
    assert len(fr.scores) == len(fr.z_grid)


def test_find_depths_two_objects(cam):
    n = 256
    a = resize(data.camera() / 255.0, (110, 100), anti_aliasing=True)
    b = resize(data.astronaut().mean(axis=2) / 255.0, (110, 100), anti_aliasing=True)
    oa = np.zeros((n, n))
    oa[73:183, 25:125] = a
    ob = np.zeros((n, n))
    ob[73:183, 131:231] = b
    za, zb = 15.0, 40.0
    ma = _sim(oa, cam.at_depth(za), sensor_plane=True, noise=Noise(gaussian_var=1e-4, seed=1))
    mb = _sim(ob, cam.at_depth(zb), sensor_plane=True, noise=Noise(gaussian_var=1e-4, seed=2))
    res = find_depths(ma.y + mb.y, cam, (10.0, 60.0), n=2)
    found = sorted(res.depths)
    assert len(found) == 2
    assert abs(found[0] / za - 1) < 0.05 and abs(found[1] / zb - 1) < 0.05, found


def test_depth_resolution_grows_with_distance(cam):
    d = [depth_resolution(cam, z) for z in (12.0, 20.0, 45.0, 300.0)]
    assert all(x > 0 for x in d) and d == sorted(d)
    assert d[1] / 20.0 < 0.05  # measurable at the paper's simulation distance


def test_focal_stack_and_refocused_reconstruction(cam, scene):
    z0 = 20.0
    m = _sim(scene, cam.at_depth(z0), noise=Noise(gaussian_var=1e-4, seed=1))
    st = focal_stack(m.y, cam, [12.0, 20.0, 40.0], "bp", backend="numpy")
    assert st.images.shape == (3, 256, 256)
    assert st.best()[0] == 20.0
    rec = reconstruct_autofocus(m.y, cam, "bp", z_range=(10.0, 60.0), backend="numpy")
    fr = rec.info.focus
    assert abs(fr.z1_best / z0 - 1) < 0.05
    assert any("autofocus" in n for n in rec.info.notes)


def test_fastbp_matches_reference_bp(cam, scene):
    from clfza.models._transfer import NumpyOperator

    m = _sim(scene, cam.at_depth(20.0), noise=Noise(gaussian_var=1e-4, seed=1))
    eng = FastBP(m.y, cam, envelope_sigma=0.0, taper=0.0)
    ref = NumpyOperator(cam.at_depth(20.0), warn=False).adjoint(m.y)
    x = eng.image(20.0)
    assert np.max(np.abs(x - ref)) <= 1e-4 * np.max(np.abs(ref))


def test_fastbp_opencl_matches_numpy(cam, scene):
    pytest.importorskip("pyopencl")
    m = _sim(scene, cam.at_depth(20.0), noise=Noise(gaussian_var=1e-4, seed=1))
    a = FastBP(m.y, cam, backend="numpy").image(25.0)
    b = FastBP(m.y, cam, backend="opencl").image(25.0)
    assert np.max(np.abs(a - b)) <= 1e-3 * np.max(np.abs(a))
