"""Iterative solvers (TwIST, FISTA, ADMM) written once against the backend's core
(:mod:`clfza.backends`), each one file: a :class:`~clfza.solvers._driver.Solver` subclass and
its options dataclass, registered in :data:`~clfza.solvers._driver.REGISTRY`. The loop they
all run in (clock, checkpoints, callbacks, stopping rule, objective history) is
:func:`clfza.solvers._driver.run`. What a method alone needs beyond the core is an operation
family (:class:`clfza.backends._base.Ops`: a numpy reference and an OpenCL implementation)
beside it: :mod:`~clfza.solvers._twist_ops`, :mod:`~clfza.solvers._fista_ops`,
:mod:`~clfza.solvers._admm_ops` (with the Fourier-diagonal x-update
:class:`~clfza.solvers._admm_ops.FourierSolve`) and :mod:`~clfza.solvers._admm_crop_ops`.

``run_solver`` validates the options, builds the backend, runs the method channel by channel
(``colour="independent"``) or on all channels at once with vectorial TV (``colour="joint"``),
and returns a :class:`clfza.solvers._result.Reconstruction`.

Options: :func:`options_class` gives a method's dataclass (:mod:`clfza.solvers._options`), and
``options_class(m).help()`` its options with their defaults. All methods: ``tau`` (Eq. 19
weight; default 0.005, the paper's simulation; ADMM's ``"auto"``, chosen from the frame, unless
``tau`` or ``weight`` is given), ``iters`` (200), ``min_iters``, ``tol``
(1e-6), ``stop`` ("objective", "step", "none"), ``tv_iters`` (inner TV iterations),
``nonneg``, ``reg`` ("tv", "l1"), ``colour``; and the run controls ``truth``,
``checkpoints``, ``callback`` (``callback(record) -> bool | None``; True stops with
``stop_reason="callback"``, see :mod:`clfza.solvers._common`), ``x0``. TwIST: ``mode``
("paper", "efficient"), ``monotone``, ``sparse``, ``lambda1``, ``tv_tol`` (efficient mode:
adaptive inner TV iterations, ``tv_iters`` is then a maximum). FISTA: ``monotone``,
``weight``. ADMM: ``weight``, ``rho``, ``mu``; on the exact model also ``mu1``, ``adapt``,
``support``.

Examples
--------
>>> from clfza.solvers import options_class
>>> options_class("fista").from_options({"tau": 0.01}).weight
0.005
"""

from __future__ import annotations

import dataclasses
import time
import warnings

import numpy as np

from ..backends import exact_model, get_backend
from ..errors import ClfzaError, finite_image
from ..models import choose_model, default_halfwidth, highpass_frame, highpass_model
from . import _admm, _admm_crop, _fista, _twist, _wiener  # noqa: F401  (registers the solvers)
from ._admm_crop import PSF_ITERS, AdmmCropSolver, default_iterations
from ._common import Monitor
from ._context import SolveContext
from ._driver import REGISTRY, check_finite, solver_class
from ._options import COLOUR_MODES, DEFAULT_BACKEND, RUN_CONTROLS, MethodOptions
from ._pnp import prior_solver
from ._result import ReconInfo, Reconstruction
from ._route import route_model
from ._tau import channel_group, default_start, record_tau, run_group, split_auto
from ._twist import DEFAULT_TV_TOL, EFFICIENT_TV_ITERS  # noqa: F401  (re-exported)

ITERATIVE: tuple[str, ...] = tuple(sorted(REGISTRY, key=lambda m: REGISTRY[m][0].order))
METHODS: tuple[str, ...] = ("bp",) + ITERATIVE
#: every method a user may name: the default route "auto" (resolve_method) and METHODS
METHOD_NAMES: tuple[str, ...] = ("auto",) + METHODS

