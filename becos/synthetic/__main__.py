"""``python -m becos.synthetic OUT_DIR``: generate the synthetic collection."""

import sys

from becos.synthetic import main

sys.exit(main())
