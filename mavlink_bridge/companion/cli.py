"""``python -m mavlink_bridge.companion``: the command line of one UAV's companion (:mod:`mavlink_bridge.companion`)."""

from __future__ import annotations

import argparse
import dataclasses
import json
import logging
import signal
import sys
from collections.abc import Sequence
from pathlib import Path
from types import FrameType
from typing import TYPE_CHECKING

from mavlink_bridge.companion.config import (
    COMMAND_TIMEOUT_S,
    EXIT_BAD_INPUT,
    EXIT_OK,
    EXIT_WRITE_FAILED,
    LOCKSTEP_COMMAND_TIMEOUT_S,
    LOCKSTEP_GRANT_S,
    PILOT_NAMES,
    CompanionConfig,
    default_command_timeout_s,
)
from mavlink_bridge.companion.status import CompanionResult
from mavlink_bridge.estimation.filter_model import FilterModel
from mavlink_bridge.link.guided_commands import SetpointDialect, add_setpoints_argument
from mavlink_bridge.link.signing_key import read_signing_key
from tssac_core.assurance.monitor import ShieldConfig
from tssac_core.common.cli import UsageError, UsageParser, bad_input_line
from tssac_core.common.errors import CheckpointError
from tssac_core.common.shield_options import SHIELD_ADJUST_HELP, adjust_option
from tssac_core.sim.airframe_response import response_option
from tssac_core.sim.scenario import Role, ScenarioError, load
from tssac_core.sim.settings_json import SettingsError
from tssac_core.sim.shield_tuning import add_tuning_options, tuning_option
from tssac_core.wire.mission_reset import MissionInput, NextMission, ResetError, redirect_stderr

if TYPE_CHECKING:
    from mavlink_bridge.companion.machine import Companion

_log = logging.getLogger("mavlink_bridge.companion")

PROG = "python -m mavlink_bridge.companion"


def shield_config(args: argparse.Namespace) -> ShieldConfig | None:
    """The monitor ``--shield`` asks for, with ``--shield-adjust`` and its tuning; None without it."""
    adjust = adjust_option(args.shield_adjust, args.shield)
    tuning = tuning_option(args, args.shield)
    return tuning.config(adjust) if args.shield else None


def build_parser() -> argparse.ArgumentParser:
    p = UsageParser(
        prog=PROG,
        description="Fly one SITL (or real) UAV over MAVLink with a trained policy or the guidance controller.",
    )
    _pilot_flags(p.add_argument_group("the pilot"))
    _link_flags(p.add_argument_group("the link"))
    _time_flags(p.add_argument_group("time and failsafes"))
    _output_flags(p.add_argument_group("outputs"))
    return p


def _pilot_flags(g: argparse._ActionsContainer) -> None:
    """The vehicle, the role and who flies it."""
    g.add_argument(
        "--connect", required=True, metavar="CONN", help="the vehicle's connection string, e.g. udpout:127.0.0.1:14560"
    )
    g.add_argument("--role", required=True, choices=[r.value for r in Role], help="which UAV this is")
    who = g.add_mutually_exclusive_group(required=True)
    who.add_argument(
        "--model",
        type=Path,
        metavar="FILE",
        help="the role's trained actor: models/tssac/<role>.npz (numpy only), <role>.onnx (onnxruntime) or <role>.pt "
        "(needs torch)",
    )
    who.add_argument(
        "--pilot",
        choices=PILOT_NAMES,
        help="fly the rule-based guidance controller, straight on (a test pilot that hits what lies ahead), or an "
        "adversary built to break the monitor (docs/runtime_assurance.md, 'Adversarial pilots')",
    )
    g.add_argument(
        "--shield", action="store_true", help="fly through the runtime-assurance monitor (docs/runtime_assurance.md)"
    )
    g.add_argument(
        "--airframe-response",
        type=Path,
        metavar="FILE",
        help="with --shield: the monitor predicts with this airframe's fitted turn lag "
        "(sim_vehicles/dynamics/airframes/<name>.response.yaml) instead of eq. 5 (docs/runtime_assurance.md)",
    )
    g.add_argument("--shield-adjust", action="store_true", help=SHIELD_ADJUST_HELP)
    add_tuning_options(g)
    g.add_argument(
        "--source-system",
        type=int,
        metavar="ID",
        help="our MAVLink system id (default: the vehicle's, as on a real vehicle; our component is 191, an onboard "
        "computer, and 255 is left to the ground station)",
    )
    g.add_argument(
        "--scenario", required=True, type=Path, metavar="FILE", help="scenario with the fixed layout the vehicle flies"
    )
    g.add_argument(
        "--filter",
        choices=[m.value for m in FilterModel],
        default=FilterModel.CONSTANT_TURN_EKF.value,
        help="Kalman filter model (default constant_turn_ekf)",
    )


