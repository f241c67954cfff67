"""Plug-and-play splitting with a learned denoiser as the prior (issue 38: ``reg="dncnn"``).

Two stages (on the transfer-function model; the exact model below). First ADMM-TV (Eq. 20)
at the given ``tau`` from the start point (``x0`` or the Wiener estimate) for
``PNP_TV_ITERS`` iterations: the TV pre-solve fills what the data lack (the transfer
function vanishes at DC and on rings, and the 6- or 17-layer network, receptive field 13 or
35 pixels, keeps its input's low frequencies: from the Wiener start alone PnP stays far
below TV, docs/measurements.md). Then ``min 1/2 ||y - K x||^2 + tau' Phi(x)``, ``tau' =
PNP_TAU_PER_TV tau``, where ``Phi`` is known only through its proximal operator, replaced by
a pretrained DnCNN (:mod:`clfza.denoisers`): split ``z = x`` and alternate half-quadratic
splitting with a decreasing noise level (DPIR: Zhang et al., "Plug-and-play image
restoration with deep denoiser prior", IEEE TPAMI 2021) from the TV image::

    sigma_k  geometric from sigma_max to sigma_min over the schedule's iterations
    rho_k  = tau' / (c sigma_k)^2
    x      = F^-1 [ F(K^T y + rho_k z) / (H_T^2 + rho_k) ]
    z      = lo + c D(clip((x - lo) / c, 0, 1), sigma_k)

``D(., sigma)`` is the denoiser at noise level ``sigma`` in its [0, 1] scale, to which the
image's range ``[lo, lo + c]`` is mapped: the 0.1th and 99.9th percentiles of the TV image
(the transfer-function model's images are DC-free, their mean is not in the data, and the
network is not shift-invariant). ``sqrt(tau' / rho)`` is the prox's noise level in the
image's units; ``tau'`` plays the role of DPIR's ``lambda sigma_n^2``. ``sigma_max`` is
``PNP_SIGMA_MAX`` (or ``sqrt(tau' / rho) / c`` when ``rho`` is given), ``sigma_min``
``PNP_SIGMA_MIN``; the schedule has ``min(iters, PNP_ITERS)`` iterations and the solve ends
with it. Half-quadratic splitting replaced the scaled ADMM with a growing penalty, and the
TV pre-solve the bare Wiener start (measured: docs/measurements.md). ``tau="auto"`` is
refused: a discrepancy search over the denoiser's stages tuned the wrong thing, and ADMM-TV's
own ``tau="auto"`` run in the pre-solve (``tau'`` from the ``tau`` it chooses) lands far from
the plug-and-play stage's best ``tau`` and below ADMM-TV at its own ``tau="auto"``; no
constant factor on it closes the gap (measured: docs/measurements.md, clfza.solvers._pnp).
Give ``tau``.

Example
-------
>>> import numpy as np, clfza
>>> cam = clfza.Camera(pitch=0.01, shape=(32, 32), r1=0.07, z1=20.0, z2=3.0, R=0.6)
>>> y = clfza.NumpyOperator(cam, warn=False).forward(np.random.default_rng(0).random((32, 32)))
>>> r = clfza.reconstruct(y, cam, "admm", backend="numpy", model="tf", reg="dncnn", tau=0.01)
>>> r.info.stats["denoiser"], r.info.stats["denoiser_calls"]
('6N', 10)

The x-update is ADMM's Fourier-diagonal solve
(:class:`~clfza.solvers._admm_ops.FourierSolve`, with the difference term off and
``mu = rho``); the rest are the backend's element-wise operations and the denoiser, on the
backend's own arrays (OpenCL: ``kernels/dncnn.cl`` on the same device, float32, the iterate
never leaves it; numpy: the float64 reference network). Colour channels solved jointly are
denoised as a batch, channel by channel. Non-negativity (``nonneg``) projects the returned
image only.

The exact model with a measured PSF (:mod:`clfza.models._exact`; :class:`PnpExactSolver`;
a mask's shadow is refused: its data weight is measured on PSFs only) runs the same two
stages: the pre-solve is the crop-split ADMM-TV
(:mod:`clfza.solvers._admm_crop`, its options and default iterations), ``tau' =
PNP_TAU_PER_TV_EXACT tau`` (the normalised operator's scale), and as ``K^T K`` is not
Fourier-diagonal there the x-update is ``PNP_CG_ITERS`` conjugate-gradient iterations on
``(K^T K + rho) x = K^T y + rho z`` warm-started from the last ``x`` (stopping early at the
relative residual ``PNP_CG_TOL``; ``K^T K p = K^T y - K^T (y - K p)`` from the backend's
residual gradient, one FFT pair each); ``z`` is projected as the crop-split ADMM projects its
``w`` (non-negativity, zero off the object region), and so is the returned image. The image's
range is read on the image window.

The variant (option ``denoiser``, default the noise-conditional 6-layer ``6N``) is chosen for
sigma (:func:`clfza.denoisers.select_variant`); where sigma leaves its training range the
record says so. PnP has no objective: the stopping rule is the relative step change, and the
reported objective is the data term ``1/2 ||y - K x||^2``.
"""

