"""``tau="auto"`` on the exact finite-aperture model (:mod:`clfza.models._exact`): ``tau`` from the
frame's noise, and the pilot passes that find it under the data term's high-pass
(:func:`exact_group`; the transfer-function model's discrepancy search and the record are in
:mod:`clfza.solvers._tau`).

Exact model with the data term's high-pass (:mod:`clfza.models._highpass`, ADMM's default on a mask
with a finite aperture): ``tau = HIGHPASS_TAU_FACTOR (p / r1') sigma`` (:func:`highpass_tau`;
``p / r1'`` at most ``HIGHPASS_PITCH_CAP``, :func:`_pixel_r1`), with
``sigma`` the Haar MAD of the model's residual after up to ``PILOT_PASSES`` short pilot passes
(:func:`_residual_noise`): on a frame whose band fills the sensor's the frame's own estimate
is an upper bound that holds signal, and a noise-free frame then gets a far worse ``tau``;
the residual of a pass is the noise on a noisy frame and shrinks with ``tau`` on a
noise-free one. On a pilot estimate whose energy lies in fewer than ``SPARSE_SUPPORT`` of its
pixels (point sources: PSNR falls steeply below the best ``tau`` and slowly above it) ``tau``
is ``SPARSE_FACTOR`` times that (:func:`sparse_factor`); on a continuous-tone estimate (a
photograph, told from graphics of a few grey levels by :func:`mid_tone_share`) it is
:func:`tone_factor` times that, lower at lower noise. About 1.75 solves in all.

Exact model without it: the same pilot passes and form, ``tau = PLAIN_TAU_FACTOR (p / r1')
sigma``, and on a frame the passes call noise-free ``NOISE_FREE_PLAIN_SHARE`` times that on the
pilot's last ``sigma`` (not ``NOISE_FREE_TAU rms(y)``: without the high-pass ``rms(y)`` holds the
aperture's bright disc, and that rule chose far too large a ``tau`` on the experiment preset;
bench/bench_tau_heldout.py). (Issue 33: the former rule, :func:`exact_tau` on the frame's own
estimate, read the Haar upper bound with a noise-free constant and chose a ``tau`` ~50x below
the best on noisy frames; :func:`exact_tau` remains for a group without pilot passes). The
passes run at least
``PILOT_MIN`` iterations: shorter ones left the signal in the residual, so ``sigma`` stayed the
frame's upper bound at low noise.

Measured PSF (a kernel that is no mask's shadow, ``B.exact.mask_shadow`` False): the same
pilot passes and ``tau = PSF_TAU_FACTOR sigma`` in the measured-PSF route's scale-free units
(unit-sum PSF, frame divided by its RMS). There is no ``r1'`` (a measured-PSF camera's is a
placeholder: read as one, the rule above chose a ``tau`` 120-380x above the best). The best
``tau / sigma`` of natural scenes stayed at about ``PSF_TAU_FACTOR`` from 128^2 to 320^2 and
across noise levels; sparse high-contrast scenes (text, bars) want far less: a pilot estimate
whose energy lies in fewer than ``PSF_SPARSE_SUPPORT`` of its pixels gets ``PSF_SPARSE_FACTOR``
times the rule's ``tau`` (:func:`psf_sparse_factor`; bench/bench_tau_psf.py and
bench/bench_tau_heldout.py; docs/measurements.md, clfza.solvers._tau_exact). A frame the
passes call noise-free gets the floor ``EXACT_FLOOR rms(y)``: with a measured PSF the
crop split's image kept improving down to it, far below the mask's ``NOISE_FREE_TAU rms(y)``
(same section).

The constants were chosen by measurement on bench_tau's exact-model camera and the
experiment preset, which also shows how closely any rule can match a ``tau`` picked on a
grid there, and ``PSF_TAU_FACTOR`` on bench_tau_psf's captures (docs/measurements.md,
clfza.solvers._tau_exact).
"""

from __future__ import annotations

import math
from collections.abc import Iterator, Sequence
from contextlib import contextmanager
from contextvars import ContextVar

import numpy as np

