"""``python -m becos``: the command line (see :mod:`becos.cli`)."""

import sys

from becos.cli import main

sys.exit(main())
