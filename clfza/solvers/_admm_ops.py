"""ADMM's operations (:mod:`clfza.solvers._admm`; the difference split also serves
:mod:`clfza.solvers._admm_crop` and :mod:`clfza.solvers._wiener`).

:class:`AdmmOps`: the x-update's right-hand side and the fused z/u (and non-negativity)
update of the split ``z = D x``. :class:`FourierSolve`: the Fourier-diagonal x-update of the
transfer-function model, ``x = F^-1 [F(rhs) / (H_T^2 + rho |D|^2 + mu)]``, as its own object
that the solver (or :func:`clfza.solvers._wiener.wiener_tf`) sets up and holds, like scico's
``CircularConvolveSolver`` plugged into its ADMM.

Each is a float64 numpy reference and an OpenCL implementation (``kernels/elementwise.cl``:
``admm_rhs``, ``admm_update``, ``admm_update_rhs16``; ``kernels/spectrum.cl``:
``admm_solve_spec``);
``AdmmOps.for_backend(B)`` and ``FourierSolve.for_backend(B)`` return the ones for ``B``.
"""

from __future__ import annotations

from abc import abstractmethod

import numpy as np
import scipy.fft

from .. import regularizers as R
from ..backends import Backend, Ops, Ready, Scalars, diff_symbol
from ..cl import DeviceArray
from ..errors import ClfzaError


class AdmmOps(Ops):
    """The difference split's operations on one backend (:class:`~clfza.backends._base.Ops`)."""

    #: whether :meth:`update_rhs` writes the new split to a spare pair (the caller then
    #: allocates one); the reference updates in place
    wants_spare = False

    @abstractmethod
    def rhs(self, out, q1, q2, v, s, rho: float, mu: float, b=None) -> None:
        """``out = b + rho D^T q + mu (v - s)``; ``b`` is ``K^T y`` (the backend's ``b``)
        unless given (the crop split's is a zero image: its data enter through ``H^T``)."""

    @abstractmethod
    def update(self, x, u1, u2, q1, q2, v, s, thr: float, nonneg: bool) -> Scalars:
        """``t = D x + u; z = shrink(t, thr); u = t - z; q = z - u``; with ``nonneg``
        ``v = max(x + s, 0), s += x - v``.

        Returns
        -------
        Scalars
            ``(Phi(x), ||D x - z||^2)``.
        """

    def update_rhs(self, x, u, spare, q, v, s, out, thr: float, nonneg: bool, rho: float,
                   mu: float, want: bool = True, b=None) -> tuple[Scalars | None, tuple, tuple]:
        """:meth:`update`, then :meth:`rhs` of the next x-update (with ``b``) into ``out``.

        ``u``: the split ``(u1, u2)``; ``spare``: two more arrays of its shape, which an
        implementation may write the new split to instead of ``u`` (so that it never reads
        what it overwrites); ``q``: the pair :meth:`update` fills for :meth:`rhs`. Here
        (the reference) :meth:`update` in place, then :meth:`rhs`. Without ``want`` the
        sums are not needed: an implementation may skip folding them (None is returned).

        Returns
        -------
        (Scalars or None, tuple, tuple)
            :meth:`update`'s sums, the pair now holding the split and the pair now spare.
        """
        sums = self.update(x, *u, *q, v, s, thr, nonneg)
        self.rhs(out, *q, v, s, rho, mu, b)
        return sums, u, spare


@AdmmOps.implements("numpy")
class NumpyAdmmOps(AdmmOps):
    """float64 reference."""

    def rhs(self, out, q1, q2, v, s, rho, mu, b=None):
        out[...] = (self.B.b if b is None else b) + rho * R.grad_circ_T(q1, q2)
        if mu:
            out += mu * (v - s)

    def update(self, x, u1, u2, q1, q2, v, s, thr, nonneg):
        d1, d2 = R.grad_circ(x)
        t1, t2 = d1 + u1, d2 + u2
        z1, z2 = R.shrink_vec(t1, t2, thr)
        u1[...] = t1 - z1
        u2[...] = t2 - z2
        q1[...] = z1 - u1
        q2[...] = z2 - u2
        if nonneg:
            a = x + s
            v[...] = np.maximum(a, 0)
            s[...] = a - v
        return Ready(R.tv_value(x), float(np.sum((d1 - z1) ** 2 + (d2 - z2) ** 2)))


