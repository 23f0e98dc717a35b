"""Scenario files: schema, loading, dumping and random layouts.

A scenario is a YAML file (see ``scenarios/*.yaml`` and ``docs/scenarios.md``) loaded into the frozen
dataclasses below. Every field is checked on load; a bad file raises :class:`ScenarioError`, whose
message is one line naming the file, the field and what is wrong.

Units: the file speaks km, degrees, m/s and seconds because that is how a mission is described; the
world (:mod:`tssac_core.sim.world`) converts to metres and radians once.

A scenario has exactly one of ``layout:`` (a fixed layout: the paper's figure 6 mission) or
``random:`` (ranges for random layouts, section 5.2.2). Random layouts are sampled by rejection until
they are feasible: no vehicle starts inside (or too close to) a radar, no radar reaches into the SAM's
detection disk, and every role's zone is reachable from every start without crossing a radar
(a flood fill on a 1 km grid with radars inflated by the clearance).
"""

from __future__ import annotations

import dataclasses
import enum
import hashlib
import math
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import yaml

from tssac_core.assurance.monitor import EstimateError, Hazards, Limits, ShieldConfig, handover_error, start_excess_m
from tssac_core.common.errors import InputError
from tssac_core.sim.yaml_file import read_yaml, typed_value


class Role(enum.Enum):
    """The three UAVs, in the order the world stores them (index = position in that order)."""

    DECOY = "decoy"
    DETECT = "detect"
    STRIKE = "strike"

    @property
    def index(self) -> int:
        return ROLES.index(self)


ROLES: tuple[Role, ...] = (Role.DECOY, Role.DETECT, Role.STRIKE)

SCENARIOS_DIR = Path(__file__).resolve().parents[2] / "scenarios"
"""The project's scenario files."""
DEFAULT_SCENARIO = SCENARIOS_DIR / "random.yaml"
"""What training and evaluation fly unless told otherwise."""


MAX_AREA_KM = 1000.0
"""The feasibility check walks a 1 km grid of the area: 10^6 cells at most."""
MAX_EPISODE_STEPS = 1_000_000
"""About 28 hours of flight at dt = 0.1 s: longer episodes are a typo, and buffers are sized by it."""
MAX_SPEED_M_S = 1000.0
MAX_LATENCY_MS = 60_000.0
MAX_LINK_LOSS = 0.6
"""The most of a link's datagrams, each way, that may fail to count (:attr:`LinkModel.frame_loss`): up to it a
companion's commands go through with their attempts sized to the link (mavlink_bridge.companion.config) and the
monitor was flown in SITL; beyond it a command round trip succeeds less than once in six tries."""
MAX_EXPECT_EPISODES = 100_000
MAX_GPS_DROPOUT = 0.9
"""The most fixes a scenario may lose: beyond it a fix comes less than once a second at 10 Hz, and a companion flies
the monitor's backup (before its first fix, from the known start) most of the time instead of its pilot."""


class ScenarioError(InputError):
    """A scenario file that cannot be used; ``str()`` is one line: ``file: field: problem``."""

    def __init__(self, source: str, field_path: str, problem: str) -> None:
        self.source = source
        self.field_path = field_path
        self.problem = problem
        where = f"{source}: {field_path}" if field_path else source
        super().__init__(f"{where}: {problem}")


# --------------------------------------------------------------------------------------- schema


@dataclass(frozen=True)
class Ranges:
    """Sensor and weapon ranges of Table 3 (km)."""

    strike_launch_km: float = 10.0
    """R1: the strike UAV's weapon launch range."""
    detect_km: float = 13.0
    """R2: the detect UAV's detection range."""
    sam_launch_km: float = 17.0
    """R3: the SAM's launch range."""
    sam_detect_km: float = 20.0
    """R4: the SAM's detection range."""


@dataclass(frozen=True)
class Radar:
    """A radar site: a hazard disk (eq. 11 costs 1 per step inside it)."""

    position_km: tuple[float, float]
    """Centre, (x east, y north) in km from the area's south-west corner."""
    radius_km: float = 12.0
    """Detection radius."""


@dataclass(frozen=True)
class VehicleSpec:
    """One UAV's performance limits (eq. 6 bounds and the action scaling)."""

    speed_min_m_s: float = 150.0
    """Lower speed bound v_min (a fixed-wing vehicle cannot hover)."""
    speed_max_m_s: float = 300.0
    """Upper speed bound v_max."""
    speed_init_m_s: float = 250.0
    """Speed at the start of an episode."""
    turn_rate_max_deg_s: float = 5.0
    """|omega| at action +-1."""
    accel_max_m_s2: float = 10.0
    """|u| at action +-1."""


@dataclass(frozen=True)
class Start:
    """A vehicle's initial pose."""

    position_km: tuple[float, float]
    """(x east, y north) in km."""
    heading_deg: float = 45.0
    """Heading phi, counter-clockwise from east (the frame of eq. 5)."""


