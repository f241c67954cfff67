"""What an FFT engine is: the interface the operator and the backends use, nothing more."""

from __future__ import annotations

from typing import Protocol, runtime_checkable


@runtime_checkable
class FFTEngine(Protocol):
    """Real 2-D FFTs on :class:`~clfza.cl.DeviceArray` for one grid and precision.

    ``name`` says which implementation it is (``clfza info``); ``batched`` is True when
    ``rfft2``/``irfft2`` also transform ``(C, H, W)`` arrays with ``C > 1`` (every channel
    plane in one call: joint colour needs it), False when they take one plane (``(H, W)`` or
    ``(1, H, W)``). The spectrum of a real ``(H, W)`` grid has ``spectrum_shape``
    ``(H, W // 2 + 1)``; ``irfft2`` includes the ``1/N`` normalisation (numpy's convention).

    ``irfft2(X, x)`` leaves ``X`` unchanged; ``irfft2(X, x, overwrite_x=True)`` may use ``X``
    as its work space (scipy.fft's ``overwrite_x``), which saves a pass over a spectrum-sized
    buffer: the callers whose ``X`` is scratch (every data term in clfza) pass it. On the
    host engine that is the inverse's column pass in place instead of through a temporary
    (measured: docs/measurements.md, clfza.fft._engine).
    """

    name: str
    batched: bool
    shape: tuple[int, int]

    @property
    def spectrum_shape(self) -> tuple[int, int]: ...

    def rfft2(self, x, X) -> None: ...

    def irfft2(self, X, x, overwrite_x: bool = False) -> None: ...
