"""The one-call public API: ``clfza.reconstruct(measurement, camera, method=..., ...)``.

``method`` is a method's name with its options as keywords (``"admm", tau=0.01``) or an
options instance (``clfza.ADMM(tau=0.01)``), turned into the same keywords here
(:func:`method_and_options`) before the solvers see them.
"""

from __future__ import annotations

import time

import numpy as np

from ..backends import BACKENDS, get_backend
from ..camera import Camera
from ..cl import DeviceArray, get_runtime
from ..errors import ClfzaError, finite_image
from ..io import check_reconstruct, check_values
from ..models import (
    PSF,
    ExactModel,
    NumpyOperator,
    OpenCLOperator,
    box_bin,
    camera_model,
    crop_to_support,
    load_psf,
    scale_psf,
)
from ..solvers import (
    AUTO_BY_DEFAULT,
    DEFAULT_BACKEND,
    DEFAULT_METHOD,
    METHODS,
    RUN_CONTROLS,
    MethodOptions,
    ReconInfo,
    Reconstruction,
    colour_energy_support,
    energy_support,
    frame_energy_support,
    method_model,
    options_class,
    resolve_method,
    run_solver,
    run_solver_batch,
    tau_auto_note,
)
from . import _device_choice as device_choice
from ._balance import DEFAULT_WHITE_BALANCE, check_white_balance, white_balance_image

device_choice.install()  # the default OpenCL device is chosen by measurement (a short solve)

__all__ = ["BACKENDS", "ReconInfo", "Reconstruction", "check_measurement", "method_and_options",
           "reconstruct"]


def check_measurement(y, camera: Camera) -> np.ndarray:
    """Validate a DC-free observation against the camera: shape, dtype, finiteness."""
    a = finite_image("measurement", y)
    if a.shape[:2] != tuple(camera.shape):
        raise ClfzaError(f"measurement has shape {a.shape[:2]}, but the camera grid is "
                         f"{tuple(camera.shape)} (rows, cols)")
    if a.ndim == 3 and a.shape[2] not in (1, 3):
        raise ClfzaError(f"a colour measurement must have 3 channels, got {a.shape[2]}")
    return a


# Back-propagation ``K^T y`` (Eqs. 11-12) is defined once per operator; the helpers below only
# choose the operator and loop over colour channels: clfza.models._transfer.NumpyOperator.adjoint
# (the float64 specification, clfza.models._transfer.back_propagate), its device twin
# clfza.models._device_operator.OpenCLOperator.adjoint (tested against it; cheaper to set up than a
# solver backend, which a one-shot BP does not need), and for the exact model its backends'
# Backend.b (the K^T y the solvers start from). clfza.focus.FastBP is the same K^T y at many depths.
def _per_channel(y: np.ndarray, bp) -> np.ndarray:
    """``bp`` applied to ``y`` (H, W), or to each channel of ``y`` (H, W, C), stacked back."""
    if y.ndim == 2:
        return bp(y)
    return np.stack([bp(y[..., c]) for c in range(y.shape[2])], axis=-1)


def _bp_numpy(y: np.ndarray, camera: Camera, model: str) -> np.ndarray:
    """``K^T y`` of the TF or padded model on the host (float64, the specification)."""

    return _per_channel(y, NumpyOperator(camera, model, warn=False).adjoint)


def _bp_opencl(y: np.ndarray, camera: Camera, device, dtype, fft: str, info: ReconInfo
               ) -> np.ndarray:
    """``K^T y`` of the TF model on an OpenCL device; records the plan and solve times."""

    t0 = time.perf_counter()
    rt = get_runtime(device)
    op = OpenCLOperator(camera, rt, dtype=dtype, fft=fft, warn=False)
    rt.finish()
    info.timings["plan"] = time.perf_counter() - t0
    info.device = rt.info.name
    t1 = time.perf_counter()
    xd = DeviceArray.empty(rt, camera.shape, op.dtype)
    out = op.empty()

    def bp(ch: np.ndarray) -> np.ndarray:
        xd.set(ch)
        return op.adjoint(xd, out).get().astype(np.float64)

    img = _per_channel(y, bp)
    info.timings["solve"] = time.perf_counter() - t1
    return img


def _bp_exact(y: np.ndarray, camera: Camera, backend: str, device, dtype, fft: str, psf,
              margin: int, info: ReconInfo) -> np.ndarray:
    """``K^T y`` of the exact model (its backend's :attr:`~clfza.backends.Backend.b`), on its
    sensor window (per channel)."""

    B = get_backend(backend, camera, device=device, dtype=dtype, fft=fft, model="exact",
                    psf=psf, margin=margin)
    info.device = B.device

    def bp(ch: np.ndarray) -> np.ndarray:
        # the device sees y / (rms ||K||) * ||K||: order one whatever the units of the frame
        # and of the PSF (a PSF scaled by 1e-100 overflowed float32 here); back in float64
        rms = float(np.sqrt(np.mean((ch - ch.mean()) ** 2)))
        r = rms if rms > 0 and np.isfinite(rms) else 1.0
        B.set_measurement((ch * (B.data_scale / r))[None])
        return B.geom.crop(B.to_host(B.b))[0].astype(np.float64) * r

    return _per_channel(y, bp)