from . import _driver as driver
from ._admm import RHO_PER_WEIGHT
from ._common import Monitor
from ._context import SolveContext
from ._noise import haar_mad_sigma, haar_scale_ratio

# exact model (see exact_tau; normalised units, operator norm 1; ||K|| ~ 255 on the
# experiment preset, so 0.027 there is 6.8 x sigma x (r / (1 - r))^(1/4) in the user's units)
EXACT_NOISE_FACTOR = 0.027   # tau = factor * sigma * (r / (1 - r))^POWER, r = N sigma^2/||y||^2
EXACT_NOISE_POWER = 0.25
EXACT_UPPER_FACTOR = 0.002   # sigma the Haar upper bound: factor * sigma * (1 + GAIN sqrt(..))
EXACT_SNR_GAIN = 2.0
EXACT_R_CAP = 0.95           # r capped (a frame of pure noise)
HIGHPASS_TAU_FACTOR = 45.0   # ... with the high-pass: tau = factor * (p / r1') * sigma,
HIGHPASS_PITCH_CAP = 0.092   # ... p / r1' at most this (the fit camera's: tau/sigma stops there)
PLAIN_TAU_FACTOR = 20.0      # ... without it: the same form, sigma from the same pilot passes
PSF_TAU_FACTOR = 0.01        # measured PSF (unit-sum kernel): tau = factor * sigma (no r1')
PILOT_FRACTION = 0.25        # ... whose sigma pilot passes of this fraction of iters find
PILOT_MIN = 100              # (at least this many iterations a pass: shorter ones stall)
PILOT_PASSES = 3             # at most this many passes
WARM_NOISE_FREE = True       # a noise-free frame's final solve continues the last pass
PILOT_SHRINK = 0.5           # another pass while sigma falls below this fraction of the last
WHITE_MAX = 1.25             # ... or while the residual is not white (Haar scale ratio above)
PILOT_STEP = 4.0             # ... then at least this much lower tau
PILOT_START_WHITE = 2.5      # a pilot start's residual above this Haar scale ratio holds signal
EXACT_FLOOR = 7e-7           # tau >= FLOOR * rms(y): model error that sigma does not see
NOISE_FREE_TAU = 7e-5        # tau = this * rms(y) where the pilot's residual is not white
NOISE_FREE_FALL = 0.5        # ... and its sigma fell below this fraction of the frame's
NOISE_FREE_PLAIN_SHARE = 0.056  # without the high-pass (if > 0) the noise-free tau is this
#                                 share of the noise rule's tau on the pilot's last sigma
SPARSE_ENERGY = 0.9          # a scene of isolated points: this share of the pilot estimate's
SPARSE_SUPPORT = 0.002       # energy in fewer than this fraction of its pixels ...
SPARSE_FACTOR = 1.4          # ... gets this multiple of the noise rule's tau (see sparse_factor)
PSF_SPARSE_SUPPORT = 0.15    # measured PSF: an estimate with energy in fewer than this fraction
PSF_SPARSE_FACTOR = 0.05     # ... of its pixels gets this multiple (see psf_sparse_factor)
TONE_MID = 0.1               # high-pass rule: an estimate with this share of mid-tone pixels
TONE_FACTOR = 0.5            # ... (continuous tone) gets this multiple at noise fraction
TONE_NOISE_REF = 0.05        # ... TONE_NOISE_REF, times (r / TONE_NOISE_REF)^TONE_POWER, at
TONE_POWER = 0.17            # ... most 1, with r at least TONE_NOISE_MIN (see tone_factor)
TONE_NOISE_MIN = 2e-3


#: a colour frame's sparse-scene decision (:func:`frame_energy_support`), or None: each solve's own
_FRAME_SUPPORT: ContextVar[float | None] = ContextVar("clfza_frame_support", default=None)


def residual2(B, x) -> float:
    g = B.empty()
    return float(B.resid_grad(x, g).get()[0])


def set_tau(opts, tau: float) -> None:
    opts.tau = tau
    if hasattr(opts, "weight"):
        opts.weight = tau / 2.0


