"""Regularisers of Eq. 19: total variation (Eq. 20) and l1, their values and proxes (float64).

These are the readable references the OpenCL kernels (``kernels/tv.cl``,
``kernels/elementwise.cl``) are tested against. Arrays are ``(H, W)`` or ``(C, H, W)``; with
``C > 1`` the channels are coupled inside the square root (vectorial TV, Bresson & Chan 2008).

Two discretisations of the gradient appear, on purpose (docs/design.md s.2):

* The **objective** ``Phi`` uses circular backward differences ``x - roll(x, 1)`` on both axes,
  no epsilon (the reference's ``TVnorm``). FISTA's FGP prox and ADMM use the same periodic
  differences, so their objective is exactly ``Phi``.
* The paper's **TV prox** (Chambolle's projection algorithm, ``tvdenoise``) uses forward
  differences that are zero at the last column/row and a divergence whose first column/row
  takes 0 for the missing neighbour difference (:func:`div_ref`); this is not quite the
  negative adjoint of the gradient (:func:`div_adjoint` is), and paper mode reproduces it.
"""

from __future__ import annotations

import numpy as np

CHAMBOLLE_DT = 0.25


def _chan(x: np.ndarray) -> np.ndarray:
    """View as (C, H, W)."""
    x = np.asarray(x, dtype=np.float64)
    return x[None] if x.ndim == 2 else x


def _dual_start(like: np.ndarray, p) -> tuple[np.ndarray, np.ndarray]:
    """A TV dual (p1, p2): zeros shaped like ``like``, or copies of a warm start ``p``."""
    if p is None:
        return np.zeros_like(like), np.zeros_like(like)
    return _chan(p[0]).copy(), _chan(p[1]).copy()


def _like(a: np.ndarray, ref: np.ndarray) -> np.ndarray:
    return a[0] if np.ndim(ref) == 2 else a


