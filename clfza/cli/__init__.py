"""The ``clfza`` command line: ``demo``, ``info``, ``reconstruct``, ``simulate``, ``focus``,
``calibrate``, ``sweep``, ``bench`` and ``tune``; :func:`main` is its entry point."""

from __future__ import annotations

from ._main import main, report_exception

__all__ = ["main", "report_exception"]
