"""One Python API (issue 32, item 5): what ``import clfza`` reaches, one result type for the
single-frame entry points, the options classes as ``method``, one meaning per name, one
default per setting and one set of validators."""

from __future__ import annotations

import argparse
import dataclasses
import importlib
import inspect
import subprocess
import sys
import warnings
from fractions import Fraction

import numpy as np
import pytest

import clfza
from clfza import Camera, ClfzaError
from clfza.solvers import DEFAULT_BACKEND, DEFAULT_METHOD

DOCUMENTED = ["clfza.models.load_psf", "clfza.focus.select_psf_depth",
              "clfza.distributed.reconstruct_many", "clfza.reconstruction.reconstruct_planned",
              "clfza.io.read_frame", "clfza.camera.Camera", "clfza.metrics.compare",
              "clfza.reconstruct", "clfza.ADMM", "clfza.FISTA", "clfza.TwIST", "clfza.Wiener"]


@pytest.fixture(scope="module")
def small():
    """A 64^2 GZP camera on the transfer-function model and a noisy measurement of a box."""
    cam = Camera(pitch=0.01, shape=(64, 64), r1=0.08 / 1.015, z1=200.0, z2=3.0, mask="gzp")
    t = np.zeros((64, 64))
    t[20:44, 16:40] = 1.0
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        m = clfza.simulate(t, cam, sensor_plane=True, noise=clfza.Noise(gaussian_var=1e-4,
                                                                          seed=0))
    return cam, m


# ---- reachability ------------------------------------------------------------------------
def test_documented_names_resolve_after_import_clfza_in_a_fresh_interpreter():
    code = ("import clfza\n"
            + "".join(f"assert callable({name}), {name!r}\n" for name in DOCUMENTED)
            + "print('ok')\n")
    res = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         timeout=300)
    assert res.returncode == 0 and res.stdout.strip() == "ok", res.stderr


@pytest.mark.parametrize("sub", clfza._SUBMODULES)
def test_every_name_in_each_subpackage_all_resolves(sub):
    mod = getattr(clfza, sub)
    assert mod is importlib.import_module(f"clfza.{sub}")
    names = getattr(mod, "__all__", None)
    if names is None:  # a plain module (metrics, regularizers): its public functions
        names = [n for n, v in vars(mod).items() if not n.startswith("_")
                 and inspect.isfunction(v) and v.__module__ == mod.__name__]
    assert names, sub
    for name in names:
        assert getattr(mod, name) is not None, f"clfza.{sub}.{name}"


def test_every_top_level_name_resolves():
    for name in clfza.__all__:
        assert getattr(clfza, name) is not None, name
    assert set(clfza._SUBMODULES) <= set(dir(clfza))


def test_short_names_are_the_solvers_options_classes():
    from clfza import solvers

    assert clfza.ADMM is solvers.AdmmOptions is solvers.options_class("admm")
    assert clfza.FISTA is solvers.options_class("fista")
    assert clfza.TwIST is solvers.options_class("twist")
    assert clfza.Wiener is solvers.options_class("wiener")
    params = inspect.signature(clfza.ADMM).parameters  # every option in the signature
    assert {"tau", "iters", "weight", "rho", "nonneg", "colour"} <= set(params)


# ---- one result type ---------------------------------------------------------------------
def test_planned_and_autofocus_results_unpack_as_image_and_info(small):
    from clfza.focus import FocusResult
    from clfza.reconstruction import Plan, reconstruct_autofocus, reconstruct_planned

    cam, m = small
    rec = reconstruct_planned(m.y, cam, "bp", backend="numpy")
    image, info = rec
    assert isinstance(rec, clfza.Reconstruction) and image is rec.image
    assert isinstance(info.plan, Plan)
    assert info.params["plan"].items() >= info.plan.to_dict().items()  # and what ran
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # the box at 200 mm gives a flat focus curve here
        rec = reconstruct_autofocus(m.y, cam, "bp", z_range=(100.0, 400.0), backend="numpy")
    image, info = rec
    assert isinstance(rec, clfza.Reconstruction) and image.shape == cam.shape
    assert isinstance(info.focus, FocusResult)
    assert info.params["z1_autofocus"] == info.focus.z1_best
    # the objects stay out of the record; a plain reconstruction carries neither
    assert "plan" not in info.to_dict() and "focus" not in info.to_dict()
    _, plain = clfza.reconstruct(m.y, cam, backend="numpy")
    assert plain.plan is None and plain.focus is None


def test_skipped_planned_result_carries_its_plan(small):
    from clfza.reconstruction import PlanWarning, reconstruct_planned

    cam, _ = small
    with pytest.warns(PlanWarning):
        image, info = reconstruct_planned(np.zeros(cam.shape), cam, "admm", backend="numpy")
    assert np.all(image == 0) and info.plan.frame_state == "empty"


