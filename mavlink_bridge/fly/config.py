"""``fly``'s settings (`FlyConfig`) from its command line, checked before any process starts."""

from __future__ import annotations

import argparse
import dataclasses
import enum
import math
import os
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

from mavlink_bridge.companion.config import LOCKSTEP_GRANT_S, check_lockstep_grant_s
from mavlink_bridge.link.connection import SerialSpec, parse_connection
from mavlink_bridge.link.guided_commands import SetpointDialect, add_setpoints_argument
from mavlink_bridge.link.signing_key import read_signing_key
from tssac_core.common.cli import SEED_MAX, UsageError, UsageParser, seed_arg
from tssac_core.common.errors import CheckpointError
from tssac_core.common.files import create_exclusively
from tssac_core.common.shield_options import SHIELD_ADJUST_HELP, adjust_option
from tssac_core.deploy.manifest import check_models as check_manifest
from tssac_core.deploy.numpy_actor import load_actor, pilot_file
from tssac_core.reporting.mission_animation import AnimationFormatError, check_target
from tssac_core.sim.adversaries import ADVERSARY_NAMES
from tssac_core.sim.airframe_response import load_response, response_option
from tssac_core.sim.lagged_starts import lagged_start_check
from tssac_core.sim.pilots import GUIDANCE, STRAIGHT
from tssac_core.sim.scenario import ROLES, Dynamics, DynamicsModel, Scenario, load
from tssac_core.sim.shield_tuning import ShieldTuning, add_tuning_options, tuning_option
from tssac_core.wire.uart import BaudError, check_baud

PROG = "python -m mavlink_bridge.fly"


class Executor(enum.Enum):
    """Where ``--workers N`` flies its missions side by side."""

    LOCAL = "local"
    """N crews in the fly process, one thread each (:mod:`mavlink_bridge.fly.side_by_side`): no Ray to start."""
    RAY = "ray"
    """N Ray tasks at once (:mod:`mavlink_bridge.fly.workers`): on a Ray fly starts, or the cluster of ``--address``."""


REPO = Path(__file__).resolve().parents[2]
DEFAULT_MODELS = REPO / "models" / "tssac"
PILOT_NAMES = (GUIDANCE, STRAIGHT, *ADVERSARY_NAMES)
"""``--pilot``: the guidance controller, the straight test pilot or an adversary (tssac_core.sim.adversaries)."""