__all__ = ["METHODS", "METHOD_NAMES", "ITERATIVE", "COLOUR_MODES", "RUN_CONTROLS", "ClfzaWarning",
           "options_class", "option_names", "check_options", "default_iters", "run_solver"]


class ClfzaWarning(UserWarning):
    """A defined but degenerate result (e.g. a constant measurement)."""


def options_class(method: str, model: str = "tf") -> type[MethodOptions]:
    """The options dataclass of an iterative method (on a model kind)."""
    return solver_class(method, model).Options


def option_names(method: str) -> set[str] | None:
    """Every keyword an iterative method takes (its options and the run controls); None for
    a method that is not an iterative solver."""
    if method not in REGISTRY:
        return None
    names = set(RUN_CONTROLS)
    for cls in REGISTRY[method]:
        names |= cls.Options.names()
    return names


def check_options(method: str, options: dict) -> None:
    """Names and values of a method's options before any data is read (the command line's
    ``--opt``): unknown names and wrong types raise :class:`~clfza.errors.ClfzaError`; the
    rules that depend on the model are checked when the solve starts. Methods that are not
    registered iterative solvers are not checked here.

    Examples
    --------
    >>> check_options("admm", {"nonneg": "maybe"})
    Traceback (most recent call last):
    ...
    clfza.errors.ClfzaError: nonneg must be true or false, got 'maybe'
    """
    names = option_names(method)
    if names is None:
        return
    unknown = sorted(set(options) - names)
    if unknown:
        raise ClfzaError(f"method {method!r} does not take option(s) {unknown}; allowed: "
                         f"{sorted(names)}")

    options, _ = split_auto(options, method)  # tau="auto": the method and weight= checked
    for cls in REGISTRY[method]:
        cls.Options.check_values({k: v for k, v in options.items() if k not in RUN_CONTROLS})


def method_model(camera, model: str, method: str, options: dict | None = None, *,
                 psf: bool = False, y=None) -> tuple[str, str]:
    """The forward model ``method`` runs on for ``camera``, and why
    (:func:`clfza.models.choose_model`), with TwIST's ``mode`` taken from ``options`` or, when
    it is not given there, from TwIST's own options default (the one place that default
    lives). Given the frame ``y``, ``model="auto"`` also weighs its noise where the camera's
    sampling alone chose the exact model (:func:`clfza.solvers._route.route_model`: Eq. 17
    when the noise swamps its model error).

    Examples
    --------
    >>> from clfza import Camera
    >>> method_model(Camera.preset("simulation"), "auto", "twist")[0]
    'tf'
    """
    mode = (options or {}).get("mode")
    if mode is None and method in REGISTRY:
        defaults = {f.name: f.default for f in dataclasses.fields(REGISTRY[method][0].Options)}
        mode = defaults.get("mode")
    kind, why = choose_model(camera, model, method=method, mode=mode, psf=psf)
    sampling_only = (model == "auto" and kind == "exact" and not psf and camera.R is None
                     and not any(camera.mask_center))
    if sampling_only and (options or {}).get("reg") == "dncnn":
        # the learned prior runs on a mask's shadow through Eq. 17 only (on the exact model
        # it stayed below ADMM-TV: clfza.solvers._pnp's refusal), which the sampling alone
        # did not rule out here
        return "tf", (f"reg='dncnn' on a mask's shadow runs on the transfer-function model "
                      f"(Eq. 17): on the exact model it stayed below ADMM-TV (measured: "
                      f"docs/measurements.md, clfza.solvers._pnp); the exact model was "
                      f"chosen for the sampling alone: {why}")
    if y is not None and sampling_only:
        return route_model(y, camera)
    return kind, why


def default_iters(method: str, model: str | None = None, psf: bool = False) -> int | None:
    """The default iteration count of an iterative method on a model kind (default: the
    method's first model; None for other methods); ``psf``: with a measured PSF (ADMM on the
    exact model: :data:`~clfza.solvers._admm_crop.PSF_ITERS`)."""
    if method not in REGISTRY:
        return None
    kind = model or REGISTRY[method][0].models[0]
    if psf and method == "admm" and kind == "exact":
        return PSF_ITERS
    return options_class(method, kind).iters


