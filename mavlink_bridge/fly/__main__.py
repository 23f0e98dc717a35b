"""``python -m mavlink_bridge.fly``: see :mod:`mavlink_bridge.fly.cli`."""

import sys

from mavlink_bridge.fly.cli import main

sys.exit(main())