# Default tau of measured-PSF solves (unit-sum PSF, RMS-normalised frame) for the methods whose
# tau is not "auto" by default (AUTO_BY_DEFAULT: ADMM's is "auto" here too, the rule of
# clfza.solvers._tau_exact), chosen with ADMM on noise-free FZA-aperture captures
# (bench/bench_lensless.py; measured: docs/measurements.md, clfza.reconstruction._reconstruct).
PSF_DEFAULT_TAU = 3e-5
# ADMM's v-split penalty for measured PSFs, fixed. In these units the residual-balancing start
# of clfza.solvers._admm_crop overshoots and its iterates peak, then fall; fixed at 0.02 they
# rise steadily (measured: docs/measurements.md, clfza.reconstruction._reconstruct).
PSF_ADMM_MU1 = 0.02


#: a one-channel measured-PSF frame whose shorter side has at least this many pixels gets its
#: ``tau="auto"`` noise from a coarse pilot (:func:`_coarse_pilot`), not full-size passes
COARSE_PILOT_MIN_SIDE = 384
COARSE_PILOT_BIN = 2  # the coarse pilot's binning, ...
COARSE_PILOT_BIN_LARGE = 3  # ... or this where the binned frame keeps enough pixels:
COARSE_PILOT_MIN_COARSE_SIDE = 160  # a shorter side of at least this many
COARSE_PILOT_ITERS = 50  # its final solve's iterations (after its own pilot passes)


def coarse_pilot_bin(shape: tuple[int, ...]) -> int:
    """The coarse pilot's binning (:func:`_coarse_pilot`) for a frame of ``shape``:
    ``COARSE_PILOT_BIN_LARGE`` where the binned frame's shorter side keeps at least
    ``COARSE_PILOT_MIN_COARSE_SIDE`` pixels, else ``COARSE_PILOT_BIN`` (chosen by
    measurement on 488^2 and 384^2 frames: docs/measurements.md,
    clfza.reconstruction._reconstruct).

    >>> coarse_pilot_bin((488, 488)), coarse_pilot_bin((384, 384))
    (3, 2)
    """
    side = min(shape[:2])
    if side // COARSE_PILOT_BIN_LARGE >= COARSE_PILOT_MIN_COARSE_SIDE:
        return COARSE_PILOT_BIN_LARGE
    return COARSE_PILOT_BIN


def _coarse_pilot(y: np.ndarray, camera: Camera, method: str, psf: np.ndarray, kw: dict
                  ) -> tuple[dict, dict | None]:
    """A measured-PSF ADMM solve's start and noise from a coarse solve (coarse to fine).

    The frame and the PSF binned (:func:`coarse_pilot_bin`: block means and sums; a remainder
    row or column cropped), solved by the default route (its own pilot passes, then
    ``COARSE_PILOT_ITERS`` iterations), the image upsampled (bilinear) to the frame: the full
    size solve starts from it and ``tau="auto"`` reads the noise from its residual (the run
    control ``pilot``) in place of pilot passes at full size, at a fraction of their cost.
    Only where the coarse solve found noise (its rule ``"noise"``); a frame it calls noise-free
    runs the full-size route unchanged. For ADMM with ``tau="auto"``, one channel, no start
    given, frames of ``COARSE_PILOT_MIN_SIDE`` pixels a side and more (the measurement:
    docs/measurements.md, clfza.reconstruction._reconstruct). Returns the keywords of the
    full-size solve and the coarse solve's record (None where it did not run or was not
    used)."""
    auto = kw.get("tau") in (None, "auto") and kw.get("weight") is None
    if (method != "admm" or y.ndim != 2 or min(y.shape) < COARSE_PILOT_MIN_SIDE or not auto
            or kw.get("x0") is not None or kw.get("model", "auto") == "padded"
            or kw.get("reg", "tv") != "tv" or kw.get("algorithm", "split") != "split"):
        return kw, None
    from skimage.transform import resize  # lazy: skimage's import is slow

    t0 = time.perf_counter()
    b = coarse_pilot_bin(y.shape)
    hb, wb = y.shape[0] // b, y.shape[1] // b
    yb = box_bin(y[:hb * b, :wb * b], b)
    pb = load_psf(psf, bin=b).array
    coarse_kw = {k: v for k, v in kw.items() if k not in RUN_CONTROLS}
    coarse_kw.update(iters=COARSE_PILOT_ITERS, min_iters=1)
    coarse = _psf_solve(yb, camera.with_shape((hb, wb), camera.pitch * b), method, pb,
                        coarse_pilot=False, **coarse_kw)
    a = coarse.info.stats.get("tau_auto") or {}
    record = {"bin": b, "shape": [hb, wb], "iterations": coarse.info.iterations,
              "rule": a.get("rule"), "tau": a.get("tau"), "seconds": 0.0, "used": False}
    if a.get("rule") == "noise":
        up = resize(coarse.image, (hb * b, wb * b), order=1, mode="edge", anti_aliasing=False)
        up = np.pad(up, ((0, y.shape[0] - hb * b), (0, y.shape[1] - wb * b)), mode="edge")
        kw = {**kw, "x0": up, "pilot": True}
        record["used"] = True
    record["seconds"] = time.perf_counter() - t0
    return kw, record


