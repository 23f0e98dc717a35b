"""The companion's settings (`CompanionConfig`) and the constants every part of it uses."""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

from mavlink_bridge.estimation.filter_model import FilterModel
from mavlink_bridge.link.guided_commands import SetpointDialect
from mavlink_bridge.link.serial_port import is_serial, parse_serial
from mavlink_bridge.link.telemetry_budget import LineBudget, check_line, companion_streams, line_budget
from tssac_core.assurance.monitor import ShieldConfig
from tssac_core.common.cli import UsageError
from tssac_core.sim import settings_json
from tssac_core.sim.adversaries import ADVERSARY_NAMES
from tssac_core.sim.pilots import GUIDANCE, STRAIGHT
from tssac_core.sim.scenario import LinkModel, Role, Scenario

GUIDED_MODE = 15
"""ArduPlane's GUIDED custom_mode (the bundled SITL follows ArduPlane's numbers)."""
LOITER_MODE = 12
"""ArduPlane's LOITER: where a companion leaves a vehicle it cannot fly (as a failsafe would)."""
PILOT_NAMES = (GUIDANCE, STRAIGHT, *ADVERSARY_NAMES)
"""``--pilot``: the guidance controller, the straight test pilot or an adversary (tssac_core.sim.adversaries)."""
MIN_POS_SIGMA_M = 0.1
MIN_VEL_SIGMA_M_S = 0.01
"""Floors for the filter's measurement noise: a noise-free SITL still quantises (cm, cm/s)."""

END_GRACE_S = 0.5
"""Wall seconds after a mission end is announced during which the vehicle's earlier heartbeats may still arrive."""
END_SILENCE_S = 0.5
"""A mission end is believed once the vehicle has then been silent this long (wall s): the SITL exits after it."""
END_CONFIRM_S = 2.0
"""... or once it has reported nothing but POWEROFF heartbeats for this long since the announcement (wall s)."""

COMMAND_TIMEOUT_S = 1.0
"""Wall seconds a command waits for its COMMAND_ACK before it is sent again (``--command-timeout-s``)."""
LOCKSTEP_COMMAND_TIMEOUT_S = 0.25
"""The same with ``--lockstep``: a lockstep world holding at its start carries every frame across its link at once
(only a lost one does not arrive), so an answer that has not come in a quarter second was lost. An answer that is only
late still counts for the next attempt's wait."""

LOCKSTEP_GRANT_S = 1.0
"""Under lockstep, the most vehicle time a setpoint answers for ahead (:mod:`tssac_core.wire.lockstep`): a trained
pilot holds each action for 10 ticks (1 s), and the vehicle's setpoint timeout is at least 1 s."""


LOCKSTEP_GRANT_MAX_S = 60.0
"""The longest ``--lockstep-grant-s``: the longest setpoint timeout a vehicle accepts (GUID_TIMEOUT, 0.1-60 s). The
grant is counted in whole milliseconds of the vehicle's clock, which an unbounded one overflows."""


def check_lockstep_grant_s(value: float) -> None:
    """``--lockstep-grant-s`` is 0 (answer every tick) up to :data:`LOCKSTEP_GRANT_MAX_S`; else one clear line."""
    if not (math.isfinite(value) and 0 <= value <= LOCKSTEP_GRANT_MAX_S):
        raise UsageError(f"--lockstep-grant-s must be 0 to {LOCKSTEP_GRANT_MAX_S:g} seconds, got {value:g}")


COMMAND_ATTEMPTS = 10
"""The fewest attempts per command. A 10% lossy link (degraded.yaml, each way) loses 19% of command round trips:
3 attempts failed 0.7% of commands, about one three-UAV mission in 25; 10 fail 1e-7."""
COMMAND_FAILURE = 1e-6
"""The chance, at most, that a command fails for want of attempts on the scenario's link."""