@dataclass(frozen=True)
class Layout:
    """Where everything is in one episode."""

    sam_km: tuple[float, float]
    """The SAM site (centre of R3 and R4, and of every role's zone)."""
    target_km: tuple[float, float]
    """The target the SAM protects (the observation's l is the distance to it)."""
    radars: tuple[Radar, ...]
    """The hazards."""
    starts: dict[str, Start]
    """Initial pose per role name (decoy, detect, strike)."""


@dataclass(frozen=True)
class RandomLayout:
    """Ranges from which random layouts are drawn (section 5.2.2: each episode a new layout)."""

    sam_x_km: tuple[float, float] = (55.0, 75.0)
    """SAM east coordinate range."""
    sam_y_km: tuple[float, float] = (55.0, 75.0)
    """SAM north coordinate range."""
    target_offset_km: tuple[float, float] = (0.0, 3.0)
    """Distance of the target from the SAM."""
    radar_count: int = 3
    """Number of radar sites."""
    radar_radius_km: tuple[float, float] = (12.0, 12.0)
    """Radar radius range."""
    radar_distance_from_sam_km: tuple[float, float] = (32.0, 45.0)
    """Distance of each radar centre from the SAM (>= R4 + radius keeps the zones clear)."""
    radar_bearing_spread_deg: float = 50.0
    """Radars lie within this angle either side of the SAM -> start-box bearing, i.e. in the way."""
    start_x_km: tuple[float, float] = (8.0, 18.0)
    """Start-box east range (all three UAVs start in it)."""
    start_y_km: tuple[float, float] = (8.0, 18.0)
    """Start-box north range."""
    start_heading_deg: tuple[float, float] = (30.0, 60.0)
    """Initial heading range."""
    start_separation_km: float = 1.0
    """Minimum distance between two UAVs at the start."""
    clearance_km: float = 2.0
    """Minimum distance from a start to a radar's edge, and the radar inflation for the reachability check."""


@dataclass(frozen=True)
class LinkModel:
    """Sensor and datalink model, read by the SITL vehicles (sim_vehicles) and the bridge's filter."""

    gps_position_sigma_m: float = 5.0
    """GPS horizontal position noise, 1 sigma."""
    gps_velocity_sigma_m_s: float = 0.5
    """GPS velocity noise, 1 sigma."""
    gps_rate_hz: float = 10.0
    """GPS fix rate."""
    gps_dropout_prob: float = 0.0
    """Probability that a fix is missing."""
    packet_loss: float = 0.0
    """Probability that a MAVLink packet is lost, each direction."""
    latency_ms: float = 0.0
    """One-way link latency."""
    duplication: float = 0.0
    """Probability that a packet is delivered twice."""
    reordering: float = 0.0
    """Probability that a packet is held back behind the next one."""
    signing: bool = False
    """Fly with MAVLink 2 message signing (``mavlink_bridge.fly`` makes a fresh key for each run
    unless ``--signing-key`` gives one)."""

    def setpoints_may_slip(self, dt_s: float) -> bool:
        """Whether a setpoint may reach the vehicle a tick later than the monitor predicts (so the vehicle flies the
        previous command one tick longer at a hand-over): a lost one, one held behind the next (reordering), or a
        round trip that is not a whole number of ticks (the monitor counts the commands in flight by rounding it)."""
        ticks = 2.0 * self.latency_ms / 1000.0 / dt_s
        return self.packet_loss > 0 or self.reordering > 0 or abs(ticks - round(ticks)) > 1e-9

    @property
    def frame_loss(self) -> float:
        """The share of datagrams, each way, that do not count on a signed link: the lost ones, and the ones held back
        behind a later one, which signing refuses as replays (their timestamp is older than one already accepted, as
        MAVLink 2 requires). ``fly`` signs by default, so the scenario's link is judged signed."""
        return 1.0 - (1.0 - self.packet_loss) * (1.0 - self.reordering)


@dataclass(frozen=True)
class Origin:
    """Geodetic position of the area's south-west corner (for GLOBAL_POSITION_INT)."""

    lat_deg: float = 47.397742
    lon_deg: float = 8.545594
    alt_m: float = 5000.0
    """Flight altitude above mean sea level."""


class Turbulence(enum.Enum):
    """Turbulence on top of a scenario's wind (JSBSim's MIL-spec model; the kinematic world flies the mean wind)."""

    NONE = "none"
    LIGHT = "light"
    MODERATE = "moderate"


MAX_WIND_M_S = 50.0
"""Winds above this are a typo (a jet stream at flight level is about 50 m/s)."""