def _record_coarse(rec: Reconstruction, coarse: dict) -> None:
    """A coarse pilot's record (:func:`_coarse_pilot`), its time and its note, on a solve's."""
    rec.info.stats["coarse_pilot"] = coarse
    for k in ("tau_search", "total"):
        rec.info.timings[k] = rec.info.timings.get(k, 0.0) + coarse["seconds"]
    if coarse["used"]:
        rec.info.notes.append(
            f"coarse pilot: the frame and the PSF binned {coarse['bin']}x "
            f"({coarse['shape'][0]}x{coarse['shape'][1]}) and solved ({coarse['iterations']} "
            f"iterations after its pilot passes, {coarse['seconds']:.2f} s); its image, "
            f"upsampled, is the start, and its residual gave the noise")
    else:
        rec.info.notes.append(
            f"coarse pilot: the frame binned {coarse['bin']}x was called {coarse['rule']} "
            f"there ({coarse['seconds']:.2f} s), so the full-size pilot passes ran")


def _psf_solve(y: np.ndarray, camera: Camera, method: str, psf: np.ndarray, *,
               coarse_pilot: bool = True, **kw) -> Reconstruction:
    """An iterative solve with a measured PSF, made scale-free: a PSF's scale (exposure of
    the point-source capture) and the frame's scale are arbitrary, and ``tau`` trades the
    data term against TV in their units. The solver sees the PSF normalised to unit sum and
    the frame divided by its RMS (about its mean); the image is scaled back, so it is in the
    units of ``psf`` and ``y`` as given. Without a ``tau`` (or ``weight``) ADMM's is
    ``"auto"`` (:data:`clfza.solvers.AUTO_BY_DEFAULT`: the noise read from the frame, as on the
    zone-plate models), the other methods' :data:`PSF_DEFAULT_TAU` (in those units)."""

    total = float(psf.sum())
    if not np.isfinite(total) or total <= 0:
        raise ClfzaError(f"the PSF must have a positive sum (it is light), got {total:.3g}")
    rms = float(np.sqrt(np.mean((y - y.mean(axis=(0, 1))) ** 2)))
    rms = rms if rms > 0 else 1.0
    if not (method in AUTO_BY_DEFAULT and kw.get("model", "auto") != "padded"):
        kw.setdefault("tau", PSF_DEFAULT_TAU)  # (ADMM's None is "auto": split_auto)
    if method == "admm":  # see PSF_ADMM_MU1
        kw.setdefault("mu1", PSF_ADMM_MU1)
        kw.setdefault("adapt", False)
        # with mu1 fixed the iterates rise steadily, and the mean of the iterates lags them
        # (measured: docs/measurements.md, clfza.reconstruction._reconstruct)
        kw.setdefault("average", False)
    coarse = None
    if coarse_pilot:
        kw, coarse = _coarse_pilot(y, camera, method, psf, kw)
    if kw.get("x0") is not None:  # a start in the units given, as the image
        kw["x0"] = np.asarray(kw["x0"], np.float64) * (total / rms)
    rec = run_solver(y / rms, camera, method, psf=psf / total, **kw)
    rec.image = rec.image * (rms / total)
    if coarse is not None:
        _record_coarse(rec, coarse)
    rec.info.notes.append(f"measured PSF: solved with the PSF normalised to unit sum and the "
                          f"frame divided by its RMS ({rms:.4g}); tau is in those units "
                          f"(scale-free), the image in the units given")
    return rec


EXACT_DATA_RMS = 0.012
"""The exact model's iterative solves see the frame scaled so that ``y / ||K||`` has this RMS
(``tau``, ``weight`` and ``x0`` with it, so the minimiser is the same in the user's units, and
``tau="auto"`` is scale-equivariant). ADMM's penalties follow ``tau``, so its path, unlike its
minimiser, depended on the frame's units (a 12-bit frame read in DN, say); scaled here, it is
the same at every scale. The value was chosen on the experiment preset's noisy planner frames
(``tau="auto"``; measured: docs/measurements.md, clfza.reconstruction._reconstruct)."""


def _solves_exact(camera: Camera, method: str, model, psf, options: dict, y=None) -> bool:

    return method_model(camera, model if isinstance(model, str) else "auto", method, options,
                        psf=psf is not None, y=y)[0] == "exact"