def exact_tau(sig_b: float, snr_r: float, upper: bool) -> tuple[float, float]:
    """The exact model's ``tau`` in the solver's normalised units (operator norm 1) from the
    noise ``sig_b`` in the same units and the frame's noise fraction ``r = N sigma^2 /
    ||y||^2`` (capped at ``EXACT_R_CAP``); ``r / (1 - r)`` is the noise over the signal's
    energy. Returns ``(tau, w)`` with ``tau = factor * sig_b * w``:

    * ``sigma`` a noise estimate (out-of-band spectrum): ``EXACT_NOISE_FACTOR`` and
      ``w = (r / (1 - r))^EXACT_NOISE_POWER``, between ``tau ~ sigma`` and the MAP scaling
      ``tau ~ sigma^2 / rms(signal)`` (the best ``tau / sigma`` grows with the frame's noise
      fraction; measured: docs/measurements.md, clfza.solvers._tau_exact);
    * ``sigma`` the Haar upper bound (it holds signal, so ``r`` is no noise fraction until
      the frame is mostly noise): ``EXACT_UPPER_FACTOR`` and ``w = 1 + EXACT_SNR_GAIN
      sqrt(r / (1 - r))``."""
    r = min(max(snr_r, 0.0), EXACT_R_CAP)
    if upper:
        w = 1.0 + EXACT_SNR_GAIN * math.sqrt(r / (1.0 - r))
        return EXACT_UPPER_FACTOR * sig_b * w, w
    w = (r / (1.0 - r)) ** EXACT_NOISE_POWER
    return EXACT_NOISE_FACTOR * sig_b * w, w


def highpass_tau(sig_b: float, norm: float, pixel_r1: float,
                 factor: float = HIGHPASS_TAU_FACTOR) -> float:
    """The exact model's ``tau`` with the data term's high-pass (:mod:`clfza.models._highpass`), in
    the solver's normalised units: ``HIGHPASS_TAU_FACTOR (p / r1') sigma`` in the user's
    units (the high-pass keeps the zone frequencies' gain, so ``tau`` means what it means
    without it); ``sig_b`` is the noise in normalised units (``sigma / norm``), ``pixel_r1``
    the pixel pitch over the shadow's ``r1'``.

    The best ``tau / sigma`` is about proportional to the pitch, as the MAP weight
    ``sigma^2 lambda p`` of a TV prior on a pixel grid is; ``HIGHPASS_TAU_FACTOR`` was chosen
    by measurement, against rules that scale with the frame's noise fraction (as
    :func:`exact_tau`) or with the scene's mean gradient (docs/measurements.md,
    clfza.solvers._tau_exact)."""
    return factor * pixel_r1 * sig_b / norm


