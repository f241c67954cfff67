"""The direct Tikhonov/Wiener solve: ``min 1/2 ||y - K x||^2 + lam/2 ||D x||^2``.

Transfer-function model (Eq. 17): ``K^T K`` and ``D^T D`` are both diagonal in Fourier space,
so the minimiser is one division (one real FFT pair, the same spectral division as ADMM's
x-update, with ``rho = lam`` and no other split)::

    x = F^-1 [ H_T F(y) / (H_T^2 + lam |D|^2) ]      (the DC, where both vanish, is set to 0)

Exact model (:mod:`clfza.models._exact`, crop and mean removal after the convolution): ``K^T K`` is
not diagonal in any basis. The normal equations restricted to the object region ``S`` (the sensor
plus the margin, as the crop-split ADMM's support constraint; without it the unobserved grid
pixels and the crop's null space take the energy), ``S^T (K^T K + lam D^T D) S u = S^T K^T y``,
are solved by preconditioned conjugate gradients, with the Fourier-diagonal
``c |H|^2 + lam |D|^2 + eps`` (``c`` = the sensor's share of the model grid) as
preconditioner: at most
:data:`CG_ITERS` iterations (4 real FFT pairs each), stopping at a relative residual of
:data:`CG_TOL`. It runs on the normalised operator like every other exact-model solver.

The default ``lam`` comes from the noise ``sigma`` estimated from the frame
(:func:`clfza.reconstruction._plan.estimate_noise`) by the discrepancy principle evaluated in closed
form on the Fourier-diagonal model (:func:`wiener_lam`): no extra solve.

``method="wiener"`` runs on the transfer-function model, on both backends: numpy float64
(reference) and OpenCL, with ADMM's Fourier-diagonal x-update
(:class:`~clfza.solvers._admm_ops.FourierSolve`, kernel ``admm_solve_spec``), see
``tests/test_wiener_tau.py``. The exact-model PCG (:func:`wiener_exact`, on the crop split's
operations, :mod:`clfza.solvers._admm_crop_ops`) is experimental and not registered: on the
experiment preset it does not converge in ``CG_ITERS`` iterations (see :func:`wiener_solve`;
measured: docs/measurements.md, clfza.solvers._wiener).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import scipy.fft

from ..backends import Backend, diff_symbol, half_weights
from ..errors import ClfzaError, positive_int
from ._admm_crop_ops import CropAdmmOps, CropFourierSolve
from ._admm_ops import AdmmOps, FourierSolve
from ._common import Stopper
from ._driver import Solver, Step, register
from ._options import MethodOptions, nonneg_number, option, positive

CG_ITERS = 30
CG_TOL = 1e-3   # on the preconditioned residual norm sqrt(r^T M^-1 r), relative
LAM_FLOOR = 1e-9  # relative to the largest |H|^2: lam never makes the division singular
KAPPA = 0.5     # discrepancy factor of the default lam (see wiener_lam)


def spectrum_power(B: Backend) -> np.ndarray:
    """|H|^2 of the (normalised) kernel on the half spectrum, host float64."""
    if B.exact is not None:
        Hn = B.Hn
        return np.abs(Hn) ** 2
    H2 = B.op.H2
    return np.asarray(H2.get() if hasattr(H2, "get") else H2, dtype=np.float64)


def is_exact(B: Backend) -> bool:
    """Whether ``B`` solves on the exact finite-aperture model."""
    return B.exact is not None


def measurement_pixels(B: Backend) -> int:
    """Pixels of one channel's measurement (the sensor on the exact model)."""
    return int(np.prod(B.sensor)) if is_exact(B) else int(np.prod(B.shape))