# ---- options instances as method ---------------------------------------------------------
@pytest.mark.parametrize("cls,name,opts", [
    ("ADMM", "admm", {"tau": 0.01, "iters": 12}),
    ("FISTA", "fista", {"tau": 0.01, "iters": 8, "monotone": False}),
    ("TwIST", "twist", {"tau": 0.01, "iters": 6, "mode": "efficient"}),
    ("Wiener", "wiener", {"lam": 0.05}),
])
def test_an_options_instance_gives_the_string_forms_image(small, cls, name, opts):
    cam, m = small
    a = clfza.reconstruct(m.y, cam, getattr(clfza, cls)(**opts), backend="numpy")
    b = clfza.reconstruct(m.y, cam, name, backend="numpy", **opts)
    assert a.info.method == b.info.method == name
    assert np.array_equal(a.image, b.image)
    assert a.info.params == b.info.params


def test_an_instance_leaves_unset_options_to_the_methods_defaults(small):
    """``clfza.ADMM(iters=3)`` with a measured PSF takes the PSF's own default tau (and ADMM's
    measured-PSF penalties), as ``"admm", iters=3`` does: unset fields are not sent."""
    from clfza.models import back_propagate  # noqa: F401  (clfza.models loads first)

    cam, m = small
    psf = np.zeros((15, 15))
    psf[7, 7], psf[7, 8], psf[6, 7] = 1.0, 0.5, 0.25
    a = clfza.reconstruct(m.y, cam, clfza.ADMM(iters=3), backend="numpy", psf=psf)
    b = clfza.reconstruct(m.y, cam, "admm", backend="numpy", psf=psf, iters=3)
    assert a.info.params["tau"] == b.info.params["tau"] != clfza.ADMM().tau
    assert np.array_equal(a.image, b.image)


def test_an_instance_takes_run_controls_and_a_field_changed_after_construction(small):
    cam, m = small
    seen = []
    opts = clfza.FISTA(tau=0.01)
    opts.iters = 4  # changed after construction: still given
    r = clfza.reconstruct(m.y, cam, opts, backend="numpy", truth=m.truth, checkpoints=[2],
                          callback=seen.append)
    assert r.info.iterations == 4 and seen
    assert r.info.checkpoints[0]["iteration"] == 2 and "psnr" in r.info.checkpoints[0]


def test_mixing_an_instance_with_option_keywords_is_an_error(small):
    cam, m = small
    with pytest.raises(ClfzaError, match="not both"):
        clfza.reconstruct(m.y, cam, clfza.ADMM(tau=0.01), backend="numpy", iters=5)


@pytest.mark.parametrize("bad", [3, clfza.ADMM, {"tau": 0.01}, None])
def test_a_method_that_is_neither_a_name_nor_an_instance_is_an_error(small, bad):
    cam, m = small
    with pytest.raises(ClfzaError, match="method must be"):
        clfza.reconstruct(m.y, cam, bad, backend="numpy")


def test_the_options_base_class_names_no_method(small):
    from clfza.solvers import MethodOptions

    cam, m = small
    with pytest.raises(ClfzaError, match="not the options of one method"):
        clfza.reconstruct(m.y, cam, MethodOptions(tau=0.01), backend="numpy")


def test_bad_values_in_an_instance_are_the_usual_errors(small):
    cam, m = small
    with pytest.raises(ClfzaError, match="tau"):
        clfza.reconstruct(m.y, cam, clfza.ADMM(tau=-1.0), backend="numpy")
    with pytest.raises(ClfzaError, match="exact model"):
        clfza.reconstruct(m.y, cam, clfza.ADMM(mu1=0.1, iters=2), backend="numpy",
                          model="tf")


def test_given_lists_what_the_instance_asks_for():
    o = clfza.TwIST(tau=0.005, mode="efficient")  # tau given, though equal to its default
    assert o.given() == {"tau": 0.005, "mode": "efficient"}
    assert clfza.Wiener().given() == {}
    assert dataclasses.replace(o, iters=7).given()["iters"] == 7


# ---- one name, one meaning ---------------------------------------------------------------
def test_focus_names_search_border_fraction_envelope_sigma():
    from clfza.focus import FastBP, autofocus, find_depths, select_psf_depth
    from clfza.reconstruction import reconstruct_autofocus

    for fn in (autofocus, find_depths, select_psf_depth, FastBP):
        params = set(inspect.signature(fn).parameters)
        assert not params & {"method", "margin", "highpass"}, fn
        assert "envelope_sigma" in params, fn
    assert "search" in inspect.signature(autofocus).parameters
    assert "border_fraction" in inspect.signature(autofocus).parameters
    assert "search" in inspect.signature(reconstruct_autofocus).parameters
    # margin stays the exact model's extra object pixels, highpass ADMM's box half-width
    assert "margin" in inspect.signature(clfza.reconstruct).parameters
    assert "highpass" in {f.name for f in dataclasses.fields(clfza.ADMM)}


