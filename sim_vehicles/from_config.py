"""``python -m sim_vehicles.from_config --config-json FILE|- [--serve]``: the SITL world started from its typed
configuration, as ``fly`` starts it.

The configuration is a :class:`~tssac_core.sim.sitl_config.SitlConfig` as one line of JSON
(:meth:`~tssac_core.sim.sitl_config.SitlConfig.to_json`), read from FILE or, with ``-``, as the first line of standard
input (fly writes it there: it holds the signing key, which no file or command line shows); with ``--serve`` the next
missions follow it on standard input (:mod:`tssac_core.wire.mission_reset`). The world then runs as ``python -m
sim_vehicles`` with the equivalent flags would (:func:`sim_vehicles.__main__.run`): the same lines on standard
output, logs and exit codes. A configuration that cannot be read is one line on stderr and exit code 2.
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Sequence
from typing import NoReturn

from sim_vehicles.__main__ import BAD_INPUT, log_to_stderr, run
from tssac_core.sim.settings_json import add_config_flags, config_text
from tssac_core.sim.sitl_config import SitlConfig
from tssac_core.wire.mission_reset import MissionInput

PROG = "python -m sim_vehicles.from_config"


class _Parser(argparse.ArgumentParser):
    """argparse, but a usage error is one line on stderr (exit 2), as ``python -m sim_vehicles``'s."""

    def error(self, message: str) -> NoReturn:
        self.exit(2, f"{PROG}: error: {message} (see --help)\n")


def build_parser() -> argparse.ArgumentParser:
    p = _Parser(prog=PROG, description="Start the SITL world from its configuration (what fly starts).")
    add_config_flags(
        p,
        "the world's configuration, one line of JSON (SitlConfig.to_json); -: standard input's first line",
    )
    return p


def read_config(where: str, missions: MissionInput) -> SitlConfig:
    """The configuration in file ``where``, or (``-``) on ``missions``' first line; raises one line."""
    return SitlConfig.from_json(*config_text(where, missions))


def main(argv: Sequence[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    log_to_stderr("warning")
    missions = MissionInput(0)  # standard input: the configuration (-), then the missions (--serve)
    try:
        config = read_config(args.config_json, missions)
    except BAD_INPUT as exc:
        print(f"{PROG}: error: {exc}", file=sys.stderr)
        return 2
    return run(config, serve=args.serve, missions=missions)


if __name__ == "__main__":
    sys.exit(main())
