"""``python -m warptex``: the command line (see :mod:`warptex.apps.cli`)."""

from warptex.apps.cli import entry

entry()
