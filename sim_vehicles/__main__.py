"""Command line: ``python -m sim_vehicles --scenario FILE [options]`` — start the SITL vehicles of a scenario.

Prints one line per vehicle with the connection string a client uses, then a ready line::

    decoy sysid=1 udpout:127.0.0.1:14560
    detect sysid=2 udpout:127.0.0.1:14570
    strike sysid=3 udpout:127.0.0.1:14580
    ready scenario=strike seed=0 clock=realtime speedup=1

With ``--serial BAUD`` each vehicle is also on a pseudo-terminal at BAUD (:mod:`sim_vehicles.link.serial_port`), and
its line names that serial port (``decoy sysid=1 /dev/pts/5,57600``); the UDP ports stay open beside it.

and, when the run ends, one ``end ...`` line (reason, success, steps, simulated time, cost per role).
With ``--serve`` the process then reads the next mission from standard input and flies it on the same ports
(the mission-reset protocol, :mod:`tssac_core.wire.mission_reset`): a ``ready mission=N ...`` line, the
mission, its ``end ...`` line, and so on until ``{"quit": true}`` or the end of the input.
Exit status: 0 when the mission ended or the run was stopped (SIGINT / SIGTERM); 2 on bad input
(scenario, key file, port in use, options), with one line on stderr; 1 on an unexpected failure.
See docs/mavlink.md for the protocol.
"""

from __future__ import annotations

import argparse
import logging
import signal
import socket
import sys
import threading
from collections.abc import Sequence
from pathlib import Path
from types import FrameType
from typing import NoReturn

from sim_vehicles.world_runner import RunResult, SitlError, WorldRunner
from tssac_core.common.cli import seed_arg
from tssac_core.sim.scenario import DynamicsModel, ScenarioError, load
from tssac_core.sim.sitl_config import DEFAULT_BASE_PORT, ClockMode, LockstepStart, SitlConfig
from tssac_core.wire.mission_reset import MissionInput, ResetError, redirect_stderr
from tssac_core.wire.signing import SigningKeyError, load_key

PROG = "python -m sim_vehicles"


class _Parser(argparse.ArgumentParser):
    """argparse, but a usage error is one line on stderr (exit 2)."""

    def error(self, message: str) -> NoReturn:
        self.exit(2, f"{PROG}: error: {message} (see --help)\n")


def build_parser() -> argparse.ArgumentParser:
    p = _Parser(
        prog=PROG,
        description="Start the SITL vehicles (decoy, detect, strike) of a scenario as MAVLink 2 systems on UDP.",
    )
    _world_flags(p.add_argument_group("the world"))
    _clock_flags(p.add_argument_group("the clock"))
    _signing_flags(p.add_argument_group("signing"))
    _output_flags(p.add_argument_group("outputs"))
    return p


def _world_flags(g: argparse._ActionsContainer) -> None:
    """The world: its scenario and physics, where its vehicles listen."""
    g.add_argument("--scenario", required=True, type=Path, metavar="FILE", help="scenario YAML file (scenarios/*.yaml)")
    g.add_argument(
        "--seed", type=seed_arg, default=0, help="seed of the random layout, GPS noise and link model (default 0)"
    )
    g.add_argument(
        "--dynamics",
        choices=[m.value for m in DynamicsModel],
        default=None,
        help=(
            "the vehicles' physics: kinematic (eq. 5-6, the training world's) or jsbsim (a JSBSim flight model per "
            "vehicle under an inner-loop autopilot); default: the scenario's dynamics section, else kinematic"
        ),
    )
    g.add_argument(
        "--aircraft",
        default=None,
        metavar="NAME|FILE",
        help="the JSBSim airframe: a bundled one (f16) or an airframe file; default: the scenario's, else f16",
    )
    g.add_argument("--host", default="127.0.0.1", help="address the vehicles bind (default 127.0.0.1)")
    g.add_argument(
        "--base-port",
        type=int,
        default=DEFAULT_BASE_PORT,
        metavar="P",
        help=f"UDP port of the decoy; detect P+10, strike P+20 (default {DEFAULT_BASE_PORT}); 0 = OS-assigned ports",
    )
    g.add_argument(
        "--serial",
        type=int,
        default=None,
        metavar="BAUD",
        help=(
            "also put every vehicle on a pseudo-terminal, a serial line at BAUD (57600, 921600, ...): its line reads "
            "DEVICE,BAUD, what a companion passes to --connect; the UDP ports stay open for ground stations"
        ),
    )
    g.add_argument(
        "--serial-byte-loss",
        type=float,
        default=0.0,
        metavar="P",
        help="with --serial: the lines drop each byte, each way, with probability P (a noisy line; default 0)",
    )


