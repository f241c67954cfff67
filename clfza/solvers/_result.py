"""What a reconstruction returns: :class:`Reconstruction` (the image) and :class:`ReconInfo`
(what was done). Below :mod:`clfza.reconstruction._reconstruct` and :mod:`clfza.solvers`, which both
build them."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np


@dataclass
class ReconInfo:
    """What a reconstruction did: method, device, iterations, timings and why it stopped."""

    method: str
    backend: str
    device: str
    dtype: str
    iterations: int = 0
    stop_reason: str = ""
    # seconds: compile (kernel builds), plan (device set-up, spectra of y), solve (the
    # iterations, checkpoints excluded), checkpoint_overhead, total
    timings: dict = field(default_factory=dict)
    objective: list = field(default_factory=list)
    checkpoints: list = field(default_factory=list)
    params: dict = field(default_factory=dict)
    notes: list = field(default_factory=list)
    mode: str = ""  # TwIST: "paper" (the reference's behaviour) or "efficient"
    evaluations: int = 0  # objective evaluations (each one real FFT pair per channel)
    ffts: int = 0  # real FFT pairs (rfft2 + irfft2) per channel plane, setup included
    stats: dict = field(default_factory=dict)  # solver-specific counters

    def to_dict(self) -> dict:
        return dict(self.__dict__)


@dataclass
class Reconstruction:
    """The reconstructed sensor-plane image (H, W) or (H, W, 3) and its :class:`ReconInfo`."""

    image: np.ndarray
    info: ReconInfo

    def __iter__(self):  # allows ``image, info = clfza.reconstruct(...)``
        yield self.image
        yield self.info
