"""``python -m tssac_core.experiments``: see :mod:`tssac_core.experiments.cli`."""

import sys

from tssac_core.common.cli import run
from tssac_core.experiments.cli import main

sys.exit(run(main))