def test_an_unknown_search_and_a_bad_border_fraction_are_errors(small):
    from clfza.focus import autofocus, central_mask

    cam, m = small
    with pytest.raises(ClfzaError, match="search must be"):
        autofocus(m.y, cam, (100.0, 400.0), search="bisect", backend="numpy")
    with pytest.raises(ClfzaError, match="border_fraction"):
        central_mask((32, 32), 0.5)
    assert central_mask((10, 10), 0.0).all()


# ---- one default, defined once -----------------------------------------------------------
def _default(fn, name):
    return inspect.signature(fn).parameters[name].default


def test_method_and_backend_defaults_are_the_same_everywhere():
    from clfza.cli._main import build_parser
    from clfza.distributed import reconstruct_many, sweep
    from clfza.focus import FastBP, autofocus, find_depths
    from clfza.reconstruction import (
        focal_stack,
        make_plan,
        reconstruct_autofocus,
        reconstruct_planned,
    )
    from clfza.solvers import SEARCH_METHOD

    # a reconstruction's default is the default route; a search's (a point per depth or
    # parameter) back-propagation
    assert DEFAULT_METHOD == "auto" and SEARCH_METHOD == "bp" and DEFAULT_BACKEND == "opencl"
    for fn in (clfza.reconstruct, reconstruct_planned, reconstruct_autofocus,
               reconstruct_many):
        assert _default(fn, "method") == DEFAULT_METHOD, fn
    assert _default(make_plan, "method") == DEFAULT_METHOD
    for fn in (focal_stack, sweep):
        assert _default(fn, "method") == SEARCH_METHOD, fn
    rc = build_parser().parse_args(["reconstruct", "raw.npy", "--camera", "simulation"])
    assert rc.method == DEFAULT_METHOD
    for fn in (clfza.reconstruct, reconstruct_planned, autofocus, find_depths, FastBP, sweep):
        assert _default(fn, "backend") == DEFAULT_BACKEND, fn
    p = build_parser()
    sw = p.parse_args(["sweep", "raw.npy", "--camera", "simulation"])
    assert (sw.method, sw.backend) == (SEARCH_METHOD, DEFAULT_BACKEND)
    fo = p.parse_args(["focus", "raw.npy", "--camera", "simulation", "--z-range", "10,60"])
    assert fo.backend == DEFAULT_BACKEND and fo.search == "golden"


def test_a_tau_sweep_with_the_default_method_names_an_iterative_one(capsys):
    from clfza.cli import main
    from clfza.distributed import sweep

    assert main(["sweep", "raw.npy", "--camera", "simulation", "--tau", "1e-3,1e-2"]) == 2
    assert "--method admm" in capsys.readouterr().err
    with pytest.raises(ClfzaError, match="method='admm'"):
        sweep("raw.npy", Camera.preset("simulation"), [1e-3], [20.0])


# ---- one set of validators ---------------------------------------------------------------
@pytest.mark.parametrize("check", ["positive", "nonnegative", "strict_number"])
@pytest.mark.parametrize("bad", [True, np.bool_(False), "3", None, [1.0]])
def test_validators_reject_bools_and_strings(check, bad):
    from clfza import errors

    with pytest.raises(ClfzaError):
        getattr(errors, check)("x", bad)


@pytest.mark.parametrize("good", [2, 2.0, np.float32(2.0), np.int64(2), Fraction(2, 1),
                                  np.array(2.0)])
def test_validators_accept_real_numbers(good):
    from clfza import errors

    assert errors.positive("x", good) == 2.0
    assert errors.nonnegative("x", good) == 2.0
    assert errors.in_range("x", good, 0, 3) == 2.0


def test_the_solvers_use_the_one_validator():
    from clfza import errors
    from clfza.solvers import _options

    assert _options.positive is errors.positive
    with pytest.raises(ClfzaError, match="tau"):
        clfza.solvers.check_options("admm", {"tau": True})
    with pytest.raises(ClfzaError, match="tau"):
        clfza.solvers.check_options("admm", {"tau": "0.01"})


def test_command_line_types_parse_text_then_validate():
    from clfza.cli._common import nonneg_float, nonneg_int, positive_float, positive_int

    assert positive_float("3") == 3.0 and nonneg_float("0") == 0.0
    assert positive_int("3") == 3 and nonneg_int("0") == 0
    for parse, text in ((positive_float, "x"), (positive_float, "-1"), (positive_float, "nan"),
                        (positive_int, "3.5"), (positive_int, "0"), (nonneg_int, "-1")):
        with pytest.raises(argparse.ArgumentTypeError, match="value must"):
            parse(text)