def _spectra(B: Backend, y: np.ndarray) -> tuple[np.ndarray, np.ndarray, int]:
    """``|Y|^2`` of the measurement (backend units, on the solve grid, summed over channels),
    ``|H|^2`` and the measured pixels per channel."""

    sensor = B.shape if B.exact is None else B.exact.sensor
    yb = np.asarray(y, dtype=np.float64).reshape((-1,) + tuple(sensor))
    yb = (yb - yb.mean(axis=(-2, -1), keepdims=True)) / B.data_scale
    if is_exact(B):
        yb = B.geom.embed(yb)
    Y2 = np.sum(np.abs(scipy.fft.rfft2(yb)) ** 2, axis=0)
    return Y2, spectrum_power(B), measurement_pixels(B)


_RTOL = 4 * np.finfo(float).eps  # scipy.optimize.brentq's default rtol
LAM_XTOL = 5e-3  # Brent's tolerance on log lam (0.5 %)


def brentq_steps(xa: float, xb: float, xtol: float, rtol: float = _RTOL, maxiter: int = 100):
    """Brent's root search as scipy.optimize.brentq runs it (its brentq.c, step for step, the
    same float64 operations), written as a generator: it yields each ``x`` to evaluate and is
    sent ``f(x)``; its return value (``StopIteration.value``) is the root. Many searches can
    then share one vectorised evaluation per round (:func:`wiener_lams`).

    Examples
    --------
    >>> g = brentq_steps(0.0, 2.0, 1e-12)
    >>> x = next(g)
    >>> try:
    ...     while True:
    ...         x = g.send(x * x - 2.0)
    ... except StopIteration as e:
    ...     root = e.value
    >>> round(root, 9)
    1.414213562
    """
    xpre, xcur = float(xa), float(xb)
    xblk = fblk = spre = scur = 0.0
    fpre = yield xpre
    fcur = yield xcur
    if fpre == 0:
        return xpre
    if fcur == 0:
        return xcur
    if math.copysign(1.0, fpre) == math.copysign(1.0, fcur):
        raise ClfzaError("brentq_steps: f(a) and f(b) must have different signs")
    for _ in range(maxiter):
        if fpre != 0 and fcur != 0 and math.copysign(1.0, fpre) != math.copysign(1.0, fcur):
            xblk, fblk = xpre, fpre
            spre = scur = xcur - xpre
        if abs(fblk) < abs(fcur):
            xpre, xcur, xblk = xcur, xblk, xcur
            fpre, fcur, fblk = fcur, fblk, fcur
        delta = (xtol + rtol * abs(xcur)) / 2
        sbis = (xblk - xcur) / 2
        if fcur == 0 or abs(sbis) < delta:
            return xcur
        if abs(spre) > delta and abs(fcur) < abs(fpre):
            if xpre == xblk:  # interpolate
                stry = -fcur * (xcur - xpre) / (fcur - fpre)
            else:  # extrapolate
                dpre = (fpre - fcur) / (xpre - xcur)
                dblk = (fblk - fcur) / (xblk - xcur)
                stry = -fcur * (fblk * dblk - fpre * dpre) / (dblk * dpre * (fblk - fpre))
            lim = 3 * abs(sbis) - delta
            if 2 * abs(stry) < (abs(spre) if abs(spre) < lim else lim):  # good short step
                spre, scur = scur, stry
            else:  # bisect
                spre = scur = sbis
        else:  # bisect
            spre = scur = sbis
        xpre, fpre = xcur, fcur
        if abs(scur) > delta:
            xcur += scur
        else:
            xcur += delta if sbis > 0 else -delta
        fcur = yield xcur
    return xcur


#: relative distance from the target within which the search's bracket decisions are taken
#: on the bracket's own end points (see :func:`_lam_steps`): far above the rounding difference
#: between the residual at ``lo`` and at ``exp(log(lo))`` (relative, below ``1e-12``: a few
#: ulp of ``lam``, twice that in the residual, plus the sums' rounding)
DECIDE_MARGIN = 1e-9


def _once(seen: dict, lam: float):
    """The residual at ``lam``: yielded for evaluation the first time, then ``seen``'s."""
    if lam not in seen:
        seen[lam] = yield lam
    return seen[lam]


