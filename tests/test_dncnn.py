"""DnCNN (issue 38): the shipped weights, the numpy reference network, the OpenCL kernels.

Provenance of the reference. ``dncnn_reference`` was compared once against scico 0.0.7's own
``scico.denoiser.DnCNN`` (JAX 0.8.1, flax 0.12.0, CPU, installed in a throwaway venv, not a
dependency of clfza) on scikit-image's camera at 256^2 with Gaussian noise: the largest
absolute difference of the float64 reference from scico's float32 output was 2.6e-7 (6L),
4.5e-7 (6M), 6.5e-7 (6H) at sigma 0.06; 2.9e-7 / 3.3e-7 / 1.5e-6 (6N) and 2.9e-7 / 3.6e-7 /
5.0e-7 (17N) at sigma 0.02 / 0.1 / 0.25; BatchNorm folded against applied literally: at most
2.2e-15. These tests do not need scico: they check the reference against an independent
convolution loop and its own invariants, and the kernels against the reference.

Tolerances. The kernels compute in float32 with BatchNorm folded (the reference's
``folded=True`` form, equal to the literal one to 1e-15 in float64). Each output is a sum of
576 products per layer over 6 or 17 layers; float32 rounding (6e-8 relative) over such sums of
activations of order 1 gives errors of order 1e-6 on images in [0, 1] (measured: at most
5.2e-7 on every CPU implementation here); the tests allow 2e-5.
"""

from __future__ import annotations

import dataclasses
import os
import re
import subprocess
import sys
import warnings
from importlib import resources

import numpy as np
import pytest

from clfza.errors import ClfzaError

dn = pytest.importorskip("clfza.denoisers")

TOL32 = 2e-5


def _loop_conv(a, w):
    """An independent 3x3 circular cross-correlation: explicit loops over pixels."""
    h, wd, _ = a.shape
    out = np.zeros((h, wd, w.shape[3]))
    for i in range(h):
        for j in range(wd):
            for di in range(3):
                for dj in range(3):
                    out[i, j] += a[(i + di - 1) % h, (j + dj - 1) % wd] @ w[di, dj]
    return out


def _shallow(w, mids: int = 1):
    """The variant's first layer, ``mids`` of its blocks and its last layer: a valid DnCNN
    with fewer layers (fast tests, Oclgrind)."""
    return dataclasses.replace(w, kernels=w.kernels[:1 + mids] + w.kernels[-1:],
                               bn_scale=w.bn_scale[:mids], bn_bias=w.bn_bias[:mids],
                               bn_mean=w.bn_mean[:mids], bn_var=w.bn_var[:mids])


# ----- weights --------------------------------------------------------------------------------
@pytest.mark.parametrize("variant", ["6L", "6M", "6H", "6N", "17N"])
def test_shipped_weights_have_the_architecture(variant):
    w = dn.load_dncnn(variant)
    c = 2 if variant.endswith("N") else 1
    assert w.layers == int(variant[:-1]) and w.conditional == (c == 2)
    assert w.kernels[0].shape == (3, 3, c, 64) and w.kernels[-1].shape == (3, 3, 64, c)
    assert all(k.shape == (3, 3, 64, 64) for k in w.kernels[1:-1])
    assert w.bn_var.shape == (w.layers - 2, 64) and np.all(w.bn_var > 0)
    assert all(k.dtype == np.float32 and np.all(np.isfinite(k)) for k in w.kernels)
    # 78 GFLOP per 512^2 call for 6 layers, 291 for 17 (the figures)
    assert w.flops(512, 512) / 1e9 == pytest.approx(78 if w.layers == 6 else 291, rel=0.02)


def test_weights_ship_with_scicos_bsd3_notice():
    d = resources.files("clfza.denoisers").joinpath("weights")
    text = d.joinpath("LICENSE").read_text("utf-8")
    assert "Los Alamos National Laboratory" in text and "BSD 3-Clause" in text


@pytest.mark.parametrize("bad", ["6X", "", None, 6, "17n"])
def test_unknown_variant_is_a_clear_error(bad):
    with pytest.raises(ClfzaError, match="variant must be one of"):
        dn.load_dncnn(bad)


def test_a_variant_not_shipped_names_the_conversion_script():
    with pytest.raises(ClfzaError, match="convert_dncnn_weights.py --variants 17L"):
        dn.load_dncnn("17L")


