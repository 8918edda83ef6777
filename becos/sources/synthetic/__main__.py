"""``python -m becos.sources.synthetic OUT_DIR``: generate the synthetic collection (``becos synthetic OUT_DIR``)."""

import sys

from becos.cli import main

sys.exit(main(["synthetic", *sys.argv[1:]]))