def exact_group(cls, B, opts, mon, x, ctx: SolveContext, n: int, y2: float):
    """The exact model: ``tau`` from the frame's noise (:func:`exact_tau`; with the data
    term's high-pass, :func:`highpass_tau` on the noise the pilot passes of
    :func:`_residual_noise` find, or ``NOISE_FREE_TAU * rms(y)`` where the residual of the
    pass that gave ``sigma`` is still not white: no noise they could resolve; without the high-pass
    ``NOISE_FREE_PLAIN_SHARE`` times the noise rule's ``tau`` on the pilot's last ``sigma``;
    with a measured PSF the floor), at least ``EXACT_FLOOR * rms(y)``; then one solve.
    ``NOISE_FREE_TAU`` and ``NOISE_FREE_PLAIN_SHARE`` were chosen by measurement on noise-free
    frames (docs/measurements.md, clfza.solvers._tau_exact). Without the high-pass the crop-split
    ADMM's short stages do not bring the residual near its limit, so the discrepancy search
    has nothing to read (measured: the same section).

    A frame the passes call noise-free continues the last pass (``WARM_NOISE_FREE``:
    :class:`~clfza.solvers._admm_crop.CropAdmmState`, its splits, duals and penalties) where
    that was measured to help, a mask's shadow with the high-pass or without an aperture;
    every other final solve starts from the last pass's image (the same section)."""

    g, s2 = ctx.group, ctx.scale2
    sigma = g.sigma
    upper = str(g.sigma_method or "").startswith("Haar")
    highpass = B.exact.highpass
    stages, total = [], 0
    factor = HIGHPASS_TAU_FACTOR if highpass else PLAIN_TAU_FACTOR
    measured = not B.exact.mask_shadow
    if measured:
        factor = PSF_TAU_FACTOR
    pixel_r1 = _pixel_r1(ctx.camera, B)
    x, sigma, stages, total, state = _residual_noise(cls, B, opts, x, ctx, factor)
    # the residual that gave sigma (the lowest of the passes') still holds signal, and the model
    # explained most of what the frame's own estimate called noise: the noise is below what the
    # passes could resolve (a residual that did not fall is what the model cannot explain:
    # sigma stays an upper bound). Read on that pass, not the last: a last pass that did not
    # converge at its lower tau leaves a structured residual above a white one
    structured = bool(stages) and noise_free_verdict(
        min(stages, key=lambda st: st[1])[2], sigma, g.sigma)
    sig_b = math.sqrt(sigma**2 / s2)
    r = n * sig_b**2 / y2 if y2 > 0 else 1.0
    support = mid_tone = None
    tone = 1.0
    if stages or highpass:
        chosen, w = highpass_tau(sig_b, math.sqrt(s2), pixel_r1, factor), 1.0
        if stages and not structured:  # (the noise-free rule below does not read it)
            images = B.exact.image_geom.crop(
                B.to_host(x).reshape((-1,) + tuple(B.exact.shape)))
            support = energy_support(images)
            frame_support = _FRAME_SUPPORT.get()  # a colour frame's, where it was decided
            decide = support if frame_support is None else frame_support
            w = scene_factor(decide, measured)
            if highpass and not measured and w == 1.0:  # not a scene of points
                mid_tone = mid_tone_share(images)
                tone = tone_factor(mid_tone, r)
                w *= tone
            chosen *= w
    else:
        chosen, w = exact_tau(sig_b, r, upper)
    floor = EXACT_FLOOR * math.sqrt(y2 / n) if n else 0.0
    rule = "noise"
    noise_free_form = None
    if structured:  # no noise the pilot could see
        if measured:  # the floor (measured: docs/measurements.md, clfza.solvers._tau_exact)
            chosen = floor
            noise_free_form = f"the floor {EXACT_FLOOR:g} x rms(y), a measured PSF's"
        elif not highpass and NOISE_FREE_PLAIN_SHARE > 0:
            chosen *= NOISE_FREE_PLAIN_SHARE
            noise_free_form = (f"{NOISE_FREE_PLAIN_SHARE:g} x the noise rule's {factor:g} x "
                               f"(p / r1') x sigma")
        else:
            chosen = NOISE_FREE_TAU * math.sqrt(y2 / n) if n else 0.0
            noise_free_form = f"{NOISE_FREE_TAU:g} x rms(y)"
        rule = "noise_free"
    if chosen < floor:  # a frame without noise: sigma holds model error only (or nothing)
        chosen, rule = floor, "floor"
    set_tau(opts, chosen)
    # a noise-free frame's final solve continues the last pass (its splits, duals and
    # penalties) where that was measured to help: a mask's shadow, high-passed or without an
    # aperture (docs/measurements.md, clfza.solvers._tau_exact)
    warm = WARM_NOISE_FREE and structured and state is not None and _continues(ctx, B)
    res = driver.run(cls(B, opts, mon, ctx), state if warm else x)
    r_final = residual2(B, res.x)
    res.stats = dict(res.stats)
    res.stats["tau_auto"] = {
        "criterion": "residual_noise" if stages else "noise_proportional", "rule": rule,
        "highpass": bool(highpass), "kernel": "measured_psf" if measured else "mask_shadow",
        "factor": factor if stages else EXACT_UPPER_FACTOR if upper else EXACT_NOISE_FACTOR,
        "noise_fraction": r, "w": w, "sigma_upper_bound": upper and not stages,
        "sigma": sigma, "sigma_frame": g.sigma,
        "sigma_method": ("Haar MAD of the pilot's residual" if stages
                         else g.sigma_method),
        "floor": EXACT_FLOOR, "tau": chosen * s2, "operator_norm": math.sqrt(s2),
        "residual2": r_final * s2, "y_energy": y2 * s2,
        # (tau, sigma of its residual, the residual's Haar scale ratio)
        "stages": [[t * s2, sg, wr] for t, sg, wr in stages],
        "residual_white": (is_white(stages[-1][2]) if stages else None),
        "white_max": WHITE_MAX, "noise_free_tau": NOISE_FREE_TAU,
        "noise_free_form": noise_free_form,
        "energy_support": support, "sparse_support": SPARSE_SUPPORT,
        "mid_tone_share": mid_tone, "tone_factor": tone,
        "frame_energy_support": _FRAME_SUPPORT.get() if support is not None else None,
        "stage_iters": _pilot_iters(opts) if stages else 0, "stage_iterations_total": total,
        "pilot_start": bool(ctx.pilot_start and stages), "continued": warm,
        "pixel_r1": pixel_r1,
        "pixel_r1_capped": bool(not measured
                                and pixel_r1 < ctx.camera.pitch / ctx.camera.r1p)}
    return res