# ----------------------------------------------------------------------------------------------
# differences
# ----------------------------------------------------------------------------------------------
def grad_ref(u: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Forward differences ``(u[x+1] - u[x], u[y+1] - u[y])``, zero at the last column/row."""
    u = np.asarray(u, dtype=np.float64)
    g1 = np.zeros_like(u)
    g2 = np.zeros_like(u)
    g1[..., :, :-1] = u[..., :, 1:] - u[..., :, :-1]
    g2[..., :-1, :] = u[..., 1:, :] - u[..., :-1, :]
    return g1, g2


def div_ref(p1: np.ndarray, p2: np.ndarray) -> np.ndarray:
    """The reference divergence ``p1 - p1(:, [1, 1:N-1]) + p2 - p2([1, 1:N-1], :)``.

    The first column/row takes 0 for the missing neighbour difference (MATLAB indexing of the
    authors' ``tvdenoise``).
    """
    d = np.zeros_like(np.asarray(p1, dtype=np.float64))
    d[..., :, 1:] += p1[..., :, 1:] - p1[..., :, :-1]
    d[..., 1:, :] += p2[..., 1:, :] - p2[..., :-1, :]
    return d


def div_adjoint(p1: np.ndarray, p2: np.ndarray) -> np.ndarray:
    """``-grad_ref^T p``: the divergence that is the exact negative adjoint of :func:`grad_ref`
    (what scikit-image's ``denoise_tv_chambolle`` uses)."""
    d = np.zeros_like(np.asarray(p1, dtype=np.float64))
    d[..., :, :-1] += p1[..., :, :-1]
    d[..., :, 1:] -= p1[..., :, :-1]
    d[..., :-1, :] += p2[..., :-1, :]
    d[..., 1:, :] -= p2[..., :-1, :]
    return d


def grad_circ(x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Circular backward differences ``D x = (x - roll(x, 1, -1), x - roll(x, 1, -2))``."""
    x = np.asarray(x, dtype=np.float64)
    return x - np.roll(x, 1, axis=-1), x - np.roll(x, 1, axis=-2)


def grad_circ_T(d1: np.ndarray, d2: np.ndarray) -> np.ndarray:
    """Adjoint of :func:`grad_circ`: ``D^T d = d1 - roll(d1, -1, -1) + d2 - roll(d2, -1, -2)``."""
    return d1 - np.roll(d1, -1, axis=-1) + d2 - np.roll(d2, -1, axis=-2)


# ----------------------------------------------------------------------------------------------
# values
# ----------------------------------------------------------------------------------------------
def tv_value(x: np.ndarray) -> float:
    """``Phi(x)``: isotropic TV with circular differences, no epsilon (Eq. 20; the reference's
    ``TVnorm``); vectorial across channels for ``(C, H, W)``."""
    d1, d2 = grad_circ(_chan(x))
    return float(np.sum(np.sqrt(np.sum(d1**2 + d2**2, axis=0))))


def l1_value(x: np.ndarray) -> float:
    """``||x||_1``."""
    return float(np.sum(np.abs(x)))


# ----------------------------------------------------------------------------------------------
# proxes
# ----------------------------------------------------------------------------------------------
def soft(v: np.ndarray, t: float) -> np.ndarray:
    """Soft thresholding ``sign(v) max(|v| - t, 0)``: the prox of ``t ||.||_1`` (TwIST's default
    Psi)."""
    return np.sign(v) * np.maximum(np.abs(v) - t, 0.0)


def shrink_vec(t1: np.ndarray, t2: np.ndarray, thr: float) -> tuple[np.ndarray, np.ndarray]:
    """Isotropic (vectorial) shrinkage of the field ``(t1, t2)``: ``max(|t| - thr, 0) t / |t|``
    with ``|t|`` over both components (and the channel axis 0 for ``(C, H, W)`` input)."""
    a1, a2 = _chan(t1), _chan(t2)
    n = np.sqrt(np.sum(a1**2 + a2**2, axis=0, keepdims=True))
    f = np.where(n > thr, 1.0 - thr / np.where(n > 0, n, 1.0), 0.0)
    return _like(f * a1, t1), _like(f * a2, t2)


def chambolle(f: np.ndarray, lam: float, iters: int, p=None, *, boundary: str = "reference"
              ) -> tuple[np.ndarray, tuple[np.ndarray, np.ndarray]]:
    """Chambolle's projection algorithm for ROF: ``min_u TV(u) + lam/2 ||f - u||^2``.

    Iterates (step ``dt = 1/4``)::

        z = div p - lam f;   p <- (p + dt grad z) / (1 + dt |grad z|);   u = f - div p / lam

    Parameters
    ----------
    f : array (H, W) or (C, H, W)
        Noisy image; channels are coupled (vectorial TV) for 3-D input.
    lam : float
        Fidelity weight. The paper's Psi calls it with ``lam = 2 / th`` (:func:`psi_tv`).
    iters : int
        Number of dual iterations (the paper: 2 in simulation, 5 in experiments).
    p : (p1, p2), optional
        Dual to start from (warm start); default zeros (the reference resets it every call).
    boundary : {"reference", "adjoint"}
        ``"reference"``: the authors' divergence (:func:`div_ref`); ``"adjoint"``: the exact
        negative adjoint (:func:`div_adjoint`), as in scikit-image.

    Returns
    -------
    (u, (p1, p2))

    Notes
    -----
    Mapping to ``skimage.restoration.denoise_tv_chambolle(f, weight)``, which minimises
    ``1/2 ||u - f||^2 + weight TV(u)`` with the adjoint divergence and the same step: its dual
    is ``p / lam`` and ``weight = 1 / lam``; ``n`` iterations here equal ``n + 1`` of its loop
    (it returns the image computed before its last dual update). The paper's ``lam = 2 / th``
    therefore means ``weight = th / 2``.
    """
    div = div_ref if boundary == "reference" else div_adjoint
    fc = _chan(f)
    p1, p2 = _dual_start(fc, p)
    for _ in range(int(iters)):
        z = div(p1, p2) - lam * fc
        z1, z2 = grad_ref(z)
        den = 1.0 + CHAMBOLLE_DT * np.sqrt(np.sum(z1**2 + z2**2, axis=0, keepdims=True))
        p1 = (p1 + CHAMBOLLE_DT * z1) / den
        p2 = (p2 + CHAMBOLLE_DT * z2) / den
    u = fc - div(p1, p2) / lam
    return _like(u, f), (_like(p1, f), _like(p2, f))


def psi_tv(x: np.ndarray, th: float, iters: int) -> np.ndarray:
    """The paper's TV Psi: ``tvdenoise(x, 2/th, iters)`` with the dual reset
    (docs/design.md s.2)."""
    return chambolle(x, 2.0 / th, iters)[0]


def fgp(b: np.ndarray, weight: float, iters: int, p=None, *, nonneg: bool = False
        ) -> tuple[np.ndarray, tuple[np.ndarray, np.ndarray]]:
    """Fast gradient projection (Beck & Teboulle 2009) for
    ``min_x 1/2 ||x - b||^2 + weight Phi(x)`` [``+ x >= 0`` with ``nonneg``].

    Uses the periodic differences of ``Phi`` (:func:`grad_circ`, ``||D||^2 <= 8``)::

        x(r) = P_C(b - weight D^T r);   p_k = P_ball(r_k + D x(r_k) / (8 weight));
        t_{k+1} = (1 + sqrt(1 + 4 t_k^2)) / 2;   r_{k+1} = p_k + (t_k - 1)/t_{k+1} (p_k - p_{k-1})

    and returns ``x(p_last)``. ``p`` warm-starts the dual (FISTA keeps it across outer
    iterations); the momentum restarts at ``t = 1`` on every call.
    """
    bc = _chan(b)
    p1, p2 = _dual_start(bc, p)

    def primal(r1, r2):
        x = bc - weight * grad_circ_T(r1, r2)
        return np.maximum(x, 0.0) if nonneg else x

    r1, r2 = p1, p2
    t = 1.0
    for _ in range(int(iters)):
        d1, d2 = grad_circ(primal(r1, r2))
        a1 = r1 + d1 / (8.0 * weight)
        a2 = r2 + d2 / (8.0 * weight)
        sc = 1.0 / np.maximum(1.0, np.sqrt(np.sum(a1**2 + a2**2, axis=0, keepdims=True)))
        q1, q2 = a1 * sc, a2 * sc
        t_new = 0.5 * (1.0 + np.sqrt(1.0 + 4.0 * t * t))
        mom = (t - 1.0) / t_new
        r1, r2 = q1 + mom * (q1 - p1), q2 + mom * (q2 - p2)
        p1, p2, t = q1, q2, t_new
    return _like(primal(p1, p2), b), (_like(p1, b), _like(p2, b))
