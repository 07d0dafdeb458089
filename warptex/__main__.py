"""``python -m warptex``: the command line (see :mod:`warptex.apps.cli`)."""

import sys

from warptex.apps.cli import main

sys.exit(main())
