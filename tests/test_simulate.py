"""The simulator: projection (Eq. 2), noise, quantisation, saturation, diffraction (Eq. 8)."""

from __future__ import annotations

import numpy as np
import pytest

from clfza import Camera, Noise, simulate
from clfza.errors import ClfzaError
from clfza.simulation import project_scene


def small_cam(**kw):
    args = dict(pitch=0.01, shape=(128, 128), r1=0.1, z1=20.0, z2=3.0, R=None, mask="gzp")
    args.update(kw)
    return Camera(**args)


def test_projection_size_and_inversion():
    cam = small_cam()
    scene = np.zeros((40, 40))
    scene[:10, :10] = 1.0  # top-left block in the object
    obj, margin = project_scene(scene, cam, object_width=4.0)  # 4 mm * 0.15 = 0.6 mm = 60 px
    assert margin == 0
    rows, cols = np.nonzero(obj > 0.5)
    # inverted: the block lands bottom-right of the image centre
    assert rows.min() > 64 and cols.min() > 64
    extent = cols.max() - (128 // 2 - 30)
    assert extent == pytest.approx(60, abs=2)


def test_projection_larger_than_sensor_gets_margin():
    cam = small_cam()
    obj, margin = project_scene(np.ones((50, 50)), cam, object_width=20.0)  # 300 px > 128
    assert margin > 0 and obj.shape[0] == 128 + 2 * margin


def test_rgb_and_integer_scenes():
    cam = small_cam()
    rgb = (np.random.default_rng(0).random((30, 30, 3)) * 255).astype(np.uint8)
    m = simulate(rgb, cam, object_width=4.0)
    assert m.y.shape == (128, 128, 3) and m.truth.max() <= 1.0


def test_gaussian_noise_variance_is_as_asked():
    cam = small_cam()
    scene = np.random.default_rng(1).random((64, 64))
    m = simulate(scene, cam, object_width=4.0, noise=Noise(gaussian_var=0.01, seed=3))
    assert np.var(m.y - m.clean_y) == pytest.approx(0.01, rel=0.05)


def test_quantisation_and_saturation():
    cam = small_cam()
    scene = np.random.default_rng(2).random((64, 64))
    m = simulate(scene, cam, object_width=4.0, noise=Noise(bit_depth=8, exposure=1.5))
    assert m.frame.max() == 255 and np.all(m.frame == np.round(m.frame))
    assert m.info["saturated_fraction"] > 0
    m16 = simulate(scene, cam, object_width=4.0, noise=Noise(bit_depth=16))
    err = np.linalg.norm(m16.y - m16.clean_y) / np.linalg.norm(m16.clean_y)
    assert err < 1e-3  # 16-bit quantisation is far below the signal


def test_poisson_noise_scales_with_photons():
    cam = small_cam()
    scene = np.random.default_rng(3).random((64, 64))
    scene[:20] = 0.0  # dark regions: the convolution's rounding must not make lam < 0
    errs = []
    for photons in (1e3, 1e5):
        m = simulate(scene, cam, object_width=4.0, noise=Noise(photons=photons, seed=0))
        errs.append(np.linalg.norm(m.y - m.clean_y))
    assert errs[1] == pytest.approx(errs[0] / 10, rel=0.2)  # shot noise ~ sqrt(photons)


def test_frame_to_y_recovers_observation():
    cam = small_cam()
    m = simulate(np.random.default_rng(4).random((64, 64)), cam, object_width=4.0,
                 noise=Noise(bit_depth=12))
    np.testing.assert_allclose(m.frame_to_y(m.frame), m.y, atol=1e-12)


def test_diffraction_lowers_zone_contrast_eq8():
    # Fine zones (local period r1^2 / r) lose contrast after propagating over z2 (Eq. 8).
    cam = small_cam(shape=(256, 256), r1=0.25, mask="gzp", wavelength=5.5e-4)
    from clfza.simulation import shadow_pattern

    geo = shadow_pattern(cam, (256, 256), diffraction=False)
    dif = shadow_pattern(cam, (256, 256), diffraction=True)
    assert np.std(dif) < np.std(geo)
    assert np.allclose(dif.mean(), geo.mean(), rtol=0.02)


@pytest.mark.parametrize("scene, kw, match", [
    (np.full((8, 8), np.nan), {}, "NaN"),
    (np.ones((8, 8), dtype=complex), {}, "dtype"),
    (-np.ones((8, 8)), {}, "negative"),
    (np.ones((8, 8, 4)), {}, "RGB"),
    (np.ones((0, 8)), {}, "empty"),
    (np.ones((8, 8)), {"object_width": -1}, "object_width"),
])
def test_bad_scenes(scene, kw, match):
    with pytest.raises(ClfzaError, match=match):
        simulate(scene, small_cam(), **kw)


@pytest.mark.parametrize("kw, match", [
    (dict(gaussian_var=-1), "gaussian_var"), (dict(photons=0), "photons"),
    (dict(read_noise=2.0), "read_noise"), (dict(bit_depth=0), "bit_depth"),
    (dict(exposure=float("inf")), "exposure"),
])
def test_bad_noise(kw, match):
    with pytest.raises(ClfzaError, match=match):
        Noise(**kw)