from __future__ import annotations

import dataclasses
import math
import time

import numpy as np

from ..denoisers import DnCNNDevice, dncnn_reference, load_dncnn, select_variant
from ..errors import ClfzaError
from ._admm import RHO_PER_WEIGHT, AdmmOptions, AdmmSolver
from ._admm_crop import AdmmCropSolver
from ._admm_crop_ops import CropAdmmOps
from ._admm_ops import FourierSolve
from ._common import Monitor, Stopper
from ._driver import Solver, Step, run

#: the denoiser's first and last noise level (its [0, 1] scale) of the geometric schedule, and
#: the schedule's length: the measured best of the candidates in docs/measurements.md (sigma
#: max 0.05, 0.1, 0.2; min 0.002 .. 0.05; 5 .. 40 iterations; chosen on two scenes, checked on
#: two held out and on measured PSFs)
PNP_SIGMA_MAX = 0.1
PNP_SIGMA_MIN = 0.02
PNP_ITERS = 10
#: the plug-and-play stage's tau' over the TV pre-solve's tau (measured best of 0.01, 0.02,
#: 0.03, 0.05, 0.1)
PNP_TAU_PER_TV = 0.03
#: the same on the exact model (its normalised operator; measured best of 1, 3, 10, 30)
PNP_TAU_PER_TV_EXACT = 3.0
#: ADMM-TV iterations of the pre-solve (the transfer-function model; on the exact model the
#: crop-split ADMM's own default, AdmmExactOptions.iters)
PNP_TV_ITERS = 200
#: exact model: conjugate-gradient iterations of one x-update (warm-started from the last x),
#: and their relative residual at which it stops early
PNP_CG_ITERS = 10
PNP_CG_TOL = 1e-3
#: the image's range [lo, lo + c] the denoiser's [0, 1] stands for: these percentiles of the
#: start point (the transfer-function model's images are DC-free: their mean is not data)
SCALE_PERCENTILES = (0.1, 99.9)


