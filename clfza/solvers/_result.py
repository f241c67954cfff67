"""What a reconstruction returns: :class:`Reconstruction` (the image) and :class:`ReconInfo`
(what was done). Below :mod:`clfza.reconstruction._reconstruct` and :mod:`clfza.solvers`, which both
build them."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np


@dataclass
class ReconInfo:
    """What a reconstruction did: method, device, iterations, timings and why it stopped.

    Attributes
    ----------
    plan : clfza.reconstruction.Plan or None
        The plan a planned reconstruction ran with
        (:func:`clfza.reconstruction.reconstruct_planned`; its record is also in
        ``params["plan"]``); None otherwise.
    focus : clfza.focus.FocusResult or None
        The depth search behind a refocused reconstruction
        (:func:`clfza.reconstruction.reconstruct_autofocus`; the depth found is also in
        ``params["z1_autofocus"]``); None otherwise.

    ``plan`` and ``focus`` are objects, not record fields: :meth:`to_dict` leaves them out
    (their JSON-ready parts are in ``params``).
    """

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
    plan: object | None = field(default=None, repr=False, compare=False)
    focus: object | None = field(default=None, repr=False, compare=False)

    def to_dict(self) -> dict:
        """The record's fields as a dict (without the ``plan`` and ``focus`` objects)."""
        return {k: v for k, v in self.__dict__.items() if k not in _OBJECTS}


_OBJECTS = ("plan", "focus")  # ReconInfo's fields that hold objects, not record values


@dataclass
class Reconstruction:
    """The reconstructed sensor-plane image (H, W) or (H, W, 3) and its :class:`ReconInfo`;
    of a stack of frames, the images ``(F, H, W[, 3])`` and a list of one record per frame."""

    image: np.ndarray
    info: ReconInfo | list[ReconInfo]

    def __iter__(self):  # allows ``image, info = clfza.reconstruct(...)``
        yield self.image
        yield self.info