@dataclass(frozen=True)
class Wind:
    """A constant wind over the whole area, at the flight altitude (DESIGN.md section 7). Absent: calm air."""

    speed_m_s: float = 0.0
    """Mean wind speed."""
    from_deg: float = 270.0
    """The direction it blows from, clockwise from north, as pilots say it (270: a west wind, blowing east)."""
    turbulence: Turbulence = Turbulence.NONE
    """Gusts on top of the mean wind (JSBSim only)."""
    max_m_s: float | None = None
    """The largest wind the scenario promises (for the runtime-assurance monitor's bound); None: ``speed_m_s``."""

    @property
    def promised_max_m_s(self) -> float:
        return self.speed_m_s if self.max_m_s is None else self.max_m_s

    def velocity_m_s(self) -> tuple[float, float]:
        """(east, north) velocity of the air mass, in the world's frame: a wind from 270 deg moves the air east."""
        to_rad = math.radians(self.from_deg + 180.0)  # the direction it blows towards, clockwise from north
        return self.speed_m_s * math.sin(to_rad), self.speed_m_s * math.cos(to_rad)


class DynamicsModel(enum.Enum):
    """What integrates the vehicles' motion in the SITL (the batched world is always kinematic)."""

    KINEMATIC = "kinematic"
    """Eq. 5-6, the training world's own model (tssac_core.sim.world)."""
    JSBSIM = "jsbsim"
    """A JSBSim flight model per vehicle, flown by an inner-loop autopilot (sim_vehicles.dynamics)."""


@dataclass(frozen=True)
class Dynamics:
    """Which physics the SITL vehicles fly (``--dynamics`` on the command line overrides ``model``)."""

    model: DynamicsModel = DynamicsModel.KINEMATIC
    """kinematic or jsbsim."""
    aircraft: str = "f16"
    """JSBSim: a bundled airframe's name (sim_vehicles/dynamics/airframes/NAME.yaml) or the path of an airframe file."""


@dataclass(frozen=True)
class Expect:
    """What the SITL regression tests require of the shipped models on this scenario."""

    episodes: int = 10
    """Missions to fly."""
    min_success_rate: float = 0.95
    """Minimum fraction of missions with the target hit."""
    max_mean_cost: float = 3.0
    """Maximum mean hazard cost per UAV per episode."""
    min_success_low95: float = 0.0
    """The lower end of the success rate's 95% Wilson interval must reach this (tssac_core.common.stats)."""
    max_cost_high95: float | None = None
    """The upper end of the mean cost's 95% bootstrap interval over missions must stay within this (None: no bound).
    Unlike the mean, it sees one costly mission among few: a single UAV 30 steps inside a radar in one of six
    missions is a mean of 1.7 but an upper bound of 5."""
    speedup: float | None = None
    """Fly at real time x this instead of lockstep. For links with latency or loss: under lockstep the
    SITL runs link delays on the wall clock and a lost setpoint holds the world until the vehicle's
    wall-clock timeout, so a 200 ms link would stretch every 0.1 s step to over 0.4 s of wall time."""


@dataclass(frozen=True)
class Scenario:
    """A whole mission description (DESIGN.md section 2)."""

    name: str
    """Short name, used in logs and results."""
    area_km: float = 100.0
    """Side of the square area; leaving it ends the episode (eq. 6 position bounds)."""
    dt_s: float = 0.1
    """Simulation step (Table 3)."""
    episode_steps: int = 4000
    """Episode cap (truncation)."""
    cost_limit: float = 3.0
    """C: hazard cost budget per UAV per episode (Table 3)."""
    ranges: Ranges = field(default_factory=Ranges)
    """R1-R4."""
    vehicles: dict[str, VehicleSpec] = field(default_factory=dict)
    """Limits per role name (decoy, detect, strike)."""
    layout: Layout | None = None
    """A fixed layout; exactly one of layout / random."""
    random: RandomLayout | None = None
    """Random layouts; exactly one of layout / random."""
    link: LinkModel = field(default_factory=LinkModel)
    """Sensor and link model for the SITL."""
    origin: Origin = field(default_factory=Origin)
    """Geodetic origin for the SITL."""
    expect: Expect | None = None
    """Regression expectations (optional)."""
    wind: Wind | None = None
    """A constant wind (optional; absent: calm air, as every figure before wind was flown)."""
    dynamics: Dynamics | None = None
    """The SITL's physics (optional; absent: kinematic)."""

    def vehicle(self, role: Role) -> VehicleSpec:
        return self.vehicles[role.value]

    def digest(self) -> str:
        """A short hash of the task the scenario defines (recorded in checkpoints); the regression
        expectations are not part of the task, so adding or changing them keeps the digest."""
        data = to_dict(self)
        data.pop("expect", None)
        text = yaml.safe_dump(data, sort_keys=True)
        return hashlib.sha256(text.encode()).hexdigest()[:16]


def _plain(value: Any) -> Any:
    if dataclasses.is_dataclass(value) and not isinstance(value, type):
        return {
            f.name: _plain(getattr(value, f.name))
            for f in dataclasses.fields(value)
            if getattr(value, f.name) is not None
        }
    if isinstance(value, enum.Enum):
        return value.value
    if isinstance(value, tuple):
        return [_plain(v) for v in value]
    if isinstance(value, dict):
        return {k: _plain(v) for k, v in value.items()}
    return value


def to_dict(scenario: Scenario) -> dict[str, Any]:
    """Plain data (what the YAML file holds) for a scenario; ``from_dict(to_dict(s)) == s``."""
    return _plain(scenario)


