"""The array-operations interface the solvers are written against: a small core, and families
of per-solver operations beside it.

A backend owns the working precision, the operator ``K`` (Eqs. 17-18) for one camera and one
measurement ``y``, and the core every solver shares: arrays, the data term, regulariser values
and proxes, linear combinations and norms (:class:`Backend`). Arrays are opaque handles of
shape ``(C, H, W)`` (C = 1, or 3 for joint colour); the solver never looks inside them except
through :meth:`Backend.to_host` at checkpoints. Operations that produce scalars (objective
pieces, norms) return a :class:`Scalars` handle; reading it (``.get()``) is the only point
where the host waits for the device, so solvers read them once per iteration (the monotone
tests need the objective) or only at checkpoints, and read several together with
:func:`read_all` (one wait on a GPU instead of one per sum).

What one solver alone needs (TwIST's two-step combination, FISTA's extrapolation, ADMM's fused
updates and its Fourier-diagonal x-update) is an operation family (:class:`Ops`) beside the
solver, in ``clfza/solvers/``: an interface class and one small implementation per backend
kind, a float64 numpy reference and an OpenCL class that names its kernels in
``kernels/*.cl``. A solver gets its backend's implementation with ``Family.for_backend(B)``
(:meth:`Backend.ops`), made once per backend and kept.

The numpy backend (:mod:`.numpy_backend`) is the float64 reference; the OpenCL backend
(:mod:`.opencl_backend`) implements the core with the kernels in ``kernels/*.cl`` and offers
the operation families its kernel registry and launch helpers.
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from dataclasses import dataclass, field
from typing import ClassVar, TypeVar

import numpy as np

from ..errors import ClfzaError


class Scalars(ABC):
    """A deferred pair of sums; ``get()`` returns them as float64 (synchronises)."""

    @abstractmethod
    def get(self) -> np.ndarray: ...

    def start_read(self) -> None:
        """Start copying the sums to the host without waiting, where that is a separate step
        (a device with its own memory); ``get()`` then waits for that copy only. A no-op
        where the sums are already readable."""
        return None


def read_all(*values: Scalars) -> list[np.ndarray]:
    """The float64 values of several deferred sums with one synchronisation: every read but
    the last is started first, so that on a GPU the last read's wait covers them all (one
    host round trip instead of one per read; on CPU devices the sums are host memory)."""
    for v in values[:-1]:
        v.start_read()
    last = values[-1].get()
    return [v.get() for v in values[:-1]] + [last]


class Ready(Scalars):
    """Scalars already on the host."""

    def __init__(self, *values: float):
        self.values = np.array(values + (0.0,) * (2 - len(values)), dtype=np.float64)
        # (at least two values; TwIST's combination returns three)

    def get(self) -> np.ndarray:
        return self.values


@dataclass
class ProxState:
    """Dual state of an iterative TV prox (Chambolle or FGP), kept across calls when warm."""

    warm: bool = False
    arrays: dict = field(default_factory=dict)
    valid: bool = False  # the stored dual may be used (warm start)


OpsT = TypeVar("OpsT", bound="Ops")


class Ops(ABC):
    """A family of fused operations one solver needs beyond the core, on one backend.

    A family is a direct subclass of :class:`Ops` whose abstract methods are its interface
    (documented there, with the float64 meaning); each implementation subclasses the family
    and registers for a backend kind (:attr:`Backend.name`: ``"numpy"``, ``"opencl"``) with
    :meth:`implements`. The OpenCL implementation names the kernels it launches in
    :attr:`KERNELS`, ``((program, (kernel, ...)), ...)`` of ``kernels/<program>.cl``; they are
    built through the backend's one build path (:meth:`OpenCLBackend.use_kernels
    <clfza.backends._opencl.OpenCLBackend.use_kernels>`) when the implementation is
    made, and kept up to date when the backend's tuning changes. Launches go through the
    backend's helpers (``launch1d``, ``launch2d``, ``launch2d_reduce``, ...), so an operation
    costs what the same launch cost inside the backend.

    ``Family.for_backend(B)`` (or ``B.ops(Family)``) returns the backend's implementation,
    made at the first call and kept on the backend (kernels and scratch buffers once per
    backend, reused by :class:`~clfza.backends.BackendCache`). State an implementation keeps
    (the x-update's spectral inverse) is the solver's to set up before use, as the backend's
    own state was.

    Example (a new solver's family, in the solver's own module)::

        class ScaleOps(Ops):
            @abstractmethod
            def scale(self, out, a: float, x) -> None: ...  # out = a x

        @ScaleOps.implements("numpy")
        class NumpyScaleOps(ScaleOps):
            def scale(self, out, a, x):
                out[...] = a * x

        @ScaleOps.implements("opencl")
        class OpenCLScaleOps(ScaleOps):
            KERNELS = (("elementwise", ("lincomb3",)),)

            def scale(self, out, a, x):
                B = self.B
                B.launch1d("lincomb3", out.buf, B.r(a), x.buf, B.r(0), x.buf, B.r(0), x.buf)

        ops = ScaleOps.for_backend(B)
    """

    KERNELS: ClassVar[tuple] = ()  # OpenCL implementations: ((program, (kernel, ...)), ...)
    kinds: ClassVar[dict[str, type]]  # per family: backend kind -> implementation

    def __init__(self, B: Backend):
        self.B = B
        if self.KERNELS:
            B.use_kernels(*self.KERNELS)

    def __init_subclass__(cls, **kwargs):
        super().__init_subclass__(**kwargs)
        if Ops in cls.__bases__:  # a family: its own table of implementations
            cls.kinds = {}

    @classmethod
    def implements(cls, kind: str):
        """Class decorator: register the decorated subclass as the family's implementation on
        backends of kind ``kind``."""
        def register(impl: type) -> type:
            cls.kinds[kind] = impl
            return impl
        return register

    @classmethod
    def for_backend(cls: type[OpsT], B: Backend) -> OpsT:
        """The family's implementation on ``B`` (:meth:`Backend.ops`)."""
        return B.ops(cls)


class Backend(ABC):
    """The core operations every solver needs. Subclasses set ``name`` (the kind the operation
    families register for), ``dtype``, ``shape``, ``nc``, ``device`` and ``ffts`` (count of
    real FFT pairs done)."""

    name: str
    device: str
    dtype: np.dtype
    shape: tuple[int, int]
    nc: int
    ffts: int = 0  # real FFT pairs done so far (one rfft2 + one irfft2 = 1)
    #: The exact finite-aperture model the backend solves on
    #: (:class:`clfza.models.ExactModel`), or None on the transfer-function model.
    exact = None
    #: Where the image sits on the model grid (``exact.geom``), or None (the sensor's grid).
    geom = None
    #: The data scale ``s``: the backend holds ``K / s`` and ``y / s`` (1: no normalisation).
    data_scale: float = 1.0
    #: Seconds spent compiling kernels and planning FFTs when the backend was made.
    compile_s: float = 0.0
    plan_s: float = 0.0

    @property
    def fourier_diagonal(self) -> bool:
        """Whether ``K^T K`` is diagonal in the Fourier basis (the transfer-function model), so
        that a Wiener/Tikhonov solve is one FFT pair."""
        return False

    # ---- operation families ------------------------------------------------------------
    def ops(self, family: type[OpsT]) -> OpsT:
        """This backend's implementation of the operation family ``family`` (:class:`Ops`),
        made at the first call and kept."""
        made = self.__dict__.setdefault("_ops", {})
        impl = made.get(family)
        if impl is None:
            cls = family.kinds.get(self.name)
            if cls is None:
                raise ClfzaError(f"{family.__name__} has no implementation on the {self.name} "
                                 f"backend (has: {', '.join(sorted(family.kinds)) or 'none'})")
            impl = made[family] = cls(self)
        return impl

    # ---- arrays ----------------------------------------------------------------------
    @abstractmethod
    def empty(self): ...

    @abstractmethod
    def from_host(self, a: np.ndarray): ...

    @abstractmethod
    def to_host(self, a) -> np.ndarray:
        """A float64 (C, H, W) host copy (synchronises)."""

    @abstractmethod
    def copy(self, dst, src) -> None: ...

    def scratch_image(self):
        """An image-shaped array (``empty()``'s shape) in the memory of the data term's FFT
        scratch, or None where the backend has none to share (the caller allocates one).
        Its contents are lost whenever the backend applies ``K`` (:meth:`resid_grad`, and
        any other FFT through the backend), so it suits an array that is dead while they
        run: FISTA's extrapolated point is read by the prox before the data term and written
        after it."""
        return None

    def zeros(self):
        return self.from_host(np.zeros((self.nc,) + tuple(self.shape)))

    @abstractmethod
    def finish(self) -> None:
        """Wait for queued work."""

    # ---- the measurement and the data term ------------------------------------------
    @abstractmethod
    def set_measurement(self, y: np.ndarray) -> None:
        """Store ``y`` (C, H, W) and precompute ``K^T y`` (:attr:`b`) and ``||y||^2``."""

    @property
    @abstractmethod
    def b(self):
        """``K^T y`` (back-propagation, Eqs. 11-12; TwIST's initialisation 2).

        The same ``K^T y`` as :func:`clfza.models._transfer.back_propagate` (the float64
        specification; the numpy backends compute it with that operator's adjoint), made once per
        measurement in :meth:`set_measurement`. The OpenCL backend evaluates it as the data
        term's gradient at ``x = 0`` (:meth:`resid_grad`, with the operator's ``H_T``) from the
        spectrum of ``y`` it keeps for every later gradient, so it needs no FFT of its own;
        the agreement tests hold it to the numpy value.
        """

    @abstractmethod
    def resid_grad(self, x, g, step: bool = False) -> Scalars:
        """``g = K^T (y - K x)`` and ``(||y - K x||^2, 0)``: the data term of Eq. 19 and its
        negative gradient, with one real FFT pair (the residual norm by Parseval).

        With ``step``, ``g = x + K^T (y - K x)`` instead: the gradient step of unit length
        (FISTA's, ``L = 1``), added where it is cheapest (on the spectrum, on the TF model).
        """

    # ---- regularisers ----------------------------------------------------------------
    @abstractmethod
    def reg_value(self, x) -> Scalars:
        """``(Phi(x), ||x||_1)``: circular TV (Eq. 20) and l1."""

    @abstractmethod
    def prox_step(self, reg: str, x, g, s: float, th: float, out, iters: int,
                  state: ProxState, tol: float = 0.0, check_every: int = 2) -> int:
        """TwIST's Psi at ``v = x + s g``: ``out = Psi(v, th)``; returns the number of inner
        iterations done.

        ``reg="tv"``: Chambolle's algorithm with ``lam = 2 / th`` (the paper's
        ``tvdenoise(v, 2/th, iters)``), dual reset unless ``state.warm``; ``reg="l1"``: soft
        thresholding at ``th``. With ``tol > 0`` (adaptive inner iterations, issue 6), ``iters``
        is a maximum: after every ``check_every``-th inner step that started from a non-zero
        dual (and is not the last) the relative change ``||p_new - p|| / ||p_new||`` is read
        back (one small reduction and one synchronisation) and the loop stops when it is
        ``<= tol``. ``tol = 0`` runs exactly ``iters`` steps (the reference).
        """

    @abstractmethod
    def project_nonneg(self, out, v) -> None:
        """``out = max(v, 0)``."""

    @abstractmethod
    def fgp_prox(self, reg: str, out, b, weight: float, iters: int, state: ProxState,
                 nonneg: bool) -> Scalars:
        """``out = argmin 1/2 ||u - b||^2 + weight R(u) [+ u >= 0]``: FGP with periodic
        differences for TV (warm-started from ``state``), soft thresholding for l1. Returns
        ``(Phi(out), ||out||_1)``."""

    # ---- linear combinations and norms ----------------------------------------------
    @abstractmethod
    def lincomb(self, out, a: float, X, b: float = 0.0, Y=None, c: float = 0.0, Z=None
                ) -> None:
        """``out = a X + b Y + c Z``."""

    @abstractmethod
    def diffnorm(self, a, b) -> Scalars:
        """``(||a - b||^2, ||a||^2)`` (relative step change)."""

    @abstractmethod
    def dot(self, a, b) -> Scalars:
        """``(<a, b>, 0)``."""