def _image_of(a: np.ndarray) -> np.ndarray:
    """A host (C, H, W) iterate as the image the user sees."""
    return a[0] if a.shape[0] == 1 else np.moveaxis(a, 0, -1)


def channels_first(a: np.ndarray) -> np.ndarray:
    return a[None] if a.ndim == 2 else np.moveaxis(a, -1, 0)


def _run_inputs(options: dict, y: np.ndarray) -> tuple:
    """The run controls ``truth`` (as given) and ``x0`` (channels first), validated."""
    truth = options.get("truth")
    if truth is not None:
        truth = finite_image("truth", truth)
        if truth.shape != y.shape:
            raise ClfzaError(f"truth has shape {truth.shape}, the measurement {y.shape}")
    x0 = options.get("x0")
    if x0 is not None:
        x0 = finite_image("x0", x0)
        if x0.shape != y.shape:
            raise ClfzaError(f"x0 has shape {x0.shape}, the measurement {y.shape}")
        x0 = channels_first(x0)
    pilot = options.get("pilot", False)
    if not isinstance(pilot, (bool, np.bool_)):
        raise ClfzaError(f"pilot must be True or False, got {pilot!r}")
    if pilot and x0 is None:
        raise ClfzaError("pilot=True marks x0 as a pilot estimate: give x0 with it")
    return truth, x0


def _constant_result(y: np.ndarray, info: ReconInfo, t_all: float) -> Reconstruction:
    """Nothing survives the DC removal: a zero image and a warning."""
    warnings.warn("the measurement is constant (all zero after removing the DC): it holds "
                  "no image information; returning a zero image", ClfzaWarning, stacklevel=4)
    info.device = "none"
    info.dtype = "float64"
    info.stop_reason = "constant_measurement"
    info.timings = {"compile": 0.0, "plan": 0.0, "solve": 0.0,
                    "total": time.perf_counter() - t_all}
    return Reconstruction(np.zeros_like(y), info)


