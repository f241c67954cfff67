"""clfza.backends: public surface."""

from __future__ import annotations

from ._select import (  # noqa: F401
    BACKENDS,
    Backend,
    BackendCache,
    Camera,
    ClfzaError,
    Ops,
    OrderedDict,
    ProxState,
    Ready,
    Scalars,
    contextmanager,
    exact_model,
    get_backend,
    reuse_backends,
)