def _link_flags(g: argparse._ActionsContainer) -> None:
    """The MAVLink link to the vehicle: the dialect, signing, commands and their retries, telemetry."""
    add_setpoints_argument(g)
    g.add_argument(
        "--signing-key", type=Path, metavar="FILE", help="MAVLink 2 signing key: 32 raw bytes or 64 hex characters"
    )
    g.add_argument(
        "--command-timeout-s",
        type=float,
        metavar="S",
        help=f"wall seconds per COMMAND_ACK wait (default {COMMAND_TIMEOUT_S:g}, with --lockstep "
        f"{LOCKSTEP_COMMAND_TIMEOUT_S:g}: a lockstep world holding at its start answers at once)",
    )
    g.add_argument(
        "--command-retries",
        type=int,
        metavar="N",
        help="attempts per command (default: 10, more over a lossy link: enough that a command fails with a chance "
        "below one in a million)",
    )
    g.add_argument(
        "--lean-telemetry",
        action="store_true",
        help="stop the vehicle's streams the companion does not use (no ground station sharing it)",
    )


def _time_flags(g: argparse._ActionsContainer) -> None:
    """The clock and the failsafes: lockstep, how long to wait for what, when to hold."""
    g.add_argument("--lockstep", action="store_true", help="the vehicle runs in lockstep: never extrapolate its clock")
    g.add_argument(
        "--lockstep-grant-s",
        type=float,
        default=LOCKSTEP_GRANT_S,
        metavar="S",
        help=f"lockstep over a link that loses nothing: answer only when the setpoint may change, granting the vehicle "
        f"up to S seconds of ticks in between (default {LOCKSTEP_GRANT_S:g}; 0: answer every tick)",
    )
    g.add_argument(
        "--timeout-s",
        type=float,
        default=30.0,
        metavar="S",
        help="wall seconds to wait for the first heartbeat (default 30)",
    )
    g.add_argument(
        "--hold-after-s",
        type=float,
        default=0.5,
        metavar="S",
        help="vehicle seconds without a fix before the hold setpoint (default 0.5)",
    )
    g.add_argument(
        "--silence-hold-s",
        type=float,
        default=2.0,
        metavar="S",
        help="wall seconds of silence before the hold when the clock cannot be extrapolated (default 2)",
    )
    g.add_argument(
        "--lost-after-s",
        type=float,
        default=10.0,
        metavar="S",
        help="wall seconds of silence before the vehicle is given up (default 10)",
    )
    g.add_argument("--duration-s", type=float, metavar="S", help="stop after this many vehicle seconds of flight")


def _output_flags(g: argparse._ActionsContainer) -> None:
    """What the companion writes and how it is run."""
    g.add_argument("--tlog", type=Path, metavar="FILE", help="write every message received and sent to this .tlog")
    g.add_argument("--status-json", type=Path, metavar="FILE", help="write the final status here")
    g.add_argument(
        "--serve",
        action="store_true",
        help=(
            "after the mission, read the next one from standard input (one JSON line: index, scenario, status_json, "
            'tlog, log) and fly it over the same link, until {"quit": true} or the end of the input'
        ),
    )
    g.add_argument(
        "--log-level",
        choices=["debug", "info", "warning", "error"],
        default="info",
        help="log level on stderr (default info)",
    )


def config_from_args(args: argparse.Namespace) -> CompanionConfig:
    scenario = load(args.scenario)
    if scenario.layout is None:
        raise UsageError(
            f"{args.scenario}: scenario has a random layout: give the layout the vehicle flies "
            "(the SITL writes it with --layout-out FILE)"
        )
    if args.model is not None and not args.model.is_file():
        raise UsageError(
            f"{args.model}: checkpoint not found (train one with python -m tssac_core.train, or use --pilot guidance)"
        )
    return CompanionConfig(
        connection=args.connect,
        role=Role(args.role),
        scenario=scenario,
        model=args.model,
        signing_key=read_signing_key(args.signing_key) if args.signing_key is not None else None,
        tlog=args.tlog,
        status_json=args.status_json,
        lockstep=args.lockstep,
        lockstep_grant_s=args.lockstep_grant_s,
        connect_timeout_s=args.timeout_s,
        command_timeout_s=(
            default_command_timeout_s(args.lockstep) if args.command_timeout_s is None else args.command_timeout_s
        ),
        command_retries=args.command_retries,
        hold_after_s=args.hold_after_s,
        silence_hold_s=args.silence_hold_s,
        lost_after_s=args.lost_after_s,
        duration_s=args.duration_s,
        filter_model=FilterModel(args.filter),
        lean_telemetry=args.lean_telemetry,
        pilot=args.pilot or "",
        shield=shield_config(args),
        airframe_response=response_option(args.airframe_response, args.shield, scenario),
        setpoints=SetpointDialect(args.setpoints),
        source_system=args.source_system,
    )