def run_solver(y, camera, method, *, backend: str = DEFAULT_BACKEND, device=None,
               dtype=np.float32,
               fft: str = "auto", model: str = "auto", psf=None, margin: int = 0,
               **options):
    """Run an iterative method on a validated DC-free observation ``y`` (H, W) or (H, W, 3).

    ``model`` (see :func:`clfza.models._exact.choose_model`): ``"auto"``, ``"tf"`` (Eq. 17),
    ``"exact"`` (the finite-aperture, cropped-sensor convolution of :mod:`clfza.models._exact`, with
    ``psf`` as its kernel when given, on a grid with ``margin`` extra object pixels), or
    ``"padded"`` (numpy reference only). On the exact model ``tau`` keeps its meaning (the
    zone term has unit gain as in Eq. 17); the solvers run on the normalised operator
    ``K / s`` with ``tau / s^2`` and report the objective in the user's units.

    Returns
    -------
    clfza.solvers._result.Reconstruction
        ``image`` (float64, the shape of ``y``) and ``info`` (iterations, timings split into
        compile/plan/solve, objective history, stop reason, device, checkpoints).
    """

    if method not in REGISTRY:
        raise ClfzaError(f"unknown method {method!r}; available: {METHODS}")
    t_all = time.perf_counter()
    kind, why = method_model(camera, model, method, options, psf=psf is not None, y=y)

    options, auto_tau = split_auto(options, method, kind)
    cls = solver_class(method, kind)
    opts = cls.Options.from_options({k: v for k, v in options.items()
                                     if k not in RUN_CONTROLS},
                                    method=method, exact=kind == "exact")
    cls = prior_solver(cls, opts)  # reg="dncnn": plug-and-play ADMM (issue 38)
    y = np.asarray(y, dtype=np.float64)
    yc = channels_first(y)
    chans = yc.shape[0]
    truth, x0 = _run_inputs(options, y)
    info = ReconInfo(method=method, backend=backend, device="", dtype="",
                     params={**opts.params(), "model": kind})
    info.notes.append(f"model: {kind} ({why})")
    if method == "twist":
        info.mode = opts.mode
    flat = [np.ptp(yc[c]) == 0 for c in range(chans)]
    if all(flat):
        return _constant_result(y, info, t_all)
    joint = opts.colour == "joint" and chans > 1
    bcam, bpsf, ys = _data_model(camera, kind, opts, psf, margin, yc, info)
    B = get_backend(backend, bcam, nc=chans if joint else 1, device=device, dtype=dtype,
                    fft=fft, model=kind, psf=bpsf, margin=margin)
    if (cls is AdmmCropSolver and opts.algorithm == "split"
            and "iters" not in opts.given()):
        # a measured PSF's default (clfza.solvers._admm_crop.default_iterations)
        opts.iters = info.params["iters"] = default_iterations(B.exact)
    scale2 = B.data_scale ** 2  # exact model: solve with K/s, tau/s^2
    ctx = SolveContext(camera, scale2, auto_tau, pilot_start=bool(options.get("pilot")))
    to_solver_units(opts, B.dtype, scale2)
    grid = describe_backend(B, info)
    groups = [list(range(chans))] if joint else [[c] for c in range(chans)]
    out = np.empty_like(yc)
    solve = over = search = 0.0
    for grp in groups:
        if len(groups) > 1 and all(flat[c] for c in grp):
            out[grp] = 0.0
            info.notes.append(f"channel {grp[0]} is constant: returned zeros")
            continue
        res, mon = _solve_group(B, ctx, cls, opts, (ys[grp], yc[grp]), grp, len(groups) > 1,
                                x0, truth, options, grid, info)
        img = check_finite(method, res.image if grid is None else grid.crop(res.image),
                           opts.tau)
        out[grp] = img
        solve += res.solve_s
        search += res.search_s
        over += mon.overhead
        record_group(info, res, mon, scale2, len(groups) > 1)
        record_tau(info, res)
    info.ffts = B.ffts
    info.timings["solve"] = solve
    if auto_tau:
        info.timings["tau_search"] = search  # tau="auto": before the solve, not in "solve"
    info.timings["checkpoint_overhead"] = over
    info.timings["total"] = time.perf_counter() - t_all
    image = out[0] if y.ndim == 2 else np.moveaxis(out, 0, -1)
    return Reconstruction(image, info)


TAU_RANGE_F32 = (1e-30, 1e30)  # normalised tau a float32 solve can carry (with headroom)


def to_solver_units(opts, dtype, scale2: float) -> None:
    """``tau`` (and a TV weight given) in the solver's normalised units, range-checked."""
    opts.tau /= scale2
    if getattr(opts, "weight", None) is not None:
        opts.weight /= scale2
    _check_tau_range(opts.tau, dtype, scale2)


def _check_tau_range(tau: float, dtype, scale2: float) -> None:
    """A one-line error where ``tau`` in the solver's normalised units is out of float32's
    range (a model or PSF scaled far from one with tau in the user's units): the solve would
    end in non-finite values."""
    lo, hi = TAU_RANGE_F32
    if np.dtype(dtype) == np.float32 and tau > 0 and not lo <= tau <= hi:
        raise ClfzaError(f"tau is {tau:.3g} in the solver's normalised units (the operator's "
                         f"norm^2 is {scale2:.3g}), outside float32's usable range "
                         f"[{lo:g}, {hi:g}]: give tau on the scale of the model (or scale the "
                         f"PSF towards unit sum), or use dtype=float64")