def energy_support(images: np.ndarray, share: float = SPARSE_ENERGY) -> float:
    """The fraction of the pixels that hold ``share`` of an estimate's energy about its median
    (mean over the channels of ``images``, shape ``(..., ny, nx)``): smallest for point
    sources, larger for text and bars, largest for natural images (the values per scene:
    docs/measurements.md, clfza.solvers._tau_exact). NaN for an all-zero estimate.

    >>> point = np.zeros((8, 8))
    >>> point[3, 3] = 1.0
    >>> energy_support(point)  # one pixel of 64
    0.015625
    """
    a = np.asarray(images, dtype=np.float64)
    a = a.reshape((-1,) + a.shape[-2:])
    out = []
    for c in a:
        e = np.sort(((c - np.median(c)) ** 2).ravel())[::-1]
        total = e.sum()
        if not total > 0:
            return math.nan
        out.append((np.searchsorted(np.cumsum(e), share * total) + 1) / e.size)
    return float(np.mean(out))


def sparse_factor(support: float) -> float:
    """The multiple of :func:`highpass_tau` for an estimate whose energy lies in this fraction
    of its pixels (:func:`energy_support`): ``SPARSE_FACTOR`` below ``SPARSE_SUPPORT`` (a few
    point sources), else 1.

    Why: PSNR(tau) is asymmetric there. For point sources it falls steeply below the best
    ``tau`` and slowly above it; the noise rule's ``tau`` scatters around the best, so on such
    a scene it should err upward. Every other scene keeps x1 here: photographs, whose best
    ``tau`` is lower and whose energy support does not tell them from a silhouette, get
    :func:`tone_factor` instead (``SPARSE_SUPPORT`` and ``SPARSE_FACTOR`` chosen by
    measurement: docs/measurements.md, clfza.solvers._tau_exact)."""
    return SPARSE_FACTOR if support < SPARSE_SUPPORT else 1.0


def psf_sparse_factor(support: float) -> float:
    """The multiple of ``PSF_TAU_FACTOR sigma`` (measured PSF) for an estimate whose energy lies
    in this fraction of its pixels (:func:`energy_support`): ``PSF_SPARSE_FACTOR`` below
    ``PSF_SPARSE_SUPPORT`` (text, bars: sparse high-contrast scenes, whose best ``tau /
    sigma`` lies well below natural scenes'), else 1 (NaN, an all-zero estimate: 1).

    The support grows with the noise (a noisier estimate spreads), so the threshold lies between
    the noisiest sparse scene's and the cleanest natural one's; ``PSF_SPARSE_SUPPORT`` and
    ``PSF_SPARSE_FACTOR`` were fitted on one half of the held-out cases and scored on the other
    (docs/measurements.md, clfza.solvers._tau_exact)."""
    return PSF_SPARSE_FACTOR if support < PSF_SPARSE_SUPPORT else 1.0


