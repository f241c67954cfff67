"""The default route's model choice for a frame: the noise against the transfer-function
model's error.

Far from critical sampling without an aperture, the transfer-function model of Eq. 17 is not
the camera's map (its sampled ``H_T`` wraps or aliases) and ``model="auto"`` runs ADMM on the
exact model, whose minimiser is the better image when the frame is clean. With enough noise
the model's error is lost under it, and the transfer-function model's one FFT pair per
iteration wins, in quality and in time; in between, the exact model's lead shrinks while its
cost per iteration stays several times Eq. 17's. :func:`model_error` measures the
transfer-function model's error on the frame's own Wiener estimate; :func:`route_model` takes
Eq. 17 when the frame's noise energy ``N sigma^2`` is at least
:data:`NOISE_OVER_MODEL_ERROR` times it (the ratio and the trade measured:
docs/measurements.md, clfza.solvers._route).
"""

from __future__ import annotations

import hashlib
from collections import OrderedDict

import numpy as np

from ..backends import get_backend
from ..camera import Camera
from ..models import NumpyOperator, camera_model
from ._noise import estimate_noise
from ._wiener import wiener_lam, wiener_tf

#: Eq. 17 when N sigma^2 >= this times the transfer-function model's error
NOISE_OVER_MODEL_ERROR = 2.0
_CACHE: OrderedDict = OrderedDict()  # (camera, frame digest) -> (noise, error) energies
_CACHE_SIZE = 8


def _planes(y: np.ndarray) -> np.ndarray:
    a = np.asarray(y, dtype=np.float64)
    return a[None] if a.ndim == 2 else np.moveaxis(a, -1, 0)


def energies(y: np.ndarray, camera: Camera) -> tuple[float, float]:
    """``(N sigma^2, ||K_exact x - K_tf x||^2)`` of a DC-free frame ``y`` (H, W) or (H, W, 3),
    summed over its channels: the noise's energy (``sigma`` estimated from the frame,
    :func:`clfza.solvers.estimate_noise`) and the transfer-function model's error on the
    frame's Wiener estimate ``x`` (Eq. 17, ``lam`` from the noise; the exact model of the
    camera's mask, :func:`clfza.models.camera_model`, with ``x`` on the sensor). Cached per
    camera and frame content (the entry point and the solver both ask).
    """
    planes = _planes(y)
    key = (camera, hashlib.blake2b(planes.tobytes(), digest_size=16).hexdigest())
    hit = _CACHE.get(key)
    if hit is not None:
        _CACHE.move_to_end(key)
        return hit
    B = get_backend("numpy", camera)
    tf = NumpyOperator(camera, "tf", warn=False)
    exact = camera_model(camera)
    noise = err = 0.0
    for p in planes:
        sigma = estimate_noise(p, camera)[0]
        B.set_measurement(p[None])
        lam, _ = wiener_lam(B, p[None], sigma)
        x = B.empty()
        wiener_tf(B, lam, x)
        d = exact.forward(exact.geom.embed(x[0])) - tf.forward(x[0])
        d -= d.mean()
        noise += p.size * sigma**2
        err += float(np.sum(d * d))
    _CACHE[key] = (noise, err)
    while len(_CACHE) > _CACHE_SIZE:
        _CACHE.popitem(last=False)
    return noise, err


def model_error(y: np.ndarray, camera: Camera) -> float:
    """The transfer-function model's error energy on the frame's own Wiener estimate,
    ``||K_exact x - K_tf x||^2`` (:func:`energies`).

    Examples
    --------
    >>> import clfza
    >>> cam = clfza.Camera.preset("simulation").with_shape((64, 64))
    >>> y = clfza.simulate(np.eye(64), cam, sensor_plane=True).y
    >>> model_error(y, cam) > 0
    True
    """
    return energies(y, camera)[1]


def route_model(y: np.ndarray, camera: Camera) -> tuple[str, str]:
    """``("tf", why)`` where the frame's noise swamps the transfer-function model's error,
    else ``("exact", why)``; for cameras the exact model was chosen for by their sampling
    alone (no aperture, the mask centred)."""
    noise, err = energies(y, camera)
    ratio = noise / err if err > 0 else np.inf
    ratio_s = f"N sigma^2 / model error = {ratio:.3g}"
    if ratio >= NOISE_OVER_MODEL_ERROR:
        return "tf", (f"far from critical sampling, but the frame's noise swamps the "
                      f"transfer-function model's error ({ratio_s} >= "
                      f"{NOISE_OVER_MODEL_ERROR:g}): Eq. 17, one FFT pair per iteration")
    return "exact", (f"far from critical sampling, where the sampled H_T wraps or aliases, "
                     f"and the transfer-function model's error stands above the frame's noise "
                     f"({ratio_s} < {NOISE_OVER_MODEL_ERROR:g})")