class PnpAdmmSolver(Solver):
    """Plug-and-play half-quadratic splitting with the DnCNN denoiser as the z-update and a
    decreasing noise level, on the transfer-function model (:mod:`clfza.solvers._pnp`);
    chosen by :func:`prior_solver` for ``method="admm"`` with ``reg="dncnn"``."""

    method = "admm"
    models = ("tf",)
    #: tau' / tau (the transfer-function model's)
    tau_per_tv = PNP_TAU_PER_TV
    xsolve_rho: float | None = None

    def stopper(self) -> Stopper:
        o = self.opts
        rule = "step" if o.stop == "objective" else o.stop
        n = min(o.iters, PNP_ITERS)
        return Stopper(rule, o.tol, min(o.min_iters or 1, n), n)

    def setup(self, x0) -> None:
        B, o = self.B, self.opts
        if getattr(B, "frames", 1) > 1:
            raise ClfzaError("reg='dncnn' runs one frame at a time (not in a batch of frames)")
        if self.context is not None and self.context.auto_tau:
            raise ClfzaError("reg='dncnn' needs a numeric tau: tau='auto' (ADMM's default) "
                             "is not available for it, as ADMM-TV's rule misses the "
                             "plug-and-play stage's best tau (docs/measurements.md, "
                             "clfza.solvers._pnp); give tau (the tau best for reg='tv' "
                             "is a good start)")
        x0 = self._tv_presolve(x0)
        self.tau = self.tau_per_tv * o.tau
        lo, hi = (float(v) for v in np.percentile(self._window(B.to_host(x0)),
                                                  SCALE_PERCENTILES))
        self.offset = lo if math.isfinite(lo) else 0.0
        self.scale = hi - lo if hi > lo and math.isfinite(hi - lo) else 1.0
        first = (math.sqrt(self.tau / o.rho) / self.scale if o.rho is not None
                 else PNP_SIGMA_MAX)
        n = min(o.iters, PNP_ITERS)
        last = min(PNP_SIGMA_MIN, first)
        self.schedule = [first * (last / first) ** (k / max(n - 1, 1)) for k in range(n)]
        self.rho = self._rho(first)
        # the variant of each sigma of the schedule: one for the noise-conditional and named
        # variants; option denoiser="blind" switches to the band of each sigma
        choices = [select_variant(sg, o.denoiser) for sg in self.schedule]
        self.variants = [c.variant for c in choices]
        used = list(dict.fromkeys(self.variants))
        self.sigma, self.variant = choices[0].sigma, choices[0].variant
        self.sigma_first = self.sigma
        names = " then ".join(used) + (" (blind: the band of each sigma)" if len(used) > 1
                                       else "")
        self.notes.append(f"prior: DnCNN {names}, sigma from {first:.4g} to "
                          f"{self.schedule[-1]:.4g} over {n} iterations (the image's "
                          f"[{self.offset:.4g}, {self.offset + self.scale:.4g}] as [0, 1]; "
                          f"rho = tau' / ({self.scale:.4g} sigma)^2)")
        for v in used:  # sigma outside a variant's training range: the first such note each
            out = [c for c in choices if c.variant == v and c.note]
            if out:
                k = len(out)
                self.notes.append(f"prior: {out[0].note}" + (
                    f" ({k} of the {n} iterations)" if n > 1 else ""))
        self._nets = self._networks(used)
        self._x_setup()
        self.x = B.empty()
        B.copy(self.x, x0)
        self.z, self.t, self.rhs = B.empty(), B.empty(), B.empty()
        B.copy(self.z, x0)
        self.one = B.from_host(np.ones(B.shape))
        self.xprev = B.empty() if self.needs_step else None
        self.calls = 0

    def _denoise(self, t, z) -> None:
        """``z = D(t, sigma)`` with the current variant's network."""
        self._nets[self.variant](t, z)

    def _networks(self, variants: list[str]) -> dict:
        """``{variant: denoise(t, z)}``: the shipped weights, on OpenCL the device network
        (its buffers allocated once) on the backend's device, on numpy the reference."""
        B = self.B
        if hasattr(B, "rt") and np.dtype(B.dtype) != np.float32:
            raise ClfzaError("reg='dncnn' on the OpenCL backend runs in float32 "
                             "(dtype=float32), its denoiser's precision")
        nets = {}
        for v in variants:
            weights = load_dncnn(v)
            if hasattr(B, "rt"):
                net = DnCNNDevice(weights, B.rt)
                nets[v] = lambda t, z, net=net: net.enqueue(t, z, self.sigma)
            else:
                def ref(t, z, weights=weights):
                    z[...] = dncnn_reference(t, weights, sigma=self.sigma)
                nets[v] = ref
        return nets

    def _tv_presolve(self, x0):
        """ADMM-TV at ``tau`` (:meth:`_tv_solver`) from ``x0`` (no checkpoints); its image is
        the plug-and-play stage's start and range."""
        cls, tv = self._tv_solver()
        t0 = time.perf_counter()
        res = run(cls(self.B, tv, Monitor(self.B), self.context), x0)
        self.tv_seconds = time.perf_counter() - t0
        self.tv_iters = res.iterations
        self.notes.append(f"prior: ADMM-TV pre-solve at the given tau, {res.iterations} "
                          f"iterations; then DnCNN at tau' = {self.tau_per_tv:g} tau")
        return res.x

    def _tv_solver(self):
        """The pre-solve's class and options: ADMM-TV at ``tau``, ``PNP_TV_ITERS``
        iterations."""
        o = self.opts
        return AdmmSolver, AdmmOptions.from_options(
            {"tau": o.tau, "iters": PNP_TV_ITERS, "nonneg": o.nonneg, "colour": o.colour},
            method="admm")

    def _window(self, a: np.ndarray) -> np.ndarray:
        """The image's pixels of a host array on the backend's grid (all of them here)."""
        return a

    def _x_setup(self) -> None:
        self.xsolve = FourierSolve.for_backend(self.B)
        self.xsolve.setup(0.0, self.rho)  # (K^T K + rho) x = rhs
        self.xsolve_rho = self.rho

    def _x_update(self) -> float:
        """``x = (K^T K + rho)^-1 (K^T y + rho z)`` (Fourier-diagonal; ``rhs`` kept up to
        date by :meth:`_rhs`); returns ``||y - K x||^2``."""
        if self.xsolve_rho != self.rho:
            self.xsolve.setup(0.0, self.rho)
            self.xsolve_rho = self.rho
        return float(self.xsolve.solve(self.rhs, self.x, True).get()[0])

    def _project_z(self) -> None:
        """The prior's constraints on ``z`` (none on the transfer-function model)."""

    def _rho(self, sigma: float) -> float:
        """The penalty at which the x-update's prox has noise level ``sigma`` (the
        denoiser's scale): ``tau' / (c sigma)^2``."""
        return self.tau / (self.scale * sigma) ** 2

    def _rhs(self) -> None:
        # rhs = K^T y + rho z
        self.B.lincomb(self.rhs, 1.0, self.B.b, self.rho, self.z)

    def start(self) -> None:
        self._rhs()
        return None

    def step(self, it: int) -> Step:
        B, c = self.B, self.scale
        if self.xprev is not None:
            B.copy(self.xprev, self.x)
        sigma = self.schedule[min(it, len(self.schedule)) - 1]
        if sigma != self.sigma:
            self.sigma = sigma
            self.rho = self._rho(sigma)
            self._rhs()
        data = self._x_update()
        # t = (x - lo) / c
        B.lincomb(self.t, 1.0 / c, self.x, -self.offset / c, self.one)
        # clipped to [0, 1], the networks' training range: beyond it DnCNN amplifies (a
        # pixel at 4 comes out near 11) and the split diverges; clipped it is bounded
        B.lincomb(self.t, -1.0, self.t, 1.0, self.one)  # 1 - t
        B.project_nonneg(self.t, self.t)
        B.lincomb(self.t, -1.0, self.t, 1.0, self.one)  # min(t, 1)
        B.project_nonneg(self.t, self.t)  # max(min(t, 1), 0)
        self.variant = self.variants[min(it, len(self.variants)) - 1]
        self._denoise(self.t, self.z)
        self.calls += 1
        B.lincomb(self.z, c, self.z, self.offset, self.one)  # z = c D(t) + lo
        self._project_z()
        self._rhs()
        dh = 0.5 * data
        step = None
        if self.xprev is not None:
            d = B.diffnorm(self.x, self.xprev).get()
            step = math.sqrt(d[0] / d[1]) if d[1] > 0 else 0.0
        return Step(dh, self.x, step=step, extra={"data": dh})

    def finish(self):
        if self.opts.nonneg:
            self.B.project_nonneg(self.x, self.x)
        return self.x

    def stats(self, history: list[float]) -> dict:
        ran = self.variants[:max(self.calls, 1)]  # the variant of each iteration run
        return {"rho": self.rho, "prior": "dncnn", "splitting": "hqs",
                "denoiser": "+".join(dict.fromkeys(ran)), "denoiser_variants": ran,
                "sigma": self.sigma,
                "sigma_first": self.sigma_first,
                "image_offset": self.offset, "image_scale": self.scale,
                "pnp_tau": self.tau, "tv_presolve_iters": self.tv_iters,
                "tv_presolve_s": self.tv_seconds, "denoiser_calls": self.calls}