def mid_tone_share(images: np.ndarray) -> float:
    """The share of an estimate's pixels in the middle 60 % of its tonal range, between its
    1st and 99th percentiles (mean over the channels of ``images``, shape ``(..., ny, nx)``):
    a few percent for graphics of two grey levels (text, bars, a silhouette, a checkerboard,
    where only the edges' pixels lie between), several times more for photographs (the values
    per scene: docs/measurements.md, clfza.solvers._tau_exact). NaN for a flat estimate.

    >>> two_levels = np.zeros((10, 10))
    >>> two_levels[:, 5:] = 1.0
    >>> mid_tone_share(two_levels)
    0.0
    >>> round(mid_tone_share(np.linspace(0.0, 1.0, 100).reshape(10, 10)), 2)
    0.58
    """
    a = np.asarray(images, dtype=np.float64)
    a = a.reshape((-1,) + a.shape[-2:])
    out = []
    for c in a:
        lo, hi = np.percentile(c, (1.0, 99.0))
        if not hi > lo:
            return math.nan
        z = (c - lo) / (hi - lo)
        out.append(float(np.mean((z > 0.2) & (z < 0.8))))
    return float(np.mean(out))


def tone_factor(mid_tone: float, noise_fraction: float) -> float:
    """The multiple of :func:`highpass_tau` for a pilot estimate with this
    :func:`mid_tone_share` on a frame with this noise fraction ``r = N sigma^2 / ||y - mean||^2``:
    on a continuous-tone estimate (``mid_tone >= TONE_MID``) ``TONE_FACTOR (r /
    TONE_NOISE_REF)^TONE_POWER``, at most 1 and with ``r`` at least ``TONE_NOISE_MIN``; on
    graphics of a few grey levels (and NaN) 1.

    Why: at the same noise the best ``tau`` of photographs lies below that of
    piecewise-constant graphics, and their best ``tau / sigma`` grows with the noise where the
    graphics' stays about constant, as the rule's does. The rule's ``HIGHPASS_TAU_FACTOR`` sits
    near the graphics'; the constants here were fitted on the photographs of the same camera
    and scored on held-out cameras (docs/measurements.md, clfza.solvers._tau_exact).

    >>> tone_factor(0.02, 0.005), round(tone_factor(0.2, 0.05), 3), tone_factor(0.2, 5.0)
    (1.0, 0.5, 1.0)
    """
    if not mid_tone >= TONE_MID:
        return 1.0
    r = max(noise_fraction, TONE_NOISE_MIN)
    return min(1.0, TONE_FACTOR * (r / TONE_NOISE_REF) ** TONE_POWER)


def scene_factor(support: float, measured: bool) -> float:
    """The multiple of the noise rule's ``tau`` for a pilot estimate whose energy lies in
    ``support`` of its pixels: :func:`sparse_factor`, times :func:`psf_sparse_factor` with a
    measured PSF."""
    return sparse_factor(support) * (psf_sparse_factor(support) if measured else 1.0)


@contextmanager
def frame_energy_support(support: float) -> Iterator[None]:
    """Within: the sparse-scene multiple of ``tau="auto"`` (:func:`scene_factor`) is decided
    on ``support``, a colour frame's (:func:`colour_energy_support`), not on each solve's own
    pilot estimate; the record keeps both (``energy_support``, ``frame_energy_support``)."""
    token = _FRAME_SUPPORT.set(float(support))
    try:
        yield
    finally:
        _FRAME_SUPPORT.reset(token)


def colour_energy_support(records: Sequence[dict | None]) -> tuple[float, list[int]] | None:
    """A colour frame's sparse-scene decision from its channels' ``tau="auto"`` records
    (``info.stats["tau_auto"]`` of channels solved one by one, as a colour PSF's are).

    Sparsity is the scene's, not a channel's; decided per channel, an estimate near
    ``PSF_SPARSE_SUPPORT`` can put one channel of a natural scene among the sparse ones and
    cut its ``tau`` 20x. Returns the channels' mean energy support and the channels whose own
    decision (:func:`scene_factor` of their own support) differs from the one on the mean,
    or None where every channel took the noise rule on its own estimate and they agree (or a
    channel has no estimate: another rule chose its ``tau``).

    >>> r = {"energy_support": 0.22, "kernel": "measured_psf", "rule": "noise"}
    >>> mean, again = colour_energy_support([r, dict(r, energy_support=0.173),
    ...                                      dict(r, energy_support=0.148)])
    >>> round(mean, 4), again  # the blue channel alone would call the scene sparse
    (0.1803, [2])
    """
    if len(records) < 2 or any(r is None or r.get("energy_support") is None
                                or r.get("rule") != "noise" for r in records):
        return None
    supports = [float(r["energy_support"]) for r in records]
    if not all(math.isfinite(v) for v in supports):
        return None
    mean = float(np.mean(supports))
    measured = [r.get("kernel") == "measured_psf" for r in records]
    joint = [scene_factor(mean, m) for m in measured]
    differ = [c for c, (v, m, j) in enumerate(zip(supports, measured, joint, strict=True))
              if scene_factor(v, m) != j]
    return (mean, differ) if differ else None