def build_companion(config: CompanionConfig) -> Companion:
    """The companion with the pilot ``config`` names (the machine, pymavlink and the filter load here, after the
    arguments are parsed: --help answers at once)."""
    from mavlink_bridge.companion.machine import Companion

    return Companion(config)


def bad_input_errors() -> tuple[type[Exception], ...]:
    """Exceptions that mean bad input: one line and exit code 2."""
    from mavlink_bridge.link.connection import LinkError

    return (UsageError, ScenarioError, SettingsError, LinkError, CheckpointError, ResetError)


def log_to_stderr(level: str) -> None:
    """The companion's log: ``level`` and up, on standard error (its log file, when fly starts it)."""
    logging.basicConfig(
        level=level.upper(), stream=sys.stderr, format="%(asctime)s %(name)s %(levelname)s: %(message)s"
    )


def main(argv: Sequence[str] | None = None) -> int:
    """A user's command line: the configuration from its flags, flown (:func:`run`)."""
    try:
        args = build_parser().parse_args(argv)
    except UsageError as exc:
        print(f"{PROG}: error: {exc}", file=sys.stderr)
        return EXIT_BAD_INPUT
    try:
        log_to_stderr(args.log_level)
        config = config_from_args(args)
    except bad_input_errors() as exc:
        print(f"{PROG}: error: {exc}", file=sys.stderr)
        return EXIT_BAD_INPUT
    return run(config, serve=args.serve)


def run(config: CompanionConfig, serve: bool, missions: MissionInput | None = None) -> int:
    """Fly ``config``'s mission, and with ``serve`` the next ones read from ``missions`` (standard input when None),
    until a quit, the end of the input or a signal; the exit code. Bad input is one line on stderr and code 2."""
    try:
        companion = build_companion(config)
    except bad_input_errors() as exc:
        print(f"{PROG}: error: {exc}", file=sys.stderr)
        return EXIT_BAD_INPUT
    stopped = False

    def stop(signum: int, _frame: FrameType | None) -> None:
        nonlocal stopped
        _log.info("signal %d: stopping", signum)
        stopped = True
        companion.request_stop()

    previous = {sig: signal.signal(sig, stop) for sig in (signal.SIGINT, signal.SIGTERM)}
    link = None
    try:
        try:
            if serve:
                from mavlink_bridge.companion.machine import open_link

                link = open_link(config)
            result = companion.run(link)
            _print_end(result)
            # --serve: mission after mission over the same link (tssac_core.wire.mission_reset).
            missions = missions or MissionInput(0)  # standard input, read only by a serving companion
            # A mission whose tlog a full disk cut was flown all the same: its status says so, and fly decides
            # whether the campaign goes on (it does not); the process serves on, so fly reads that mission's end.
            while link is not None and result.exit_code in (EXIT_OK, EXIT_WRITE_FAILED) and not stopped:
                mission = missions.next(lambda: stopped)
                if mission is None:
                    break
                if mission.log is not None:
                    redirect_stderr(mission.log)
                config = next_mission_config(config, mission)
                companion = build_companion(config)
                if stopped:  # a signal before the line above stopped the last mission's companion, not this one
                    break
                result = companion.run(link)
                _print_end(result)
        except bad_input_errors() as exc:
            print(f"{PROG}: error: {exc}", file=sys.stderr)
            return EXIT_BAD_INPUT
        except OSError as exc:  # the status file could not be written (a full disk): the run's record is lost
            print(f"{PROG}: error: {bad_input_line(exc)}", file=sys.stderr)
            return EXIT_WRITE_FAILED
    finally:
        if link is not None:
            link.close()
        for sig, handler in previous.items():
            signal.signal(sig, handler)
    return result.exit_code


def next_mission_config(config: CompanionConfig, mission: NextMission) -> CompanionConfig:
    """The configuration of a served mission: its scenario (fixed layout), status file and tlog."""
    scenario = load(mission.scenario)
    if scenario.layout is None:
        raise UsageError(f"{mission.scenario}: mission {mission.index} needs a scenario with a fixed layout")
    return dataclasses.replace(config, scenario=scenario, status_json=mission.status_json, tlog=mission.tlog)


def _print_end(result: CompanionResult) -> None:
    lat = result.latency_ms
    lat_text = f" latency_p50_ms={lat['p50']:.3f} latency_p99_ms={lat['p99']:.3f}" if lat else ""
    vt = "-" if result.vehicle_time_s is None else f"{result.vehicle_time_s:.1f}"
    print(
        f"end role={result.role} status={result.status} vehicle_time_s={vt} steps={result.counters.control_steps} "
        f"holds={result.counters.holds} restarts={result.counters.restarts}{lat_text} "
        f"message={json.dumps(result.message)}",
        flush=True,
    )


if __name__ == "__main__":
    sys.exit(main())
