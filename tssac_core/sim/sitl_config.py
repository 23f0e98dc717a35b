"""Configuration of a SITL run (what ``python -m sim_vehicles``'s flags set, or what fly gives the world it starts), as
frozen dataclasses. It lives below both: the SITL (:mod:`sim_vehicles`) runs it, fly (:mod:`mavlink_bridge.fly`) builds
it, and neither package imports the other."""

from __future__ import annotations

import enum
from dataclasses import dataclass
from pathlib import Path

from tssac_core.sim import settings_json
from tssac_core.sim.scenario import Dynamics, DynamicsModel, Scenario
from tssac_core.wire.uart import check_baud

DEFAULT_BASE_PORT = 14560
"""Vehicle i binds base + PORT_STRIDE * i (decoy 14560, detect 14570, strike 14580)."""
PORT_STRIDE = 10
"""Port step between vehicles, as in ArduPilot's multi-instance SITL."""


class ClockMode(enum.Enum):
    """How simulated time advances."""

    REALTIME = "realtime"
    """One world step every dt / speedup wall seconds."""
    LOCKSTEP = "lockstep"
    """One world step per round of setpoints from the vehicles under companion control."""


class LockstepStart(enum.Enum):
    """When a lockstep world takes its first step."""

    ALL = "all"
    """Once every vehicle is armed in GUIDED (whole-team regression missions: nobody flies alone)."""
    ANY = "any"
    """Once any vehicle is armed in GUIDED (single-vehicle experiments)."""


