"""The numpy reference DnCNN: scico's ``DnCNNNet`` as it is defined, in float64 or float32.

Channels-last; 3x3 cross-correlation with circular padding and no bias; ReLU after the first
convolution; ``conv -> BatchNorm (running statistics, eps 1e-5) -> ReLU`` blocks; the last
convolution; output = input - network(input). The noise-conditional variants take a constant
sigma image as a second input channel and return ``x - y[..., 0]``. BatchNorm is applied
literally here (``folded=False``), or folded into the convolutions as the OpenCL kernels run it
(``folded=True``, :meth:`~clfza.denoisers.DnCNNWeights.folded`).
"""

from __future__ import annotations

import numpy as np

from ._weights import BN_EPS, DnCNNWeights


def conv3x3_circular(a: np.ndarray, w: np.ndarray) -> np.ndarray:
    """3x3 cross-correlation with circular padding, channels-last, no bias.

    ``out[..., i, j, o] = sum_{di, dj, c} a[..., (i + di - 1) % H, (j + dj - 1) % W, c]
    * w[di, dj, c, o]`` for ``a`` of shape (..., H, W, Cin) and ``w`` (3, 3, Cin, Cout); in
    ``a``'s dtype (``w`` is cast to it). The channel sums are ``np.einsum`` without BLAS, whose
    summation order is the same at every pixel: a shifted input gives the shifted output
    exactly (a BLAS matrix product may sum edge blocks in another order, 1 ulp apart).

    Examples
    --------
    >>> import numpy as np
    >>> from clfza.denoisers import conv3x3_circular
    >>> w = np.zeros((3, 3, 1, 1)); w[1, 2] = 1.0  # the right-hand neighbour
    >>> conv3x3_circular(np.arange(4.0).reshape(1, 4, 1), w)[0, :, 0]
    array([1., 2., 3., 0.])
    """
    w = np.asarray(w, a.dtype)
    out = np.zeros(a.shape[:-1] + (w.shape[3],), a.dtype)
    for di in range(3):
        for dj in range(3):
            shifted = np.roll(a, (1 - di, 1 - dj), axis=(-3, -2))
            out += np.einsum("...c,co->...o", shifted, w[di, dj], optimize=False)
    return out


def dncnn_reference(x: np.ndarray, weights: DnCNNWeights, sigma: float | None = None,
                    dtype=np.float64, folded: bool = False) -> np.ndarray:
    """Apply a pretrained DnCNN in numpy: the reference of the OpenCL kernels.

    Parameters
    ----------
    x : ndarray
        A (H, W) image or a (N, H, W) batch of them, intensities in [0, 1].
    weights : DnCNNWeights
        From :func:`~clfza.denoisers.load_dncnn`.
    sigma : float, optional
        The noise standard deviation (same [0, 1] scale): the constant second input channel of
        the ``N`` variants; ignored (may be None) for the blind ones.
    dtype : numpy dtype
        float64 (the reference) or float32 (every operation in float32, as the kernels run).
    folded : bool
        Apply BatchNorm folded into the convolutions and the sigma channel as a bias (the
        kernels' form) instead of literally.

    Returns
    -------
    ndarray
        ``x - DnCNN(x)``, shape of ``x``, in ``dtype``.

    Examples
    --------
    >>> import numpy as np
    >>> from clfza.denoisers import dncnn_reference, load_dncnn
    >>> dncnn_reference(np.full((8, 8), 0.5), load_dncnn("6N"), sigma=0.05).shape
    (8, 8)
    """
    dt = np.dtype(dtype)
    x = np.asarray(x, dt)
    single = x.ndim == 2
    a0 = x[None] if single else x
    if weights.conditional:
        s = np.asarray(0.0 if sigma is None else sigma, dt)
    if folded:
        f = weights.folded(dt)
        a = conv3x3_circular(a0[..., None], f.weights[0]) + f.biases[0]
        if weights.conditional:
            a = a + s * f.sigma_bias
        a = np.maximum(a, 0)
        for w, b in zip(f.weights[1:-1], f.biases[1:-1], strict=True):
            a = np.maximum(conv3x3_circular(a, w) + b, 0)
        y = conv3x3_circular(a, f.weights[-1])[..., 0]
    else:
        inp = a0[..., None]
        if weights.conditional:
            inp = np.concatenate([inp, np.broadcast_to(s, inp.shape).astype(dt)], axis=-1)
        a = np.maximum(conv3x3_circular(inp, weights.kernels[0]), 0)
        for i, k in enumerate(weights.kernels[1:-1]):
            c = conv3x3_circular(a, k)
            inv = (np.asarray(weights.bn_var[i], dt) + dt.type(BN_EPS)) ** dt.type(-0.5)
            c = (c - weights.bn_mean[i].astype(dt)) * inv * weights.bn_scale[i].astype(dt)
            a = np.maximum(c + weights.bn_bias[i].astype(dt), 0)
        y = conv3x3_circular(a, weights.kernels[-1])[..., 0]
    out = a0 - y
    return out[0] if single else out