def _exact_solve(y: np.ndarray, camera: Camera, method: str, **kw) -> Reconstruction:
    """An iterative solve on the exact model with the frame scaled to
    :data:`EXACT_DATA_RMS` (``tau``, ``weight`` and ``x0`` with it); the image, ``tau`` and
    the objectives are returned in the user's units."""

    psf = kw.get("psf")
    norm = psf.norm if isinstance(psf, ExactModel) else camera_model(
        camera, margin=kw.get("margin", 0)).norm
    rms = float(np.sqrt(np.mean((y - y.mean(axis=(0, 1))) ** 2))) / norm
    c = rms / EXACT_DATA_RMS if rms > 0 and np.isfinite(rms) else 1.0
    if kw.get("tau") is None and kw.get("weight") is None and method not in AUTO_BY_DEFAULT:
        kw["tau"] = options_class(method, "exact").tau  # the default, in user units
    for key in ("tau", "weight", "x0"):
        v = kw.get(key)
        if v is not None and not isinstance(v, str):
            kw[key] = np.asarray(v, np.float64) / c if key == "x0" else float(v) / c
    callback = kw.get("callback")
    if callback is not None:  # the records in the user's units (a discrepancy stop reads them)
        kw["callback"] = lambda record: callback(_in_user_units(record, c))
    rec = run_solver(y / c, camera, method, **kw)
    info = rec.info
    info.checkpoints = [_in_user_units(r, c) for r in info.checkpoints]
    rec.image = rec.image * c
    for key in ("tau", "weight"):  # one value, or one per colour channel solved separately
        v = info.params.get(key)
        if isinstance(v, (int, float)):
            info.params[key] = float(v) * c
        elif isinstance(v, list):
            info.params[key] = [float(t) * c for t in v]
    info.objective = [[g * c * c for g in f] if isinstance(f, list) else f * c * c
                      for f in info.objective]  # one history per channel group, or one
    for key in ("objective_mean", "objective_last"):
        if key in info.stats:
            info.stats[key] *= c * c
    autos = _tau_records(info)
    for auto in autos:
        for key in ("tau", "tau0", "sigma", "sigma_frame"):  # in the units of y and the image
            if isinstance(auto.get(key), (int, float)):
                auto[key] *= c
        if auto.get("criterion") == "residual_noise":  # pilot passes: (tau, sigma, ratio)
            auto["stages"] = [[t * c, sg * c, wr] for t, sg, wr in auto.get("stages", [])]
    if autos:  # their notes, written in the divided frame's units, again in the units given
        records = iter(autos)
        info.notes = [tau_auto_note(next(records)) if n.startswith("tau=auto:") else n
                      for n in info.notes]
    info.stats["data_scale_factor"] = c
    info.notes.append(f"exact model: solved on the frame divided by {c:.4g} (RMS "
                      f"{EXACT_DATA_RMS:g}; ADMM's path depends on the data's units), tau "
                      f"with it; image, tau and objectives are in the units given")
    return rec


def _tau_records(info) -> list[dict]:
    """The ``tau="auto"`` records of a solve, one per channel group in the order of their notes:
    each colour channel's where they were solved separately (``info.stats["channels"]``; the
    last is also ``info.stats["tau_auto"]``), else the one in ``info.stats``."""
    chans = [ch["tau_auto"] for ch in info.stats.get("channels", [])
             if isinstance(ch.get("tau_auto"), dict)]
    if chans:
        return chans
    auto = info.stats.get("tau_auto")
    return [auto] if isinstance(auto, dict) else []


def _in_user_units(record: dict, c: float) -> dict:
    """A monitor record of a solve on the frame divided by ``c`` in the frame's own units:
    the objective and the data term (``1/2 ||y - K x||^2``, ``||y - K x||^2``) times ``c^2``
    (PSNR/SSIM/MSE are after the affine fit to the truth, so unit-free)."""
    out = dict(record)
    for key in ("objective", "data", "residual_norm2"):
        if isinstance(out.get(key), (int, float)):
            out[key] = float(out[key]) * c * c
    return out


def _per_channel_psf(y: np.ndarray, camera: Camera, method: str, psf: np.ndarray, **kw
                     ) -> Reconstruction:
    """A colour PSF: each channel of ``y`` with its own PSF channel."""
    if y.ndim != 3 or y.shape[2] != psf.shape[2]:
        raise ClfzaError(f"a colour PSF {psf.shape} needs a colour measurement with "
                         f"{psf.shape[2]} channels, got shape {y.shape}")
    # the per-pixel run controls go channel by channel
    per = {k: kw.pop(k) for k in ("x0", "truth") if kw.get(k) is not None}
    for k, v in per.items():
        if np.shape(v) != y.shape:
            raise ClfzaError(f"{k} has shape {np.shape(v)}, the measurement {y.shape}")
    x0 = per.get("x0")
    nc = psf.shape[2]
    # coarse pilots (where they apply) for every channel first: the sparse-scene decision is
    # then the frame's from their images, before any full-size solve
    pre = [(kw, None)] * nc if x0 is not None else [
        _coarse_pilot(y[..., c], camera, method, psf[..., c], kw) for c in range(nc)]
    used = [r is not None and r["used"] for _, r in pre]
    decided = None
    if all(used):
        decided = float(np.mean([energy_support(k["x0"][None]) for k, _ in pre]))

    def channel(c: int) -> Reconstruction:
        start = {k: np.asarray(v)[..., c] for k, v in per.items()}
        # the keywords _coarse_pilot returned: with its start where it was used, else kw
        rec = reconstruct(y[..., c], camera, method, psf=psf[..., c], **pre[c][0], **start)
        if pre[c][1] is not None:
            _record_coarse(rec, pre[c][1])
        return rec

    if decided is not None:
        with frame_energy_support(decided):
            parts = [channel(c) for c in range(nc)]
    else:
        parts = [channel(c) for c in range(nc)]
    # tau="auto": whether the scene is sparse is the frame's decision, not a channel's
    # (clfza.solvers.colour_energy_support); a channel that decided otherwise alone is solved
    # again with the frame's decision
    joint = None if decided is not None else colour_energy_support(
        [p.info.stats.get("tau_auto") for p in parts])
    if joint is not None:
        support, again = joint
        with frame_energy_support(support):
            for c in again:
                parts[c] = channel(c)
        own = ", ".join(f"{p.info.stats['tau_auto']['energy_support']:.3g}" for p in parts)
    info = parts[0].info
    # every channel's record, as a colour frame's channels solved one by one record them
    # (clfza.solvers.record_group): stats per channel, the objective histories, tau per
    # channel where they differ, the notes of all
    info.stats = {"channels": [dict(p.info.stats) for p in parts]}
    info.objective = [p.info.objective for p in parts]
    info.iterations = max(p.info.iterations for p in parts)
    taus = [p.info.params.get("tau") for p in parts]
    if any(t != taus[0] for t in taus[1:]):
        info.params["tau"] = taus
    for p in parts[1:]:
        info.notes += [n for n in p.info.notes if n not in info.notes]
    info.notes.append("colour PSF: each channel reconstructed with its own PSF")
    if joint is not None:
        info.notes.append(
            f"tau=auto: the sparse-scene decision taken on the channels' mean energy support "
            f"{support:.3g} (per channel {own}); channel(s) "
            f"{', '.join(map(str, again))} decided otherwise alone and were solved again")
        info.stats["colour_energy_support"] = {"mean": support, "solved_again": again}
    info.timings = {k: sum(p.info.timings.get(k, 0.0) for p in parts)
                    for k in parts[0].info.timings}
    return Reconstruction(np.stack([p.image for p in parts], axis=-1), info)


