"""clfza.solvers: public surface."""

from __future__ import annotations

from ._run import (  # noqa: F401
    COLOUR_MODES,
    DEFAULT_TV_TOL,
    EFFICIENT_TV_ITERS,
    ITERATIVE,
    METHODS,
    REGISTRY,
    RUN_CONTROLS,
    TAU_RANGE_F32,
    ClfzaError,
    ClfzaWarning,
    MethodOptions,
    Monitor,
    ReconInfo,
    Reconstruction,
    check_finite,
    check_options,
    default_iters,
    finite_image,
    option_names,
    options_class,
    run_solver,
    solver_class,
)