def from_dict(data: Any, source: str = "<scenario>") -> Scenario:
    """Build and validate a scenario from plain data; raises ScenarioError."""
    scenario = typed_value(Scenario, data, "", source, ScenarioError)
    validate(scenario, source)
    return scenario


def load(path: str | Path) -> Scenario:
    """Load and validate a scenario file; raises ScenarioError (one line) on any problem."""
    return from_dict(read_yaml(path, ScenarioError), str(path))


def load_for_batched_world(path: str | Path) -> Scenario:
    """:func:`load` for the commands that fly the batched world (training, evaluation): it integrates eq. 5-6, so a
    scenario that asks for other physics is refused in one line rather than flown as something it is not."""
    s = load(path)
    if s.dynamics is not None and s.dynamics.model is not DynamicsModel.KINEMATIC:
        raise ScenarioError(
            str(path),
            "dynamics.model",
            f"{s.dynamics.model.value} flies only in the SITL (python -m mavlink_bridge.fly); the batched world is "
            "kinematic: remove the section, or set it to kinematic",
        )
    return s


def dump(scenario: Scenario, path: str | Path) -> None:
    """Write a scenario file that :func:`load` reads back equal."""
    Path(path).write_text(yaml.safe_dump(to_dict(scenario), sort_keys=False))


# ----------------------------------------------------------------------------------- validation


def _checker(source: str) -> Callable[[bool, str, str], None]:
    """``check(ok, where, problem)``: ScenarioError naming ``source`` and the field ``where`` unless ``ok``."""

    def check(ok: bool, where: str, problem: str) -> None:
        if not ok:
            raise ScenarioError(source, where, problem)

    return check


def validate(s: Scenario, source: str) -> None:
    """Semantic checks beyond types; raises ScenarioError naming the field."""

    check = _checker(source)
    check(0 < s.area_km <= MAX_AREA_KM, "area_km", f"must be in (0, {MAX_AREA_KM:g}] km, got {s.area_km}")
    check(0 < s.dt_s <= 1.0, "dt_s", f"must be in (0, 1] s, got {s.dt_s}")
    check(
        0 < s.episode_steps <= MAX_EPISODE_STEPS,
        "episode_steps",
        f"must be in 1..{MAX_EPISODE_STEPS}, got {s.episode_steps}",
    )
    check(s.cost_limit >= 0, "cost_limit", f"must be >= 0, got {s.cost_limit}")
    r = s.ranges
    for name in ("strike_launch_km", "detect_km", "sam_launch_km", "sam_detect_km"):
        check(0 < getattr(r, name) <= s.area_km, f"ranges.{name}", f"must be in (0, area_km = {s.area_km}] km")
    check(
        r.strike_launch_km < r.detect_km < r.sam_launch_km < r.sam_detect_km,
        "ranges",
        "inconsistent: need R1 strike_launch_km < R2 detect_km < R3 sam_launch_km < R4 sam_detect_km, got "
        f"{r.strike_launch_km} / {r.detect_km} / {r.sam_launch_km} / {r.sam_detect_km}",
    )
    _validate_vehicles(s, source)
    check((s.layout is None) != (s.random is None), "layout", "give exactly one of 'layout' (fixed) or 'random'")
    if s.layout is not None:
        _validate_layout(s, s.layout, source)
    if s.random is not None:
        _validate_random(s, s.random, source)
    _validate_link(s.link, source)
    check(-90 <= s.origin.lat_deg <= 90, "origin.lat_deg", "must be in [-90, 90]")
    check(-180 <= s.origin.lon_deg <= 180, "origin.lon_deg", "must be in [-180, 180]")
    if s.wind is not None:
        _validate_wind(s, s.wind, source)
    if s.expect is not None:
        _validate_expect(s.expect, source)


def _validate_vehicles(s: Scenario, source: str) -> None:
    """One vehicle per role, each with speeds, turn rate and acceleration a fixed-wing UAV can have."""

    check = _checker(source)
    names = [role.value for role in ROLES]
    for key in s.vehicles:
        check(key in names, f"vehicles.{key}", f"unknown role (allowed: {', '.join(names)})")
    for name in names:
        check(name in s.vehicles, f"vehicles.{name}", "missing required vehicle")
        v = s.vehicles[name]
        where = f"vehicles.{name}"
        check(v.speed_min_m_s > 0, f"{where}.speed_min_m_s", "must be positive (a fixed-wing UAV cannot hover)")
        check(
            v.speed_min_m_s < v.speed_max_m_s <= MAX_SPEED_M_S,
            f"{where}.speed_max_m_s",
            f"must be above speed_min_m_s and at most {MAX_SPEED_M_S:g} m/s",
        )
        check(
            v.speed_min_m_s <= v.speed_init_m_s <= v.speed_max_m_s,
            f"{where}.speed_init_m_s",
            f"must lie in [speed_min_m_s, speed_max_m_s] = [{v.speed_min_m_s}, {v.speed_max_m_s}]",
        )
        check(0 < v.turn_rate_max_deg_s <= 90, f"{where}.turn_rate_max_deg_s", "must be in (0, 90] deg/s")
        check(0 < v.accel_max_m_s2 <= 100, f"{where}.accel_max_m_s2", "must be in (0, 100] m/s^2")