# ----- the reference --------------------------------------------------------------------------
def test_circular_convolution_matches_an_explicit_loop(rng):
    a = rng.standard_normal((5, 7, 3))
    w = rng.standard_normal((3, 3, 3, 4))
    np.testing.assert_allclose(dn.conv3x3_circular(a, w), _loop_conv(a, w), rtol=0,
                               atol=1e-12)


@pytest.mark.parametrize("variant", ["6N", "6M"])
def test_reference_matches_the_layers_written_out(variant, rng):
    """The whole network against its definition with the loop convolution: relu(conv),
    relu(BN(conv)), conv; x - y[..., 0]; sigma as a constant second input channel."""
    w = _shallow(dn.load_dncnn(variant), mids=2)
    x, sigma = rng.random((9, 8)), 0.07
    inp = x[..., None]
    if w.conditional:
        inp = np.concatenate([inp, np.full_like(inp, sigma)], axis=-1)
    a = np.maximum(_loop_conv(inp, w.kernels[0].astype(float)), 0)
    for i, k in enumerate(w.kernels[1:-1]):
        c = _loop_conv(a, k.astype(float))
        c = ((c - w.bn_mean[i]) / np.sqrt(w.bn_var[i].astype(float) + 1e-5) * w.bn_scale[i]
             + w.bn_bias[i])
        a = np.maximum(c, 0)
    want = x - _loop_conv(a, w.kernels[-1].astype(float))[..., 0]
    got = dn.dncnn_reference(x, w, sigma=sigma)
    np.testing.assert_allclose(got, want, rtol=0, atol=1e-12)


@pytest.mark.parametrize("variant", ["6N", "6H"])
def test_folded_batchnorm_and_sigma_bias_equal_the_literal_network(variant, rng):
    w = dn.load_dncnn(variant)
    x = rng.random((2, 16, 12))
    for sigma in (0.0, 0.13):
        lit = dn.dncnn_reference(x, w, sigma=sigma)
        fold = dn.dncnn_reference(x, w, sigma=sigma, folded=True)
        np.testing.assert_allclose(fold, lit, rtol=0, atol=1e-12)


def test_float32_reference_within_float32_tolerance(rng):
    w = dn.load_dncnn("6N")
    x = rng.random((20, 24))
    r64 = dn.dncnn_reference(x, w, sigma=0.1)
    r32 = dn.dncnn_reference(x, w, sigma=0.1, dtype=np.float32)
    assert r32.dtype == np.float32
    assert np.abs(r32 - r64).max() < TOL32


def test_residual_form_output_is_input_minus_network(rng):
    """A zero last layer: the network's estimate of the noise is zero, the output is x."""
    w = dn.load_dncnn("6L")
    z = dataclasses.replace(w, kernels=w.kernels[:-1] + (np.zeros_like(w.kernels[-1]),))
    x = rng.random((10, 11))
    np.testing.assert_array_equal(dn.dncnn_reference(x, z), x)
    # and a non-zero one changes it: the output is x minus something that depends on x
    assert np.abs(dn.dncnn_reference(x, w) - x).max() > 1e-3


def test_circular_edges_a_shifted_input_gives_the_shifted_output_exactly(rng):
    w = dn.load_dncnn("6N")
    x = rng.random((12, 10))
    y = dn.dncnn_reference(x, w, sigma=0.05)
    ys = dn.dncnn_reference(np.roll(x, (5, -3), axis=(0, 1)), w, sigma=0.05)
    np.testing.assert_array_equal(ys, np.roll(y, (5, -3), axis=(0, 1)))


def test_sigma_channel_changes_the_output_and_matters_only_for_n_variants(rng):
    x = rng.random((12, 12))
    n6 = dn.load_dncnn("6N")
    lo, hi = (dn.dncnn_reference(x, n6, sigma=s) for s in (0.02, 0.2))
    assert np.abs(lo - hi).max() > 1e-3
    blind = dn.load_dncnn("6M")
    np.testing.assert_array_equal(dn.dncnn_reference(x, blind, sigma=0.02),
                                  dn.dncnn_reference(x, blind, sigma=0.2))


def test_denoising_reduces_the_noise_on_a_smooth_image(rng):
    yy, xx = np.mgrid[:48, :48] / 48.0
    clean = 0.3 + 0.4 * np.sin(3 * xx) * np.cos(2 * yy)
    noisy = clean + 0.1 * rng.standard_normal(clean.shape)
    out = dn.denoise(noisy, 0.1, backend="numpy")
    assert np.sqrt(np.mean((out - clean) ** 2)) < 0.5 * np.sqrt(np.mean((noisy - clean) ** 2))


