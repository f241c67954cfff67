"""How fast each solver reaches the exact model's minimiser (issue 33, "the default route must
deliver"): objective gap against iterations and time, and PSNR against the truth.

The problem, the same for every candidate of a case (user units; ``x`` on the model grid of
:class:`clfza.models.ExactModel`)::

    F(x) = 1/2 ||y_d - K_d x||^2 + (tau / 2) TV(x) + i_C(x),
    C = {x >= 0, x = 0 off the object region}

with ``TV`` the circular isotropic TV of Eq. 20 (:func:`clfza.regularizers.tv_value`; the
solvers' weight is ``w = tau / 2``, :mod:`clfza.solvers._fista`), ``(K_d, y_d)`` the camera's
exact model and frame, or, with the data term's box high-pass (:mod:`clfza.models._highpass`),
the high-passed model of the sensor's interior and the filtered frame. ``C`` is what the
exact model's ADMM enforces by default (``nonneg`` and ``support``). Every candidate's
iterate is scored on ``F`` at the *feasible* point ``P_C(x)`` (the ADMM returns exactly that
projection; clfza's FISTA has no support constraint, so its iterate is projected here), and the
PSNR is that of the sensor window of ``P_C(x)`` after the affine fit of
:func:`clfza.metrics.compare` (``fit_affine`` + ``psnr``, no SSIM).

Cases (the ``natural`` scene, scikit-image's camera, 60 % of the sensor width; each noise-free
and at the paper's Fig. 7 noise, Gaussian variance 0.01 on ``y``):

* ``sim256``: the ``simulation`` preset resampled to 256^2 at pitch 0.02 mm (the same sensor
  area; ``r1'^2 / (N p^2) = 0.68``, far from critical sampling, so ``model="auto"`` runs the
  exact model for ADMM; no aperture, so no high-pass; model grid 512^2);
* ``exp300_hp`` / ``exp300_nohp``: the ``experiment`` preset simulated at 300^2, pitch 0.03 mm
  (8x the preset's pixel; as ``bench/bench_tau.py``), finite aperture, with the default
  high-pass (``k = 4``, grid 480^2) and without it (``highpass=0``, grid 480^2).
* ``psf160_photons`` / ``psf160_clean``: a measured PSF
  (:func:`clfza.simulation.simulate_psf_capture`: the camera scene at 160^2 through a
  full-aperture mask, the PSF captured at the scene's depth at 20000 photons and cut to its
  energy support; grid 256^2), the frame at 2000 photons (read noise 2, 8 bits) and
  noise-free, in the measured-PSF route's units (unit-sum PSF, frame divided by its RMS).
  clfza's candidates run the route's own settings (the crop split at ``rho = 4 w`` with
  ``mu1`` fixed, no averaging: clfza.reconstruction's ``_psf_solve``).

``tau`` per case is fixed: the choice of ``tau="auto"`` on the default route
(``clfza.reconstruct(y, cam, "admm", tau="auto", model="exact"[, highpass=0])``, recorded with
its PSNR and time), except ``sim256_fig7``, where that choice (0.0027) is far below the
converged PSNR's best tau: there the hindsight-best of the tau check below (the converged
candidate's PSNR) is used, and the auto tau is reported.

Candidates (all float64 numpy on the host, single-threaded FFTs as in clfza's numpy backend;
all start from zeros except clfza's FISTA, whose exact-model default start is ``K^T y``):

* ``admm``: ``clfza.reconstruct(..., "admm", model="exact", backend="numpy", stop="none")``,
  the crop split of :mod:`clfza.solvers._admm_crop` with its defaults (``mu1`` by residual
  balancing, ``average``, ``relax`` 1, the high-pass where the case has it). Its output at a
  budget of ``k`` iterations is what it returns at ``k``: the better (on ``F``) of the projected
  last iterate and the projected iterate-weighted mean; both are in the JSON.
* ``fista``: ``clfza.reconstruct(..., "fista", model="exact", backend="numpy", nonneg=True,
  stop="none")``, clfza's monotone FISTA on the normalised operator (no high-pass and no
  support option: run on the cases without the high-pass only).
* ``apg``: ``clfza.reconstruct(..., "admm", model="exact", backend="numpy",
  algorithm="apg", stop="none")``, ``fista_restart`` made a solver of clfza
  (:mod:`clfza.solvers._apg_exact`: the same iteration on the model grid, the support through
  the FGP prox's off-region value, ``APG_TV_ITERS`` inner iterations, zero start, the
  high-pass where the case has it).
* ``fista_restart`` (new, here): FISTA (Beck & Teboulle 2009) on ``F`` with function-value
  adaptive restart (O'Donoghue & Candes 2015): momentum reset when ``F`` rises. Step ``1/L``,
  ``L = 1`` on the operator normalised by ``1.02 ||K||`` (clfza's power-iteration norm).
  The prox of ``w TV + i_C`` is FGP (Beck & Teboulle 2009) with ``FR_INNER`` warm-started
  inner iterations, on the object region padded by one zero row and column (the grid's
  circular TV of a point that is zero off the region equals that array's circular TV, exactly),
  so the prox costs a region-sized array, not a grid-sized one. ``A x_k`` is kept, so ``A y``
  of the extrapolated point is a linear combination and ``F(x_k)`` needs no extra FFT: two
  real FFT pairs per iteration on the grid, like the ADMM.
* ``pdhg`` (new, here): Pock-Chambolle primal-dual (PDHG) on ``[A; D]`` with ``G = i_C``,
  ``F1* `` the data term's conjugate, ``F2*`` the TV ball. Diagonal preconditioning: Pock &
  Chambolle's (2011) ``alpha = 1`` sums ``sum_j |M_ij|`` are, for the oscillating zone
  kernels (the simulation preset and the high-passed model), 40-90x ``||A||`` (measured and
  recorded as ``pc_abs_sum_ratio``), which would make ``tau sigma ||A||^2`` ~ 5e-4; so the
  preconditioner is block-diagonal with a scalar per block (``sigma_A = GAMMA_A / tau``,
  ``sigma_D = (1 - GAMMA_A) / (8 tau)``, ``tau (sigma_A ||A||^2 + sigma_D ||D||^2) < 1``) and
  the primal-dual ratio ``tau`` is balanced by residuals (Goldstein, Li, Yuan, Esser &
  Baraniuk 2015). Two real FFT pairs per iteration. Tried in the prototype (400-800 iterations,
  all cases): ``GAMMA_A`` 0.5 / 0.9, ``tau0`` 1 / 10, with and without the balancing: the
  same or slower.

* ``ld_cg`` (new, here; not in the default set): a Krylov method on the data term, TV by
  lagged diffusivity (Vogel & Oman 1996): outer steps freeze the TV weights
  ``1 / sqrt(|D x|^2 + LD_EPS^2)`` and run ``LD_INNER`` warm-started conjugate-gradient steps
  on ``(A^T A + w D^T W D) x = A^T b`` over the object region; no non-negativity (CG has no
  projection). One ``A^T A`` product per CG step, two real FFT pairs, as the others' iteration.
  It asks whether an accelerated Krylov solve of the smooth part reaches the image sooner
  than the splitting methods when ``tau`` is small (noise-free frames).

``f_ref``: the lowest ``F`` any run reached, including ``fista_restart`` continued to
``--ref-iters`` (default 20x ADMM's 400) or until its objective changes by less than
``REF_STALL`` relative over ``REF_WINDOW`` iterations; the JSON names the run and iteration
and gives that stall. Gap = ``(F - f_ref) / f_ref``.

Time. The traces carry the raw clock of each run (checkpoint evaluation excluded), which the
other load of a shared 2-core machine inflates unevenly; the table's seconds are
``iterations x`` the candidate's median cost per iteration on that case, measured in separate
short runs (``COST_ITERS`` iterations, no checkpoints, ``COST_ROUNDS`` rounds with the
case's candidates interleaved in each), in the same process. The load averages at the start
and end are in the JSON.

The tau check (on by default; ``--no-tau-check``): PSNR(tau) at 4-5 taus on ``sim256_fig7``
(including the auto tau) for ADMM at its default budget (400 iterations, returned output) and
for the converged ``fista_restart``, to see whether a converged solver's PSNR(tau) is smooth.

Writes ``bench/results/exact_convergence_<machine>.{json,md,png}`` (``--replot JSON`` rewrites
the markdown and the plot of a saved run). Issue 33's own case, the simulation preset as it is
(512^2, grid 1024^2), is too slow for the default set; its tau check runs alone with
``--cases --tau-check-case sim512_fig7 --tau-check-taus 0.03 0.1 --tau-check-iters 2000
--tag sim512_taucheck``.

    .venv/bin/python bench/bench_exact_convergence.py [--iters 1000] [--ref-iters 8000]
        [--cases sim256_clean exp300_hp_fig7 ...] [--candidates admm apg ...]
        [--case-tau sim256_fig7=0.1] [--no-tau-check] [--tag TAG]

Measured (AMD EPYC, 2 usable cores shared with other work, load average 1-3.5;
``bench/results/exact_convergence_amd-epyc-2c*``; iteration counts are at checkpoints, every
20 up to 400, every 50 to 1000, every 250 beyond):

* Finite aperture with the high-pass, Fig. 7 noise (tau=auto 0.41): ADMM within 1 % of
  ``f_ref`` at 200 iterations, 0.1 % at 850; ``fista_restart`` at 140 and 300 (about half
  the time per iteration here). ADMM at its 400 is 0.3 % above ``f_ref`` with 33.1 dB, the
  minimiser 32.9 dB: the default route delivers there.
* The same noise-free (tau=auto 7e-5): ADMM is 33 % above ``f_ref`` at 400 (62.5 dB) and
  8.5 % at 1000 (68.5 dB); ``fista_restart`` reaches 1 % at 1000 and 0.1 % at 1250
  iterations (89.3 dB); the minimiser has 90.2 dB.
* Without the high-pass ADMM's gap stays between 10^3 and 10^5 through 1000 iterations
  (27.3 / 25.8 dB at 400); ``fista_restart`` reaches 1 % at 3000 / 1250
  (noise-free / Fig. 7), towards 52.9 / 30.3 dB. clfza's FISTA (no support constraint) and
  ``pdhg`` are far behind everywhere (``pdhg`` within 1 % once, at 650 iterations).
* Simulation preset at 256^2 (no aperture): noise-free (tau=auto 2.2e-4) no candidate is
  within 1 % by 1000 (ADMM 6.7 %, 39.8 dB); ``fista_restart`` reaches it at 1500 (60.7 dB),
  the minimiser 66.9 dB against ADMM's 32.9 dB at 400. Fig. 7 noise at tau 0.1: ADMM 1 % at
  80 iterations, ``fista_restart`` at 100; both end at 28.9 dB.
* At 400 iterations ADMM's PSNR is above ``fista_restart``'s in all six cases, though its
  objective is the higher in five: PSNR does not follow the objective on the way (at a 1 % gap the
  candidates' PSNR differs by up to 6.5 dB), only near the minimiser.
* Measured PSF (``--cases psf160_photons psf160_clean --candidates admm apg fista_restart
  --iters 1000 --ref-iters 4000 --no-tau-check --tag psf160``): at 2000 photons (tau=auto
  9.4e-4) the ADMM is within 1 % of ``f_ref`` at 160 iterations and 0.1 % at 260 (21.46 dB;
  the minimiser 21.34); noise-free (tau=auto 2.2e-5) its gap grows (8.4 at 400, 15 at 1000;
  24.5 / 31.9 dB: ``mu1`` fixed at the route's 0.02 is far too small for that tau), where
  ``apg`` and ``fista_restart`` reach 1 % at 650 (33.66 dB, the minimiser 33.65). The
  default route still returns 33.67 dB there: its final solve starts from its pilot passes'
  image.
* PSNR(tau) of the converged solve is smooth and unimodal (sim256_fig7, tau 0.0027 (auto),
  0.01, 0.03, 0.1, 0.3: 10.7, 12.3, 19.8, 28.9, 28.7 dB; ADMM at 400: 13.0, 15.5, 20.6,
  29.1, 28.7). At the preset's 512^2 (tau=auto 0.0093): ``fista_restart`` after 2000
  iterations (its F still falling by 1e-5-2e-4 per 500; ADMM at 400 within 0.14 % of it)
  15.7 dB, ADMM at 400 16.6; at tau 0.1 29.2 and 30.0 dB. Issue 33's 15.9 dB is the tau
  rule without the high-pass, not convergence.
"""