def _validate_link(lk: LinkModel, source: str) -> None:
    """Probabilities, noise and latency a link can have, and a loss that lets commands through."""

    check = _checker(source)
    for name in ("gps_dropout_prob", "packet_loss", "duplication", "reordering"):
        check(
            0.0 <= getattr(lk, name) <= 1.0, f"link.{name}", f"must be a probability in [0, 1], got {getattr(lk, name)}"
        )
    check(
        lk.gps_dropout_prob <= MAX_GPS_DROPOUT,
        "link.gps_dropout_prob",
        f"must be at most {MAX_GPS_DROPOUT:g}, got {lk.gps_dropout_prob:g}: a companion that gets no fix flies the "
        "monitor's backup from its start, and one that gets almost none, nowhere",
    )
    check(
        lk.frame_loss <= MAX_LINK_LOSS,
        "link",
        f"packet_loss {lk.packet_loss:g} and reordering {lk.reordering:g} leave {1 - lk.frame_loss:.0%} of the frames "
        f"each way (a frame held behind a later one is a replay to signing): at most {MAX_LINK_LOSS:.0%} may be lost, "
        "or no command gets through reliably",
    )
    for name in ("gps_position_sigma_m", "gps_velocity_sigma_m_s"):
        check(getattr(lk, name) >= 0, f"link.{name}", "must be >= 0")
    check(0 <= lk.latency_ms <= MAX_LATENCY_MS, "link.latency_ms", f"must be in [0, {MAX_LATENCY_MS:g}] ms")
    check(0 < lk.gps_rate_hz <= 100, "link.gps_rate_hz", "must be in (0, 100] Hz")


def _validate_expect(e: Expect, source: str) -> None:
    """What a regression test may promise: counts and rates in their ranges."""

    check = _checker(source)
    check(
        0 < e.episodes <= MAX_EXPECT_EPISODES,
        "expect.episodes",
        f"must be positive and at most {MAX_EXPECT_EPISODES}",
    )
    check(0 <= e.min_success_rate <= 1, "expect.min_success_rate", "must be in [0, 1]")
    check(e.max_mean_cost >= 0, "expect.max_mean_cost", "must be >= 0")
    check(0 <= e.min_success_low95 <= 1, "expect.min_success_low95", "must be in [0, 1]")
    check(e.max_cost_high95 is None or e.max_cost_high95 >= 0, "expect.max_cost_high95", "must be >= 0")
    check(
        e.speedup is None or 0 < e.speedup <= 1000,
        "expect.speedup",
        "must be positive and at most 1000",
    )


def _validate_wind(s: Scenario, w: Wind, source: str) -> None:
    """A wind every vehicle can fly in: below its slowest airspeed (else it cannot make headway), within the promise."""
    slowest = min(v.speed_min_m_s for v in s.vehicles.values())
    if not 0.0 <= w.speed_m_s <= MAX_WIND_M_S:
        raise ScenarioError(source, "wind.speed_m_s", f"must be in [0, {MAX_WIND_M_S:g}] m/s, got {w.speed_m_s}")
    if not 0.0 <= w.from_deg < 360.0:
        raise ScenarioError(source, "wind.from_deg", f"must be in [0, 360) deg, got {w.from_deg}")
    if not w.speed_m_s <= w.promised_max_m_s <= MAX_WIND_M_S:
        raise ScenarioError(
            source, "wind.max_m_s", f"must be in [speed_m_s, {MAX_WIND_M_S:g}] = [{w.speed_m_s}, {MAX_WIND_M_S:g}] m/s"
        )
    if w.promised_max_m_s >= 0.5 * slowest:
        raise ScenarioError(
            source,
            "wind.max_m_s" if w.max_m_s is not None else "wind.speed_m_s",
            f"{w.promised_max_m_s:g} m/s is too strong to fly in: a wind must stay below half the slowest vehicle's "
            f"speed_min_m_s ({slowest:g} m/s), so that every vehicle makes headway and can turn into it",
        )


def _max_radius_km(s: Scenario) -> float:
    return s.area_km / 4


def _validate_layout(s: Scenario, lay: Layout, source: str) -> None:
    problem = layout_problem(s, lay, clearance_km=0.0)
    if problem is not None:
        raise ScenarioError(source, problem[0], problem[1])


