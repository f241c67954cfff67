"""Subcommands of the ``clfza`` command line, one module each: its ``NAME``, ``HELP`` and
``DESCRIPTION``, ``add_arguments(parser)`` and the entry point ``run(args)``."""

from __future__ import annotations

from ..reconstruction import install_device_choice
from . import _bench as bench
from . import _calibrate as calibrate
from . import _focus as focus
from . import _reconstruct as reconstruct
from . import _simulate as simulate
from . import _sweep as sweep
from . import _tune as tune
from ._common import add_subcommand

# every command (and ``clfza info``) chooses the default OpenCL device by measurement
install_device_choice()

MODULES = (reconstruct, simulate, focus, calibrate, bench, sweep, tune)


def register_all(subparsers, common) -> None:
    """Add every subcommand to ``subparsers``; ``common`` is the parent parser that carries
    ``--quiet``, ``--verbose`` and ``--debug``."""
    for mod in MODULES:
        mod.add_arguments(add_subcommand(subparsers, common, mod.NAME, mod.HELP,
                                         mod.DESCRIPTION))