def noise_free_verdict(ratio: float, sigma: float, sigma_frame: float) -> bool:
    """Whether a residual calls the frame noise-free: it is not white (it still holds signal,
    :func:`is_white`) and its ``sigma`` fell to ``NOISE_FREE_FALL`` of the frame's own
    estimate ``sigma_frame`` or below (the model explained most of what that estimate called
    noise).

    >>> noise_free_verdict(1.4, 0.001, 0.01), noise_free_verdict(1.0, 0.001, 0.01)
    (True, False)
    """
    return not is_white(ratio) and sigma <= NOISE_FREE_FALL * sigma_frame


def is_white(ratio: float) -> bool:
    """Whether a residual with this :func:`clfza.solvers._noise.haar_scale_ratio` is noise (as much
    energy at the second Haar scale as at the first, up to ``WHITE_MAX``) rather than signal
    the model has not explained yet (NaN, a zero residual, is not)."""
    return ratio <= WHITE_MAX


def _pixel_r1(camera, B=None) -> float:
    """The pitch over the shadow's ``r1'`` of the camera the solve was given, at most
    ``HIGHPASS_PITCH_CAP`` under the data term's high-pass (the best ``tau / sigma`` grows with
    the pitch up to the camera the rule was fitted on and no further; measured:
    docs/measurements.md, clfza.solvers._tau_exact); 1 for a measured PSF
    (``B.exact.mask_shadow`` False): it has no ``r1'`` (a measured-PSF camera's ``r1`` is a
    placeholder), and its rule is ``PSF_TAU_FACTOR sigma`` (see :func:`exact_group`)."""
    if B is not None and B.exact is not None and not B.exact.mask_shadow:
        return 1.0
    ratio = camera.pitch / camera.r1p
    if B is not None and B.exact is not None and B.exact.highpass:
        return min(ratio, HIGHPASS_PITCH_CAP)
    return ratio


def _continues(ctx: SolveContext, B) -> bool:
    """Whether a solve may continue the last pilot pass: a mask's shadow, high-passed or
    without an aperture (measured: docs/measurements.md, clfza.solvers._tau_exact)."""
    return B.exact.mask_shadow and (bool(B.exact.highpass) or ctx.camera.R is None)


def _pilot_iters(opts) -> int:
    """Iterations of one pilot pass (:func:`_residual_noise`)."""
    return max(PILOT_MIN, int(round(PILOT_FRACTION * opts.iters)))