class PnpExactSolver(PnpAdmmSolver):
    """:class:`PnpAdmmSolver` on the exact model with a measured PSF (a mask's shadow is
    refused, :meth:`setup`): the
    crop-split ADMM-TV (:mod:`clfza.solvers._admm_crop`, its options and default iterations)
    as the pre-solve, the x-update by conjugate gradients on ``(K^T K + rho) x = K^T y + rho
    z`` (``PNP_CG_ITERS``, warm-started; ``K^T K p = K^T y - K^T (y - K p)``, one FFT pair per
    iteration), and ``z`` projected as the crop-split ADMM projects its ``w`` (non-negativity,
    zero off the object region); the image's range from the image window's percentiles."""

    models = ("exact",)
    tau_per_tv = PNP_TAU_PER_TV_EXACT
    #: run on a mask's shadow too (refused by default; bench/bench_dncnn.py --quality-exact
    #: sets it to measure that case)
    allow_mask_shadow = False

    def setup(self, x0) -> None:
        if self.B.exact.mask_shadow and not self.allow_mask_shadow:
            raise ClfzaError(
                "reg='dncnn' on the exact model runs with a measured PSF only: on a mask's "
                "shadow its data weight (PNP_TAU_PER_TV_EXACT, measured on PSFs) leaves the "
                "image below ADMM-TV's, and no one weight fits both (measured: "
                "bench/results/dncnn_quality_experiment_*, docs/measurements.md, "
                "clfza.solvers._pnp); use model='tf' (command line: --model tf) or reg='tv'")
        super().setup(x0)

    def _tv_solver(self):
        o = self.opts
        fields = {f.name: f for f in dataclasses.fields(o)}
        defaults = {k: fields[k].default for k in ("iters", "stop", "tol", "stop_window")}
        # the penalty and iterations its weights were measured with (a mask's shadow's: the
        # measured-PSF defaults of clfza.solvers._admm_crop came later, unmeasured here)
        tv = dataclasses.replace(o, reg="tv", denoiser=None, rho=RHO_PER_WEIGHT * o.weight,
                                 min_iters=1, **defaults)
        return AdmmCropSolver, tv

    def _window(self, a: np.ndarray) -> np.ndarray:
        return self.B.exact.image_geom.crop(a)

    def _x_setup(self) -> None:
        B = self.B
        self.g, self.r, self.p, self.ap, self.s0 = (B.empty() for _ in range(5))
        self.ops = CropAdmmOps.for_backend(B)
        self.cg_iters = 0

    def _x_update(self) -> float:
        B, rho = self.B, self.rho
        # r = K^T y + rho z - (K^T K + rho) x = K^T (y - K x) + rho (z - x)
        B.resid_grad(self.x, self.g)
        B.lincomb(self.r, 1.0, self.g, rho, self.z, -rho, self.x)
        B.copy(self.p, self.r)
        rr = rr0 = float(B.dot(self.r, self.r).get()[0])
        for _ in range(PNP_CG_ITERS):
            if rr <= PNP_CG_TOL ** 2 * rr0 or rr == 0.0:
                break
            B.resid_grad(self.p, self.g)  # g = K^T y - K^T K p
            B.lincomb(self.ap, 1.0, B.b, -1.0, self.g, rho, self.p)  # A p
            pap = float(B.dot(self.p, self.ap).get()[0])
            if not pap > 0.0:
                break
            alpha = rr / pap
            B.lincomb(self.x, 1.0, self.x, alpha, self.p)
            B.lincomb(self.r, 1.0, self.r, -alpha, self.ap)
            rr_new = float(B.dot(self.r, self.r).get()[0])
            B.lincomb(self.p, 1.0, self.r, rr_new / rr, self.p)
            rr = rr_new
            self.cg_iters += 1
        return float(B.data_term(self.x))

    def _rhs(self) -> None:
        """The CG's right-hand side is formed in :meth:`_x_update` (no Fourier division)."""

    def _project(self, out, v) -> None:
        """``out = proj(v)``: non-negativity and/or zero off the object region."""
        o = self.opts
        if not (o.nonneg or o.support):
            self.B.copy(out, v)
            return
        self.B.lincomb(self.s0, 0.0, v)
        self.ops.w_update(v, out, self.s0, o.nonneg, o.support)

    def _project_z(self) -> None:
        self._project(self.p, self.z)
        self.B.copy(self.z, self.p)

    def finish(self):
        self._project(self.p, self.x)
        return self.p

    def stats(self, history: list[float]) -> dict:
        return {**super().stats(history), "x_update": "cg", "cg_iters": self.cg_iters}


def prior_solver(cls: type[Solver], opts) -> type[Solver]:
    """The solver class that runs ``opts``: :class:`PnpAdmmSolver` (transfer-function model)
    or :class:`PnpExactSolver` (exact model) for ADMM with ``reg="dncnn"``, else ``cls``."""
    if cls.method == "admm" and getattr(opts, "reg", "tv") == "dncnn":
        return PnpExactSolver if "exact" in cls.models else PnpAdmmSolver
    return cls