def method_of(options: MethodOptions) -> str:
    """The method whose options class ``options`` is an instance of (the nearest in its
    class's ancestry: the exact model's ADMM options are ADMM's)."""
    mro = type(options).__mro__
    best, rank = None, len(mro)
    for m in METHODS:
        if m == "bp":
            continue
        cls = options_class(m)
        if isinstance(options, cls) and mro.index(cls) < rank:
            best, rank = m, mro.index(cls)
    if best is None:
        raise ClfzaError(f"{type(options).__name__} is not the options of one method; use "
                         "clfza.ADMM, clfza.FISTA, clfza.TwIST or clfza.Wiener")
    return best


def method_and_options(method, options: dict) -> tuple[str, dict]:
    """``(name, keyword options)`` of ``method``: a method's name with ``options`` as they
    are, or an options instance (``clfza.ADMM(tau=0.01)``) whose given fields
    (:meth:`~clfza.solvers.MethodOptions.given`) become the options. With an instance,
    ``options`` may hold the run controls (``truth``, ``checkpoints``, ``callback``, ``x0``)
    and nothing else: an option given twice, or in two places, is an error.

    Examples
    --------
    >>> from clfza.solvers import AdmmOptions
    >>> method_and_options(AdmmOptions(tau=0.01, iters=100), {})
    ('admm', {'tau': 0.01, 'iters': 100})
    >>> method_and_options("admm", {"tau": 0.01})
    ('admm', {'tau': 0.01})
    """
    if isinstance(method, str):
        return method, options
    if not isinstance(method, MethodOptions):
        raise ClfzaError(f"method must be a method name {METHODS} or an options instance "
                         f"(clfza.ADMM, clfza.FISTA, clfza.TwIST, clfza.Wiener), got "
                         f"{type(method).__name__} {method!r}")
    name = method_of(method)
    mixed = sorted(set(options) - RUN_CONTROLS)
    if mixed:
        raise ClfzaError(f"give {name}'s options in the {type(method).__name__} instance or as "
                         f"keywords with method={name!r}, not both: got keyword(s) {mixed} "
                         f"beside {method!r}")
    return name, {**method.given(), **options}