@dataclass(frozen=True)
class FlyConfig:
    scenario_path: Path
    scenario: Scenario
    models: Path | None
    """None = the guidance controller."""
    episodes: int
    seed: int
    lockstep: bool
    speedup: float
    json_path: Path | None
    tlog_dir: Path | None
    plot_path: Path | None
    signing_key_path: Path | None
    """The key file of the run (the user's ``--signing-key``, or the one fly makes); None: unsigned."""
    connect: tuple[str, str, str] | None
    logs_dir: Path | None
    mission_timeout_s: float
    startup_timeout_s: float
    progress: bool
    lean_telemetry: bool = False
    """The companions stop the streams they do not read (:func:`lean_telemetry`)."""
    lockstep_grant_s: float = LOCKSTEP_GRANT_S
    """Under lockstep, the companions' ``--lockstep-grant-s`` (0: they answer every tick)."""
    pilot: str = GUIDANCE
    """Without models: ``guidance``, ``straight`` or an adversary's name (:data:`PILOT_NAMES`)."""
    shield: bool = False
    """The companions fly through the runtime-assurance monitor (``--shield``, docs/runtime_assurance.md)."""
    airframe_response: Path | None = None
    """The airframe's fitted response their monitors predict with (``--airframe-response``); None: eq. 5."""
    shield_adjust: bool = False
    """The monitors fly the passing action nearest a failing proposal before the backup (``--shield-adjust``)."""
    shield_tuning: ShieldTuning = ShieldTuning()
    """The monitors' hand-back and the policies' route (``--shield-release-m`` and the rest)."""
    setpoints: SetpointDialect = SetpointDialect.BODY_RATES
    """How the companions command GUIDED (``--setpoints``: body rates, or ArduPlane's GUIDED_CHANGE_* commands)."""
    mission: int | None = None
    """Fly only this mission index of ``seed`` (its layout and noise are those of mission ``mission`` of a full run)."""
    signing: bool = True
    """Sign every frame: with a key fly makes for the run when ``--signing-key`` gives none and fly starts the world
    (``--no-signing`` turns it off; with ``--connect`` only ``--signing-key`` signs)."""

    @property
    def makes_key(self) -> bool:
        """fly makes a fresh key for this run: signing on, no key given, a world of its own."""
        return self.signing and self.signing_key_path is None and self.connect is None

    def indices(self) -> Sequence[int]:
        """The mission indices to fly: ``--mission K`` alone, or 0 .. episodes - 1 but those already flown (``done``;
        a range, not a list, when there are none: ``--episodes`` may be large)."""
        every = range(self.mission, self.mission + 1) if self.mission is not None else range(self.episodes)
        return [i for i in every if i not in self.done] if self.done else every

    workers: int = 1
    """Missions at once (1: one after the other, here)."""
    executor: Executor = Executor.LOCAL
    """Where the missions fly side by side: crews in this process, or Ray tasks."""
    ray_address: str | None = None
    """An existing Ray cluster for the missions (None: with the Ray executor, a Ray started inside the command)."""
    animate_path: Path | None = None
    """``--animate``: each mission as a .gif or .mp4 film (tssac_core.reporting.mission_animation)."""
    serial_baud: int | None = None
    """``--serial BAUD``: the world puts every vehicle on a pseudo-terminal at BAUD and the companions fly over it."""
    serial_byte_loss: float = 0.0
    """``--serial-byte-loss P``: the world's serial lines drop each byte with probability P."""
    persistent: bool = True
    """One world and three companions fly every mission of the run (of each worker), reset between missions
    (tssac_core.wire.mission_reset); False (``--fresh-processes``): four new processes per mission."""
    resume: bool = False
    """``--resume``: fly on from the ``--json`` file's missions (:mod:`mavlink_bridge.fly.resume`)."""
    done: frozenset[int] = frozenset()
    """The mission indices the resumed file already holds: not flown again."""
    checkpoint_s: float = 30.0
    """``--checkpoint-s S``: the ``--json`` file is written with the missions flown so far at most every S seconds of
    wall time (:mod:`mavlink_bridge.fly.checkpoint`)."""

    @property
    def on_ray(self) -> bool:
        return self.executor is Executor.RAY


def build_parser() -> argparse.ArgumentParser:
    p = UsageParser(
        prog=PROG, description="Fly whole missions over MAVLink: a SITL world plus one companion process per UAV."
    )
    _mission_flags(p.add_argument_group("the mission"))
    _clock_flags(p.add_argument_group("the clock"))
    _link_flags(p.add_argument_group("the link"))
    _output_flags(p.add_argument_group("outputs"))
    _side_by_side_flags(p.add_argument_group("side by side"))
    return p


