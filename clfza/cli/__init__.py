"""clfza.cli: public surface."""

from __future__ import annotations

from ._main import (  # noqa: F401
    ArgumentParser,
    ClfzaError,
    build_parser,
    camera_report,
    common_options,
    log,
    main,
    report_exception,
    setup_logging,
)