def layout_problem(
    s: Scenario, lay: Layout, clearance_km: float, protected_starts: bool = True, shield: ShieldConfig | None = None
) -> tuple[str, str] | None:
    """Why a layout cannot be flown, as (field, problem), or None: the one rule for a scenario file's fixed layout
    and for every layout drawn from a random one (:func:`sample_layout`), so that a layout the batched world flies
    is one a SITL world accepts. Every site and start inside the area, radii within bounds, one start per role,
    then :func:`infeasibility`."""

    def inside(p: tuple[float, float]) -> bool:
        return 0 <= p[0] <= s.area_km and 0 <= p[1] <= s.area_km

    if not inside(lay.sam_km):
        return "layout.sam_km", f"{lay.sam_km} is outside the {s.area_km} km area"
    if not inside(lay.target_km):
        return "layout.target_km", f"{lay.target_km} is outside the {s.area_km} km area"
    for i, radar in enumerate(lay.radars):
        where = f"layout.radars[{i}]"
        if not 0 < radar.radius_km <= _max_radius_km(s):
            return f"{where}.radius_km", f"out of range: {radar.radius_km} (allowed (0, {_max_radius_km(s)}] km)"
        if not inside(radar.position_km):
            return f"{where}.position_km", f"{radar.position_km} is outside the area"
    names = [role.value for role in ROLES]
    for key in lay.starts:
        if key not in names:
            return f"layout.starts.{key}", f"unknown role (allowed: {', '.join(names)})"
    for name in names:
        if name not in lay.starts:
            return f"layout.starts.{name}", "missing required start"
        if not inside(lay.starts[name].position_km):
            return f"layout.starts.{name}.position_km", "outside the area"
    return infeasibility(s, lay, clearance_km, protected_starts, shield)


def _validate_random(s: Scenario, rnd: RandomLayout, source: str) -> None:
    for f in dataclasses.fields(rnd):
        value = getattr(rnd, f.name)
        if isinstance(value, tuple) and value[0] > value[1]:
            raise ScenarioError(source, f"random.{f.name}", f"range is empty: {value[0]} > {value[1]}")
    lo, hi = rnd.radar_radius_km
    if not (0 < lo and hi <= _max_radius_km(s)):
        raise ScenarioError(
            source,
            "random.radar_radius_km",
            f"out of range: {rnd.radar_radius_km} (allowed (0, {_max_radius_km(s)}] km)",
        )
    if rnd.radar_count < 0 or rnd.radar_count > 10:
        raise ScenarioError(source, "random.radar_count", f"must be in [0, 10], got {rnd.radar_count}")
    for name in ("sam_x_km", "sam_y_km", "start_x_km", "start_y_km"):
        a, b = getattr(rnd, name)
        if a < 0 or b > s.area_km:
            raise ScenarioError(source, f"random.{name}", f"range {a}..{b} leaves the {s.area_km} km area")
    # One draw proves the ranges can produce a feasible layout at all.
    try:
        sample_layout(s, np.random.default_rng(0))
    except RuntimeError as exc:
        raise ScenarioError(source, "random", str(exc)) from None


# -------------------------------------------------------------------------------- feasibility


GRID_KM = 1.0


def infeasibility(
    s: Scenario, lay: Layout, clearance_km: float, protected_starts: bool = True, shield: ShieldConfig | None = None
) -> tuple[str, str] | None:
    """Why a layout is unusable, as (field, problem), or None if it is feasible.

    Checks: no start inside a radar (plus ``clearance_km``), every start one the runtime-assurance monitor
    protects (:func:`unprotected_start`), and every role's zone reachable from its start through radar-free
    cells of the area (radars inflated by ``clearance_km``).
    """
    r = s.ranges
    for name, start in lay.starts.items():
        for i, radar in enumerate(lay.radars):
            d = math.dist(start.position_km, radar.position_km)
            if d <= radar.radius_km + clearance_km:
                return (
                    f"layout.starts.{name}",
                    f"starts inside (or within {clearance_km} km of) radar {i} ({d:.1f} km from its centre)",
                )
    unprotected = unprotected_start(s, lay, shield) if protected_starts else None
    if unprotected is not None:
        return unprotected
    n = int(round(s.area_km / GRID_KM))
    centres = (np.arange(n) + 0.5) * GRID_KM
    gx, gy = np.meshgrid(centres, centres, indexing="ij")
    free = np.ones((n, n), dtype=bool)
    for radar in lay.radars:
        free &= np.hypot(gx - radar.position_km[0], gy - radar.position_km[1]) > radar.radius_km + clearance_km
    d_sam = np.hypot(gx - lay.sam_km[0], gy - lay.sam_km[1])
    zones = {
        Role.DECOY.value: (d_sam > r.sam_launch_km) & (d_sam <= r.sam_detect_km),
        Role.DETECT.value: (d_sam > r.strike_launch_km) & (d_sam <= r.detect_km),
        Role.STRIKE.value: d_sam < r.strike_launch_km,
    }
    cells = {
        name: (min(int(st.position_km[0] / GRID_KM), n - 1), min(int(st.position_km[1] / GRID_KM), n - 1))
        for name, st in lay.starts.items()
    }
    reached: list[np.ndarray] = []
    for name, cell in cells.items():
        reach = next((c for c in reached if c[cell]), None)  # starts in one component share a fill
        if reach is None:
            seed = np.zeros_like(free)
            seed[cell] = True
            reach = _flood(seed, free | seed)
            reached.append(reach)
        if not (reach & zones[name] & free).any():
            return (
                f"layout.starts.{name}",
                f"its zone cannot be reached from {lay.starts[name].position_km} without crossing a radar",
            )
    return None


