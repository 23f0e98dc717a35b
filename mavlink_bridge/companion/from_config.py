"""``python -m mavlink_bridge.companion.from_config --config-json FILE|- [--serve]``: a companion started from its
typed configuration, as ``fly`` starts each one.

The configuration is a :class:`~mavlink_bridge.companion.config.CompanionConfig` as one line of JSON
(:meth:`~mavlink_bridge.companion.config.CompanionConfig.to_json`), read from FILE or, with ``-``, as the first line
of standard input (fly writes it there: it holds the signing key, which no file or command line shows); with
``--serve`` the next missions follow it on standard input (:mod:`tssac_core.wire.mission_reset`). The companion then
flies as ``python -m mavlink_bridge.companion`` with the equivalent flags would
(:func:`mavlink_bridge.companion.cli.run`): the same output, logs and exit codes. A configuration that cannot be read
is one line on stderr and exit code 2.
"""

from __future__ import annotations

import sys
from collections.abc import Sequence

from mavlink_bridge.companion.cli import bad_input_errors, log_to_stderr, run
from mavlink_bridge.companion.config import EXIT_BAD_INPUT, CompanionConfig
from tssac_core.common.cli import UsageParser
from tssac_core.sim.settings_json import add_config_flags, config_text
from tssac_core.wire.mission_reset import MissionInput

PROG = "python -m mavlink_bridge.companion.from_config"


def build_parser() -> UsageParser:
    p = UsageParser(prog=PROG, description="Fly one UAV's companion from its configuration (what fly starts).")
    add_config_flags(
        p,
        "the companion's configuration, one line of JSON (CompanionConfig.to_json); -: standard input's first line",
    )
    return p


def read_config(where: str, missions: MissionInput) -> CompanionConfig:
    """The configuration in file ``where``, or (``-``) on ``missions``' first line; raises one line."""
    return CompanionConfig.from_json(*config_text(where, missions))


def main(argv: Sequence[str] | None = None) -> int:
    try:
        args = build_parser().parse_args(argv)
        log_to_stderr("info")
        missions = MissionInput(0)  # standard input: the configuration (-), then the missions (--serve)
        config = read_config(args.config_json, missions)
    except bad_input_errors() as exc:
        print(f"{PROG}: error: {exc}", file=sys.stderr)
        return EXIT_BAD_INPUT
    return run(config, serve=args.serve, missions=missions)


if __name__ == "__main__":
    sys.exit(main())