def _mission_flags(g: argparse._ActionsContainer) -> None:
    """What flies, where, and which missions."""
    g.add_argument(
        "--scenario",
        required=True,
        type=Path,
        metavar="FILE",
        help="scenario file (scenarios/strike.yaml, scenarios/random.yaml)",
    )
    who = g.add_mutually_exclusive_group()
    who.add_argument(
        "--models",
        type=Path,
        metavar="DIR",
        help=f"directory with decoy.pt, detect.pt, strike.pt and their .npz exports (default "
        f"{DEFAULT_MODELS.relative_to(REPO)}), or with decoy.onnx, detect.onnx, strike.onnx (export --format onnx)",
    )
    who.add_argument(
        "--pilot",
        choices=PILOT_NAMES,
        help="fly every UAV with the rule-based guidance controller, straight on (a test pilot), or an adversary "
        "built to break the monitor (docs/runtime_assurance.md, 'Adversarial pilots')",
    )
    g.add_argument(
        "--shield",
        action="store_true",
        help="the companions fly through the runtime-assurance monitor (docs/runtime_assurance.md); counts in the JSON",
    )
    g.add_argument(
        "--airframe-response",
        type=Path,
        metavar="FILE",
        help="with --shield: the monitors predict with this airframe's fitted turn lag "
        "(sim_vehicles/dynamics/airframes/f16.response.yaml for --dynamics jsbsim's f16) instead of eq. 5",
    )
    g.add_argument("--shield-adjust", action="store_true", help=SHIELD_ADJUST_HELP)
    add_tuning_options(g)
    g.add_argument(
        "--dynamics",
        choices=[m.value for m in DynamicsModel],
        help=(
            "the SITL vehicles' physics: kinematic (eq. 5-6, the training world's) or jsbsim (a JSBSim flight model "
            "per vehicle under an inner-loop autopilot); default: the scenario's dynamics section, else kinematic"
        ),
    )
    g.add_argument(
        "--aircraft",
        metavar="NAME|FILE",
        help="with jsbsim: a bundled airframe (f16) or an airframe file; default: the scenario's, else f16",
    )
    g.add_argument("--episodes", type=int, default=1, metavar="N", help="missions to fly (default 1)")
    g.add_argument(
        "--seed",
        type=seed_arg,
        default=0,
        metavar="S",
        help="mission i uses seed S + i for its random layout and sensor noise (default 0)",
    )
    g.add_argument(
        "--mission",
        type=int,
        metavar="K",
        help="fly only mission K of --seed (e.g. one of the JSON's worst_missions; with --plot)",
    )


def _clock_flags(g: argparse._ActionsContainer) -> None:
    """How the world keeps time, and how long a mission may take."""
    clock = g.add_mutually_exclusive_group()
    clock.add_argument(
        "--lockstep",
        action="store_true",
        help=(
            "step the world once per round of setpoints (the default; with --connect: the running world is in lockstep)"
        ),
    )
    clock.add_argument(
        "--speedup", type=float, metavar="X", help="run the world in real time times X instead of lockstep"
    )
    g.add_argument(
        "--lockstep-grant-s",
        type=float,
        default=LOCKSTEP_GRANT_S,
        metavar="S",
        help=f"lockstep over a link that loses nothing: each companion answers only when its setpoint may change, "
        f"granting its vehicle up to S seconds of ticks in between (default {LOCKSTEP_GRANT_S:g}; 0: every tick)",
    )
    g.add_argument(
        "--mission-timeout-s",
        type=float,
        default=900.0,
        metavar="S",
        help="wall seconds a mission may take (default 900)",
    )


def _link_flags(g: argparse._ActionsContainer) -> None:
    """The MAVLink link between the companions and their vehicles."""
    add_setpoints_argument(g)
    g.add_argument(
        "--signing-key",
        type=Path,
        metavar="FILE",
        help="MAVLink 2 signing key (32 raw bytes or 64 hex characters) for the world and the companions",
    )
    g.add_argument(
        "--no-signing",
        action="store_true",
        help="fly unsigned (default: every frame signed with a key made for the run, or --signing-key's)",
    )
    g.add_argument(
        "--connect",
        nargs=3,
        metavar=("DECOY", "DETECT", "STRIKE"),
        help="fly running vehicles at these connection strings instead of starting a world",
    )
    streams = g.add_mutually_exclusive_group()
    streams.add_argument(
        "--lean-telemetry",
        action="store_true",
        help=(
            "companions stop the vehicle streams they do not use (GLOBAL_POSITION_INT, ATTITUDE, VFR_HUD): faster, "
            "leaner tlogs (the default in lockstep worlds fly starts; this flag also asks for it with --speedup or "
            "--connect)"
        ),
    )
    streams.add_argument(
        "--full-telemetry",
        action="store_true",
        help="keep every vehicle stream on at its default rate (the default with --speedup and --connect)",
    )
    g.add_argument(
        "--serial",
        type=int,
        metavar="BAUD",
        help="the companions fly over serial lines: the world puts every vehicle on a pseudo-terminal at BAUD "
        "(57600, 921600, ...) and each companion connects to its vehicle's (docs/real_vehicles.md)",
    )
    g.add_argument(
        "--serial-byte-loss",
        type=float,
        default=0.0,
        metavar="P",
        help="with --serial: the lines drop each byte, each way, with probability P (a noisy line; default 0)",
    )