# ----- the API --------------------------------------------------------------------------------
def test_variant_choice_by_sigma():
    assert dn.select_variant(0.1).variant == "6N" and dn.select_variant(0.1).note is None
    assert dn.select_variant(0.1, layers=17).variant == "17N"
    assert [dn.select_variant(s, "blind").variant for s in (0.03, 0.1, 0.18)] == [
        "6L", "6M", "6H"]
    c = dn.select_variant(0.15, "6L")
    assert c.variant == "6L" and "6N" in c.note and "6H" in c.note
    assert dn.select_variant(None, "6L").note is None
    assert "above the training range" in dn.select_variant(0.3).note


def test_denoise_warns_and_returns_the_note_outside_the_training_range(rng):
    x = rng.random((8, 8))
    with pytest.warns(dn.DnCNNRangeWarning, match="above the training range"):
        _, note = dn.denoise(x, 0.35, backend="numpy", return_note=True)
    assert "0.35" in note
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        _, note = dn.denoise(x, 0.05, backend="numpy", return_note=True)
    assert note is None


def test_colour_is_denoised_channel_by_channel(rng):
    rgb = rng.random((10, 9, 3))
    d = dn.DnCNN("6N", backend="numpy")
    out = d(rgb, sigma=0.05)
    assert out.shape == rgb.shape
    for c in range(3):
        np.testing.assert_allclose(out[..., c], d(rgb[..., c], sigma=0.05), rtol=0, atol=1e-14)


@pytest.mark.parametrize("x, sigma, match", [
    (np.full((8, 8), np.nan), 0.1, "NaN"),
    (np.zeros((8,)), 0.1, "grey"),
    (np.zeros((8, 8, 5)), 0.1, "grey"),
    (np.zeros((2, 8)), 0.1, "3x3"),
    (np.zeros((8, 8), complex), 0.1, "real"),
    ("image", 0.1, "array"),
    (np.zeros((8, 8)), -0.1, "sigma"),
    (np.zeros((8, 8)), True, "sigma"),
    (np.zeros((8, 8)), float("inf"), "sigma"),
    (np.zeros((8, 8)), None, "sigma"),
])
def test_bad_inputs_are_clear_errors(x, sigma, match):
    with pytest.raises(ClfzaError, match=match):
        dn.denoise(x, sigma, backend="numpy")


def test_bad_options_are_clear_errors():
    with pytest.raises(ClfzaError, match="backend"):
        dn.DnCNN("6N", backend="torch")
    with pytest.raises(ClfzaError, match="layers"):
        dn.select_variant(0.1, layers=8)
    with pytest.raises(ClfzaError, match="kernel"):
        dn.DnCNNDevice(dn.load_dncnn("6N"), kernel="fast")
    for bad in (0, 9, 2.5, True):
        with pytest.raises(ClfzaError, match="pixels per work-item"):
            dn.DnCNNDevice(dn.load_dncnn("6N"), pixels=bad)


# ----- OpenCL ---------------------------------------------------------------------------------
@pytest.mark.agreement
@pytest.mark.parametrize("kernel, pixels", [("cpu", 4), ("cpu", 3), ("tiled", 4)])
@pytest.mark.parametrize("variant", ["6N", "6L", "17N"])
def test_opencl_matches_the_float64_reference(rt, variant, kernel, pixels, rng):
    """Odd sizes (the CPU kernel's tail of 1 pixel of 4 or 2 of 3, partial 16x16 tiles) and a
    batch of two."""
    w = dn.load_dncnn(variant)
    x = rng.random((2, 37, 29))
    d = dn.DnCNNDevice(w, rt, kernel=kernel, pixels=pixels)
    for sigma in (0.0, 0.12):
        got = d(x, sigma)
        assert got.shape == x.shape and got.dtype == np.float32
        assert np.abs(got - dn.dncnn_reference(x, w, sigma=sigma)).max() < TOL32


