"""``python -m tssac_core.train``: see :mod:`tssac_core.train.cli`."""

import sys

from tssac_core.train.cli import console

sys.exit(console())