def _output_flags(g: argparse._ActionsContainer) -> None:
    """What the run writes and shows."""
    g.add_argument(
        "--json", type=Path, metavar="FILE", help="write the results here (also the finished missions when interrupted)"
    )
    g.add_argument(
        "--resume",
        action="store_true",
        help="with --json FILE: keep the missions FILE holds (a campaign stopped part-way, of the same settings) and "
        "fly only the others",
    )
    g.add_argument(
        "--checkpoint-s",
        type=float,
        default=FlyConfig.checkpoint_s,
        metavar="S",
        help="while flying, write --json FILE with the missions flown so far at most every S seconds of wall time "
        "(a killed campaign loses at most that much; --resume flies on from it; 0: after every mission; default 30)",
    )
    g.add_argument(
        "--tlog", type=Path, metavar="DIR", help="write DIR/mission-NNN/<role>.tlog (each companion's MAVLink traffic)"
    )
    g.add_argument(
        "--plot",
        type=Path,
        metavar="FILE",
        help="draw the trajectories (FILE, or FILE-NNN.ext per mission when there are several)",
    )
    g.add_argument(
        "--animate",
        type=Path,
        metavar="FILE",
        help="film each mission: trajectories, radar rings, events, backup stretches (FILE.gif with Pillow, or "
        "FILE.mp4 with ffmpeg; FILE-NNN.ext per mission when there are several)",
    )
    g.add_argument(
        "--logs",
        type=Path,
        metavar="DIR",
        help="keep each mission's scenario, truth log and process logs here (default: a temporary directory)",
    )
    g.add_argument("--no-progress", action="store_true", help="no progress bar")


def _side_by_side_flags(g: argparse._ActionsContainer) -> None:
    """Missions flown at once: crews side by side here, or Ray tasks."""
    g.add_argument(
        "--workers",
        type=int,
        default=1,
        metavar="N",
        help="fly N missions at once, each with its own world and companions on their own ports (default 1: one "
        "after the other); the same results as one after the other",
    )
    g.add_argument(
        "--executor",
        choices=[e.value for e in Executor],
        help="where --workers flies: local (the default: N crews of processes side by side, started by this "
        "command) or ray (N Ray tasks, on a Ray this command starts, or the cluster of --address)",
    )
    g.add_argument(
        "--address",
        metavar="HOST:PORT",
        help="fly the missions on this existing Ray cluster (implies --executor ray); --models, --logs, --tlog and "
        "--plot must be on a filesystem every node sees",
    )
    g.add_argument(
        "--fresh-processes",
        action="store_true",
        help="start a new world and new companions for every mission instead of resetting the running ones "
        "(slower; the same results)",
    )