@AdmmOps.implements("opencl")
class OpenCLAdmmOps(AdmmOps):
    """Fused kernels on the image plane: the update with its two sums (``admm_update``), the
    right-hand side (``admm_rhs``), and the update with the next right-hand side in one launch
    (``admm_update_rhs``; on CPU devices in float32 with one channel ``admm_update16`` and
    ``admm_update_rhs16``, 16 columns per work-item)."""

    KERNELS = (("elementwise", ("admm_rhs", "admm_update", "admm_update_rhs")),)
    wants_spare = True

    def __init__(self, B):
        super().__init__(B)
        # CPU devices: 16 columns per work-item (measured: docs/measurements.md,
        # clfza.solvers._admm_ops)
        if B.rows16:
            B.use_kernels(("elementwise", ("admm_update16", "admm_update_rhs16")))

    def rhs(self, out, q1, q2, v, s, rho, mu, b=None):
        B = self.B
        r = B.r
        B.launch2d("admm_rhs", out.buf, (B.b if b is None else b).buf, q1.buf, q2.buf, v.buf,
                   s.buf, r(rho), r(mu), B.fpar.buf)

    def update(self, x, u1, u2, q1, q2, v, s, thr, nonneg):
        B = self.B
        args = (x.buf, u1.buf, u2.buf, q1.buf, q2.buf, v.buf, s.buf, B.r(thr), B.i32(nonneg),
                B.fpar.buf)
        if B.rows16:
            return B.launch_rows16_reduce("admm_update16", *args)
        return B.launch2d_reduce("admm_update", *args)

    def update_rhs(self, x, u, spare, q, v, s, out, thr, nonneg, rho, mu, want=True, b=None):
        """One kernel, ``admm_update_rhs`` (CPU devices, float32, one channel:
        ``admm_update_rhs16``): the new split goes to ``spare``, q is not stored (5 arrays
        read and 5 written instead of the two kernels' 16 passes; the same images bit for
        bit; measured: docs/measurements.md, clfza.solvers._admm_ops); the sums folded only
        when wanted."""
        B = self.B
        r = B.r
        args = (x.buf, u[0].buf, u[1].buf, spare[0].buf, spare[1].buf, v.buf, s.buf, out.buf,
                (B.b if b is None else b).buf, r(thr), B.i32(nonneg), r(rho), r(mu), B.fpar.buf)
        if B.rows16:
            sums = B.launch_rows16_reduce("admm_update_rhs16", *args, fold=want)
        else:
            sums = B.launch2d_reduce("admm_update_rhs", *args, fold=want)
        return sums, spare, u


# ----------------------------------------------------------------------------------------
# the Fourier-diagonal x-update (transfer-function model)
# ----------------------------------------------------------------------------------------
def _inverse(H2: np.ndarray, shape: tuple[int, int], rho, mu) -> np.ndarray:
    """``1 / (H_T^2 + rho |D|^2 + mu)`` on the half spectrum, 0 where the sum vanishes; with
    ``rho`` and ``mu`` arrays (one value per frame of a batch), one inverse per frame,
    ``(F, Hs, Ws)``."""
    rho, mu = np.asarray(rho, np.float64), np.asarray(mu, np.float64)
    if rho.ndim or mu.ndim:
        rho, mu = np.broadcast_arrays(rho, mu)
        rho, mu = rho[:, None, None], mu[:, None, None]
    den = H2 + rho * diff_symbol(shape) + mu
    return np.where(den > 0, 1.0 / np.where(den > 0, den, 1.0), 0.0)


class FourierSolve(Ops):
    """The x-update ``(K^T K + rho D^T D + mu) x = rhs`` on the transfer-function model, where
    both ``K^T K`` and ``D^T D`` are diagonal in Fourier space: one real FFT pair and one
    division (:class:`~clfza.backends._base.Ops`; the exact model's is
    :class:`clfza.solvers._admm_crop_ops.CropFourierSolve`)."""

    def __init__(self, B: Backend):
        if B.exact is not None:
            raise NotImplementedError("the exact model uses the crop-split ADMM (admm_crop)")
        super().__init__(B)

    @abstractmethod
    def setup(self, rho, mu) -> None:
        """Precompute ``1 / (H_T^2 + rho |D|^2 + mu)`` on the half spectrum (on a backend of a
        batch of frames ``rho`` and ``mu`` may be arrays, one value per frame)."""

    @abstractmethod
    def solve(self, rhs, x, want: bool) -> Scalars | None:
        """``x = F^-1 [F(rhs) / (H_T^2 + rho |D|^2 + mu)]``; with ``want`` also
        ``(||y - K x||^2, 0)`` (from the same spectrum, by Parseval)."""