def _lam_steps(hmax: float, target: float, norm: float):
    """The residual evaluations of one ``lam`` search (generator: yields ``lam``, is sent the
    predicted residual at it; returns ``(lam, residual ratio)``, see :func:`wiener_lam`).

    The bracket ``[lo, hi]``'s two decisions (does the residual reach the target at ``lo``,
    or not even at ``hi``?) are taken on the residuals at ``exp(log(lo))`` and
    ``exp(log(hi))``, the points Brent's search evaluates first, and each distinct ``lam`` is
    evaluated once (the last Brent point is the returned ``lam``, whose ratio is then known):
    11 evaluations instead of 14 in the common case. A decision value within
    :data:`DECIDE_MARGIN` of the target is re-evaluated at the end point itself, so every
    decision, and with it ``lam`` and its ratio, is bit for bit the search's on ``lo`` and
    ``hi``."""
    lo, hi = LAM_FLOOR * hmax, 1e6 * hmax
    seen: dict = {}
    if not target > 0:
        lam = lo
    else:
        ulo, uhi = math.log(lo), math.log(hi)
        flo = yield from _once(seen, math.exp(ulo))
        if not abs(flo - target) > DECIDE_MARGIN * target:
            flo = yield from _once(seen, lo)
        if flo >= target:
            lam = lo
        else:
            fhi = yield from _once(seen, math.exp(uhi))
            if not abs(fhi - target) > DECIDE_MARGIN * target:
                fhi = yield from _once(seen, hi)
            if fhi <= target:
                lam = hi
            else:  # the residual grows with lam: Brent's method on log lam, to 0.5 %
                search = brentq_steps(ulo, uhi, LAM_XTOL)
                u = next(search)
                try:
                    while True:
                        fx = math.log((yield from _once(seen, math.exp(u))) / target)
                        if math.isnan(fx):
                            raise ClfzaError("the Wiener lam search met a NaN residual")
                        u = search.send(fx)
                except StopIteration as e:
                    lam = math.exp(e.value)
    ratio = (yield from _once(seen, lam)) / norm if norm > 0 else float("inf")
    return float(lam), float(ratio)


#: values (frames x kept frequencies) of one numpy pass over the discrepancy sums: about a
#: 512^2 frame's (1 MiB of float64; larger passes leave the caches and run slower than one
#: frame at a time, measured: docs/measurements.md, clfza.solvers._wiener), several for
#: small frames
LAM_CHUNK = 1 << 17