def _flood(seed: np.ndarray, passable: np.ndarray) -> np.ndarray:
    """4-connected flood fill of ``passable`` cells from ``seed``: every cell of the components it touches.

    Whole runs at a time (a run: a maximal stretch of passable cells along a row, or along a column):
    a run that holds a reached cell is reached entirely. Rows and columns alternate until nothing grows,
    which ends on the same cells as growing by one neighbour per pass, in a few passes instead of one per
    cell of the longest path (the reachability check of every sampled layout runs it).
    """
    along_rows = _run_ids(passable)
    along_cols = _run_ids(passable.T).T
    reach = seed & passable
    while True:
        grown = _fill_runs(_fill_runs(reach, along_rows, passable), along_cols, passable)
        if np.array_equal(grown, reach):
            return reach
        reach = grown


def _run_ids(passable: np.ndarray) -> np.ndarray:
    """An id per cell of the run of passable cells along its row that it belongs to (blocked cells get the
    id of the run before them: callers mask them out)."""
    start = passable.copy()
    start[:, 1:] &= ~passable[:, :-1]  # a run starts at a passable cell after a blocked one or the edge
    return np.cumsum(start, axis=None).reshape(passable.shape)


def _fill_runs(reach: np.ndarray, run_ids: np.ndarray, passable: np.ndarray) -> np.ndarray:
    """``reach`` grown to the whole of every run it touches."""
    touched = np.zeros(int(run_ids.max()) + 1, dtype=bool)
    touched[run_ids[reach]] = True
    return touched[run_ids] & passable


SENSOR_SIGMA_FLOOR = (0.1, 0.01)
"""The least position (m) and velocity (m/s) sigma a companion's Kalman filter assumes, whatever the scenario says."""


def start_error(s: Scenario, speed_m_s: np.ndarray, cfg: ShieldConfig) -> EstimateError:
    """The monitor's error bound at a companion's first decision, from the scenario's sensors: ``sigma_k`` times
    the GPS's position sigma, its velocity sigma (speed) and that over the speed (heading), the Kalman filter's
    covariance when it starts from one fix; and over a link where a setpoint may slip (:meth:`LinkModel.
    setpoints_may_slip`) one setpoint lost or late at the first command."""
    pos = max(s.link.gps_position_sigma_m, SENSOR_SIGMA_FLOOR[0])
    vel = max(s.link.gps_velocity_sigma_m_s, SENSOR_SIGMA_FLOOR[1])
    k = cfg.sigma_k
    sensors = EstimateError(np.full(3, k * pos), k * vel / np.maximum(speed_m_s, 1.0), np.full(3, k * vel))
    slips = s.link.setpoints_may_slip(s.dt_s)
    return sensors + handover_error(_limits(s), s.dt_s, cfg.handover_ticks if slips else 0)


def _limits(s: Scenario) -> Limits:
    specs = [s.vehicle(role) for role in ROLES]
    return Limits(
        np.array([v.speed_min_m_s for v in specs]),
        np.array([v.speed_max_m_s for v in specs]),
        np.radians([v.turn_rate_max_deg_s for v in specs]),
        np.array([v.accel_max_m_s2 for v in specs]),
    )


StartCheck = Callable[[Layout], "tuple[str, str] | None"]
"""A further check of a layout's starts: the (field, problem) of the first it refuses, or None."""


def start_scene(s: Scenario, lay: Layout) -> tuple[np.ndarray, Hazards, Limits]:
    """The three UAVs' starts as the monitor sees them, (3, 4): x, y (m), the scenario's initial speed and the start
    heading (rad) in decoy, detect, strike order; the layout's radars and area for each; and their limits."""
    specs = [s.vehicle(role) for role in ROLES]
    state = np.array(
        [
            [*(c * 1000.0 for c in lay.starts[role.value].position_km), spec.speed_init_m_s, 0.0]
            for role, spec in zip(ROLES, specs, strict=True)
        ]
    )
    state[:, 3] = np.radians([lay.starts[role.value].heading_deg for role in ROLES])
    k = len(lay.radars)
    centres = np.array([r.position_km for r in lay.radars], dtype=np.float64).reshape(1, k, 2) * 1000.0
    radii = np.array([r.radius_km for r in lay.radars], dtype=np.float64).reshape(1, k) * 1000.0
    hz = Hazards(np.repeat(centres, 3, axis=0), np.repeat(radii, 3, axis=0), s.area_km * 1000.0)
    return state, hz, _limits(s)


def start_problem(role: Role, excess_m: float) -> tuple[str, str]:
    """The (field, problem) of a start the monitor cannot protect: its best backup lacks ``-excess_m``."""
    return (
        f"layout.starts.{role.value}",
        f"the runtime-assurance monitor cannot protect this start: its best backup lacks {-excess_m:.0f} m "
        "of clearance from the radars and the area's edges",
    )