def command_attempts(link: LinkModel) -> int:
    """Attempts per command so that all of them fail with a chance below :data:`COMMAND_FAILURE`: a round trip (the
    command there, its ACK back) succeeds with (1 - frame_loss)^2 (:attr:`LinkModel.frame_loss`); at least
    :data:`COMMAND_ATTEMPTS`. At the validator's limit of 60% each way: 80 attempts (20 s in lockstep)."""
    round_trip = (1.0 - link.frame_loss) ** 2
    if round_trip >= 1.0:
        return COMMAND_ATTEMPTS
    if round_trip <= 0.0:
        raise UsageError("the scenario's link delivers no frame: no command can get through")
    return max(COMMAND_ATTEMPTS, math.ceil(math.log(COMMAND_FAILURE) / math.log(1.0 - round_trip)))


def default_command_timeout_s(lockstep: bool) -> float:
    """``--command-timeout-s`` when none is given: :data:`LOCKSTEP_COMMAND_TIMEOUT_S` under lockstep, else
    :data:`COMMAND_TIMEOUT_S`."""
    return LOCKSTEP_COMMAND_TIMEOUT_S if lockstep else COMMAND_TIMEOUT_S


EXIT_OK = 0
EXIT_WRITE_FAILED = 1
"""The flight ended, but what it was to write was not all written (a tlog cut by a full disk)."""
EXIT_BAD_INPUT = 2
EXIT_VEHICLE = 3


