"""``python -m tssac_core.train``: see :mod:`tssac_core.train.cli`."""

import sys

from tssac_core.common.cli import run
from tssac_core.train.cli import main

sys.exit(run(main))