def reconstruct(measurement, camera: Camera, method: str | MethodOptions = DEFAULT_METHOD, *,
                backend: str = DEFAULT_BACKEND, device: str | None = None, dtype=np.float32,
                fft: str = "auto", model: str = "auto", psf=None, margin: int = 0,
                psf_scale: float | str | None = None,
                white_balance: str = DEFAULT_WHITE_BALANCE, **options) -> Reconstruction:
    """Reconstruct the sensor-plane image from a DC-free observation ``y``.

    Parameters
    ----------
    measurement : array (H, W) or (H, W, 3), or a stack (F, H, W) or (F, H, W, 3)
        The DC-free observation in the units of ``K`` (see :mod:`clfza.simulation`;
        :func:`clfza.io.frame_to_measurement` turns a raw frame into one). A stack of frames
        of the camera is solved as one batch where the method allows it
        (:func:`clfza.solvers.run_solver_batch`: ADMM, FISTA (TV) and TwIST (TV) on the
        transfer-function model, ``tau`` one value, one per frame or ``"auto"``), else frame
        by frame.
    camera : Camera
        The camera; ``measurement`` must have its shape.
    method : str or options instance
        ``"auto"`` (the default, :data:`clfza.solvers.DEFAULT_METHOD`: ADMM with
        ``tau="auto"`` on the forward model the camera and the frame's noise call for,
        :func:`clfza.solvers.resolve_method`; the record's first note says so); ``"bp"``
        (back-propagation, Eqs. 11-12); ``"twist"`` (the paper's TwIST, Eqs. 19-21;
        ``mode="paper"`` reproduces the authors' run, ``mode="efficient"`` warm-starts the TV
        dual; ``reg="tv"`` or ``"l1"``); ``"fista"`` (monotone FISTA with an FGP TV prox);
        ``"admm"`` (ADMM-TV with an exact Fourier-space update; the fastest); ``"wiener"``
        (the direct Tikhonov solve). See :mod:`clfza.solvers` for the options (``tau``,
        ``iters``, ``tol``, ``nonneg``, ``colour``, ...). Or an options instance,
        :class:`clfza.ADMM`, :class:`clfza.FISTA`, :class:`clfza.TwIST` or
        :class:`clfza.Wiener`, whose signature lists every option with its default: the
        options it was given are the method's options (the others keep the method's
        defaults, as with the string form); option keywords beside an instance are an error
        (the run controls ``truth``, ``checkpoints``, ``callback``, ``x0`` are not options
        and may be given). Back-propagation has no options and no options class.
    backend : {"opencl", "numpy"}
        OpenCL (float32 by default; the default, :data:`clfza.solvers.DEFAULT_BACKEND`) or
        the float64 numpy reference.
    device : str, optional
        OpenCL device spec (see :func:`clfza.cl.get_runtime`).
    dtype : numpy dtype
        Working precision of the OpenCL backend.
    fft : str
        FFT policy of the OpenCL backend ("auto", "host", "device", "vkfft").
    model : {"auto", "tf", "exact", "padded"}
        Forward model (:func:`clfza.models._exact.choose_model`): ``"auto"`` runs the exact
        finite-aperture model (:mod:`clfza.models._exact`) where the transfer-function model of Eq.
        17 is not the camera's map (finite aperture, off-centre mask, far from critical sampling,
        a measured PSF) and Eq. 17 elsewhere; the info record's notes say which and why.
        ``"padded"``: the exact model for objects on the sensor (numpy only).
    psf : array (H, W) or (H, W, 3), clfza.models._psf.PSF or clfza.models._exact.ExactModel,
    optional
        A measured point-spread function on the frame's pitch, centred (see
        :func:`clfza.models._psf.load_psf`): the operator instead of the camera's mask; colour PSFs
        reconstruct per channel. An :class:`~clfza.models._exact.ExactModel` is used as it is (e.g.
        :func:`clfza.models._exact.binned_model` for a pixel-binned frame).
    margin : int
        Exact model: object-plane pixels around the sensor that are modelled (scenes larger
        than the sensor's footprint); 0 keeps the object on the sensor.
    psf_scale : float, "auto" or None
        A measured ``psf`` captured at another depth than the scene's: magnify it by this
        factor about its centre (:func:`clfza.models.scale_psf`; a point at depth ``z``
        casts a shadow magnified by ``1 + z2/z``), or ``"auto"``: find the factor from the
        frame (:func:`clfza.focus.find_psf_scale` over its default range,
        :func:`clfza.focus.default_scale_range`). The record says what was
        applied (``info.params["psf_scale"]``, the search in ``info.stats["psf_scale"]``).
    white_balance : {"psf", "grey", "none"}
        Colour images only (:mod:`clfza.reconstruction._balance`): ``"psf"`` (default)
        divides out the sensor's channel gains that a colour PSF's channel sums give (a PSF
        from :func:`clfza.models.load_psf` keeps them in ``info["channel_sums"]``), or,
        without a colour PSF, balances by grey-world; ``"grey"``: grey-world (the channels'
        means made equal); ``"none"``: the sensor's colours. The gains divided out are in
        ``info.stats["white_balance"]``.
    **options
        Method parameters (``tau``, ``iters``, ...) with a method's name; the run controls
        (``truth``, ``checkpoints``, ``callback``, ``x0``) with either form.

    Returns
    -------
    Reconstruction
        ``.image`` (float64) and ``.info``; unpacks as ``image, info``. Of a stack: the
        images ``(F, H, W[, 3])`` and a list of the frames' records.

    Examples
    --------
    >>> import clfza
    >>> cam = clfza.Camera.preset("simulation").with_shape((64, 64))
    >>> y = clfza.simulate(np.eye(64), cam, sensor_plane=True).y
    >>> image, info = clfza.reconstruct(y, cam, "bp", backend="numpy")  # back-propagation
    >>> image, info = clfza.reconstruct(y, cam, clfza.ADMM(tau=0.01, iters=20),
    ...                                 backend="numpy")
    >>> info.method, info.params["tau"], info.iterations <= 20
    ('admm', 0.01, True)
    >>> same, _ = clfza.reconstruct(y, cam, "admm", tau=0.01, iters=20, backend="numpy")
    >>> bool(np.array_equal(image, same))
    True
    """
    method, options = method_and_options(method, options)
    method, options, route = resolve_method(method, options)
    if backend not in BACKENDS:
        raise ClfzaError(f"backend must be one of {BACKENDS}, got {backend!r}")
    if psf is None and getattr(camera, "kind", "fza") == "psf":
        raise ClfzaError(f"camera {camera.name!r} is a measured-PSF camera (no zone plate to "
                         "model): give its point-source capture as psf= (clfza.models.load_psf; "
                         "the command line's --psf)")
    kw = dict(backend=backend, device=device, dtype=dtype, fft=fft, model=model, psf=psf,
              margin=margin, psf_scale=psf_scale)
    wb = check_white_balance(white_balance)
    stack = _stack_of(measurement, camera)
    if stack is not None:
        return _noted(_reconstruct_stack(stack, camera, method, kw, options, wb), route)
    return _noted(balanced(_reconstruct_one(measurement, camera, method, kw, options), wb,
                            psf), route)