from __future__ import annotations

import argparse
import contextlib
import json
import math
import subprocess
import time
import warnings
from dataclasses import dataclass
from pathlib import Path
from unittest import mock

import numpy as np
import scipy.fft

import clfza
import clfza.solvers._driver as solver_driver
import clfza.solvers._run as solver_run
from clfza import regularizers as R
from clfza.backends import exact_model
from clfza.benchmarks import _scenes as scenes
from clfza.benchmarks._machine import machine_record, machine_slug
from clfza.benchmarks._report import machine_lines, write_result_files
from clfza.metrics import compare, fit_affine, psnr
from clfza.models import (
    NORM_SAFETY,
    camera_model,
    crop_to_support,
    default_halfwidth,
    highpass_frame,
    highpass_model,
    load_psf,
)
from clfza.simulation import Noise, simulate_psf_capture
from clfza.solvers import default_iters
from clfza.solvers._common import Monitor

RESULTS = Path(__file__).parent / "results"
ROOT = Path(__file__).resolve().parents[1]
FIG7 = Noise(gaussian_var=0.01)
# a measured-PSF capture's sensor (tests/test_tau_psf.py's), and its PSF capture's
PSF_NOISE = Noise(photons=2000.0, read_noise=2.0, bit_depth=8, exposure=0.9, seed=1)
PSF_CAPTURE_NOISE = Noise(photons=20000.0, read_noise=2.0, bit_depth=8, exposure=0.9, seed=2)

FR_INNER = 5  # FGP iterations per prox in fista_restart (warm-started dual)
LD_INNER = 25  # ld_cg: CG steps per outer (lagged-diffusivity) step
LD_EPS = 1e-3  # ld_cg: the TV weights' smoothing, in the normalised units
GAMMA_A = 0.5  # pdhg: the data block's share of the step condition
PDHG_TAU0 = 1.0
REF_STALL = 1e-7  # the reference run stops when F changes by less than this ...
REF_WINDOW = 500  # ... relative over this many iterations
COST_ITERS = 30
COST_ROUNDS = 5  # rounds of short runs, the candidates of a case interleaved in each
GAPS = (1e-2, 1e-3, 1e-4)
TAU_CHECK_CASE = "sim256_fig7"
TAU_CHECK_TAUS = (0.01, 0.03, 0.1, 0.3)  # plus the case's tau="auto" choice


