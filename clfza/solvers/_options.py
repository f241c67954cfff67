"""Method options: one dataclass per method, with its defaults and its validation.

Every iterative method's options derive from :class:`MethodOptions` (the options all of them
take); a solver file declares its own subclass with :func:`option` fields, e.g.::

    @dataclass(kw_only=True)
    class FistaOptions(MethodOptions):
        monotone: bool = option(True, boolean, "reject steps that raise the objective")
        weight: float | None = option(None, positive, "TV weight; default tau / 2")

:meth:`MethodOptions.from_options` is the single entry for the API (keyword arguments), the
command line (``--opt KEY=VALUE``, parsed to int/float/bool/str first) and the planner: it
rejects unknown names, type-checks every value (``nonneg="maybe"`` is an error, not True),
fills the defaults that depend on other options (:meth:`MethodOptions.resolve`) and checks
the rules between options. A value of None means "the method's default".

The run controls ``truth``, ``checkpoints``, ``callback``, ``x0`` and ``pilot`` are not method
options: :func:`clfza.solvers.run_solver` takes them for every method (:data:`RUN_CONTROLS`).
``pilot=True`` marks ``x0`` as a pilot estimate for ``tau="auto"`` on the exact model: its
residual gives the noise in place of the pilot passes (:func:`clfza.solvers.exact_group`).

An options instance is also what :func:`clfza.reconstruct` takes as ``method`` (the classes
are ``clfza.ADMM``, ``clfza.FISTA``, ``clfza.TwIST`` and ``clfza.Wiener``): the options it
was given (:meth:`MethodOptions.given`) become the keyword options, the others keep the
method's defaults, which can depend on the model and on a measured PSF.

The package's defaults of a solve, defined once here: :data:`DEFAULT_METHOD` and
:data:`DEFAULT_BACKEND`.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable, Mapping
from dataclasses import dataclass

import numpy as np

# ``positive`` and ``nonnegative`` are the one set of validators (clfza.errors); the solver
# modules import them from here with the option checks below
from ..errors import ClfzaError, nonnegative, positive, positive_int

#: The method of :func:`clfza.reconstruct`, :func:`clfza.reconstruct_many`, the planner,
#: autofocus and ``clfza reconstruct`` when none is named: ``"auto"``, the default route
#: (:func:`resolve_method`: ADMM with ``tau="auto"`` on the forward model that the camera and
#: the frame's noise call for).
DEFAULT_METHOD = "auto"
#: The method of a search over many points (focal stacks, sweeps) when none is named:
#: back-propagation (Eqs. 11-12), one FFT pair a point.
SEARCH_METHOD = "bp"
#: What the default route ``"auto"`` runs (:func:`resolve_method`)
AUTO_ROUTE = "admm"
#: The backend every entry point uses when none is named (solves, the focus search's fast
#: back-propagation, batches and sweeps): OpenCL, float32 by default.
DEFAULT_BACKEND = "opencl"



def resolve_method(method: str, options: dict) -> tuple[str, dict, str | None]:
    """``(method, options, note)``: ``"auto"`` resolved to the default route (ADMM, with
    ``tau="auto"`` unless a ``tau`` or TV ``weight`` is given; its model chosen by
    :func:`clfza.solvers.method_model` with the frame's noise), and the note for the record;
    any other method as it is (note None).

    Examples
    --------
    >>> resolve_method("auto", {"iters": 50})[:2]
    ('admm', {'iters': 50, 'tau': 'auto'})
    >>> resolve_method("fista", {"tau": 0.01})
    ('fista', {'tau': 0.01}, None)
    """
    if method != "auto":
        return method, options, None
    out = dict(options)
    if out.get("tau") is None and out.get("weight") is None:
        out["tau"] = "auto"
    return AUTO_ROUTE, out, ("method: auto, the default route: ADMM with tau chosen from the "
                             "data, on the forward model the camera and the frame's noise "
                             "call for")


STOP_RULES = ("objective", "step", "none")
COLOUR_MODES = ("independent", "joint")
REGULARISERS = ("tv", "l1")
#: what every iterative method takes besides its options (see :mod:`clfza.solvers._common`)
RUN_CONTROLS = frozenset({"truth", "checkpoints", "callback", "x0", "pilot"})


# ---- value checks: (name, value) -> validated value, or ClfzaError ----------------------
#: A finite number >= 0 (tolerances): :func:`clfza.errors.nonnegative`.
nonneg_number = nonnegative


def integer(minimum: int) -> Callable:
    """An integer >= ``minimum`` (integral floats such as 5.0 are accepted)."""
    def check(name: str, v) -> int:  # a bool or a string is an error (clfza.errors)
        return positive_int(name, v, minimum)
    return check


def boolean(name: str, v) -> bool:
    """True or False (numpy booleans and the integers 0 and 1 too); anything else fails."""
    if isinstance(v, (bool, np.bool_)):
        return bool(v)
    if isinstance(v, (int, np.integer)) and v in (0, 1):
        return bool(v)
    raise ClfzaError(f"{name} must be true or false, got {v!r}")


def choice(*values: str) -> Callable:
    """One of ``values``."""
    def check(name: str, v) -> str:
        if not isinstance(v, str) or v not in values:
            raise ClfzaError(f"{name} must be one of {values}, got {v!r}")
        return v
    return check


#: Why the methods other than ADMM refuse ``reg="dncnn"`` (issue 38), in one line: the
#: candidates measured in docs/measurements.md (clfza.solvers._pnp)
DNCNN_ELSEWHERE = (
    "reg='dncnn' (the DnCNN learned prior) is a prior for method 'admm' only (plug-and-play); "
    "this method refuses it: measured from the same TV start, the denoiser as FISTA's prox "
    "stayed below plug-and-play ADMM on every case, far below on the noisy frames (TwIST's "
    "step takes the same prox; RED: below it on the natural scenes; docs/measurements.md, "
    "clfza.solvers._pnp); run method 'admm' with reg='dncnn', a numeric tau and, without a "
    "measured PSF, model='tf' (command line: --method admm --opt reg=dncnn --tau T --model "
    "tf)")


def regulariser(name: str, v) -> str:
    """One of :data:`REGULARISERS`; ``"dncnn"`` (ADMM's own, :mod:`clfza.solvers._pnp`) is
    refused with :data:`DNCNN_ELSEWHERE`, the reason and what to run instead."""
    if isinstance(v, str) and v == "dncnn":
        raise ClfzaError(DNCNN_ELSEWHERE)
    return choice(*REGULARISERS)(name, v)


def open_unit(name: str, v) -> float:
    """A number in (0, 1)."""
    t = positive(name, v)
    if not t < 1:
        raise ClfzaError(f"{name} must be in (0, 1), got {v!r}")
    return t


def relaxation(name: str, v) -> float:
    """An ADMM over-relaxation factor in (0, 2)."""
    t = positive(name, v)
    if not t < 2:
        raise ClfzaError(f"{name} must be in (0, 2), got {v!r}")
    return t


def option(default, check: Callable, doc: str = "", shown: str | None = None):
    """A dataclass field that is a method option: its default, its check and a line of help
    (``shown``: the default as help states it, where the field's value is a stand-in)."""
    meta = {"check": check, "doc": doc}
    if shown is not None:
        meta["shown"] = shown
    return dataclasses.field(default=default, metadata=meta)


@dataclass(kw_only=True)
class MethodOptions:
    """The options every iterative method takes (Eq. 19 and the stopping rule).

    An instance remembers which options it was given (the constructor's keywords, and any
    field changed since): :meth:`given`.
    """

    def __new__(cls, *args, **kwargs):
        self = super().__new__(cls)
        object.__setattr__(self, "_given", frozenset(kwargs))  # read by given()
        return self

    tau: float = option(0.005, positive, "Eq. 19 weight (the paper's simulation: 0.005)")
    iters: int = option(200, integer(1), "maximum number of iterations")
    min_iters: int | None = option(None, integer(0), "no stop before this iteration")
    tol: float = option(1e-6, nonneg_number, "tolerance of the stopping rule")
    stop: str = option("objective", choice(*STOP_RULES),
                       "relative objective change, relative step change, or none")
    stop_window: int | None = option(None, integer(1), "the objective rule's window: the "
                                     "relative change over this many iterations (ADMM: the "
                                     "spread of the objective), 1 = each iteration's",
                                     shown="the method's")
    nonneg: bool | None = option(None, boolean, "constrain the image to x >= 0")
    reg: str = option("tv", regulariser, "regulariser: TV (Eq. 20) or l1 (reg='dncnn': "
                      "method admm)")
    colour: str = option("independent", choice(*COLOUR_MODES),
                         "colour channels solved one by one or jointly (vectorial TV)")

    @classmethod
    def names(cls) -> set[str]:
        return {f.name for f in dataclasses.fields(cls)}

    @classmethod
    def help(cls) -> dict[str, str]:
        """``{name: "doc (default ...)"}`` for every option."""
        return {f.name: f"{f.metadata.get('doc', '')} (default "
                        f"{f.metadata.get('shown', repr(f.default))})"
                for f in dataclasses.fields(cls)}

    @classmethod
    def from_options(cls, options: Mapping, *, method: str = "", exact: bool = False
                     ) -> MethodOptions:
        """Validated options from a mapping of names to values (unknown names, wrong types
        and broken rules raise :class:`~clfza.errors.ClfzaError` with one line)."""
        known = cls.names()
        unknown = sorted(set(options) - known - RUN_CONTROLS)
        if unknown:
            raise ClfzaError(f"method {method!r} does not take option(s) {unknown}; allowed: "
                             f"{sorted(known | RUN_CONTROLS)}")
        o = cls(**cls.check_values(options))
        o.resolve(exact)
        return o

    @classmethod
    def check_values(cls, options: Mapping) -> dict:
        """The given options (None dropped) checked one by one: types and ranges, not the
        rules between options."""
        values = {}
        for f in dataclasses.fields(cls):
            v = options.get(f.name)
            if v is not None:
                values[f.name] = f.metadata["check"](f.name, v)
        return values

    def resolve(self, exact: bool) -> None:
        """Fill the defaults that depend on other options and check the rules between them
        (subclasses extend it)."""
        if self.min_iters is None:
            self.min_iters = 1
        if self.nonneg is None:
            self.nonneg = False

    def params(self) -> dict:
        """The resolved options, for the info record."""
        return dataclasses.asdict(self)

    def given(self) -> dict:
        """The options this instance asks for, by name: those passed to the constructor and
        those changed since (not yet checked: :meth:`from_options` checks them). The others
        are left to the method, whose defaults can depend on the model (the exact model's
        ADMM runs 400 iterations) and on a measured PSF (its own ``tau``, 200 iterations).

        Examples
        --------
        >>> from clfza.solvers import AdmmOptions
        >>> AdmmOptions(tau=0.01, iters=100).given()
        {'tau': 0.01, 'iters': 100}
        """
        named = getattr(self, "_given", frozenset())
        return {f.name: getattr(self, f.name) for f in dataclasses.fields(self)
                if f.name in named or getattr(self, f.name) != f.default}