def balanced(rec: Reconstruction, mode: str, psf) -> Reconstruction:
    """A colour reconstruction white-balanced (:func:`white_balance_image`), the gains in
    ``info.stats["white_balance"]``; a grey one as it is."""
    image, record = white_balance_image(rec.image, mode, psf)
    if record is not None:
        rec.image = image
        rec.info.stats["white_balance"] = record
        rec.info.notes.append(f"white balance {record['applied']} ({record['reason']}): "
                              f"gains {np.round(record['gains'], 4).tolist()} divided out")
    return rec


def _noted(rec: Reconstruction, route: str | None) -> Reconstruction:
    """``rec`` with the default route's note first in its record(s)."""
    if route is not None:
        for info in rec.info if isinstance(rec.info, list) else [rec.info]:
            info.notes.insert(0, route)
            info.params["method_asked"] = "auto"
    return rec


def _reconstruct_one(measurement, camera: Camera, method: str, kw: dict, options: dict
                     ) -> Reconstruction:
    """One frame (:func:`reconstruct`, its method resolved)."""
    backend, device, dtype, fft = kw["backend"], kw["device"], kw["dtype"], kw["fft"]
    model, psf, margin = kw["model"], kw["psf"], kw["margin"]
    y = check_measurement(measurement, camera)
    if kw.get("psf_scale") is not None:
        psf, found = _scaled_psf(y, camera, psf, kw["psf_scale"])
        rec = _reconstruct_one(y, camera, method, {**kw, "psf": psf, "psf_scale": None},
                               options)
        for info in [rec.info]:
            info.params["psf_scale"] = float(psf.info["scale"])
            if found is not None:
                info.stats["psf_scale"] = found
            info.notes.append(f"measured PSF magnified by {psf.info['scale']:.5g}"
                              + (" (found from the frame)" if found is not None else ""))
        return rec
    if y.ndim == 3 and y.shape[2] == 1:
        y = y[..., 0]

    check_values("measurement", y, dtype if backend == "opencl" else "float64")  # not NaN
    check_reconstruct(y.shape[:2], 1 if y.ndim == 2 else y.shape[2], method,
                      model=model if isinstance(model, str) else "auto")

    if psf is None or isinstance(psf, ExactModel):
        psf_arr = psf
    else:
        psf_arr = np.asarray(getattr(psf, "array", psf), np.float64)
    cut = None
    if isinstance(psf_arr, np.ndarray) and method != "bp":
        psf_arr, cut = _support_of(psf_arr, camera)
    if isinstance(psf_arr, np.ndarray) and psf_arr.ndim == 3:
        return _cut_noted(_per_channel_psf(
            y, camera, method, psf_arr, backend=backend, device=device, dtype=dtype, fft=fft,
            model=model, margin=margin, **options), cut)
    if isinstance(psf_arr, np.ndarray) and method != "bp":
        return _cut_noted(_psf_solve(
            y, camera, method, psf_arr, backend=backend, device=device, dtype=dtype, fft=fft,
            model=model, margin=margin, **options), cut)
    if method != "bp":
        return _iterative(y, camera, method, backend=backend, device=device, dtype=dtype,
                          fft=fft, model=model, psf=psf_arr, margin=margin, **options)
    if options:
        raise ClfzaError(f"method 'bp' takes no options, got {sorted(options)}")
    return _reconstruct_bp(y, camera, backend=backend, device=device, dtype=dtype, fft=fft,
                           model=model, psf=psf_arr, margin=margin)


def _support_of(psf: np.ndarray, camera: Camera) -> tuple[np.ndarray, dict | None]:
    """An iterative solve's measured PSF cut to the box that holds all but 1e-4 of its light
    (:func:`clfza.models.crop_to_support`: the padded grid is sized by the kernel's array, and
    a captured PSF's tail is often dark), each channel's sum kept; and what was cut (None:
    nothing). The same image, a faster solve (measured: docs/measurements.md,
    clfza.models._psf)."""
    if psf.min() < 0:  # light is non-negative: a signed kernel is used as given
        return psf, None
    out = crop_to_support(PSF(array=psf, pitch=camera.pitch))
    record = out.info["support_cut"]
    if tuple(record["to"]) == tuple(record["from"]):
        return psf, None
    return np.asarray(out.array), record


def _cut_noted(rec: Reconstruction, cut: dict | None) -> Reconstruction:
    """``rec`` with the PSF's support cut in its record(s) (``stats["psf_support_cut"]``)."""
    if cut is not None:
        for info in rec.info if isinstance(rec.info, list) else [rec.info]:
            info.stats["psf_support_cut"] = cut
            info.notes.append(f"measured PSF cut to its light's support: {cut['from']} -> "
                              f"{cut['to']} ({cut['light_cut']:.1e} of the light cut)")
    return rec