@dataclass(frozen=True)
class Case:
    name: str
    preset: str  # a camera preset, or "psf": a measured-PSF capture (simulate_psf_capture)
    shape: tuple[int, int]
    pitch: float
    noise: Noise | None
    highpass: bool  # the default high-pass (where the camera has one) or none

    def camera(self) -> clfza.Camera:
        return clfza.Camera.preset(self.preset).with_shape(self.shape, self.pitch)


@dataclass
class PsfMeasurement:
    """A measured-PSF case's frame, truth and PSF in the measured-PSF route's scale-free units
    (clfza.reconstruction's ``_psf_solve``: the PSF at unit sum, the frame divided by its RMS
    about its mean), so that the route's own normalisation is the identity and ``tau`` means
    the same to every candidate."""

    y: np.ndarray
    truth: np.ndarray
    psf: np.ndarray
    camera: clfza.Camera


def psf_measurement(case: Case) -> PsfMeasurement:
    """The camera scene captured through a full-aperture mask, its PSF at the scene's depth
    (no scale search: the scale is known) cut to its energy support, the frame in the route's
    units."""
    from skimage import data

    cap = simulate_psf_capture(data.camera(), shape=case.shape, scene_z1=400.0, psf_z1=400.0,
                               noise=case.noise, psf_noise=PSF_CAPTURE_NOISE)
    # cut to its energy support as the route cuts it, so that every candidate has its grid
    psf = crop_to_support(load_psf(cap.psf, background="border", center="centroid")).array
    psf = psf / psf.sum()
    y = np.asarray(cap.y, np.float64)
    y = y / float(np.sqrt(np.mean((y - y.mean()) ** 2)))
    return PsfMeasurement(y, np.asarray(cap.truth, np.float64), psf, cap.camera)


CASES = {c.name: c for c in (
    Case("sim256_clean", "simulation", (256, 256), 0.02, None, True),
    Case("sim256_fig7", "simulation", (256, 256), 0.02, FIG7, True),
    Case("exp300_hp_clean", "experiment", (300, 300), 0.03, None, True),
    Case("exp300_hp_fig7", "experiment", (300, 300), 0.03, FIG7, True),
    Case("exp300_nohp_clean", "experiment", (300, 300), 0.03, None, False),
    Case("exp300_nohp_fig7", "experiment", (300, 300), 0.03, FIG7, False),
    # issue 33's own case (the preset as it is; grid 1024^2): not in the default set
    Case("sim512_fig7", "simulation", (512, 512), 0.01, FIG7, True),
    # measured PSFs (issue 33 item 1's third kind; issue 34): a capture of the camera scene
    # at 2000 photons (as tests/test_tau_psf.py) and noise-free
    Case("psf160_photons", "psf", (160, 160), 0.0066, PSF_NOISE, False),
    Case("psf160_clean", "psf", (160, 160), 0.0066, None, False),
)}
DEFAULT_CASES = [n for n in CASES if n != "sim512_fig7"]


# ------------------------------------------------------------------------------------------
# the problem
# ------------------------------------------------------------------------------------------
class Problem:
    """``F`` of one case in user units, and the normalised pieces the new candidates use:
    ``A = K_d / s``, ``b = P y_d / s``, ``w = tau / (2 s^2)`` (``s = 1.02 ||K_d||``, the
    normalisation of clfza's exact backends), so ``F = s^2 (1/2 ||A x - b||^2 + w TV(x))``
    on ``C``. Arrays of the new candidates live on the *work array*: the object region padded
    by one zero row and column (``sub``)."""

    def __init__(self, cam: clfza.Camera, y: np.ndarray, truth: np.ndarray, tau: float,
                 highpass: bool, psf: np.ndarray | None = None):
        self.psf = psf
        base = camera_model(cam) if psf is None else exact_model(cam, psf)
        self.k = default_halfwidth(cam, None) if highpass else 0
        self.model = m = highpass_model(base, self.k) if self.k else base
        yd = highpass_frame(y, self.k) if self.k else np.asarray(y, np.float64)
        self.yd = m.remove_mean(yd)
        self.s = NORM_SAFETY * m.norm
        self.Hn = m.Hs / self.s
        self.b = self.yd / self.s
        self.tau = float(tau)
        self.w = self.tau / 2.0 / self.s**2
        self.truth = truth
        self.shape = m.shape
        g = m.geom
        self.geom = g
        (oy, ox), (sy, sx), mg = g.offset, g.sensor, g.margin
        self.r0 = (oy - mg, ox - mg)
        self.rshape = (sy + 2 * mg, sx + 2 * mg)
        self.sub = tuple(min(r + 1, n) for r, n in zip(self.rshape, self.shape, strict=True))
        self.mask = np.zeros(self.sub)
        self.mask[:self.rshape[0], :self.rshape[1]] = 1.0
        self.region = self.embed(self.mask)

    # work array <-> grid
    def embed(self, a: np.ndarray) -> np.ndarray:
        out = np.zeros(self.shape)
        (r, c), (h, w) = self.r0, self.sub
        out[r:r + h, c:c + w] = a
        return out

    def extract(self, a: np.ndarray) -> np.ndarray:
        (r, c), (h, w) = self.r0, self.sub
        return a[r:r + h, c:c + w]

    # the normalised operator on work arrays (one real FFT pair each, on the grid)
    def A(self, xs: np.ndarray) -> np.ndarray:
        v = scipy.fft.irfft2(scipy.fft.rfft2(self.embed(xs)) * self.Hn, s=self.shape)
        c = self.geom.crop(v)
        return c - c.mean()

    def AT(self, r: np.ndarray) -> np.ndarray:
        e = self.geom.embed(r - r.mean())
        return self.extract(scipy.fft.irfft2(scipy.fft.rfft2(e) * np.conj(self.Hn),
                                             s=self.shape))

    def proj(self, xs: np.ndarray) -> np.ndarray:
        return np.maximum(xs, 0.0) * self.mask

    def f_norm(self, xs: np.ndarray, Ax: np.ndarray) -> float:
        """``F / s^2`` of a feasible work array with its ``A x``."""
        return 0.5 * float(np.sum((Ax - self.b) ** 2)) + self.w * tv_value(xs)

    # the score of any candidate: F and PSNR of P_C(x), x a grid array in user units
    def evaluate(self, x: np.ndarray) -> tuple[float, float]:
        xp = np.maximum(x, 0.0) * self.region
        r = self.model.forward(xp) - self.yd
        F = 0.5 * float(np.sum(r * r)) + 0.5 * self.tau * R.tv_value(xp)
        img = self.model.image_geom.crop(xp)
        return F, psnr(fit_affine(img, self.truth), self.truth)

    def pc_abs_sum_ratio(self) -> float:
        """Pock & Chambolle's alpha = 1 preconditioner against the block-scalar one:
        ``||A||^2 / (median column |A| sum + 4) / (median row |A| sum)`` over the region
        (the mean removal left out): the ``tau sigma ||A||^2`` it would give the data block."""
        habs = scipy.fft.rfft2(np.abs(self.model.kernel_grid) / self.s)
        col = scipy.fft.irfft2(scipy.fft.rfft2(self.geom.sensor_mask()) * np.conj(habs),
                               s=self.shape)[self.region > 0]
        row = self.geom.crop(scipy.fft.irfft2(scipy.fft.rfft2(self.region) * habs,
                                              s=self.shape))
        nrm = self.model.norm / self.s
        return float(nrm**2 / (np.median(col) + 4.0) / np.median(row))