@dataclass(frozen=True)
class SitlConfig:
    """Everything a ``sim_vehicles.world_runner.WorldRunner`` needs."""

    scenario: Scenario
    """The mission; a random scenario gets its layout drawn with ``seed``."""
    seed: int = 0
    """Seeds the layout (``sample_layout(scenario, numpy.random.default_rng(seed))``), GPS noise and link model."""
    host: str = "127.0.0.1"
    """Address the vehicles bind."""
    base_port: int = DEFAULT_BASE_PORT
    """UDP port of vehicle 0; vehicle i binds base + 10 i; 0 = every vehicle gets an OS-assigned port."""
    clock: ClockMode = ClockMode.REALTIME
    """Real time (scaled by ``speedup``) or lockstep."""
    speedup: float = 1.0
    """Simulated seconds per wall second (REALTIME; also the pace of an unattended lockstep world)."""
    lockstep_start: LockstepStart = LockstepStart.ALL
    """Which vehicles must be armed in GUIDED before the first step (LOCKSTEP, or REALTIME with ``hold_start``)."""
    hold_start: bool = False
    """REALTIME: hold the world at t = 0, like lockstep, until the ``lockstep_start`` vehicles are armed in
    GUIDED, then run at real time x speedup. Without it the vehicles fly from the ready line, and at
    10x the few wall seconds that companions take to start are a minute of uncontrolled flight."""
    signing_key: bytes | None = None
    """32-byte MAVLink 2 signing key; None = signing off."""
    unsigned_monitors: bool = False
    """With signing: accept unsigned HEARTBEAT / RADIO_STATUS from passive monitors (at most 4, each with a
    telemetry budget of 2,000 bytes/s; they can command nothing). Off: only signed, fresh frames make a client
    (docs/mavlink.md, Security)."""
    truth_log: Path | None = None
    """JSON Lines truth log (states, costs, events, summary); None = no log."""
    layout_out: Path | None = None
    """Write the layout used as a fixed-layout scenario file here."""
    tlog_dir: Path | None = None
    """Write one ``<role>.tlog`` per vehicle (MAVLink in and out, mavlogdump-readable) here."""
    setpoint_timeout_s: float = 1.0
    """Failsafe after this long without a setpoint while armed in GUIDED (sim s; wall s at a lockstep barrier)."""
    linger_s: float = 1.0
    """After the mission ends, keep serving this many simulated seconds (under lockstep at once, the link on simulated
    time)."""
    outputs: tuple[tuple[str, int], ...] = ()
    """Ground-station addresses (``--out udpout:HOST:PORT``): every vehicle streams to each from the start and
    takes commands from it, as ArduPilot SITL's ``--out`` (a listening ground station sees all three)."""
    dynamics_model: DynamicsModel | None = None
    """``--dynamics``: the physics every mission flies, over the scenario's ``dynamics:`` section (None: the
    scenario's, kinematic without one)."""
    aircraft: str | None = None
    """``--aircraft``: the JSBSim airframe, over the scenario's (None: the scenario's, f16 without one)."""
    serial_baud: int | None = None
    """``--serial BAUD``: every vehicle also on a pseudo-terminal, a serial line at this baud rate
    (:mod:`sim_vehicles.link.serial_port`); None: UDP only."""
    serial_byte_loss: float = 0.0
    """``--serial-byte-loss P``: the serial lines drop each byte, each way, with this probability (a noisy line)."""
    monitor_response: Path | None = None
    """The airframe response the companions' monitors predict with (``fly --airframe-response``): the world refuses
    one fitted to another version of the airframe it flies, before the mission (None: nothing to check)."""

    def to_json(self) -> str:
        """This configuration as one line of JSON (:mod:`tssac_core.sim.settings_json`): what fly gives a world it
        starts (``python -m sim_vehicles.from_config``). It holds the signing key."""
        return settings_json.to_json(self)

    @classmethod
    def from_json(cls, text: str, source: str = "the world's configuration") -> SitlConfig:
        """The configuration :meth:`to_json` wrote, equal. Anything else raises one line: a
        :class:`~tssac_core.sim.settings_json.SettingsError` (a malformed, missing or unknown field, or a value the
        configuration refuses) or a ScenarioError (a scenario that does not validate)."""
        return settings_json.mission_settings_from_json(cls, text, source)

    @property
    def dynamics(self) -> Dynamics:
        """The physics this mission flies: the command line's choices over the scenario's section."""
        d = self.scenario.dynamics or Dynamics()
        return Dynamics(
            model=self.dynamics_model or d.model, aircraft=d.aircraft if self.aircraft is None else self.aircraft
        )

    def __post_init__(self) -> None:
        if not (self.speedup > 0.0 and self.speedup < float("inf")):
            raise ValueError(f"speedup must be a positive number, got {self.speedup}")
        if not (self.setpoint_timeout_s > 0.0 and self.setpoint_timeout_s < float("inf")):
            raise ValueError(f"setpoint timeout must be a positive number of seconds, got {self.setpoint_timeout_s}")
        if not (0.0 <= self.linger_s < float("inf")):
            raise ValueError(f"linger must be >= 0 s, got {self.linger_s}")
        if self.base_port != 0 and not (1 <= self.base_port <= 65535 - 2 * PORT_STRIDE):
            raise ValueError(f"base port must be 0 or in 1..{65535 - 2 * PORT_STRIDE}, got {self.base_port}")
        if self.signing_key is not None and len(self.signing_key) != 32:
            raise ValueError(f"signing key must be 32 bytes, got {len(self.signing_key)}")

        if self.serial_baud is not None:
            check_baud(self.serial_baud, "--serial")
        if not 0.0 <= self.serial_byte_loss < 1.0:
            raise ValueError(f"--serial-byte-loss must be in [0, 1), got {self.serial_byte_loss}")
        if self.serial_byte_loss > 0.0 and self.serial_baud is None:
            raise ValueError("--serial-byte-loss needs --serial BAUD (it is the serial line that drops bytes)")
        for host, port in self.outputs:
            if not (1 <= port <= 65535):
                raise ValueError(f"--out port must be in 1..65535, got {port} for {host}")

    def port_for(self, index: int) -> int:
        """The UDP port vehicle ``index`` binds (0 = OS-assigned)."""
        return 0 if self.base_port == 0 else self.base_port + PORT_STRIDE * index