def _scaled_psf(y: np.ndarray, camera: Camera, psf, scale) -> tuple:
    """The measured PSF magnified by ``scale`` (a number, or ``"auto"``: found from ``y`` by
    :func:`clfza.focus.find_psf_scale`), cut to the window a frame of this grid can see
    (``2N - 1``); returns it and the search's record (None for a given number)."""
    from ..focus import find_psf_scale  # lazy: clfza.focus imports clfza.reconstruction

    if psf is None or isinstance(psf, ExactModel):
        raise ClfzaError("psf_scale needs a measured psf (an array or clfza.models.PSF)")
    p = psf if isinstance(psf, PSF) else load_psf(np.asarray(psf), normalise="none")
    found = None
    if isinstance(scale, str):
        if scale != "auto":
            raise ClfzaError(f"psf_scale must be a number > 0, 'auto' or None, got {scale!r}")
        res = find_psf_scale(y, p, camera=camera)
        found = res.to_dict()
        scale = res.scale
    cap = (2 * camera.shape[0] - 1, 2 * camera.shape[1] - 1)
    return scale_psf(p, scale, max_shape=cap), found


def _stack_of(measurement, camera: Camera) -> np.ndarray | None:
    """The frames of a stack ``(F, H, W)`` or ``(F, H, W, 3)`` of the camera's shape (a
    frame's own ``(H, W, 3)`` is colour, not a stack), validated; None for one frame."""
    shape = np.shape(measurement)
    grid = tuple(camera.shape)
    if len(shape) == 3 and shape[:2] != grid and shape[1:] == grid:
        pass
    elif not (len(shape) == 4 and shape[1:3] == grid):
        return None
    frames = finite_image("measurement", measurement)
    for f in frames:
        check_measurement(f, camera)
    return frames


def _reconstruct_stack(frames: np.ndarray, camera: Camera, method: str, kw: dict,
                       options: dict, white_balance: str = DEFAULT_WHITE_BALANCE
                       ) -> Reconstruction:
    """A stack: one batch for the iterative methods on the transfer-function model
    (:func:`clfza.solvers.run_solver_batch` decides what batches), else frame by frame."""
    if frames.ndim == 4 and frames.shape[3] == 1:
        frames = frames[..., 0]
    for f in frames:
        check_values("measurement", f, kw["dtype"] if kw["backend"] == "opencl" else "float64")
    batchable = (method != "bp" and kw["psf"] is None and not any(
        _solves_exact(camera, method, kw["model"], None, options, f) for f in frames))
    if batchable:
        check_reconstruct(frames.shape[1:3], 1 if frames.ndim == 3 else 3, method,
                          model=kw["model"] if isinstance(kw["model"], str) else "auto")
        out = run_solver_batch(frames, camera, method,
                               **{k: v for k, v in kw.items() if k != "psf_scale"}, **options)
        out = [balanced(r, white_balance, None) for r in out]
    else:
        tau = options.get("tau")
        taus = (list(tau) if tau is not None and not isinstance(tau, str) and np.ndim(tau)
                else [tau] * len(frames))
        if len(taus) != len(frames):
            raise ClfzaError(f"tau has {len(taus)} values for {len(frames)} frames: give one, "
                             "or one per frame")
        out = [reconstruct(f, camera, method, **kw, white_balance=white_balance,
                           **({**options, "tau": t} if t is not None else options))
               for f, t in zip(frames, taus, strict=True)]
    return Reconstruction(np.stack([r.image for r in out]), [r.info for r in out])


def _iterative(y: np.ndarray, camera: Camera, method: str, **kw) -> Reconstruction:
    """An iterative solve: on the exact model with the frame at a fixed scale
    (:func:`_exact_solve`), else as it comes."""

    options = {k: v for k, v in kw.items() if k not in ("backend", "device", "dtype", "fft",
                                                         "model", "psf", "margin")}
    if _solves_exact(camera, method, kw.get("model", "auto"), kw.get("psf"), options, y):
        return _exact_solve(y, camera, method, **kw)
    return run_solver(y, camera, method, **kw)


def _reconstruct_bp(y: np.ndarray, camera: Camera, *, backend: str = DEFAULT_BACKEND, device=None,
                    dtype=np.float32, fft: str = "auto", model: str = "auto", psf=None,
                    margin: int = 0) -> Reconstruction:
    """``K^T y`` (Eqs. 11-12: the in-focus image, its twin and no DC) of a validated
    observation, on the model :func:`clfza.models._exact.choose_model` picks (``method="bp"`` of
    :func:`reconstruct`, which validates the arguments first; the float64 array alone is
    :func:`clfza.models._transfer.back_propagate`)."""

    psf_arr = psf
    kind, why = method_model(camera, model, "bp", psf=psf_arr is not None)
    info = ReconInfo(method="bp", backend=backend, device="host (numpy)",
                     dtype="float64" if backend == "numpy" else np.dtype(dtype).name,
                     params={"model": kind}, notes=[f"model: {kind} ({why})"])
    t0 = time.perf_counter()
    if kind == "exact":
        img = _bp_exact(y, camera, backend, device, dtype, fft, psf_arr, margin, info)
        info.timings["solve"] = time.perf_counter() - t0
    elif backend == "numpy":
        img = _bp_numpy(y, camera, kind)
        info.timings["solve"] = time.perf_counter() - t0
    else:
        if kind != "tf":
            raise ClfzaError(f"model={kind!r} runs on backend='numpy' only; use "
                             "model='exact' on OpenCL")
        img = _bp_opencl(y, camera, device, dtype, fft, info)
    info.timings["total"] = time.perf_counter() - t0
    info.iterations = 1
    info.stop_reason = "direct"
    return Reconstruction(img, info)
