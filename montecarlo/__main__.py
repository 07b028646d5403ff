"""``python -m montecarlo``: the command line (see :mod:`montecarlo.cli`)."""

from montecarlo.cli import entry_point

entry_point()
