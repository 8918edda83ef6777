"""``python -m becos``: the command line (see :mod:`becos.cli`)."""

from becos.cli import program

program()