def config_from_args(argv: Sequence[str] | None) -> FlyConfig:
    a = build_parser().parse_args(argv)
    check_numbers(a)
    scenario = with_dynamics(load(a.scenario), a.dynamics, a.aircraft)
    models: Path | None = None
    if a.pilot is None:
        models = (a.models if a.models is not None else DEFAULT_MODELS).resolve()
        check_models(models)
    check_link(a, scenario)
    connect = connect_of(a, scenario)
    if a.address is not None and a.executor == Executor.LOCAL.value:
        raise UsageError("--address is a Ray cluster: it flies with --executor ray, not local")
    executor = Executor.RAY if a.address is not None else Executor(a.executor or Executor.LOCAL.value)
    # A world fly starts runs in lockstep unless --speedup; vehicles it did not start are taken to run in
    # real time unless --lockstep says otherwise (a companion must not extrapolate a lockstep clock).
    lockstep = a.lockstep or (a.speedup is None and connect is None)
    return FlyConfig(
        scenario_path=a.scenario.resolve(),
        scenario=scenario,
        models=models,
        episodes=a.episodes,
        seed=a.seed,
        mission=a.mission,
        lockstep=lockstep,
        speedup=1.0 if a.speedup is None else float(a.speedup),
        json_path=a.json,
        tlog_dir=a.tlog.resolve() if a.tlog is not None else None,
        plot_path=a.plot.resolve() if a.plot is not None else None,
        animate_path=a.animate.resolve() if a.animate is not None else None,
        signing_key_path=a.signing_key.resolve() if a.signing_key is not None else None,
        connect=connect,
        logs_dir=a.logs.resolve() if a.logs is not None else None,
        mission_timeout_s=a.mission_timeout_s,
        startup_timeout_s=60.0,
        progress=not a.no_progress,
        lean_telemetry=lean_telemetry(a.lean_telemetry, a.full_telemetry, lockstep, connect is None),
        lockstep_grant_s=a.lockstep_grant_s,
        pilot=a.pilot or GUIDANCE,
        shield=a.shield,
        airframe_response=airframe_response_of(a, scenario),
        shield_adjust=adjust_option(a.shield_adjust, a.shield),
        shield_tuning=tuning_option(a, a.shield),
        setpoints=SetpointDialect(a.setpoints),
        signing=not a.no_signing,
        workers=a.workers,
        executor=executor,
        ray_address=a.address,
        persistent=not a.fresh_processes,
        resume=a.resume,
        checkpoint_s=a.checkpoint_s,
        serial_baud=a.serial,
        serial_byte_loss=a.serial_byte_loss,
    )


def check_numbers(a: argparse.Namespace) -> None:
    """Counts, seeds, times and the film's format: UsageError (one line) for a value no flag's type refuses."""
    if a.episodes <= 0:
        raise UsageError(f"--episodes must be positive, got {a.episodes}")
    if a.seed + max(a.episodes - 1, a.mission or 0) > SEED_MAX:
        raise UsageError(
            f"--seed plus the last mission's index must stay within {SEED_MAX} (mission i flies seed S + i)"
        )
    if a.workers <= 0:
        raise UsageError(f"--workers must be positive, got {a.workers}")
    if a.mission is not None and a.mission < 0:
        raise UsageError(f"--mission must be >= 0, got {a.mission}")
    if a.mission is not None and a.episodes != 1:
        raise UsageError("--mission flies one mission: leave --episodes out")
    if a.resume and (a.json is None or a.mission is not None):
        raise UsageError("--resume flies on from a campaign's --json FILE: give --json, and no --mission")
    if not (math.isfinite(a.checkpoint_s) and a.checkpoint_s >= 0):
        raise UsageError(f"--checkpoint-s must be a number of seconds >= 0, got {a.checkpoint_s}")
    if a.speedup is not None and not (math.isfinite(a.speedup) and a.speedup > 0):
        raise UsageError(f"--speedup must be a positive number, got {a.speedup}")
    if not (math.isfinite(a.mission_timeout_s) and a.mission_timeout_s > 0):
        raise UsageError("--mission-timeout-s must be positive")
    check_lockstep_grant_s(a.lockstep_grant_s)
    if a.animate is not None:
        try:
            check_target(a.animate)
        except AnimationFormatError as exc:
            raise UsageError(str(exc)) from None