def wiener_lams(B: Backend, Y2: np.ndarray, sigmas, nch: int = 1,
                kappa: float | None = None, H2: np.ndarray | None = None
                ) -> list[tuple[float, float]]:
    """:func:`wiener_lam` of many frames from their power spectra ``Y2`` (``(F, H, W//2+1)``:
    ``|Y|^2`` of each mean-free measurement in backend units, summed over its ``nch``
    channels; ``sigmas``: each frame's noise, user units; ``H2``: :func:`spectrum_power` of
    ``B``, read from the device when not given). The frames' Brent searches run in
    lockstep, each round's residuals one numpy pass over the frames (chunks of
    :data:`LAM_CHUNK` values): each frame gets, bit for bit, the ``lam`` it gets alone.

    Examples
    --------
    >>> import numpy as np, scipy.fft
    >>> from clfza import Camera
    >>> from clfza.backends import get_backend
    >>> B = get_backend("numpy", Camera.preset("simulation").with_shape((32, 32)))
    >>> y = np.random.default_rng(0).normal(size=(2, 32, 32))
    >>> Y2 = np.abs(scipy.fft.rfft2(y - y.mean(axis=(1, 2), keepdims=True))) ** 2
    >>> [round(a / b, 12) for (a, _), (b, _) in zip(wiener_lams(B, Y2, [1.0, 1.0]),
    ...                                            [wiener_lam(B, y[0], 1.0),
    ...                                             wiener_lam(B, y[1], 1.0)])]
    [1.0, 1.0]
    """
    kappa = KAPPA if kappa is None else float(kappa)
    Y2 = np.asarray(Y2, dtype=np.float64)
    H2 = spectrum_power(B) if H2 is None else H2
    n = measurement_pixels(B)
    shape = tuple(B.shape)
    G = float(np.prod(shape))
    Dsym = diff_symbol(shape)
    w = half_weights(shape).copy()
    w[0, 0] = 0.0
    hmax = float(H2.max()) if H2.size and H2.max() > 0 else 1.0
    rs: dict = {}   # the kept frequencies' r, per distinct mask
    rows: dict = {}  # mask -> [frames], and their kept weights stacked (one row each)
    gens, pending = [], []
    for f, sigma in enumerate(sigmas):
        wy = w * Y2[f]
        sb = float(sigma) / B.data_scale
        # the filter lam D / (|H|^2 + lam D) is lam / (r + lam) with r = |H|^2 / D, on the
        # frequencies that carry weight (D > 0 off DC)
        keep = (wy > 0) & (Dsym > 0)
        key = keep.tobytes()
        if key not in rs:
            rs[key] = H2[keep] / Dsym[keep]
            rows[key] = ([], [])
        rows[key][0].append(f)
        rows[key][1].append(wy[keep])
        gen = _lam_steps(hmax, kappa * nch * n * sb**2, nch * n * sb**2)
        gens.append(gen)
        try:
            pending.append(next(gen))
        except StopIteration as e:  # no noise: lam at its floor, nothing to evaluate
            pending.append(e.value)
    out: list = [None] * len(gens)
    live = set(range(len(gens)))
    for f in range(len(gens)):
        if isinstance(pending[f], tuple):
            out[f] = pending[f]
            live.discard(f)
    stacks = {}
    for key, (fs, wk) in rows.items():
        step = max(1, LAM_CHUNK // max(1, rs[key].size))
        stacks[key] = [(fs[i:i + step], np.stack(wk[i:i + step]))
                       for i in range(0, len(fs), step)]
    while live:
        vals = {}
        for key, parts in stacks.items():
            r = rs[key]
            for fs, wk in parts:
                sel = [k for k, f in enumerate(fs) if f in live]
                if not sel:
                    continue
                w_live = wk if len(sel) == len(fs) else wk[sel]
                lam = np.array([pending[fs[k]] for k in sel])[:, None]
                # lam / (r + lam), then (wk f) f: the one-frame expression's operations, in
                # place; np.sum, not np.dot: a BLAS call wakes OpenBLAS's threads, which then
                # spin beside PoCL's on a 2-core CPU and slow the next solve (measured:
                # docs/measurements.md, clfza.solvers._wiener); a row's sum is that row's alone
                fl = np.add(r[None, :], lam)
                np.divide(lam, fl, out=fl)
                t = np.multiply(w_live, fl)
                t *= fl
                s = np.sum(t, axis=1)
                for j, k in enumerate(sel):
                    vals[fs[k]] = float(s[j]) / G
        for f in list(live):
            try:
                pending[f] = gens[f].send(vals[f])
            except StopIteration as e:
                out[f] = e.value
                live.discard(f)
    return out


def wiener_lam(B: Backend, y: np.ndarray, sigma: float, kappa: float | None = None
               ) -> tuple[float, float]:
    """``lam`` by the discrepancy principle on the Fourier-diagonal model: the ``lam`` whose
    predicted residual ``sum_f |Y|^2 (lam |D|^2 / (|H|^2 + lam |D|^2))^2 / N_grid`` equals
    ``kappa * N sigma^2`` (``sigma`` in the user's units; exact model: the circulant
    approximation on the model grid). Returns ``(lam, residual ratio at lam)`` in the
    backend's units. The PSNR-best ``lam`` leaves part of the noise energy in the residual (it
    keeps the zone frequencies): :data:`KAPPA` = 0.5 (chosen by measurement:
    docs/measurements.md, clfza.solvers._wiener). Brent's method on ``log lam`` to 0.5 %
    (:func:`brentq_steps`); :func:`wiener_lams` runs many frames at once.
    """
    Y2, H2, n = _spectra(B, y)
    nch = max(1, int(round(np.asarray(y).size / n)))
    return wiener_lams(B, Y2[None], [sigma], nch, kappa, H2=H2)[0]


# -- small generic helpers over both backends ---------------------------------------------
def _dot(B: Backend, a, b) -> float:
    return float(B.dot(a, b).get()[0])


def wiener_tf(B: Backend, lam: float, x) -> float:
    """``x`` = the Tikhonov solution on the transfer-function model; returns ``||y - K x||^2``."""
    xsolve = FourierSolve.for_backend(B)
    xsolve.setup(lam, 0.0)
    return float(xsolve.solve(B.b, x, True).get()[0])


class _ExactNormal:
    """``A p = (K^T K + lam D^T D) p`` and the Fourier preconditioner on an exact backend.

    The measurement is set to zero while it is in use (``resid_grad`` then gives
    ``-K^T K p`` without cancellation against ``K^T y``); :meth:`close` restores it."""

    def __init__(self, B: Backend, lam: float, y: np.ndarray):
        self.B, self.lam, self.y = B, lam, y
        self.ops, self.zops = CropAdmmOps.for_backend(B), AdmmOps.for_backend(B)
        self.xsolve = CropFourierSolve.for_backend(B)
        self.g, self.t = B.empty(), B.empty()
        self.u1, self.u2, self.q1, self.q2 = (B.zeros() for _ in range(4))
        self.zero = B.zeros()
        self.hx = B.empty()
        self.sc = B.empty()
        share = measurement_pixels(B) / float(np.prod(B.shape))
        eps = 1e-6 * lam + 1e-12
        self.xsolve.setup(share, lam, eps)
        B.set_measurement(np.zeros_like(y))

    def support(self, a) -> None:
        """``a`` = zero off the object region, in place (``S S^T``)."""
        self.B.lincomb(self.sc, 0.0, self.sc)
        self.ops.w_update(a, a, self.sc, False, True)

    def apply(self, p, out) -> None:
        B = self.B
        B.resid_grad(p, self.g)                       # g = -K^T K p
        self.zops.update(p, self.u1, self.u2, self.q1, self.q2, self.zero, self.zero, 0.0,
                         False)
        self.zops.rhs(self.t, self.q1, self.q2, self.zero, self.zero, self.lam, 0.0)
        B.lincomb(out, -1.0, self.g, 1.0, self.t)     # K^T K p + lam D^T D p
        if isinstance(self.u1, np.ndarray):           # the update accumulates u: reset
            self.u1[...] = 0.0
            self.u2[...] = 0.0
        else:
            B.lincomb(self.u1, 0.0, self.u1)
            B.lincomb(self.u2, 0.0, self.u2)
        self.support(out)

    def precond(self, r, out) -> None:
        z = self.zero
        self.xsolve.solve(out, self.hx, z, z, z, r, z, 0.0, 1.0, 0.0)
        self.support(out)

    def close(self) -> None:
        self.B.set_measurement(self.y)


def wiener_exact(B: Backend, lam: float, x, y: np.ndarray, iters: int = CG_ITERS,
                 tol: float = CG_TOL) -> tuple[float, int, float]:
    """PCG on the exact model's normal equations; ``y`` is the measurement (C, Sy, Sx) the
    backend holds. Returns ``(||y - K x||^2, CG iterations, relative residual)``."""
    b = B.empty()
    B.copy(b, B.b)
    A = _ExactNormal(B, lam, y)
    A.support(b)
    r, z, p, q = B.empty(), B.empty(), B.empty(), B.empty()
    try:
        B.lincomb(x, 0.0, b)
        B.copy(r, b)
        bn = math.sqrt(max(_dot(B, b, b), 0.0))
        A.precond(r, z)
        B.copy(p, z)
        rz = _dot(B, r, z)
        rz0 = rz
        it, rel = 0, 0.0 if bn == 0 else 1.0
        while bn > 0 and it < iters:
            it += 1
            A.apply(p, q)
            pq = _dot(B, p, q)
            if not pq > 0:
                break
            alpha = rz / pq
            B.lincomb(x, 1.0, x, alpha, p)
            B.lincomb(r, 1.0, r, -alpha, q)
            A.precond(r, z)
            rz_new = _dot(B, r, z)
            rel = math.sqrt(max(rz_new, 0.0) / rz0) if rz0 > 0 else 0.0
            if rel <= tol:
                break
            B.lincomb(p, 1.0, z, rz_new / rz if rz else 0.0, p)
            rz = rz_new
    finally:
        A.close()
    g = B.empty()
    data = float(B.resid_grad(x, g).get()[0])
    return data, it, rel


def wiener_solve(B: Backend, lam: float, x, y: np.ndarray | None = None) -> dict:
    # exact model: experimental (not registered as a method): on the experiment preset
    # CG_ITERS PCG iterations do not converge (measured: docs/measurements.md,
    # clfza.solvers._wiener): the aperture's disc term makes the normal equations too
    # ill-conditioned for this preconditioner
    """The Tikhonov solution into ``x`` on either model; returns a stats dict with ``data``
    (``||y - K x||^2`` in the backend's units)."""
    if is_exact(B):
        if y is None:
            raise ValueError("the exact model's Wiener solve needs the measurement")
        data, its, rel = wiener_exact(B, lam, x, y)
        return {"data": data, "cg_iterations": its, "cg_relative_residual": rel,
                "lam": lam}
    return {"data": wiener_tf(B, lam, x), "lam": lam}



def one_step(name: str, v) -> int:
    """1, the only iteration count a direct solve has (anything else is an error)."""
    if positive_int(name, v) != 1:
        raise ClfzaError(f"{name} must be 1 for wiener, a direct solve (one step), got {v!r}")
    return 1

@dataclass(kw_only=True)
class WienerOptions(MethodOptions):
    """``lam``: the Tikhonov weight (user units; default: from the noise, :func:`wiener_lam`);
    ``kappa``: the discrepancy factor of the default rule; ``sigma``: the noise standard
    deviation of ``y`` (default: :func:`clfza.reconstruction._plan.estimate_noise`)."""

    lam: float | None = option(None, positive, "Tikhonov weight (default: from the noise)")
    kappa: float = option(KAPPA, positive, "discrepancy factor of the default lam")
    sigma: float | None = option(None, nonneg_number, "noise std of y (default: estimated)")
    iters: int = option(1, one_step, "1: the direct solve is one step")


@register
class Wiener(Solver):
    """``method="wiener"``: the direct Tikhonov/Wiener solve on the transfer-function model
    (one FFT pair). The measurement and the noise come from :meth:`prepare`, which
    :func:`clfza.solvers.run_solver` calls per channel group (via
    :func:`clfza.solvers._tau.prepare_group`)."""

    method = "wiener"
    models = ("tf",)
    Options = WienerOptions
    order = 5

    def stopper(self) -> Stopper:
        return Stopper("none", 0.0, 1, 1)

    def setup(self, x0) -> None:
        o = self.opts
        ctx = self.context
        g = ctx.group if ctx is not None else None
        y, sigma = (g.y, g.sigma) if g is not None else (None, None)
        if o.sigma is not None:
            sigma = o.sigma
        if o.lam is not None:
            self.lam, self.ratio = o.lam / (ctx.scale2 if ctx is not None else 1.0), None
        elif y is None or sigma is None:
            raise ClfzaError("wiener needs lam= or the measurement's noise (run it through "
                             "clfza.reconstruct)")
        else:
            self.lam, self.ratio = wiener_lam(self.B, y, sigma, o.kappa)
        self.sigma = sigma
        self.x = self.B.empty()

    def step(self, it: int) -> Step:
        data = 0.5 * wiener_tf(self.B, self.lam, self.x)
        return Step(objective=data, x=self.x, extra={"data": data})

    def finish(self):
        return self.x

    def stats(self, history: list[float]) -> dict:
        return {"lam": self.lam, "sigma": self.sigma, "discrepancy_ratio": self.ratio}