@FourierSolve.implements("numpy")
class NumpyFourierSolve(FourierSolve):
    """float64 reference."""

    def setup(self, rho, mu):
        B = self.B
        self.inv = _inverse(B.op.H2, B.shape, rho, mu)

    def solve(self, rhs, x, want):
        B = self.B
        B.ffts += B.nc
        X = scipy.fft.rfft2(rhs) * self.inv
        x[...] = scipy.fft.irfft2(X, s=B.shape)
        if not want:
            return Ready(0.0)
        Rs = B.Y - B.op.H * X
        return Ready(float(np.sum(B.w * np.abs(Rs) ** 2)) / (B.shape[0] * B.shape[1]))


@FourierSolve.implements("opencl")
class OpenCLFourierSolve(FourierSolve):
    """The FFT pair of the backend's engine around one spectral kernel (the division and the
    residual's sum), on the backend's spectrum ``X``. :meth:`setup` sends each frame's
    ``(rho, mu)`` and fills the inverse spectra ``1 / (H_T^2 + rho |D|^2 + mu)`` on the device
    (``admm_inverse_fill``: from the shared ``H_T^2`` and ``|D|^2``'s two 1-D factors, stored
    once), one per frame or one shared when every frame has the same pair; :func:`_inverse`
    is its float64 specification."""

    KERNELS = (("spectrum", ("admm_solve_spec", "admm_inverse_fill")),)

    def __init__(self, B: Backend):
        super().__init__(B)
        if B.spec8:  # CPUs, float32: the row-vector variant (OpenCLBackend.spec_pass)
            B.use_kernels(("spectrum", ("admm_solve_spec8",)))
        ny, nx = B.shape
        # |D|^2 = 4 sin^2(pi kx / W) + 4 sin^2(pi ky / H) (diff_symbol), its two factors
        dsym = np.concatenate([4 * np.sin(np.pi * np.arange(nx // 2 + 1) / nx) ** 2,
                               4 * np.sin(np.pi * np.arange(ny) / ny) ** 2])
        self.dsym = DeviceArray.from_host(B.rt, dsym.astype(B.dtype))
        self.pen = DeviceArray.empty(B.rt, (B.frames, 2), B.dtype)
        self.inv = None  # (frames or 1, H, W/2 + 1), made at the first setup
        self.inv_frames = B.i32(0)

    def setup(self, rho, mu):
        B = self.B
        rho, mu = np.asarray(rho, np.float64), np.asarray(mu, np.float64)
        if rho.ndim > 1 or mu.ndim > 1:
            raise ClfzaError("rho and mu are scalars or one value per frame")
        for v in (rho, mu):
            if v.ndim and v.shape[0] != B.frames:
                raise ClfzaError(f"{v.shape[0]} penalties for a batch of {B.frames} frames")
        pen = np.empty((B.frames, 2), B.dtype)
        pen[:, 0], pen[:, 1] = np.broadcast_to(rho, B.frames), np.broadcast_to(mu, B.frames)
        if not np.all(np.isfinite(pen)):
            raise ClfzaError(f"rho and mu must be finite, got {rho} and {mu}")
        shared = bool(np.all(pen == pen[0]))  # one inverse serves every frame
        planes = 1 if shared else B.frames
        self.inv_frames = B.i32(not shared)
        if self.inv is None or (planes > 1 and self.inv.shape[0] == 1):
            self.inv = DeviceArray.empty(B.rt, (planes, B.shape[0], B.ws), B.dtype)
        # pen and inv written through the (in-order) queue, not waited for: a solve already
        # queued reads the inverse it was queued with
        B.write_async(self.pen, pen)
        B.k["admm_inverse_fill"](B.rt.queue, (B.ws, B.shape[0], planes), None, self.inv.buf,
                                 B.op.H2.buf, self.dsym.buf, self.pen.buf, B.i32(B.ws),
                                 B.i32(B.shape[0]))

    def solve(self, rhs, x, want):
        B = self.B
        ny, nx = B.shape
        B.fft.rfft2(rhs, B.X)
        red = B.spec_pass("admm_solve_spec", (B.X.buf, B.Y.buf, B.op.H.buf, self.inv.buf),
                          (B.i32(want), self.inv_frames))
        res = red.reduce(1.0 / (ny * nx), planes=1) if want else None
        B.fft.irfft2(B.X, x, overwrite_x=True)
        B.ffts += B.nc * B.frames
        return res