def check_link(a: argparse.Namespace, scenario: Scenario) -> None:
    """Signing and the serial lines: a key that reads, flags that go together."""
    if a.signing_key is not None:
        read_signing_key(a.signing_key)
        if a.no_signing:
            raise UsageError("--no-signing and --signing-key contradict each other: give one")
    if a.no_signing and scenario.link.signing:
        raise UsageError(f"{a.scenario}: the scenario asks for signing (link.signing: true): leave out --no-signing")
    if a.serial is not None:
        try:
            check_baud(a.serial, "--serial")
        except BaudError as exc:
            raise UsageError(str(exc)) from None
    if not (0.0 <= a.serial_byte_loss < 1.0):
        raise UsageError(f"--serial-byte-loss must be in [0, 1), got {a.serial_byte_loss}")
    if a.serial_byte_loss > 0.0 and a.serial is None:
        raise UsageError("--serial-byte-loss needs --serial BAUD (it is the serial line that drops bytes)")


def connect_of(a: argparse.Namespace, scenario: Scenario) -> tuple[str, str, str] | None:
    """``--connect``: the three running vehicles' connections, checked with what may go with them (None: fly starts
    its world)."""
    if a.connect is None:
        return None
    if a.serial is not None:
        raise UsageError(
            "--serial sets up the serial lines of the world fly starts: with --connect give the "
            "serial devices themselves (--connect /dev/ttyUSB0,57600 ...)"
        )
    for text in a.connect:
        try:
            spec = parse_connection(text)
        except ValueError as exc:
            raise UsageError(str(exc)) from None
        if isinstance(spec, SerialSpec) and not os.path.exists(spec.device):
            raise UsageError(f"--connect {text}: serial device {spec.device} does not exist")
    if a.episodes != 1:
        raise UsageError("--connect flies the running vehicles once: --episodes must be 1")
    if a.workers != 1 or a.address is not None or a.executor is not None:
        raise UsageError("--connect flies the running vehicles from here: no --workers, --executor or --address")
    if a.dynamics is not None or a.aircraft is not None:
        raise UsageError("--dynamics and --aircraft set the physics of the world fly starts: not with --connect")
    if scenario.layout is None:
        raise UsageError(
            f"{a.scenario}: with --connect the scenario must have the fixed layout the vehicles fly "
            "(python -m sim_vehicles --layout-out FILE writes it)"
        )
    if a.plot is not None or a.animate is not None:
        raise UsageError(
            "--plot and --animate draw from the world's truth log, which fly has only for the worlds it starts "
            "(not with --connect)"
        )
    return (a.connect[0], a.connect[1], a.connect[2])


def with_dynamics(scenario: Scenario, model: str | None, aircraft: str | None) -> Scenario:
    """The scenario with the command line's physics over its ``dynamics:`` section (the file fly writes for each
    mission carries them to the world)."""
    if model is None and aircraft is None:
        return scenario
    d = scenario.dynamics or Dynamics()
    chosen = Dynamics(
        model=d.model if model is None else DynamicsModel(model), aircraft=d.aircraft if aircraft is None else aircraft
    )
    if chosen.model is DynamicsModel.KINEMATIC and aircraft is not None:
        raise UsageError("--aircraft names a JSBSim airframe: fly it with --dynamics jsbsim")
    return dataclasses.replace(scenario, dynamics=chosen)


def airframe_response_of(a: argparse.Namespace, scenario: Scenario) -> Path | None:
    """``--airframe-response``: checked (:func:`~tssac_core.sim.airframe_response.response_option`), and for the
    airframe the world flies: a response models a JSBSim airframe, not the kinematic vehicles, nor another airframe."""
    path = response_option(a.airframe_response, a.shield, scenario)
    if path is None:
        return None
    dynamics = scenario.dynamics or Dynamics()
    if dynamics.model is DynamicsModel.KINEMATIC:
        raise UsageError("--airframe-response models a JSBSim airframe: fly it with --dynamics jsbsim")
    response = load_response(path)
    if Path(dynamics.aircraft).stem != response.aircraft:
        raise UsageError(
            f"--airframe-response {path.name} is fitted to {response.aircraft}, but the world flies {dynamics.aircraft}"
        )
    problem = None if scenario.layout is None else lagged_start_check(scenario, response)(scenario.layout)
    if problem is not None:
        raise UsageError(f"{scenario.name}: {problem[0]}: {problem[1]}")
    return path