# circular differences on a work array (= grid differences of a point zero off the region)
def grad(x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    d1 = np.empty_like(x)
    d2 = np.empty_like(x)
    np.subtract(x[:, 1:], x[:, :-1], out=d1[:, 1:])
    np.subtract(x[:, 0], x[:, -1], out=d1[:, 0])
    np.subtract(x[1:], x[:-1], out=d2[1:])
    np.subtract(x[0], x[-1], out=d2[0])
    return d1, d2


def grad_T(d1: np.ndarray, d2: np.ndarray) -> np.ndarray:
    out = np.empty_like(d1)
    np.subtract(d1[:, :-1], d1[:, 1:], out=out[:, :-1])
    np.subtract(d1[:, -1], d1[:, 0], out=out[:, -1])
    out[:-1] += d2[:-1]
    out[:-1] -= d2[1:]
    out[-1] += d2[-1] - d2[0]
    return out


def tv_value(x: np.ndarray) -> float:
    d1, d2 = grad(x)
    return float(np.sum(np.sqrt(d1 * d1 + d2 * d2)))


def fgp_prox(v: np.ndarray, lam: float, iters: int, p: tuple, mask: np.ndarray):
    """``argmin_z 1/2 ||z - v||^2 + lam TV(z) + i_C(z)`` by FGP, dual warm-started from
    ``p``; returns ``(z, p)``."""
    p1, p2 = p
    r1, r2 = p1, p2
    t = 1.0
    step = 1.0 / (8.0 * lam)
    for _ in range(iters):
        z = np.maximum(v - lam * grad_T(r1, r2), 0.0)
        z *= mask
        d1, d2 = grad(z)
        d1 *= step
        d2 *= step
        d1 += r1
        d2 += r2
        n = np.sqrt(d1 * d1 + d2 * d2)
        np.maximum(n, 1.0, out=n)
        d1 /= n
        d2 /= n
        t_new = 0.5 * (1.0 + math.sqrt(1.0 + 4.0 * t * t))
        mom = (t - 1.0) / t_new
        r1 = d1 + mom * (d1 - p1)
        r2 = d2 + mom * (d2 - p2)
        p1, p2, t = d1, d2, t_new
    z = np.maximum(v - lam * grad_T(p1, p2), 0.0)
    z *= mask
    return z, (p1, p2)


# ------------------------------------------------------------------------------------------
# traces
# ------------------------------------------------------------------------------------------
class Trace:
    """Checkpoints of one run of a new candidate: ``(iteration, clock s, F, PSNR)``; the
    evaluation is off the clock."""

    def __init__(self, prob: Problem, checkpoints):
        self.prob = prob
        self.at = set(checkpoints)
        self.rows: list[dict] = []
        self.pause = 0.0
        self.t0 = time.perf_counter()
        self.stats: dict = {}

    def maybe(self, it: int, xs: np.ndarray) -> None:
        if it not in self.at:
            return
        ti = time.perf_counter()
        F, p = self.prob.evaluate(self.prob.embed(xs))
        self.rows.append({"iteration": it, "time_s": ti - self.t0 - self.pause,
                          "objective": F, "psnr": p})
        self.pause += time.perf_counter() - ti

    def elapsed(self) -> float:
        return time.perf_counter() - self.t0 - self.pause


def fista_restart(prob: Problem, iters: int, checkpoints=(), inner: int = FR_INNER,
                  stall: tuple[float, int] | None = None) -> Trace:
    """FISTA with function-value restart on ``F`` (see the module docstring). ``stall``
    ``(rel, window)``: stop once ``F`` changed by less than ``rel`` over ``window``
    iterations (the reference run)."""
    tr = Trace(prob, checkpoints)
    x = np.zeros(prob.sub)
    Ax = np.zeros_like(prob.b)
    xo, Axo = x, Ax
    p = (np.zeros(prob.sub), np.zeros(prob.sub))
    t, beta = 1.0, 0.0
    fx = prob.f_norm(x, Ax)
    best = [fx]  # the lowest F so far, per iteration
    restarts = 0
    tr.maybe(0, x)
    it = 0
    for it in range(1, iters + 1):
        if beta:
            y = x + beta * (x - xo)
            Ay = Ax + beta * (Ax - Axo)
        else:
            y, Ay = x, Ax
        g = prob.AT(Ay - prob.b)
        z, p = fgp_prox(y - g, prob.w, inner, p, prob.mask)  # L = 1
        Az = prob.A(z)
        fz = prob.f_norm(z, Az)
        if fz > fx:  # O'Donoghue & Candes: keep the point, reset the momentum
            t, beta = 1.0, 0.0
            restarts += 1
        else:
            t_new = 0.5 * (1.0 + math.sqrt(1.0 + 4.0 * t * t))
            beta, t = (t - 1.0) / t_new, t_new
        xo, Axo, x, Ax, fx = x, Ax, z, Az, fz
        best.append(min(best[-1], fx))
        tr.maybe(it, x)
        if stall and it >= stall[1] and best[-stall[1] - 1] - best[-1] <= stall[0] * best[-1]:
            break
    tr.stats = {"restarts": restarts, "iterations": it, "inner": inner}
    if it not in tr.at:
        tr.at.add(it)
        tr.maybe(it, x)
    return tr


def pdhg(prob: Problem, iters: int, checkpoints=(), gamma_a: float = GAMMA_A,
         tau0: float = PDHG_TAU0, adapt: bool = True) -> Trace:
    """PDHG with block-scalar (diagonal) preconditioning and residual balancing of the
    primal-dual ratio (see the module docstring)."""
    tr = Trace(prob, checkpoints)
    x = np.zeros(prob.sub)
    Ax = np.zeros_like(prob.b)
    p = np.zeros_like(prob.b)
    q1, q2 = np.zeros(prob.sub), np.zeros(prob.sub)
    ATp, DTq = np.zeros(prob.sub), np.zeros(prob.sub)
    tau = tau0
    ga, gd = 0.99 * gamma_a, 0.99 * (1.0 - gamma_a) / 8.0
    alpha, eta, delta = 0.5, 0.95, 1.5
    w = prob.w
    changes = 0
    tr.maybe(0, x)
    for it in range(1, iters + 1):
        sa, sd = ga / tau, gd / tau
        xn = prob.proj(x - tau * (ATp + DTq))
        Axn = prob.A(xn)
        xb = 2.0 * xn - x
        pn = (p + sa * (2.0 * Axn - Ax - prob.b)) / (1.0 + sa)
        d1, d2 = grad(xb)
        a1 = q1 + sd * d1
        a2 = q2 + sd * d2
        sc = 1.0 / np.maximum(1.0, np.sqrt(a1 * a1 + a2 * a2) / w)
        q1n, q2n = a1 * sc, a2 * sc
        ATpn, DTqn = prob.AT(pn), grad_T(q1n, q2n)
        if adapt:  # Goldstein et al. 2015: primal and dual residuals in their metrics
            dx = x - xn
            prim = float(np.linalg.norm(dx / tau - (ATp - ATpn) - (DTq - DTqn)))
            e1, e2 = grad(dx)
            dual = math.sqrt(float(np.sum(((p - pn) / sa - (Ax - Axn)) ** 2))
                             + float(np.sum(((q1 - q1n) / sd - e1) ** 2
                                            + ((q2 - q2n) / sd - e2) ** 2)))
            if prim > delta * dual:
                tau, alpha, changes = tau / (1.0 - alpha), alpha * eta, changes + 1
            elif prim < dual / delta:
                tau, alpha, changes = tau * (1.0 - alpha), alpha * eta, changes + 1
        x, Ax, p, q1, q2, ATp, DTq = xn, Axn, pn, q1n, q2n, ATpn, DTqn
        tr.maybe(it, x)
    tr.stats = {"tau_final": tau, "tau_changes": changes, "gamma_a": gamma_a, "tau0": tau0}
    return tr


def ld_cg(prob: Problem, iters: int, checkpoints=(), inner: int = LD_INNER,
          eps: float = LD_EPS) -> Trace:
    """Lagged-diffusivity TV with conjugate-gradient inner solves on the region (see the module
    docstring); ``iters`` counts CG steps (one ``A^T A`` product each)."""
    tr = Trace(prob, checkpoints)
    m = prob.mask
    x = np.zeros(prob.sub)
    rhs = prob.AT(prob.b) * m
    tr.maybe(0, x)
    it = 0
    outer = 0
    while it < iters:
        d1, d2 = grad(x)
        wt = 1.0 / np.sqrt(d1 * d1 + d2 * d2 + eps * eps)

        def op(v, wt=wt):
            g1, g2 = grad(v)
            return (prob.AT(prob.A(v * m)) + prob.w * grad_T(wt * g1, wt * g2)) * m

        r = rhs - op(x)
        p = r.copy()
        rr = float(np.sum(r * r))
        for _ in range(min(inner, iters - it)):
            q = op(p)
            alpha = rr / float(np.sum(p * q))
            x = x + alpha * p
            r = r - alpha * q
            rn = float(np.sum(r * r))
            p = r + (rn / rr) * p
            rr = rn
            it += 1
            tr.maybe(it, x)
        outer += 1
    tr.stats = {"outer": outer, "inner": inner, "eps": eps}
    return tr


# ------------------------------------------------------------------------------------------
# clfza's own solvers, with their iterates captured at checkpoints
# ------------------------------------------------------------------------------------------
class CaptureMonitor(Monitor):
    """clfza's monitor that also keeps host copies of the iterate at each checkpoint (the
    ADMM's last iterate and its mean both), off the solve clock."""

    def record(self, it, x, objective, **extra):
        t = time.perf_counter()
        s = getattr(self, "solver", None)
        if s is not None and getattr(s, "xbar", None) is not None:
            snap = {"last": self.B.to_host(s.x).copy(), "mean": self.B.to_host(s.xbar).copy()}
        else:
            snap = {"x": self.B.to_host(x).copy()}
        self.snaps = getattr(self, "snaps", {})
        self.snaps.setdefault(int(it), snap)
        self.overhead += time.perf_counter() - t
        return super().record(it, x, objective, **extra)


@contextlib.contextmanager
def capture():
    """Patch the monitor clfza's run_solver builds and hand each solver to its monitor."""
    monitors = []
    run = solver_driver.run

    def run_capturing(solver, x0):
        solver.mon.solver = solver
        monitors.append(solver.mon)
        return run(solver, x0)

    with mock.patch.object(solver_run, "Monitor", CaptureMonitor), \
            mock.patch.object(solver_driver, "run", run_capturing):
        yield monitors


#: the candidates that are clfza's own solvers: candidate -> the method clfza runs
CLFZA_RUNS = {"admm": "admm", "apg": "admm", "fista": "fista"}
CANDIDATES = ("admm", "apg", "fista", "fista_restart", "pdhg")
ALL_CANDIDATES = CANDIDATES + ("ld_cg",)


def clfza_options(method: str, prob: Problem) -> dict:
    """The options of clfza's candidates (``apg``: the exact model's ``algorithm="apg"``;
    with a measured PSF, the PSF, and no high-pass option: the route has none)."""
    if prob.psf is not None:
        return {"psf": prob.psf} | ({"algorithm": "apg"} if method == "apg" else {}) | (
            {} if method in ("admm", "apg") else {"nonneg": True})
    if method in ("admm", "apg"):
        return ({} if prob.k else {"highpass": 0}) | (
            {"algorithm": "apg"} if method == "apg" else {})
    return {"nonneg": True}


def run_clfza(prob: Problem, cam, y, method: str, iters: int, checkpoints) -> list[dict]:
    with capture() as monitors:
        r = clfza.reconstruct(y, cam, CLFZA_RUNS[method], model="exact", backend="numpy",
                              tau=prob.tau,
                              iters=iters, stop="none", checkpoints=sorted(checkpoints),
                              **clfza_options(method, prob))
    mon = monitors[-1]
    c = r.info.stats.get("data_scale_factor", 1.0)  # a measured PSF: its own units
    rows = []
    for rec in mon.records:
        it = rec["iteration"]
        scores = {k: prob.evaluate(c * a[0]) for k, a in mon.snaps[it].items()}
        best = min(scores, key=lambda k: scores[k][0])
        row = {"iteration": it, "time_s": rec["time"], "objective": scores[best][0],
               "psnr": scores[best][1]}
        if len(scores) > 1:
            row["returned"] = best
            row.update({f"{k}_objective": v[0] for k, v in scores.items()})
            row.update({f"{k}_psnr": v[1] for k, v in scores.items()})
        rows.append(row)
    return rows


def one_cost(prob: Problem, cam, y, name: str) -> float:
    """Seconds per iteration of one short run without checkpoints."""
    if name in CLFZA_RUNS:
        r = clfza.reconstruct(y, cam, CLFZA_RUNS[name], model="exact", backend="numpy",
                              tau=prob.tau, iters=COST_ITERS, stop="none",
                              **clfza_options(name, prob))
        return r.info.timings["solve"] / r.info.iterations
    run = {"fista_restart": fista_restart, "ld_cg": ld_cg}.get(name, pdhg)
    tr = run(prob, COST_ITERS)
    return tr.elapsed() / COST_ITERS


def costs_per_iteration(prob: Problem, cam, y, names) -> dict:
    """Per candidate, the seconds per iteration of ``COST_ROUNDS`` short runs, the
    candidates interleaved round by round (a burst of the machine's other load then falls on
    all of them, not on one)."""
    samples: dict = {n: [] for n in names}
    for _ in range(COST_ROUNDS):
        for n in names:
            samples[n].append(one_cost(prob, cam, y, n))
    return samples


# ------------------------------------------------------------------------------------------
# one case
# ------------------------------------------------------------------------------------------
def checkpoint_list(iters: int, ref_iters: int) -> list[int]:
    pts = {0, 5, 10, 15, 20, 30, 40, 50, 60, 70, 80, 90, 100}
    pts |= set(range(100, 400, 20)) | set(range(400, iters + 1, 50)) | {iters}
    pts |= set(range(iters, ref_iters + 1, 250)) | {ref_iters}
    return sorted(p for p in pts if p <= ref_iters)


def default_route(meas, cam, case: Case) -> dict:
    """``tau="auto"`` on the default route (OpenCL, float32; the numpy backend where OpenCL
    fails): its tau, PSNR and time."""
    kw = ({"psf": meas.psf} if case.preset == "psf" else {} if case.highpass
          else {"highpass": 0})
    for backend in ("opencl", "numpy"):
        try:
            t0 = time.perf_counter()
            r = clfza.reconstruct(meas.y, cam, "admm", tau="auto", model="exact",
                                  backend=backend, **kw)
            a = r.info.stats.get("tau_auto", {})
            return {"backend": backend, "tau": float(r.info.params["tau"]),
                    "psnr": compare(r.image, meas.truth)["psnr"],
                    "wall_s": time.perf_counter() - t0, "iterations": r.info.iterations,
                    "pilot_iterations": a.get("stage_iterations_total", 0),
                    "continued": a.get("continued"), "rule": a.get("rule"),
                    "image": np.asarray(r.image, np.float64)}
        except Exception as exc:  # noqa: BLE001 - record and fall back to numpy
            err = f"{backend}: {exc}"
    return {"error": err}


def crossing(rows: list[dict], f_ref: float, gap: float) -> dict:
    """First checkpoint with gap <= ``gap``, and the first after which it stays there."""
    first = stay = None
    for i, r in enumerate(rows):
        ok = (r["objective"] - f_ref) / f_ref <= gap
        if ok and first is None:
            first = r
        if ok and stay is None and all((s["objective"] - f_ref) / f_ref <= gap
                                       for s in rows[i:]):
            stay = r
    return {"first_iteration": None if first is None else first["iteration"],
            "first_psnr": None if first is None else first["psnr"],
            "stays_iteration": None if stay is None else stay["iteration"],
            "stays_psnr": None if stay is None else stay["psnr"]}


def run_case(case: Case, iters: int, ref_iters: int, tau: float | None = None,
             log=print, candidates=CANDIDATES) -> dict:
    if case.preset == "psf":
        meas = psf_measurement(case)
        cam = meas.camera
    else:
        cam = case.camera()
        meas = scenes.measurement("natural", cam, case.noise).measurement
    route = default_route(meas, cam, case)
    tau_used = route["tau"] if tau is None else tau
    prob = Problem(cam, meas.y, meas.truth, tau_used, case.highpass,
                   getattr(meas, "psf", None))
    image = route.pop("image", None)
    if image is not None and tau is None:  # the route's own image on F (its own tau)
        route["objective"] = prob.evaluate(prob.model.image_geom.embed(image))[0]
    cps = checkpoint_list(iters, ref_iters)
    main_cps = [c for c in cps if c <= iters]
    out = {"case": case.name, "preset": case.preset, "shape": list(case.shape),
           "pitch_mm": case.pitch, "noise": None if case.noise is None else (
               "photons=2000, read noise 2, 8 bits" if case.preset == "psf"
               else "gaussian_var=0.01"),
           "highpass_k": prob.k, "model_grid": list(prob.shape), "work_array": list(prob.sub),
           "regime_ratio": None if prob.psf is not None else cam.regime.ratio,
           "operator_norm": prob.model.norm,
           "default_route": route, "tau": tau_used,
           "tau_source": "tau='auto' of the default route" if tau is None else
           "fixed: the tau check's hindsight-best (converged fista_restart) or --case-tau",
           "pc_abs_sum_ratio": prob.pc_abs_sum_ratio(), "iters": iters, "runs": {}}
    log(f"== {case.name}: tau {tau_used:.4g} ({out['tau_source']}), high-pass k={prob.k}, "
        f"grid {prob.shape}; default route {route.get('psnr', float('nan')):.2f} dB")
    names = [n for n in ALL_CANDIDATES
             if n in candidates and (n != "fista" or prob.k == 0)]
    if "fista_restart" not in names:
        names.append("fista_restart")  # the reference run
    for name in names:
        t0 = time.perf_counter()
        if name in CLFZA_RUNS:
            rows, stats = run_clfza(prob, cam, meas.y, name, iters, main_cps), {}
        elif name == "fista_restart":
            tr = fista_restart(prob, ref_iters, cps, stall=(REF_STALL, REF_WINDOW))
            rows, stats = tr.rows, tr.stats
        else:
            tr = (ld_cg if name == "ld_cg" else pdhg)(prob, iters, main_cps)
            rows, stats = tr.rows, tr.stats
        out["runs"][name] = {"rows": rows, "stats": stats, "wall_s": time.perf_counter() - t0}
        last = [r for r in rows if r["iteration"] <= iters][-1]
        log(f"   {name:14s} F({last['iteration']}) = {last['objective']:.6g}, "
            f"PSNR {last['psnr']:.2f} dB, {time.perf_counter() - t0:.0f} s wall", flush=True)
    for name, samples in costs_per_iteration(prob, cam, meas.y, names).items():
        run = out["runs"][name]
        run["cost_samples_s"] = samples
        run["cost_per_iter_s"] = float(np.median(samples))
    log(f"   ms per iteration (median of {COST_ROUNDS} interleaved rounds): "
        + ", ".join(f"{n} {1e3 * r['cost_per_iter_s']:.1f}" for n, r in out["runs"].items()),
        flush=True)
    # the reference
    best = min(((n, r) for n, run in out["runs"].items() for r in run["rows"]),
               key=lambda nr: nr[1]["objective"])
    f_ref = best[1]["objective"]
    fr = out["runs"]["fista_restart"]["rows"]
    tail = [r for r in fr if r["iteration"] >= fr[-1]["iteration"] - REF_WINDOW]
    out["f_ref_from"] = {"run": best[0], "iteration": best[1]["iteration"],
                         "psnr": best[1]["psnr"]}
    if "objective" in route:
        if route["objective"] < f_ref:
            f_ref = route["objective"]
            out["f_ref_from"] = {"run": "default_route", "iteration": route["iterations"]
                                 + route["pilot_iterations"], "psnr": route["psnr"]}
        route["gap"] = (route["objective"] - f_ref) / f_ref
    out["f_ref"] = f_ref
    out["reference_run"] = {"run": "fista_restart",
                            "iterations": out["runs"]["fista_restart"]["stats"]["iterations"],
                            "relative_change_last_window": (tail[0]["objective"]
                                                            - tail[-1]["objective"])
                            / tail[-1]["objective"], "window": REF_WINDOW}
    for run in out["runs"].values():
        rows = [r for r in run["rows"] if r["iteration"] <= iters]
        for r in run["rows"]:
            r["gap"] = (r["objective"] - f_ref) / f_ref
        summ = {}
        for gap in GAPS:
            c = crossing(rows, f_ref, gap)
            for key in ("first", "stays"):
                it = c[f"{key}_iteration"]
                c[f"{key}_seconds"] = None if it is None else it * run["cost_per_iter_s"]
            summ[f"{gap:g}"] = c
        at400 = [r for r in rows if r["iteration"] == default_iters("admm", "exact")]
        summ["at_400"] = at400[0] if at400 else None
        summ["at_end"] = rows[-1]
        run["summary"] = summ
    return out


def tau_check(case: Case, taus, max_iters: int, log=print) -> dict:
    """PSNR(tau): ADMM at its default budget (returned output) and the converged
    fista_restart (the reference run's stall rule, at most ``max_iters`` iterations)."""
    cam = case.camera()
    meas = scenes.measurement("natural", cam, case.noise).measurement
    route = default_route(meas, cam, case)
    rows = []
    n = default_iters("admm", "exact")
    for tau in sorted({*taus, route["tau"]}):
        prob = Problem(cam, meas.y, meas.truth, tau, case.highpass)
        a = run_clfza(prob, cam, meas.y, "admm", n, [n])[-1]
        tr = fista_restart(prob, max_iters, range(0, max_iters + 1, REF_WINDOW),
                           stall=(REF_STALL, REF_WINDOW))
        f = tr.rows[-1]
        before = [r for r in tr.rows if r["iteration"] <= f["iteration"] - REF_WINDOW]
        change = ((before[-1]["objective"] - f["objective"]) / f["objective"]
                  if before else None)
        gap_admm = (a["objective"] - f["objective"]) / f["objective"]
        rows.append({"tau": tau, "auto": tau == route["tau"], "admm_400_psnr": a["psnr"],
                     "admm_400_objective": a["objective"], "admm_400_gap": gap_admm,
                     "converged_psnr": f["psnr"], "converged_objective": f["objective"],
                     "converged_iterations": f["iteration"],
                     "converged_change_last_window": change})
        log(f"   tau {tau:.4g}: ADMM@{n} {a['psnr']:.2f} dB (gap {gap_admm:.2g}); converged "
            f"{f['psnr']:.2f} dB ({f['iteration']} iterations)", flush=True)
    best = max(rows, key=lambda r: r["converged_psnr"])
    return {"case": case.name, "admm_iters": n, "rows": rows, "best_tau": best["tau"],
            "default_route": route}


# ------------------------------------------------------------------------------------------
# reporting
# ------------------------------------------------------------------------------------------
def revision() -> dict:
    def git(*args):
        try:
            return subprocess.run(["git", *args], cwd=ROOT, text=True, capture_output=True,
                                  timeout=30).stdout.strip()
        except (OSError, subprocess.SubprocessError):
            return None

    return {"commit": git("rev-parse", "HEAD"),
            "clfza_modified": bool(git("status", "--porcelain", "--", "clfza"))}


def _fmt(v, spec=".0f", none="—"):
    return none if v is None else format(v, spec)


def case_notes(case: dict) -> list[str]:
    """The fastest candidate to a 1 % gap (to stay) within the common budget, and where the
    reference run (fista_restart continued) crossed each gap."""
    out = []
    for key, unit in (("stays_iteration", "iterations"), ("stays_seconds", "s")):
        hits = [(run["summary"]["0.01"][key], name) for name, run in case["runs"].items()
                if run["summary"]["0.01"][key] is not None]
        if hits:
            v, name = min(hits)
            out.append(f"- Fastest to a 1 % gap within {case['iters']} iterations "
                       f"({unit}): {name}, {v:.4g} {unit}.")
        else:
            out.append(f"- No candidate within 1 % of f_ref by iteration {case['iters']}.")
            break
    fr = case["runs"].get("fista_restart")
    if fr:
        parts = []
        for gap in GAPS:
            c = crossing(fr["rows"], case["f_ref"], gap)
            it = c["first_iteration"]
            parts.append(f"{gap:g}: " + ("not reached" if it is None else
                                         f"iteration {it} ({it * fr['cost_per_iter_s']:.1f} s, "
                                         f"{c['first_psnr']:.2f} dB)"))
        out.append(f"- fista_restart continued to {fr['stats']['iterations']} iterations "
                   f"(the reference run; checkpoints every 250 past {case['iters']}), first "
                   f"below the gap " + "; ".join(parts) + ".")
    return out


def markdown(result: dict) -> str:
    lines = ["# Convergence on the exact model (issue 33)", "",
             "`bench/bench_exact_convergence.py`; problem, candidates and normalisation in its "
             "docstring. Gap = (F - f_ref) / f_ref on the feasible point P_C(x); seconds = "
             "iterations x the median cost per iteration (float64 numpy, single-threaded "
             "FFTs); \"stays\" = the first checkpoint after which the gap stays below.", ""]
    lines += machine_lines(result["machine"])
    rev = result["revision"]
    lines += [f"- Commit {rev['commit']} (clfza/ modified: {rev['clfza_modified']}; at the end "
              f"{rev['at_end']['commit']}, modified {rev['at_end']['clfza_modified']}); load "
              f"average at the end {result['load_average_end']}; wall {result['wall_s']:.0f} s",
              ""]
    for case in result["cases"]:
        route = case["default_route"]
        lines += [f"## {case['case']}", "",
                  f"tau = {case['tau']:.4g} ({case['tau_source']}); default route (tau=auto "
                  f"{route.get('tau', float('nan')):.4g}, {route.get('backend')}): "
                  f"{route.get('psnr', float('nan')):.2f} dB"
                  + (f", F gap {route['gap']:.2g} after {route['pilot_iterations']} pilot and "
                     f"{route['iterations']} final iterations"
                     + (" (continued)" if route.get("continued") else "")
                     if "gap" in route else "") + ". High-pass k = "
                  f"{case['highpass_k']}, grid {case['model_grid']}. f_ref = "
                  f"{case['f_ref']:.7g} ({case['f_ref_from']['run']} at iteration "
                  f"{case['f_ref_from']['iteration']}, {case['f_ref_from']['psnr']:.2f} dB; "
                  f"its last {case['reference_run']['window']} iterations changed F by "
                  f"{case['reference_run']['relative_change_last_window']:.1e}).", ""]
        head = ["candidate", "ms/it", "1 %: it (stays)", "1 %: s (stays)", "PSNR at 1 % (stays)",
                "0.1 %: it (stays)", "0.1 %: s (stays)", "PSNR at 0.1 % (stays)",
                "gap / PSNR at 400", f"gap / PSNR at {case['iters']}"]
        lines += ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
        for name, run in case["runs"].items():
            s = run["summary"]
            cells = [name, f"{1e3 * run['cost_per_iter_s']:.1f}"]
            for g in ("0.01", "0.001"):
                c = s[g]
                cells += [f"{_fmt(c['first_iteration'])} ({_fmt(c['stays_iteration'])})",
                          f"{_fmt(c['first_seconds'], '.1f')} ({_fmt(c['stays_seconds'], '.1f')})",
                          f"{_fmt(c['first_psnr'], '.2f')} ({_fmt(c['stays_psnr'], '.2f')})"]
            for key in ("at_400", "at_end"):
                r = s[key]
                cells.append("—" if r is None else f"{r['gap']:.2g} / {r['psnr']:.2f}")
            lines.append("| " + " | ".join(cells) + " |")
        lines += [""] + case_notes(case) + [""]
    tc = result.get("tau_check")
    if tc:
        lines += [f"## PSNR(tau), {tc['case']}", "",
                  f"ADMM at its default budget ({tc['admm_iters']} iterations, returned output) "
                  "against fista_restart run to its stall (the reference rule).", "",
                  "| tau | ADMM@400 PSNR | ADMM@400 gap | converged PSNR | converged at | "
                  f"its F change over the last {REF_WINDOW} |",
                  "|---|---|---|---|---|---|"]
        for r in tc["rows"]:
            ch = r.get("converged_change_last_window")
            lines.append(f"| {r['tau']:.4g}{' (auto)' if r['auto'] else ''} | "
                         f"{r['admm_400_psnr']:.2f} | {r['admm_400_gap']:.2g} | "
                         f"{r['converged_psnr']:.2f} | {r['converged_iterations']} | "
                         f"{'—' if ch is None else format(ch, '.1e')} |")
        lines.append("")
    return "\n".join(lines) + "\n"


COLORS = {"admm": "C0", "fista": "C2", "fista_restart": "C3", "pdhg": "C1", "apg": "C4",
          "ld_cg": "C5"}


def plot(result: dict, path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    cases = result["cases"]
    tc = result.get("tau_check")
    fig, axes = plt.subplots(len(cases) + bool(tc), 3, figsize=(15, 3.2 * (len(cases)
                                                                          + bool(tc))),
                             squeeze=False)
    if tc:
        ax, ax2 = axes[-1][0], axes[-1][1]
        ts = [r["tau"] for r in tc["rows"]]
        ax.semilogx(ts, [r["admm_400_psnr"] for r in tc["rows"]], "o-", color=COLORS["admm"],
                    label=f"admm, {tc['admm_iters']} iterations (returned)")
        ax.semilogx(ts, [r["converged_psnr"] for r in tc["rows"]], "s-",
                    color=COLORS["fista_restart"], label="fista_restart, converged")
        auto = [r["tau"] for r in tc["rows"] if r["auto"]]
        for t in auto:
            ax.axvline(t, color="0.6", lw=0.6, ls="--")
        ax.set_xlabel("tau (dashed: tau='auto')")
        ax.set_ylabel("PSNR (dB)")
        ax.set_title(f"PSNR(tau), {tc['case']}", fontsize=9)
        ax.grid(alpha=0.3)
        ax.legend(fontsize=7)
        ax2.loglog(ts, [r["admm_400_gap"] if r["admm_400_gap"] > 0 else np.nan
                         for r in tc["rows"]], "o-",
                   color=COLORS["admm"])
        ax2.set_xlabel("tau")
        ax2.set_ylabel(f"admm gap at {tc['admm_iters']} (to the converged F)")
        ax2.grid(alpha=0.3, which="both")
        axes[-1][2].axis("off")
    for row, case in zip(axes, cases, strict=False):
        for name, run in case["runs"].items():
            rs = [r for r in run["rows"] if r["iteration"] > 0]
            its = [r["iteration"] for r in rs]
            # the reference point itself (gap 0) has no place on a log axis
            gaps = [r["gap"] if r["gap"] > 0 else np.nan for r in rs]
            secs = [r["iteration"] * run["cost_per_iter_s"] for r in rs]
            kw = {"color": COLORS.get(name), "lw": 1.2, "label": name}
            row[0].loglog(its, gaps, **kw)
            row[1].loglog(secs, gaps, **kw)
            row[2].semilogx(its, [r["psnr"] for r in rs], **kw)
            if name == "admm":
                row[2].semilogx(its, [r.get("last_psnr", np.nan) for r in rs], ":",
                                color=kw["color"], lw=0.8, label="admm last iterate")
        for ax in row[:2]:
            ax.axhline(1e-2, color="0.6", lw=0.6, ls="--")
            ax.axvline(default_iters("admm", "exact") if ax is row[0] else np.nan,
                       color="0.6", lw=0.6, ls=":")
            ax.set_ylabel("(F - f_ref) / f_ref")
            ax.grid(alpha=0.3, which="both")
        row[2].axhline(case["f_ref_from"]["psnr"], color="0.6", lw=0.6, ls="--")
        row[2].set_ylabel("PSNR (dB)")
        row[2].grid(alpha=0.3)
        row[0].set_xlabel("iteration")
        row[1].set_xlabel("seconds (iterations x median cost per iteration)")
        row[2].set_xlabel("iteration")
        row[0].set_title(f"{case['case']}: tau {case['tau']:.3g}, k={case['highpass_k']}",
                         fontsize=9)
        row[2].set_title(f"default route (tau=auto): "
                         f"{case['default_route'].get('psnr', float('nan')):.2f} dB",
                         fontsize=9)
        row[0].legend(fontsize=7)
        row[2].legend(fontsize=7)
    m = result["machine"]
    fig.suptitle(f"exact model convergence; {m['cpu_model']}, {m['cores_usable']} cores, "
                 f"load {m['load_average']}; commit {result['revision']['commit'][:8]}",
                 fontsize=9)
    fig.tight_layout(rect=(0, 0, 1, 0.985))
    fig.savefig(path, dpi=90)
    plt.close(fig)


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--iters", type=int, default=1000, help="iterations of every candidate "
                   "(default 1000, 2.5x ADMM's exact-model budget)")
    p.add_argument("--ref-iters", type=int, default=None, help="most iterations of the "
                   "reference run (default 20x ADMM's budget: 8000)")
    p.add_argument("--cases", nargs="*", default=DEFAULT_CASES, choices=list(CASES))
    p.add_argument("--no-tau-check", action="store_true")
    p.add_argument("--tau-check-case", default=TAU_CHECK_CASE, choices=list(CASES))
    p.add_argument("--tau-check-taus", type=float, nargs="+", default=list(TAU_CHECK_TAUS),
                   help="taus of the check besides the case's tau='auto' choice")
    p.add_argument("--tau-check-iters", type=int, default=3000, help="most iterations of "
                   "the converged runs of the tau check (default 3000)")
    p.add_argument("--candidates", nargs="+", default=list(CANDIDATES), choices=ALL_CANDIDATES,
                   help="candidates to run (fista_restart always: the reference run)")
    p.add_argument("--case-tau", nargs="*", default=[], metavar="CASE=TAU",
                   help="a fixed tau for a case (e.g. a hindsight-best tau of an earlier tau "
                   "check) instead of its tau='auto' choice")
    p.add_argument("--tag", default="", help="suffix of the result files")
    p.add_argument("--out", default=str(RESULTS))
    p.add_argument("--replot", metavar="JSON", help="rewrite the markdown and the plot of an "
                   "earlier run's JSON (nothing is measured)")
    a = p.parse_args(argv)
    warnings.simplefilter("ignore")
    if a.replot:
        src = Path(a.replot)
        result = json.loads(src.read_text())
        md = markdown(result)
        src.with_suffix(".md").write_text(md)
        plot(result, src.with_suffix(".png"))
        print(md)
        return 0
    t_all = time.perf_counter()
    ref_iters = a.ref_iters or 20 * default_iters("admm", "exact")
    machine = machine_record()
    rev = revision()
    result = {"machine": machine, "revision": rev, "iters": a.iters, "ref_iters": ref_iters,
              "settings": {"fr_inner": FR_INNER, "gamma_a": GAMMA_A, "pdhg_tau0": PDHG_TAU0,
                           "ref_stall": REF_STALL, "ref_window": REF_WINDOW,
                           "cost_iters": COST_ITERS, "cost_rounds": COST_ROUNDS},
              "cases": []}
    taus = {k: float(v) for k, v in (kv.split("=", 1) for kv in a.case_tau)}
    if not a.no_tau_check:
        print(f"== tau check on {a.tau_check_case}", flush=True)
        tc = tau_check(CASES[a.tau_check_case], a.tau_check_taus, a.tau_check_iters)
        result["tau_check"] = tc
        taus[a.tau_check_case] = tc["best_tau"]
    for name in a.cases:
        result["cases"].append(run_case(CASES[name], a.iters, ref_iters, taus.get(name),
                                        candidates=a.candidates))
    rev["at_end"] = revision()
    result["load_average_end"] = machine_record()["load_average"]
    result["wall_s"] = time.perf_counter() - t_all
    stem = Path(a.out) / (f"exact_convergence_{machine_slug(machine)}"
                          + (f"_{a.tag}" if a.tag else ""))
    md = markdown(result)
    print(md)
    for path in write_result_files(stem, result, md, plot):
        print("wrote", path)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