@dataclass(frozen=True)
class CompanionConfig:
    """Everything a :class:`Companion` needs (what the command line sets)."""

    connection: str
    """pymavlink connection string of the vehicle (``udpout:HOST:PORT``)."""
    role: Role
    scenario: Scenario
    """A scenario with a fixed layout (the one the vehicle flies)."""
    model: Path | None = None
    """A role checkpoint (``decoy.pt`` ...); None = the guidance controller."""
    signing_key: bytes | None = None
    tlog: Path | None = None
    """Write every message received and sent here (.tlog)."""
    status_json: Path | None = None
    """Write the final status (counters, latencies) here."""
    lockstep: bool = False
    """The vehicle runs in lockstep: never extrapolate its clock."""
    lockstep_grant_s: float = LOCKSTEP_GRANT_S
    """Under lockstep over a link that loses and reorders nothing, answer a tick only when the setpoint may change,
    granting the vehicle the ticks up to this many seconds ahead in between (:mod:`tssac_core.wire.lockstep`);
    0: answer every tick."""
    connect_timeout_s: float = 30.0
    """Wall seconds to wait for the first heartbeat."""
    command_timeout_s: float = COMMAND_TIMEOUT_S
    """Wall seconds to wait for each COMMAND_ACK."""
    command_retries: int | None = None
    """Attempts per command; None: :func:`command_attempts` for the scenario's link (10 on a link that loses at most
    10% each way, up to 80 at the 60% the validator allows)."""
    hold_after_s: float = 0.5
    """Vehicle seconds without a position fix after which the hold setpoint is flown."""
    silence_hold_s: float = 2.0
    """Wall seconds without any message after which the hold is sent when the vehicle's clock cannot be extrapolated
    (lockstep, or its rate not yet known). More than the 1 s a waiting lockstep vehicle is quiet for."""
    lost_after_s: float = 10.0
    """Wall seconds without any message after which the vehicle is given up."""
    restart_jump_s: float = 1.0
    """A vehicle clock that goes back by more than this is a restart (reordering is far smaller)."""
    settle_s: float = 0.005
    """Wall seconds to wait for the tick's position fix once the tick is known (it usually comes in the same burst);
    not used under lockstep, where a step's telemetry is one datagram and a missing fix was lost."""
    duration_s: float | None = None
    """Stop after this many vehicle seconds of flight (None: fly until the mission ends)."""
    filter_model: FilterModel = FilterModel.CONSTANT_TURN_EKF
    source_system: int | None = None
    """Our MAVLink system id (``--source-system``); None: the vehicle's, as a companion computer on a real vehicle
    has it (component 191, an onboard computer; 255 is left to the ground station). Until the vehicle's first
    heartbeat names it, the system id the bundled SITL gives the role (decoy 1, detect 2, strike 3)."""
    pilot: str = ""
    """Without a model: ``guidance`` (the default), ``straight`` or an adversary's name (:data:`PILOT_NAMES`)."""
    shield: ShieldConfig | None = None
    """Fly through the runtime-assurance monitor (:mod:`mavlink_bridge.companion.shield`); None: the pilot alone."""
    airframe_response: Path | None = None
    """The airframe's fitted response the monitor predicts with (``--airframe-response``,
    :mod:`tssac_core.sim.airframe_response`); None: eq. 5."""
    lean_telemetry: bool = False
    """Ask the vehicle to stop the streams the companion does not use (GLOBAL_POSITION_INT, ATTITUDE,
    VFR_HUD): less work on both sides when no ground station shares the vehicle (fly's own worlds)."""
    setpoints: SetpointDialect = SetpointDialect.BODY_RATES
    """How GUIDED is commanded: body rates, or ArduPlane's GUIDED_CHANGE_HEADING / _SPEED
    (:mod:`mavlink_bridge.link.guided_commands`)."""

    def to_json(self) -> str:
        """This configuration as one line of JSON (:mod:`tssac_core.sim.settings_json`): what fly gives a companion
        it starts (``python -m mavlink_bridge.companion.from_config``). It holds the signing key."""
        return settings_json.to_json(self)

    @classmethod
    def from_json(cls, text: str, source: str = "the companion's configuration") -> CompanionConfig:
        """The configuration :meth:`to_json` wrote, equal. Anything else raises one line: a
        :class:`~tssac_core.sim.settings_json.SettingsError` (a malformed, missing or unknown field, or a value the
        configuration refuses) or a ScenarioError (a scenario that does not validate)."""
        return settings_json.mission_settings_from_json(cls, text, source)

    @property
    def line_budget(self) -> LineBudget | None:
        """On a serial line: the companion's streams against the line (:mod:`mavlink_bridge.link.telemetry_budget`);
        None on UDP."""
        if not is_serial(self.connection):
            return None
        try:
            baud = parse_serial(self.connection).baud
        except ValueError as exc:
            raise UsageError(str(exc)) from None
        streams = companion_streams(self.scenario.dt_s, self.lockstep, self.setpoints)
        return line_budget(baud, streams, self.signing_key is not None)

    @property
    def attempts(self) -> int:
        """Attempts per command: ``command_retries``, else sized to the scenario's link (:func:`command_attempts`)."""
        return self.command_retries if self.command_retries is not None else command_attempts(self.scenario.link)

    def __post_init__(self) -> None:
        if self.scenario.layout is None:
            raise UsageError(
                f"scenario '{self.scenario.name}' has a random layout: the companion needs the layout the vehicle "
                f"flies "
                "(the SITL writes it with --layout-out FILE)"
            )
        for name in (
            "connect_timeout_s",
            "command_timeout_s",
            "hold_after_s",
            "silence_hold_s",
            "lost_after_s",
            "restart_jump_s",
        ):
            value = getattr(self, name)
            if not (math.isfinite(value) and value > 0):
                raise UsageError(f"--{name.replace('_', '-')} must be a positive number of seconds, got {value}")
        if self.lost_after_s <= self.silence_hold_s:
            raise UsageError("--lost-after-s must be longer than --silence-hold-s")
        if self.duration_s is not None and not (math.isfinite(self.duration_s) and self.duration_s > 0):
            raise UsageError(f"--duration-s must be positive, got {self.duration_s}")
        check_lockstep_grant_s(self.lockstep_grant_s)
        if self.command_retries is not None and self.command_retries < 1:
            raise UsageError("--command-retries must be at least 1")
        budget = self.line_budget
        too_slow = None if budget is None else check_line(budget)
        if too_slow is not None:
            raise UsageError(f"--connect {self.connection}: {too_slow}")
        if self.source_system is not None and not 1 <= self.source_system <= 255:
            raise UsageError(f"--source-system must be a MAVLink system id, 1 to 255, got {self.source_system}")
        if self.pilot and self.pilot not in PILOT_NAMES:
            raise UsageError(f"--pilot must be one of {', '.join(PILOT_NAMES)}, got {self.pilot!r}")