def monitor_scope(scenario: Scenario, airframe_response: Path | None = None) -> str | None:
    """Why the runtime-assurance monitor's proof does not cover this scenario's flight (None: it does). The proof
    predicts with eq. 5 in still air (docs/runtime_assurance.md): a JSBSim airframe lags its commands and cannot brake
    as hard, and a wind carries the vehicles off the predicted paths. With an airframe's fitted response the monitor
    predicts with its lag, and its bound holds within a residual measured against JSBSim (in wind, its backups end in
    the ground loiter, whose excursion the response measured too): measured, not proved."""
    dynamics = scenario.dynamics or Dynamics()
    wind = scenario.wind is not None and scenario.wind.promised_max_m_s > 0.0
    if airframe_response is not None:
        if wind and scenario.wind is not None:  # the response's loiter covers it: checked before anything flies
            return (
                f"the monitor predicts with the airframe response {airframe_response.name}, its backups ending in the "
                f"ground loiter: its bound holds within a residual and an excursion measured against JSBSim in winds "
                f"up to the fitted maximum (the scenario promises {scenario.wind.promised_max_m_s:g} m/s), not a proof"
            )
        return (
            f"the monitor predicts with the airframe response {airframe_response.name}: its bound holds within a "
            "residual measured against JSBSim in still air, not a proof"
        )
    reasons = []
    if dynamics.model is not DynamicsModel.KINEMATIC:
        reasons.append(f"{dynamics.model.value} {dynamics.aircraft} dynamics")
    if wind and scenario.wind is not None:
        reasons.append(f"a {scenario.wind.promised_max_m_s:g} m/s wind")
    if not reasons:
        return None
    return (
        f"the monitor's guarantee covers the kinematic model (eq. 5) in still air, not {' and '.join(reasons)}: "
        "it flies as a best effort here"
    )


def lean_telemetry(lean: bool, full: bool, lockstep: bool, own_world: bool) -> bool:
    """Whether the companions stop the streams they do not read: ``--lean-telemetry``, else by default in a lockstep
    world fly starts (nobody else reads its streams, and every frame not sent is CPU off the lockstep's critical
    path), unless ``--full-telemetry``. A world fly did not start may serve ground stations: full unless asked."""
    if lean or full:
        return lean
    return lockstep and own_world


def make_signing_key(directory: Path) -> Path:
    """A fresh random 32-byte MAVLink 2 signing key, readable by its owner only: a new file of ours, whatever was at
    its name (a key planted readable by all, or a link to a file of someone else's choice) removed, never used."""
    path = directory / "signing.key"
    with os.fdopen(create_exclusively(path, 0o600), "wb") as fh:
        fh.write(os.urandom(32))
    return path


def check_models(models: Path) -> None:
    """The directory's manifest matches its files and the three roles' actors load (UsageError otherwise, one line),
    with a hint when they are missing."""
    hint = "fly with --pilot guidance, or train with python -m tssac_core.train --out DIR and pass --models DIR"
    if not models.is_dir():
        raise UsageError(f"{models}: models directory not found ({hint})")
    try:
        check_manifest(models, [])  # first: a changed file is refused before any of them is read
    except CheckpointError as exc:
        raise UsageError(str(exc)) from None
    try:
        for role in ROLES:
            load_actor(pilot_file(models, role), role)
    except CheckpointError as exc:
        raise UsageError(f"{exc} ({hint})") from None