@pytest.mark.agreement
def test_opencl_residual_circular_edges_and_api(rt, rng):
    w = dn.load_dncnn("6N")
    z = dataclasses.replace(w, kernels=w.kernels[:-1] + (np.zeros_like(w.kernels[-1]),))
    x = rng.random((16, 20))
    np.testing.assert_array_equal(dn.DnCNNDevice(z, rt)(x, 0.1), x.astype(np.float32))
    d = dn.DnCNNDevice(w, rt)
    y = d(x, 0.1)
    ys = d(np.roll(x, (3, 7), axis=(0, 1)), 0.1)
    assert np.abs(ys - np.roll(y, (3, 7), axis=(0, 1))).max() < 1e-6
    # the API on the device agrees with the numpy backend, colour and grey
    rgb = rng.random((16, 20, 3))
    got = dn.denoise(rgb, 0.05, backend="opencl", device=rt.info.index)
    assert np.abs(got - dn.denoise(rgb, 0.05, backend="numpy")).max() < TOL32


@pytest.mark.agreement
def test_opencl_buffers_are_allocated_once_per_shape(rt, rng):
    d = dn.DnCNNDevice(dn.load_dncnn("6N"), rt)
    d(rng.random((16, 16)), 0.1)
    act = [a.buf.int_ptr for a in d._act]
    d(rng.random((16, 16)), 0.05)
    assert [a.buf.int_ptr for a in d._act] == act


CHILD_BUILD = r"""
import json, numpy as np
from clfza.cl import get_runtime
from clfza.denoisers import DnCNNDevice, load_dncnn
rt = get_runtime()
DnCNNDevice(load_dncnn("6N"), rt)(np.zeros((8, 8)), 0.1)
print("BUILD-LOGS " + json.dumps(rt.build_logs))
"""


@pytest.mark.agreement
def test_dncnn_cl_builds_without_warnings(rt, tmp_path):
    """Fresh program caches (a cached build may return an empty log), as tests/
    test_build_logs.py does for the solvers' programs."""
    import json

    from clfza.cl import warning_lines

    env = dict(os.environ, POCL_CACHE_DIR=str(tmp_path / "pocl"), PYOPENCL_NO_CACHE="1",
               PYOPENCL_CTX=os.environ.get("PYOPENCL_CTX") or rt.info.index)
    p = subprocess.run([sys.executable, "-c", CHILD_BUILD], env=env, capture_output=True,
                       text=True, timeout=600)
    assert p.returncode == 0, p.stderr[-3000:]
    logs = json.loads(next(ln for ln in p.stdout.splitlines()
                           if ln.startswith("BUILD-LOGS "))[len("BUILD-LOGS "):])
    assert any("dncnn.cl" in k for k in logs), logs
    bad = {k: warning_lines(v) for k, v in logs.items() if warning_lines(v)}
    assert not bad, bad
    assert p.stderr.strip() == "", p.stderr[-3000:]


ERRORS = re.compile(r"Invalid (read|write)|data race|out of bounds", re.IGNORECASE)
CHILD_OCLGRIND = r"""
import dataclasses, numpy as np
from clfza.cl import get_runtime
from clfza.denoisers import DnCNNDevice, dncnn_reference, load_dncnn
rt = get_runtime()
print("device:", rt.info.name, rt.info.kind)
w = load_dncnn("6N")
w = dataclasses.replace(w, kernels=w.kernels[:2] + w.kernels[-1:], bn_scale=w.bn_scale[:1],
                        bn_bias=w.bn_bias[:1], bn_mean=w.bn_mean[:1], bn_var=w.bn_var[:1])
x = np.random.default_rng(0).random((1, 18, 17))
ref = dncnn_reference(x, w, sigma=0.1)
for kernel in ("auto", "cpu"):
    d = DnCNNDevice(w, rt, kernel=kernel)
    err = float(np.abs(d(x, 0.1) - ref).max())
    print(f"kernel {d.kernel} err {err:.3g}")
    assert err < 2e-5, err
"""


@pytest.mark.oclgrind
def test_dncnn_kernels_clean_under_oclgrind(oclgrind):
    """The GPU path (Oclgrind is a GPU to clfza: the tiled kernel through local memory) and
    the CPU kernel on an 18x17 image (a partial tile in both directions, a 4-pixel tail) with
    one 64 -> 64 layer: no invalid access, no data race, and the reference's result."""
    p = oclgrind(["-c", CHILD_OCLGRIND])
    assert p.returncode == 0, p.stdout[-2000:] + p.stderr[-4000:]
    assert "device: Oclgrind" in p.stdout and "kernel tiled" in p.stdout, p.stdout
    assert "kernel cpu" in p.stdout, p.stdout
    reports = [ln for ln in p.stderr.splitlines() if ERRORS.search(ln)]
    assert not reports, "\n".join(reports[:40])