def _clock_flags(g: argparse._ActionsContainer) -> None:
    """How the world keeps time, starts and ends."""
    clock = g.add_mutually_exclusive_group()
    clock.add_argument(
        "--speedup", type=float, default=None, metavar="X", help="run X times faster than real time (default 1)"
    )
    clock.add_argument(
        "--lockstep", action="store_true", help="advance one step per round of setpoints from the armed GUIDED vehicles"
    )
    g.add_argument(
        "--lockstep-start",
        choices=[m.value for m in LockstepStart],
        default=LockstepStart.ALL.value,
        help="lockstep (or --hold-start): start once all (default) or any vehicle is armed in GUIDED",
    )
    g.add_argument(
        "--hold-start",
        action="store_true",
        help="real time too: hold the world at t = 0 until the --lockstep-start vehicles are armed in GUIDED",
    )
    g.add_argument(
        "--setpoint-timeout-s", type=float, default=1.0, metavar="S", help="setpoint-timeout failsafe (default 1.0 s)"
    )
    g.add_argument(
        "--linger-s",
        type=float,
        default=1.0,
        metavar="S",
        help="simulated seconds to keep serving after the mission ends (default 1.0)",
    )


def _signing_flags(g: argparse._ActionsContainer) -> None:
    """MAVLink 2 signing."""
    g.add_argument(
        "--signing-key", type=Path, metavar="FILE", help="MAVLink 2 signing key: 32 raw bytes or 64 hex characters"
    )
    g.add_argument(
        "--unsigned-monitors",
        action="store_true",
        help=(
            "with --signing-key: let passive monitors in with unsigned HEARTBEAT/RADIO_STATUS (4 at most, 2 kB/s of "
            "telemetry each)"
        ),
    )


def _output_flags(g: argparse._ActionsContainer) -> None:
    """What the world writes and how it is run."""
    g.add_argument("--truth-log", type=Path, metavar="FILE", help="write the truth log (JSON Lines) here")
    g.add_argument(
        "--layout-out", type=Path, metavar="FILE", help="write the layout flown as a fixed-layout scenario file here"
    )
    g.add_argument(
        "--tlog-dir", type=Path, metavar="DIR", help="write <role>.tlog telemetry logs (mavlogdump-readable) here"
    )
    g.add_argument(
        "--out",
        action="append",
        default=[],
        metavar="udpout:HOST:PORT",
        help="also stream every vehicle to this ground-station address and take its commands (repeatable)",
    )
    g.add_argument(
        "--serve",
        action="store_true",
        help=(
            "after the mission, read the next one from standard input (one JSON line: index, scenario, seed, "
            'truth_log, tlog_dir, log) and fly it on the same ports, until {"quit": true} or the end of the input'
        ),
    )
    g.add_argument(
        "--log-level",
        choices=["debug", "info", "warning", "error"],
        default="warning",
        help="log level on stderr (default warning)",
    )


def config_from_args(args: argparse.Namespace) -> SitlConfig:
    """Build the run's configuration; raises ScenarioError, SigningKeyError or ValueError (one line each)."""
    scenario = load(args.scenario)
    key = load_key(args.signing_key) if args.signing_key is not None else None
    return SitlConfig(
        scenario=scenario,
        seed=args.seed,
        host=args.host,
        base_port=args.base_port,
        clock=ClockMode.LOCKSTEP if args.lockstep else ClockMode.REALTIME,
        speedup=1.0 if args.speedup is None else args.speedup,
        lockstep_start=LockstepStart(args.lockstep_start),
        hold_start=args.hold_start,
        signing_key=key,
        unsigned_monitors=args.unsigned_monitors,
        truth_log=args.truth_log,
        layout_out=args.layout_out,
        tlog_dir=args.tlog_dir,
        setpoint_timeout_s=args.setpoint_timeout_s,
        linger_s=args.linger_s,
        outputs=tuple(parse_output(o) for o in args.out),
        dynamics_model=None if args.dynamics is None else DynamicsModel(args.dynamics),
        aircraft=args.aircraft,
        serial_baud=args.serial,
        serial_byte_loss=args.serial_byte_loss,
    )