def unprotected_start(s: Scenario, lay: Layout, cfg: ShieldConfig | None = None) -> tuple[str, str] | None:
    """The first UAV whose start the runtime-assurance monitor cannot protect, as (field, problem), or None.

    The monitor's guarantee (docs/runtime_assurance.md) covers every state from which one of its backups keeps the
    margin for ever; the start is the one state it does not choose, so a layout is admitted only if every start is
    such a state, in both places the monitor runs: the batched world (the true state, margin
    :attr:`ShieldConfig.margin_m`) and a companion in lockstep (the same margin less the error bound of
    :func:`start_error`, after the link's round trip of the hold), with the margins of ``cfg`` (the monitor's that
    flies: ``evaluate --shield-margin-m``; default :class:`ShieldConfig`). It holds for any decision interval."""
    cfg = ShieldConfig() if cfg is None else cfg
    state, hz, lim = start_scene(s, lay)
    batched = start_excess_m(state, hz, lim, s.dt_s, cfg, cfg.margin_m)
    hold = round(2.0 * s.link.latency_ms / 1000.0 / s.dt_s)
    error = start_error(s, state[:, 2], cfg)
    companion = start_excess_m(state, hz, lim, s.dt_s, cfg, cfg.margin_m, hold_steps=hold, error=error)
    for role, excess in zip(ROLES, np.minimum(batched, companion), strict=True):
        if excess < 0:
            return start_problem(role, float(excess))
    return None


def sample_layout(
    s: Scenario,
    rng: np.random.Generator,
    max_tries: int = 1000,
    protected_starts: bool = True,
    shield: ShieldConfig | None = None,
    start_check: StartCheck | None = None,
) -> Layout:
    """Draw one feasible layout from ``s.random`` (the fixed layout if the scenario has one).

    A draw with a start the runtime-assurance monitor cannot protect (:func:`unprotected_start`) is drawn again,
    so every mission flown or evaluated starts where the monitor's guarantee holds. ``protected_starts=False``
    (training and its validation, where no monitor flies) keeps the draws a recipe has always had, so that a run
    trains again bit for bit; such a start is about one layout in 4,000 of ``scenarios/random.yaml``. ``shield``:
    the monitor's margins the starts are checked with (default :class:`ShieldConfig`). ``start_check``: a further
    check of the starts (a monitor that predicts with an airframe's response:
    :func:`tssac_core.sim.lagged_starts.lagged_start_check`); a draw it refuses is drawn again, a fixed layout it
    refuses raises :class:`ScenarioError`."""
    if s.random is None:
        assert s.layout is not None
        problem = None if start_check is None else start_check(s.layout)
        if problem is not None:
            raise ScenarioError(s.name, *problem)
        if protected_starts and shield is not None and shield != ShieldConfig():
            # The file was checked with the default margins on load; a monitor with others checks them again.
            problem = unprotected_start(s, s.layout, shield)
            if problem is not None:
                raise ScenarioError(s.name, problem[0], f"{problem[1]} (with the margin {shield.margin_m:g} m)")
        return s.layout
    rnd = s.random
    r4 = s.ranges.sam_detect_km
    for _ in range(max_tries):
        sam = (rng.uniform(*rnd.sam_x_km), rng.uniform(*rnd.sam_y_km))
        off_d, off_a = rng.uniform(*rnd.target_offset_km), rng.uniform(-math.pi, math.pi)
        target = (sam[0] + off_d * math.cos(off_a), sam[1] + off_d * math.sin(off_a))
        box_centre = (sum(rnd.start_x_km) / 2, sum(rnd.start_y_km) / 2)
        axis = math.atan2(box_centre[1] - sam[1], box_centre[0] - sam[0])
        radars = []
        for _k in range(rnd.radar_count):
            radius = rng.uniform(*rnd.radar_radius_km)
            lo = max(rnd.radar_distance_from_sam_km[0], r4 + radius)  # zones stay clear of hazards
            dist = rng.uniform(lo, max(lo, rnd.radar_distance_from_sam_km[1]))
            bearing = axis + math.radians(rng.uniform(-rnd.radar_bearing_spread_deg, rnd.radar_bearing_spread_deg))
            radars.append(Radar((sam[0] + dist * math.cos(bearing), sam[1] + dist * math.sin(bearing)), radius))
        starts: dict[str, Start] = {}
        for role in ROLES:
            for _attempt in range(50):
                p = (rng.uniform(*rnd.start_x_km), rng.uniform(*rnd.start_y_km))
                if all(math.dist(p, q.position_km) >= rnd.start_separation_km for q in starts.values()):
                    break
            starts[role.value] = Start(p, rng.uniform(*rnd.start_heading_deg))
        layout = Layout(sam, target, tuple(radars), starts)
        if layout_problem(s, layout, rnd.clearance_km, protected_starts, shield) is None:
            if start_check is None or start_check(layout) is None:
                return layout
    raise RuntimeError(f"no feasible layout in {max_tries} draws: the random ranges leave no way to the zones")
