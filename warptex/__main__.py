"""``python -m warptex``: the command line (see :mod:`warptex.cli`)."""

import sys

from warptex.cli import main

sys.exit(main())