def parse_output(text: str) -> tuple[str, int]:
    """``udpout:HOST:PORT`` (or ``HOST:PORT``) -> (IPv4 address, port); raises ValueError with one line."""
    spec = text[len("udpout:") :] if text.startswith("udpout:") else text
    host, sep, port_text = spec.rpartition(":")
    if not sep or not host or not port_text.isdigit():
        raise ValueError(f"--out {text!r}: expected udpout:HOST:PORT")
    try:
        address = socket.gethostbyname(host)
    except OSError:
        raise ValueError(f"--out {text!r}: cannot resolve host {host!r}") from None
    return address, int(port_text)


def log_to_stderr(level: str) -> None:
    """The world's log: ``level`` and up, on standard error (its log file, when fly starts it)."""
    logging.basicConfig(
        level=level.upper(), stream=sys.stderr, format="%(asctime)s %(name)s %(levelname)s: %(message)s"
    )


BAD_INPUT = (ScenarioError, SigningKeyError, SitlError, ValueError)
"""What the world refuses in one line on stderr, with exit code 2 (a SettingsError is a ValueError)."""


def main(argv: Sequence[str] | None = None) -> int:
    """A user's command line: the configuration from its flags, run (:func:`run`)."""
    args = build_parser().parse_args(argv)
    log_to_stderr(args.log_level)
    try:
        config = config_from_args(args)
    except BAD_INPUT as exc:
        print(f"{PROG}: error: {exc}", file=sys.stderr)
        return 2
    return run(config, serve=args.serve)


def run(config: SitlConfig, serve: bool, missions: MissionInput | None = None) -> int:
    """Run ``config``'s world: its endpoint and ready lines, the mission, its end line, and with ``serve`` the next
    missions read from ``missions`` (standard input when None); the exit code."""
    try:
        runner = WorldRunner(config)
    except BAD_INPUT as exc:
        print(f"{PROG}: error: {exc}", file=sys.stderr)
        return 2

    def stop(signum: int, _frame: FrameType | None) -> None:
        logging.getLogger(__name__).info("signal %d: stopping", signum)
        runner.request_stop()

    # Signal handlers can only be installed from the main thread (main() may be called from elsewhere).
    in_main_thread = threading.current_thread() is threading.main_thread()
    previous = {sig: signal.signal(sig, stop) for sig in (signal.SIGINT, signal.SIGTERM)} if in_main_thread else {}
    try:
        for ep in runner.endpoints:
            print(f"{ep.role} sysid={ep.sysid} {ep.connection_string}")
        speed = "lockstep" if config.clock is ClockMode.LOCKSTEP else f"realtime speedup={config.speedup:g}"
        dynamics = config.dynamics.model.value
        print(f"ready scenario={config.scenario.name} seed={config.seed} clock={speed} dynamics={dynamics}", flush=True)
        _print_end(runner.run_mission())
        missions = missions or MissionInput(0)  # standard input, read only by a serving world
        while serve and not runner.stop_requested:
            try:
                mission = missions.next(lambda: runner.stop_requested)
                if mission is None:
                    break
                if mission.log is not None:
                    redirect_stderr(mission.log)
                runner.next_mission(load(mission.scenario), mission.seed, mission.truth_log, mission.tlog_dir)
            except (ResetError, ScenarioError, SitlError, OSError) as exc:
                print(f"{PROG}: error: {exc}", file=sys.stderr)
                return 2
            print(f"ready mission={mission.index} scenario={runner.scenario.name} seed={mission.seed}", flush=True)
            _print_end(runner.run_mission())
    finally:
        runner.close()
        for sig, handler in previous.items():
            signal.signal(sig, handler)
    return 0


def _print_end(result: RunResult) -> None:
    costs = " ".join(f"cost_{role}={c:g}" for role, c in result.cost.items())
    print(
        f"end reason={result.end} success={str(result.success).lower()} steps={result.steps} "
        f"sim_time_s={result.sim_time_s:.1f} {costs}",
        flush=True,
    )


if __name__ == "__main__":
    sys.exit(main())