def _data_model(camera, kind: str, opts, psf, margin: int, yc: np.ndarray, info: ReconInfo):
    """The camera, kernel and frames (channels first) the backend sees: as given, or on the
    exact model with the data term's box high-pass (:mod:`clfza.models._highpass`, ADMM's
    ``highpass``), the high-passed model of the sensor's interior and the frames through it."""
    if kind != "exact" or getattr(opts, "highpass", 0) == 0:  # off, or not ADMM's options
        return camera, psf, yc
    k = opts.highpass

    # off without the support constraint: see clfza.models._highpass.default_halfwidth
    if k is None:
        k = opts.highpass = default_halfwidth(camera, psf) if opts.support else 0
        info.params["highpass"] = k
        if k == 0:
            return camera, psf, yc
    model = highpass_model(exact_model(camera, psf, margin), k)
    info.notes.append(f"exact model: the data term through a {2 * k + 1}-pixel box high-pass "
                      f"(highpass={k}): the frame's constant and linear ramps and its {k}-pixel "
                      f"border are not data; the image covers the whole sensor")
    return camera.with_shape(model.sensor), model, highpass_frame(yc, k)


def describe_backend(B, info: ReconInfo):
    """Device, precision, set-up timings and the exact model's grid in the info record;
    returns the image's window on the model grid (None on the transfer-function model)."""
    grid = None
    if B.exact is not None:
        grid = B.exact.image_geom
        info.stats["model_grid"] = list(grid.grid)
        info.stats["operator_norm"] = B.data_scale
    info.device = B.device
    info.dtype = B.dtype.name
    info.timings["compile"] = B.compile_s
    info.timings["plan"] = B.plan_s
    return grid


def record_group(info: ReconInfo, res, mon: Monitor, scale2: float, several: bool) -> None:
    """One channel group's run into the info record (objective in the user's units; one
    history per group when there are several, and the solver's statistics of each group in
    ``info.stats["channels"]``, else in ``info.stats`` itself)."""
    info.iterations = max(info.iterations, res.iterations)
    info.stop_reason = res.stop_reason
    hist = [f * scale2 for f in res.objective]
    info.objective = info.objective + [hist] if several else hist
    info.checkpoints += mon.records
    info.evaluations += res.evaluations
    if several:
        info.stats.setdefault("channels", []).append(dict(res.stats))
    else:
        info.stats.update(res.stats)
    info.notes += res.notes


def _solve_group(B, ctx: SolveContext, cls, opts, yg: tuple, grp: list[int], several: bool,
                 x0, truth, controls: dict, grid, info: ReconInfo):
    """One channel (or the joint channels) through the driver: measurement (``yg``: the
    frames the backend sees and the frames as given, which ``ctx.group`` takes), start point,
    monitor; returns the driver's result (with the host image) and the monitor."""

    def crop(a: np.ndarray) -> np.ndarray:
        return a if grid is None else grid.crop(a)

    tp = time.perf_counter()
    B.set_measurement(yg[0])
    ctx.group = channel_group(B, ctx, *yg)
    if x0 is not None:
        x0d = B.from_host(x0[grp] if grid is None else grid.embed(x0[grp]))
    else:  # Wiener for FISTA/ADMM, K^T y for TwIST (clfza.solvers._tau.default_start)
        x0d, note = default_start(B, ctx, cls.method)
        if note and note not in info.notes:
            info.notes.append(note)
    info.timings["plan"] += time.perf_counter() - tp
    tr = None
    if truth is not None:
        tc = channels_first(truth)
        tr = tc[grp][0] if len(grp) == 1 else np.moveaxis(tc[grp], 0, -1)
    mon = Monitor(B, controls.get("checkpoints"), controls.get("callback"), tr,
                  channel=grp[0] if several else None,
                  to_image=lambda a: _image_of(crop(a)), scale=ctx.scale2)
    res = run_group(cls, B, opts, mon, x0d, x0 is None, ctx)
    res.image = B.to_host(res.x)
    return res, mon
