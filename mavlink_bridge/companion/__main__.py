"""``python -m mavlink_bridge.companion``: see :mod:`mavlink_bridge.companion.cli`."""

import sys

from mavlink_bridge.companion.cli import main

sys.exit(main())