def _residual_noise(cls, B, opts, x, ctx: SolveContext, factor: float = HIGHPASS_TAU_FACTOR):
    """The noise of a frame whose band fills the sensor's (the Haar estimate then holds
    signal: an upper bound), from what the model cannot explain: pilot passes of
    ``PILOT_FRACTION`` of the iterations at :func:`highpass_tau` of the current ``sigma``,
    each followed by the Haar MAD (:func:`clfza.solvers._noise.haar_mad_sigma`) of the residual
    ``y - K x`` on the host (one float64 FFT pair per channel); ``sigma`` falls to it. Another
    pass follows while it falls by more than ``PILOT_SHRINK`` a pass or while the residual is
    not white (:func:`is_white`: a noisy frame's residual is its noise, white, from the first
    pass; a noise-free frame's shrinks with ``tau`` and keeps the structure of the signal not
    yet explained), at most ``PILOT_PASSES`` passes, each from the last. Returns the last
    pass's image, ``sigma``, the passes ``(tau, sigma of its residual, its Haar scale
    ratio)``, their iterations (what they find on bench_tau's exact camera, and the Haar scale
    ratios behind ``WHITE_MAX``: docs/measurements.md, clfza.solvers._tau_exact) and where the
    last pass ended (:meth:`~clfza.solvers._admm_crop.AdmmCropSolver.end_state`; None without
    a pass or for a solver that keeps none), for the final solve to continue.

    With ``ctx.pilot_start`` (the start is a pilot estimate, e.g. a coarse solve's image) its
    own residual comes first, as a pass of ``tau`` 0 and no iterations: no pass runs unless it
    looks noise-free (:func:`noise_free_verdict`) or its Haar scale ratio is above
    ``PILOT_START_WHITE`` (far more structure than a noisy frame's residual shows: a
    noise-free frame whose sigma has not fallen yet); then the passes run from it, as from
    any start (the ratios measured: docs/measurements.md, clfza.reconstruction._reconstruct)."""

    quiet = Monitor(B)
    s2 = ctx.scale2
    sigma = ctx.group.sigma
    model = B.exact
    frames = np.asarray(ctx.group.y, dtype=np.float64).reshape((-1,) + tuple(model.sensor))
    frames = model.remove_mean(frames)
    stages: list[tuple[float, float, float]] = []
    total, tau = 0, math.inf

    def residual_noise(x) -> tuple[float, float]:
        xs = B.to_host(x).reshape((-1,) + tuple(model.shape))
        resid = [f - model.forward(xc) for f, xc in zip(frames, xs, strict=True)]
        return (math.sqrt(float(np.mean([haar_mad_sigma(r) ** 2 for r in resid]))),
                float(np.mean([haar_scale_ratio(r) for r in resid])))

    if ctx.pilot_start and sigma > 0:  # the start is a pilot estimate: its residual first
        found, ratio = residual_noise(x)
        stages.append((0.0, found, ratio))
        sigma = min(sigma, found)
        if not noise_free_verdict(ratio, sigma, ctx.group.sigma) and ratio <= PILOT_START_WHITE:
            return x, sigma, stages, total, None
        # it looks noise-free, or holds far more signal than noise: the passes run from it,
        # as from any start, at a tau below the one the rule gives this sigma
        tau = highpass_tau(sigma / math.sqrt(s2), math.sqrt(s2), _pixel_r1(ctx.camera, B),
                           factor)
    saved = (opts.iters, opts.min_iters)
    # ADMM's penalty, if it has one and it was not given: the passes run at the one the rule
    # was fitted on (RHO_PER_WEIGHT w), whatever the final solve's default is
    # (clfza.solvers._admm_crop.penalty_per_weight)
    pilot_rho = getattr(opts, "rho", 0.0) is None
    last_state = None
    it = _pilot_iters(opts)
    opts.iters, opts.min_iters = it, min(it, opts.min_iters or 1)
    try:
        for _ in range(PILOT_PASSES):
            if not sigma > 0:
                break
            # a residual that is not white holds signal the last tau kept out: at least
            # PILOT_STEP lower, whatever its sigma says
            cap = tau / PILOT_STEP if stages and not is_white(stages[-1][2]) else math.inf
            tau = min(cap, highpass_tau(sigma / math.sqrt(s2), math.sqrt(s2),
                                        _pixel_r1(ctx.camera, B), factor))
            set_tau(opts, tau)
            if pilot_rho:
                opts.rho = RHO_PER_WEIGHT * opts.weight
            solver = cls(B, opts, quiet, ctx)
            res = driver.run(solver, x)
            x, total = res.x, total + res.iterations
            last_state = getattr(solver, "end_state", None)
            found, ratio = residual_noise(x)
            stages.append((tau, found, ratio))
            shrinking = found < PILOT_SHRINK * sigma
            sigma = min(sigma, found)
            if not shrinking and is_white(ratio):
                break
    finally:
        opts.iters, opts.min_iters = saved
        if pilot_rho:
            opts.rho = None
    return x, sigma, stages, total, (last_state() if last_state is not None else None)
