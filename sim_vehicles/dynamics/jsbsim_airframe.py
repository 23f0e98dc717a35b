"""A JSBSim airframe flown by a GUIDED-style inner loop: a physics backend of the SITL vehicles.

:class:`JsbsimAirframe` owns one ``jsbsim.FGFDMExec`` and turns the companion's setpoints -- a heading rate
(project frame: counter-clockwise positive, a LEFT turn is positive) and a forward acceleration -- into stick,
rudder and throttle, as ArduPlane's GUIDED mode would (:class:`InnerLoop`, every ``autopilot_every`` physics
substeps; gains per airframe in ``airframes/<name>.yaml``):

- speed (true airspeed): a reference integrates the commanded acceleration, clipped to the vehicle's speed
  limits; throttle PI on the error, a feed-forward of the reference's rate, anti-windup; optionally the speed brake;
- turn: coordinated-turn bank ``phi = atan(V omega / g)``, clipped to the bank limit, plus a small integral of the
  heading-rate error that runs only while the bank is within a gate of its command (ungated it winds up during
  the roll-in); the bank error becomes a roll-rate command to the airframe's flight control system (the f16's
  stick is a roll-rate command); the rudder cancels the FCS's yaw damper in the turn so the turn is coordinated;
- altitude (held at the start altitude): PI to a climb rate, a flight-path-angle loop to a load factor
  ``n = (V gamma_dot / g + cos gamma) / cos phi`` (its 1 / cos phi is the level-turn compensation), the pitch rate
  of that load factor ``q = g / V (n - cos gamma cos phi)``, and stick = feed-forward + PI on the pitch-rate error,
  plus a share of the roll stick (the f16 model's flaperons make lift when it rolls). JSBSim's positive elevator
  command is nose down; :class:`Controls` keeps a nose-up pitch stick.

The commanded turn rate is the heading rate in the air mass (a coordinated turn): in wind the ground track's rate
differs, as it does for a real aircraft. The speed held is the true airspeed.

Frames. The project's world is flat: x east, y north, heading and course counter-clockwise from east. The
position is not converted from JSBSim's latitude and longitude: the airframe integrates JSBSim's north/east ground
velocity itself (trapezoidal, every physics substep) from the start position, so step 0 is exactly at the
scenario's start. Attitude follows MAVLink: roll right positive, pitch up positive, yaw clockwise from north.

Creating an airframe loads the model with JSBSim kept off stdout (:func:`_jsbsim_quiet`), puts the wind in the
initial conditions, trims with JSBSim's own trim at the start's speed, heading and altitude, and flies
``settle_s`` straight and level under the inner loop.

The f16 at 5,000 m (``tests/test_jsbsim_airframe.py``; course rate, calm air): heading-rate step 0 -> 5 deg/s
t90 2.3 / 2.0 / 1.8 s at 150 / 250 / 300 m/s, overshoot below 4 %, steady error below 0.04 deg/s, altitude within
4 m; +5 -> -5 deg/s t90 2.8 s at 250 m/s; a roll-out from a right turn briefly overshoots to 6-7.5 deg/s (the
flaperon lift). Create + trim + settle about 0.03-0.05 s of CPU; three airframes stepped 0.1 s in about 1-1.5 ms
of CPU (``benchmarks/bench_jsbsim.py``).
"""

from __future__ import annotations

import contextlib
import ctypes
import dataclasses
import io
import logging
import math
import os
import sys
import threading
from collections.abc import Callable, Iterator, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any, TypeVar

import jsbsim
import yaml

from tssac_core.sim.scenario import Turbulence

if TYPE_CHECKING:
    from _typeshed import DataclassInstance

log = logging.getLogger(__name__)

FT_M = 0.3048
"""Metres per foot (JSBSim's properties are in feet)."""
G_M_S2 = 9.80665
"""Standard gravity (m/s^2), the one the coordinated-turn bank uses."""
AIRFRAMES_DIR = Path(__file__).resolve().parent / "airframes"
"""The bundled airframe files: ``<name>.yaml``."""
REFERENCE_LAT_DEG = 0.0
"""Where JSBSim's aircraft starts (the equator at the prime meridian). The project's world is flat: the position
is integrated from JSBSim's ground velocity, so the latitude and longitude only set gravity and the Earth's rate."""
REFERENCE_LON_DEG = 0.0
MAX_SUBSTEPS_PER_STEP = 1_000_000
"""A step longer than this many physics substeps is a unit error (hours of flight in one call)."""

_STDOUT_LOCK = threading.Lock()
"""Serialises the stdout redirections: two threads interleaving them could leave stdout on /dev/null."""


class AirframeError(Exception):
    """An airframe that cannot be used (unknown name, bad file, a model JSBSim does not load); one line."""


_MILSPEC_TURB_TYPE = 3
"""``atmosphere/turb-type`` of JSBSim's MIL-F-8785C (Dryden-like) turbulence model (FGWinds::ttMilspec)."""
# JSBSim's MIL-F-8785C turbulence (``atmosphere/turb-type`` 3): above 2,000 ft its intensity follows the probability of
# exceedance; the wind at 20 ft sets it near the ground. Light: probability of exceedance 1e-2 (severity index 3),
# 15 kt at 20 ft above ground; moderate: 1e-3 (severity index 4), 30 kt.
_TURBULENCE_SETTINGS: dict[Turbulence, tuple[float, float]] = {
    Turbulence.LIGHT: (3.0, 15.0 * 1852.0 / 3600.0 / FT_M),
    Turbulence.MODERATE: (4.0, 30.0 * 1852.0 / 3600.0 / FT_M),
}
"""Severity index (probability-of-exceedance row) and wind at 20 ft above ground (ft/s), per MIL-F-8785C."""


@dataclass(frozen=True)
class Wind:
    """A steady wind (same everywhere) and the turbulence on top of it."""

    speed_m_s: float = 0.0
    """Speed of the air over the ground (m/s)."""
    from_deg: float = 0.0
    """Where the wind blows FROM, clockwise from north (deg), as pilots say: 270 is a westerly, air moving east."""
    turbulence: Turbulence = Turbulence.NONE
    """Turbulence level (JSBSim's MIL-F-8785C model)."""

    def __post_init__(self) -> None:
        if not (math.isfinite(self.speed_m_s) and self.speed_m_s >= 0.0 and math.isfinite(self.from_deg)):
            raise ValueError(f"wind needs a finite speed >= 0 and a finite direction: {self}")

    @property
    def east_m_s(self) -> float:
        """East component of the air's velocity (m/s): positive for a wind from the west."""
        return -self.speed_m_s * math.sin(math.radians(self.from_deg))

    @property
    def north_m_s(self) -> float:
        """North component of the air's velocity (m/s): positive for a wind from the south."""
        return -self.speed_m_s * math.cos(math.radians(self.from_deg))


@dataclass(frozen=True)
class StartState:
    """Where and how the airframe starts, in the project frame (flat world, x east, y north)."""

    east_m: float
    """Position east (m)."""
    north_m: float
    """Position north (m)."""
    alt_m: float
    """Altitude above sea level (m); the inner loop holds it."""
    speed_m_s: float
    """True airspeed (m/s)."""
    heading_rad: float
    """Heading, counter-clockwise from east (rad): 0 flies east, pi/2 north."""

    def __post_init__(self) -> None:
        values = (self.east_m, self.north_m, self.alt_m, self.speed_m_s, self.heading_rad)
        if not all(math.isfinite(v) for v in values) or self.speed_m_s <= 0.0:
            raise ValueError(f"a start needs finite values and a positive speed: {self}")


@dataclass(frozen=True)
class AirframeState:
    """The airframe after a step, in the project frame (position, course, turn rate) and MAVLink's (attitude)."""

    time_s: float
    """Time since step 0 (s)."""
    east_m: float
    """Position east (m), integrated from the ground velocity."""
    north_m: float
    """Position north (m)."""
    alt_m: float
    """Altitude above sea level (m)."""
    groundspeed_m_s: float
    """Horizontal speed over the ground (m/s)."""
    course_rad: float
    """Ground track, counter-clockwise from east, in (-pi, pi]: d(east)/dt = v cos(course), d(north)/dt = v sin."""
    airspeed_m_s: float
    """True airspeed (m/s)."""
    yaw_rad: float
    """Heading of the nose, clockwise from north, in (-pi, pi] (MAVLink ATTITUDE.yaw)."""
    roll_rad: float
    """Bank, right wing down positive (MAVLink)."""
    pitch_rad: float
    """Pitch, nose up positive (MAVLink)."""
    roll_rate_rad_s: float
    """Body roll rate p (rad/s)."""
    pitch_rate_rad_s: float
    """Body pitch rate q (rad/s)."""
    yaw_rate_rad_s: float
    """Body yaw rate r (rad/s), right positive."""
    climb_m_s: float
    """Vertical speed, up positive (m/s)."""
    turn_rate_rad_s: float
    """Course change over the last step / its length (rad/s), counter-clockwise (left) positive."""
    accel_m_s2: float
    """Groundspeed change over the last step / its length (m/s^2)."""
    wind_east_m_s: float
    """East component of the air's velocity at the airframe, turbulence included (m/s)."""
    wind_north_m_s: float
    """North component of the air's velocity at the airframe, turbulence included (m/s)."""
    throttle: float
    """Throttle command, 0 (idle) to 1 (full afterburner on the f16; 0.5 is military power)."""


@dataclass(frozen=True)
class AirframeLimits:
    """What the airframe can do under its inner loop, declared in its file for the speed envelope the file names
    (worst cases over it; the file gives the measured figures per speed)."""

    bank_limit_deg: float
    """Largest bank the inner loop commands (deg)."""
    max_accel_m_s2: float
    """Forward acceleration achievable anywhere in the envelope (m/s^2, positive)."""
    max_decel_m_s2: float
    """Forward deceleration achievable anywhere in the envelope (m/s^2, negative)."""


@dataclass(frozen=True)
class AirframeGains:
    """The inner loop's gains (the loops are in the module docstring; the airframe file says what each is)."""

    turn_ki_rad_per_rad: float
    """Bank (rad) per rad of accumulated heading-rate error."""
    turn_integral_max_deg: float
    """Clip of the turn integral's share of the bank (deg)."""
    turn_gate_deg: float
    """The turn integral runs only while |bank - command| is below this (deg)."""
    bank_gain_1_s: float
    """Roll-rate command (rad/s) per rad of bank error."""
    p_max_rad_s: float
    """Clip of the roll-rate command (rad/s)."""
    roll_stick_per_rad_s: float
    """Roll stick per rad/s of roll-rate command (the FCS's own normalisation)."""
    rudder_per_turn_yaw_rate_s: float
    """Rudder command per rad/s of a coordinated turn's yaw rate, negated (cancels a yaw damper's opposition)."""
    throttle_kp_per_m_s: float
    """Throttle per m/s of airspeed error."""
    throttle_ki_per_m: float
    """Throttle per m of accumulated airspeed error."""
    throttle_per_accel_s2_m: float
    """Throttle feed-forward per m/s^2 of commanded acceleration (while the reference moves)."""
    speedbrake_on_m_s: float
    """The speed brake extends at idle once the airspeed exceeds the reference by this (m/s); <= 0: never."""
    speedbrake_off_m_s: float
    """It retracts once the excess is below this (m/s)."""
    altitude_kp_1_s: float
    """Climb rate (m/s) per m of altitude error."""
    altitude_ki_1_s2: float
    """Climb rate (m/s) per m s of accumulated altitude error."""
    climb_max_m_s: float
    """Clip of the climb-rate command (m/s)."""
    gamma_gain_1_s: float
    """Flight-path-angle rate (rad/s) per rad of flight-path-angle error."""
    load_factor_min: float
    """Lower clip of the load-factor command (g)."""
    load_factor_max: float
    """Upper clip of the load-factor command (g)."""
    stick_per_pitch_rate_s: float
    """Pitch-stick feed-forward per rad/s of pitch-rate command."""
    stick_per_g: float
    """Pitch-stick feed-forward per g of load factor above 1."""
    pitch_kp_s: float
    """Pitch stick per rad/s of pitch-rate error."""
    pitch_ki: float
    """Pitch stick per rad of accumulated pitch-rate error."""
    pitch_per_roll_stick: float
    """Pitch stick (nose up) added per unit of roll stick (right positive): offsets lift that rolling makes."""
    settle_heading_gain_1_s: float
    """Heading hold during the settle: heading rate (rad/s) per rad of heading error."""


@dataclass(frozen=True)
class AirframeSpec:
    """An airframe file, loaded: which JSBSim model, how fast to run it, its limits and inner-loop gains."""

    name: str
    """The file's stem (``f16``)."""
    model: str
    """JSBSim model name (``aircraft/<model>/<model>.xml`` under ``root_dir``)."""
    root_dir: Path | None
    """JSBSim model directory (aircraft/, engine/, systems/); None = the jsbsim wheel's."""
    physics_rate_hz: float
    """JSBSim integration rate (Hz)."""
    autopilot_every: int
    """The inner loop runs every n-th physics substep."""
    settle_s: float
    """Straight and level flight after the trim, before step 0 (s)."""
    limits: AirframeLimits
    gains: AirframeGains


# --------------------------------------------------------------------------------------------- loading

_D = TypeVar("_D", bound="DataclassInstance")


def load_airframe(name_or_path: str | Path) -> AirframeSpec:
    """The airframe named ``name_or_path`` (a bundled file, e.g. ``f16``) or in that YAML file; a file that
    cannot be used raises :class:`AirframeError` naming the file and the key."""
    path = airframe_path(name_or_path)
    raw = _read_mapping(path)
    source = str(path)
    limits = _build(AirframeLimits, _mapping(raw.get("limits"), source, "limits"), source, "limits.")
    gains = _build(AirframeGains, _mapping(raw.get("gains"), source, "gains"), source, "gains.")
    given = {"name": path.stem, "root_dir": _root_dir(raw.get("root_dir"), path), "limits": limits, "gains": gains}
    top = {k: v for k, v in raw.items() if k not in ("root_dir", "limits", "gains")}
    spec = _build(AirframeSpec, top, source, "", given)
    _check_spec(spec, source)
    return spec


def airframe_path(name_or_path: str | Path) -> Path:
    """The airframe file named ``name_or_path`` (a bundled name or a path); :class:`AirframeError` if there is none."""
    text = str(name_or_path)
    if isinstance(name_or_path, Path) or "/" in text or text.endswith((".yaml", ".yml")):
        path = Path(name_or_path)
        if not path.is_file():
            raise AirframeError(f"{path}: no such airframe file")
        return path
    path = AIRFRAMES_DIR / f"{text}.yaml"
    if not text.isidentifier() or not path.is_file():
        known = ", ".join(sorted(p.stem for p in AIRFRAMES_DIR.glob("*.yaml") if "." not in p.stem))
        raise AirframeError(f"unknown airframe {text!r} (bundled: {known}; or give a path to a YAML file)")
    return path


def _read_mapping(path: Path) -> dict[str, Any]:
    try:
        raw = yaml.safe_load(path.read_text(encoding="utf-8"))
    except OSError as exc:
        raise AirframeError(f"{path}: cannot read file ({exc.strerror or exc})") from None
    except (yaml.YAMLError, UnicodeDecodeError) as exc:
        reason = " ".join(str(getattr(exc, "problem", None) or exc).split())
        raise AirframeError(f"{path}: not valid YAML: {reason}") from None
    return _mapping(raw, str(path), "")


def _mapping(raw: object, source: str, where: str) -> dict[str, Any]:
    if not isinstance(raw, dict) or not all(isinstance(k, str) for k in raw):
        what = f"{where}: " if where else ""
        raise AirframeError(f"{source}: {what}expected a mapping of names to values")
    return raw


def _build(
    cls: type[_D], raw: Mapping[str, Any], source: str, prefix: str, given: Mapping[str, Any] | None = None
) -> _D:
    """``cls(**raw, **given)`` with every key of ``raw`` a field not in ``given`` and every value of the field's
    type (numbers finite)."""
    given = given or {}
    fields = {f.name: f for f in dataclasses.fields(cls) if f.name not in given}
    for key in raw:
        if key not in fields:
            raise AirframeError(f"{source}: {prefix}{key}: unknown key (known: {', '.join(sorted(fields))})")
    values: dict[str, Any] = dict(given)
    for name, fld in fields.items():
        if name not in raw:
            raise AirframeError(f"{source}: {prefix}{name}: missing")
        values[name] = _typed(raw[name], fld.type, source, prefix + name)
    return cls(**values)


def _typed(value: object, type_name: object, source: str, where: str) -> object:
    if type_name in ("float", float):
        if isinstance(value, bool) or not isinstance(value, int | float) or not math.isfinite(value):
            raise AirframeError(f"{source}: {where}: expected a finite number, got {value!r}")
        return float(value)
    if type_name in ("int", int):
        if isinstance(value, bool) or not isinstance(value, int):
            raise AirframeError(f"{source}: {where}: expected an integer, got {value!r}")
        return value
    if type_name in ("str", str):
        if not isinstance(value, str) or not value:
            raise AirframeError(f"{source}: {where}: expected a name, got {value!r}")
        return value
    raise AirframeError(f"{source}: {where}: unsupported field type {type_name!r}")


def _root_dir(raw: object, path: Path) -> Path | None:
    if raw is None:
        return None
    if not isinstance(raw, str) or not raw:
        raise AirframeError(f"{path}: root_dir: expected a directory path, got {raw!r}")
    root = Path(raw).expanduser()
    return root if root.is_absolute() else (path.parent / root).resolve()


def _check_spec(spec: AirframeSpec, source: str) -> None:
    """Ranges the loops rely on; the model's file must exist where JSBSim will look for it."""
    checks = (
        (spec.physics_rate_hz >= 10.0, "physics_rate_hz: must be at least 10"),
        (spec.autopilot_every >= 1, "autopilot_every: must be at least 1"),
        (spec.settle_s >= 0.0, "settle_s: must not be negative"),
        (0.0 < spec.limits.bank_limit_deg < 90.0, "limits.bank_limit_deg: must be in (0, 90)"),
        (spec.limits.max_accel_m_s2 > 0.0, "limits.max_accel_m_s2: must be positive"),
        (spec.limits.max_decel_m_s2 < 0.0, "limits.max_decel_m_s2: must be negative"),
        (spec.gains.p_max_rad_s > 0.0, "gains.p_max_rad_s: must be positive"),
        (spec.gains.load_factor_min < 1.0 < spec.gains.load_factor_max, "gains.load_factor_min/max: must bracket 1"),
    )
    for ok, problem in checks:
        if not ok:
            raise AirframeError(f"{source}: {problem}")
    root = Path(spec.root_dir) if spec.root_dir is not None else Path(jsbsim.get_default_root_dir())
    model_file = root / "aircraft" / spec.model / f"{spec.model}.xml"
    if not model_file.is_file():
        raise AirframeError(f"{source}: model: no JSBSim model {spec.model!r} ({model_file} does not exist)")


# --------------------------------------------------------------------------------------------- JSBSim


@contextlib.contextmanager
def _jsbsim_quiet() -> Iterator[None]:
    """Keep JSBSim off stdout meanwhile: it prints its banner (and load and trim complaints) even at debug level
    0, and this process may speak JSON there. The wheel's logger writes to Python's ``sys.stdout`` (captured
    here and logged at DEBUG); file descriptor 1 goes to /dev/null too, for anything native. Both are
    process-wide: another thread's stdout writes meanwhile would be lost too."""
    with _STDOUT_LOCK:
        if sys.stdout is not None:
            sys.stdout.flush()  # this process's own output goes out before fd 1 moves
        with contextlib.redirect_stdout(io.StringIO()) as text, _fd1_to_devnull():
            yield
    if said := " ".join(text.getvalue().split()):
        log.debug("JSBSim said: %s", said)


@contextlib.contextmanager
def _fd1_to_devnull() -> Iterator[None]:
    saved = os.dup(1)
    devnull = os.open(os.devnull, os.O_WRONLY)
    try:
        os.dup2(devnull, 1)
        yield
    finally:
        _flush_c_stdio()
        os.dup2(saved, 1)
        os.close(saved)
        os.close(devnull)


def _flush_c_stdio() -> None:
    """Flush C's stdio buffers, so nothing written while fd 1 was /dev/null comes out after it is back."""
    with contextlib.suppress(OSError, AttributeError):
        ctypes.CDLL(None).fflush(None)


def _new_fdm(spec: AirframeSpec) -> jsbsim.FGFDMExec:
    """A JSBSim executive with ``spec``'s model loaded, at ``spec``'s physics rate, quiet (call with stdout
    redirected: the constructor prints the banner)."""
    root = str(spec.root_dir) if spec.root_dir is not None else None
    try:
        fdm = jsbsim.FGFDMExec(root)
        fdm.set_debug_level(0)
        loaded = fdm.load_model(spec.model)
    except (OSError, RuntimeError) as exc:
        reason = " ".join(str(exc).split())  # JSBSim's messages span lines
        raise AirframeError(f"{spec.name}: JSBSim cannot load model {spec.model!r}: {reason}") from None
    if not loaded:
        raise AirframeError(f"{spec.name}: JSBSim cannot load model {spec.model!r} from {root or 'the wheel'}")
    fdm.set_dt(1.0 / spec.physics_rate_hz)
    fdm.disable_output()
    return fdm


def _set_turbulence(fdm: jsbsim.FGFDMExec, wind: Wind, seed: int) -> None:
    """Turbulence, seeded: the turbulence draws from ``atmosphere/randomseed`` (measured: ``simulation/randomseed``
    does not change it; set too, for the rest of JSBSim). The seeds are C ints: ``seed`` is taken modulo 2^31."""
    fdm["simulation/randomseed"] = float(seed % 2**31)
    fdm["atmosphere/randomseed"] = float(seed % 2**31)
    if wind.turbulence is Turbulence.NONE:
        fdm["atmosphere/turb-type"] = 0.0
        return
    severity, wind_20ft_fps = _TURBULENCE_SETTINGS[wind.turbulence]
    fdm["atmosphere/turb-type"] = float(_MILSPEC_TURB_TYPE)
    fdm["atmosphere/turbulence/milspec/windspeed_at_20ft_AGL-fps"] = wind_20ft_fps
    fdm["atmosphere/turbulence/milspec/severity"] = severity


def _set_initial_conditions(fdm: jsbsim.FGFDMExec, start: StartState, wind: Wind) -> None:
    """Start at the start's altitude, true airspeed and heading, level, in the wind, engine running, gear up;
    trimmed. The wind goes in through the initial conditions (``run_ic`` overwrites the atmosphere's), and the
    velocity as a ground velocity, the air's plus the wind (``ic/vt-fps`` in a crosswind points the aircraft
    sideways, and JSBSim's trim then fails)."""
    fdm["ic/vw-mag-fps"] = wind.speed_m_s / FT_M
    fdm["ic/vw-dir-deg"] = (wind.from_deg + 180.0) % 360.0  # JSBSim's is the direction the air moves TOWARD
    fdm["ic/lat-geod-deg"] = REFERENCE_LAT_DEG
    fdm["ic/long-gc-deg"] = REFERENCE_LON_DEG
    fdm["ic/h-sl-ft"] = start.alt_m / FT_M
    fdm["ic/psi-true-deg"] = math.degrees(_wrap_2pi(math.pi / 2.0 - start.heading_rad))
    fdm["ic/vn-fps"] = (start.speed_m_s * math.sin(start.heading_rad) + wind.north_m_s) / FT_M
    fdm["ic/ve-fps"] = (start.speed_m_s * math.cos(start.heading_rad) + wind.east_m_s) / FT_M
    fdm["ic/vd-fps"] = 0.0
    if not fdm.run_ic():
        raise AirframeError("JSBSim refused the initial conditions")
    fdm["propulsion/set-running"] = -1.0
    fdm["gear/gear-cmd-norm"] = 0.0
    fdm["gear/gear-pos-norm"] = 0.0
    try:
        fdm["simulation/do_simple_trim"] = 1.0  # tFull: throttle, elevator trim and attitude for level flight
    except jsbsim.TrimFailureError:
        log.warning(
            "JSBSim's trim failed at %.0f m/s, %.0f m: settling from the initial conditions only",
            start.speed_m_s,
            start.alt_m,
        )


def _wrap_pi(angle_rad: float) -> float:
    """``angle_rad`` wrapped to (-pi, pi]."""
    wrapped = math.remainder(angle_rad, 2.0 * math.pi)
    return math.pi if wrapped == -math.pi else wrapped


def _wrap_2pi(angle_rad: float) -> float:
    return angle_rad % (2.0 * math.pi)


def _clip(value: float, low: float, high: float) -> float:
    return low if value < low else high if value > high else value


class _Node:
    """One JSBSim property, read and written through its node (no name lookup per access)."""

    __slots__ = ("get", "set")

    def __init__(self, fdm: jsbsim.FGFDMExec, name: str) -> None:
        node = fdm.get_property_manager().get_node(name)
        if node is None:
            raise AirframeError(f"the JSBSim model has no property {name!r}")
        self.get: Callable[[], float] = node.get_double_value
        self.set: Callable[[float], bool] = node.set_double_value


class _Sim:
    """One JSBSim executive and the properties the airframe reads (feet, radians) and writes (commands)."""

    def __init__(self, fdm: jsbsim.FGFDMExec) -> None:
        self.fdm = fdm
        self.v_north = _Node(fdm, "velocities/v-north-fps")
        self.v_east = _Node(fdm, "velocities/v-east-fps")
        self.v_down = _Node(fdm, "velocities/v-down-fps")
        self.vtrue = _Node(fdm, "velocities/vtrue-fps")
        self.alt = _Node(fdm, "position/h-sl-ft")
        self.phi = _Node(fdm, "attitude/phi-rad")
        self.theta = _Node(fdm, "attitude/theta-rad")
        self.psi = _Node(fdm, "attitude/psi-rad")
        self.psidot = _Node(fdm, "velocities/psidot-rad_sec")
        self.gamma = _Node(fdm, "flight-path/gamma-rad")
        self.p = _Node(fdm, "velocities/p-rad_sec")
        self.q = _Node(fdm, "velocities/q-rad_sec")
        self.r = _Node(fdm, "velocities/r-rad_sec")
        self.wind_north = _Node(fdm, "atmosphere/total-wind-north-fps")
        self.wind_east = _Node(fdm, "atmosphere/total-wind-east-fps")
        self.aileron = _Node(fdm, "fcs/aileron-cmd-norm")
        self.elevator = _Node(fdm, "fcs/elevator-cmd-norm")
        self.rudder = _Node(fdm, "fcs/rudder-cmd-norm")
        self.throttle = _Node(fdm, "fcs/throttle-cmd-norm")
        self.speedbrake = _Node(fdm, "fcs/speedbrake-cmd-norm")

    def measurements(self) -> Measurements:
        """What the inner loop reads, in metres and radians."""
        return Measurements(
            airspeed_m_s=max(self.vtrue.get() * FT_M, 1.0),
            alt_m=self.alt.get() * FT_M,
            bank_rad=self.phi.get(),
            pitch_rad=self.theta.get(),
            gamma_rad=self.gamma.get(),
            pitch_rate_rad_s=self.q.get(),
            yaw_rate_rad_s=self.psidot.get(),
        )

    def command(self, controls: Controls) -> None:
        """Write the inner loop's output (JSBSim's elevator command is nose down: the pitch stick negated)."""
        self.aileron.set(controls.roll_stick)
        self.elevator.set(-controls.pitch_stick)
        self.rudder.set(controls.rudder)
        self.throttle.set(controls.throttle)
        self.speedbrake.set(controls.speedbrake)


# --------------------------------------------------------------------------------------------- inner loop


@dataclass(frozen=True, slots=True)
class Controls:
    """One inner-loop output, in JSBSim's command conventions."""

    roll_stick: float
    """``fcs/aileron-cmd-norm`` (-1..1, right roll positive)."""
    pitch_stick: float
    """Pitch stick, nose up positive (-1..1); ``fcs/elevator-cmd-norm`` is its negative (nose down positive)."""
    rudder: float
    """``fcs/rudder-cmd-norm``."""
    throttle: float
    """``fcs/throttle-cmd-norm`` (0..1)."""
    speedbrake: float
    """``fcs/speedbrake-cmd-norm`` (0 or 1)."""


@dataclass(frozen=True, slots=True)
class Measurements:
    """What the inner loop reads from JSBSim, converted (m, m/s, rad; bank right positive)."""

    airspeed_m_s: float
    """True airspeed (at least 1 m/s)."""
    alt_m: float
    """Altitude above sea level."""
    bank_rad: float
    """Bank (Euler roll), right wing down positive."""
    pitch_rad: float
    """Pitch (Euler), nose up positive."""
    gamma_rad: float
    """Flight-path angle, climbing positive."""
    pitch_rate_rad_s: float
    """Body pitch rate q."""
    yaw_rate_rad_s: float
    """Heading (Euler yaw angle) rate, clockwise positive."""


class InnerLoop:
    """The GUIDED-style inner loop (module docstring): setpoints and measurements in, :class:`Controls` out.

    Works in JSBSim's frame: heading rate clockwise (right turn positive; the airframe negates the project's
    counter-clockwise command), bank right positive, pitch up positive, true airspeed in m/s, altitude in m.
    """

    def __init__(self, spec: AirframeSpec, speed_min_m_s: float, speed_max_m_s: float) -> None:
        g = spec.gains
        self.gains = g
        self.bank_limit_rad = math.radians(spec.limits.bank_limit_deg)
        self.cos_bank_limit = math.cos(self.bank_limit_rad)
        self.turn_gate_rad = math.radians(g.turn_gate_deg)
        self.turn_integral_max_rad = math.radians(g.turn_integral_max_deg)
        self.speed_min_m_s = speed_min_m_s
        self.speed_max_m_s = speed_max_m_s
        self.speed_ref_m_s = speed_min_m_s
        """Airspeed reference (m/s): integrates the commanded acceleration."""
        self.alt_ref_m = 0.0
        """Altitude held (m)."""
        self.bank_cmd_rad = 0.0
        """Last bank command (rad, right positive)."""
        self.throttle_integral = 0.0
        self.turn_integral_rad = 0.0
        self.climb_integral_m_s = 0.0
        self.pitch_integral = 0.0
        self.speedbrake = False

    def reset(self, speed_ref_m_s: float, alt_ref_m: float, throttle: float) -> None:
        """Hold ``speed_ref_m_s`` and ``alt_ref_m``, the throttle integrator starting at ``throttle``."""
        self.speed_ref_m_s = _clip(speed_ref_m_s, self.speed_min_m_s, self.speed_max_m_s)
        self.alt_ref_m = alt_ref_m
        self.bank_cmd_rad = 0.0
        self.throttle_integral = throttle
        self.turn_integral_rad = 0.0
        self.climb_integral_m_s = 0.0
        self.pitch_integral = 0.0
        self.speedbrake = False

    def update(
        self,
        yaw_rate_cmd_rad_s: float,
        accel_cmd_m_s2: float,
        m: Measurements,
        dt_s: float,
    ) -> Controls:
        """One update: a clockwise heading rate and a forward acceleration commanded, ``m`` measured."""
        throttle, speedbrake = self.speed(accel_cmd_m_s2, m.airspeed_m_s, dt_s)
        roll_stick = self.roll(yaw_rate_cmd_rad_s, m, dt_s)
        pitch_stick = self.pitch(m, dt_s) + self.gains.pitch_per_roll_stick * roll_stick
        return Controls(
            roll_stick=roll_stick,
            pitch_stick=_clip(pitch_stick, -1.0, 1.0),
            rudder=self.rudder(m),
            throttle=throttle,
            speedbrake=speedbrake,
        )

    def speed(self, accel_cmd_m_s2: float, airspeed_m_s: float, dt_s: float) -> tuple[float, float]:
        """Throttle (0..1) and speed brake (0 or 1): PI on the airspeed error to a reference that integrates the
        commanded acceleration, plus a feed-forward of the command while the reference moves."""
        g = self.gains
        ref = _clip(self.speed_ref_m_s + accel_cmd_m_s2 * dt_s, self.speed_min_m_s, self.speed_max_m_s)
        ref_rate_m_s2 = (ref - self.speed_ref_m_s) / dt_s  # the command, but 0 once the reference is clipped
        self.speed_ref_m_s = ref
        error = ref - airspeed_m_s
        raw = self.throttle_integral + g.throttle_kp_per_m_s * error + g.throttle_per_accel_s2_m * ref_rate_m_s2
        if (raw < 1.0 or error < 0.0) and (raw > 0.0 or error > 0.0):  # anti-windup: frozen while saturated
            self.throttle_integral = _clip(self.throttle_integral + g.throttle_ki_per_m * error * dt_s, 0.0, 1.0)
        throttle = _clip(raw, 0.0, 1.0)
        if g.speedbrake_on_m_s > 0.0:
            if -error > g.speedbrake_on_m_s and throttle <= 0.0:
                self.speedbrake = True
            elif -error < g.speedbrake_off_m_s:
                self.speedbrake = False
        return throttle, 1.0 if self.speedbrake else 0.0

    def roll(self, yaw_rate_cmd_rad_s: float, m: Measurements, dt_s: float) -> float:
        """Roll stick (-1..1, right positive): coordinated-turn bank plus the gated turn integral, the bank error
        made a roll-rate command for the FCS."""
        g = self.gains
        bank_ff = math.atan(m.airspeed_m_s * yaw_rate_cmd_rad_s / G_M_S2)
        bank_cmd = _clip(bank_ff + self.turn_integral_rad, -self.bank_limit_rad, self.bank_limit_rad)
        if abs(m.bank_rad - bank_cmd) < self.turn_gate_rad:  # ungated, it winds up during the roll-in
            self.turn_integral_rad = _clip(
                self.turn_integral_rad + g.turn_ki_rad_per_rad * (yaw_rate_cmd_rad_s - m.yaw_rate_rad_s) * dt_s,
                -self.turn_integral_max_rad,
                self.turn_integral_max_rad,
            )
        self.bank_cmd_rad = bank_cmd
        p_cmd = _clip(g.bank_gain_1_s * (bank_cmd - m.bank_rad), -g.p_max_rad_s, g.p_max_rad_s)
        return _clip(g.roll_stick_per_rad_s * p_cmd, -1.0, 1.0)

    def rudder(self, m: Measurements) -> float:
        """Rudder command that keeps the turn coordinated: minus the gain times the yaw rate of a coordinated
        turn at the commanded bank, ``r = g sin(bank_cmd) cos(pitch) / V``."""
        r_turn = G_M_S2 * math.sin(self.bank_cmd_rad) * math.cos(m.pitch_rad) / m.airspeed_m_s
        return -self.gains.rudder_per_turn_yaw_rate_s * r_turn

    def pitch(self, m: Measurements, dt_s: float) -> float:
        """Pitch stick, nose up positive: altitude PI to a climb rate, a flight-path loop to a load factor (with
        the 1 / cos(bank) of a level turn), the pitch rate of that load factor, then feed-forward + PI on it."""
        g = self.gains
        error = self.alt_ref_m - m.alt_m
        climb_cmd = g.altitude_kp_1_s * error + self.climb_integral_m_s
        if -g.climb_max_m_s < climb_cmd < g.climb_max_m_s:  # anti-windup
            self.climb_integral_m_s += g.altitude_ki_1_s2 * error * dt_s
        climb_cmd = _clip(climb_cmd, -g.climb_max_m_s, g.climb_max_m_s)
        gamma_cmd = math.asin(_clip(climb_cmd / m.airspeed_m_s, -0.5, 0.5))
        cos_gamma = math.cos(m.gamma_rad)
        cos_bank = math.cos(m.bank_rad)
        gamma_rate_cmd = g.gamma_gain_1_s * (gamma_cmd - m.gamma_rad)
        load_factor = (m.airspeed_m_s * gamma_rate_cmd / G_M_S2 + cos_gamma) / max(cos_bank, self.cos_bank_limit)
        load_factor = _clip(load_factor, g.load_factor_min, g.load_factor_max)
        q_cmd = G_M_S2 / m.airspeed_m_s * (load_factor - cos_gamma * cos_bank)
        q_error = q_cmd - m.pitch_rate_rad_s
        feed_forward = g.stick_per_pitch_rate_s * q_cmd + g.stick_per_g * (load_factor - 1.0)
        raw = feed_forward + g.pitch_kp_s * q_error + self.pitch_integral
        if -1.0 < raw < 1.0:  # anti-windup
            self.pitch_integral += g.pitch_ki * q_error * dt_s
        return _clip(raw, -1.0, 1.0)


# --------------------------------------------------------------------------------------------- airframe


class JsbsimAirframe:
    """One aircraft in JSBSim under the inner loop; :meth:`step` advances it by a world step.

    ``speed_min_m_s`` and ``speed_max_m_s`` bound the airspeed reference (the vehicle's limits; the start speed
    must lie within them). ``seed`` seeds JSBSim's random numbers (the turbulence; modulo 2^31). Equal arguments
    and setpoints give bit-for-bit equal states.
    """

    def __init__(
        self,
        spec: AirframeSpec,
        start: StartState,
        wind: Wind = Wind(),
        speed_min_m_s: float = 150.0,
        speed_max_m_s: float = 300.0,
        seed: int = 0,
    ) -> None:
        if not 0.0 < speed_min_m_s <= start.speed_m_s <= speed_max_m_s:
            raise ValueError(
                f"start speed {start.speed_m_s} m/s must lie in the speed limits [{speed_min_m_s}, {speed_max_m_s}]"
            )
        self.spec = spec
        self.start = start
        self.wind = wind
        self._h_s = 1.0 / spec.physics_rate_hz
        self._loop = InnerLoop(spec, speed_min_m_s, speed_max_m_s)
        self._substep = 0
        self._east_m = start.east_m
        self._north_m = start.north_m
        self._time_s = 0.0
        with _jsbsim_quiet():  # the banner, and the trim's complaints (~15 ms)
            fdm = _new_fdm(spec)
            _set_turbulence(fdm, wind, seed)
            _set_initial_conditions(fdm, start, wind)
        sim = _Sim(fdm)
        self._loop.reset(start.speed_m_s, start.alt_m, sim.throttle.get())
        self._settle(sim)
        self._sim: _Sim | None = sim
        self._state = self._measure(sim, None, 0.0)

    @property
    def state(self) -> AirframeState:
        """The state after the last step (at step 0: after the settle, at the start position)."""
        return self._state

    @property
    def fdm(self) -> jsbsim.FGFDMExec:
        """The JSBSim executive (to read other properties; writing to it bypasses the inner loop)."""
        if self._sim is None:
            raise RuntimeError("the airframe is closed")
        return self._sim.fdm

    @property
    def loop(self) -> InnerLoop:
        """The inner loop (its references and integrators, for inspection)."""
        return self._loop

    def step(self, turn_rate_cmd_rad_s: float, accel_cmd_m_s2: float, dt_s: float) -> AirframeState:
        """Advance ``dt_s`` (a whole number of physics substeps) under the setpoints: heading rate (rad/s,
        counter-clockwise = LEFT positive, project frame) and forward acceleration (m/s^2)."""
        if self._sim is None:
            raise RuntimeError("the airframe is closed")
        if not (math.isfinite(turn_rate_cmd_rad_s) and math.isfinite(accel_cmd_m_s2)):
            raise ValueError(f"setpoints must be finite: {turn_rate_cmd_rad_s}, {accel_cmd_m_s2}")
        substeps = self._substeps(dt_s)
        self._fly(self._sim, substeps, -turn_rate_cmd_rad_s, accel_cmd_m_s2, heading_hold_rad=None)
        self._time_s += dt_s
        self._state = self._measure(self._sim, self._state, dt_s)
        return self._state

    def close(self) -> None:
        """Release JSBSim (idempotent); a later :meth:`step` raises RuntimeError."""
        self._sim = None

    def __enter__(self) -> JsbsimAirframe:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def _substeps(self, dt_s: float) -> int:
        exact = dt_s * self.spec.physics_rate_hz
        substeps = round(exact) if math.isfinite(exact) else 0
        if not 1 <= substeps <= MAX_SUBSTEPS_PER_STEP or abs(substeps - exact) > 1e-6 * max(1.0, exact):
            raise ValueError(f"dt_s {dt_s} is not a whole number of {self.spec.physics_rate_hz} Hz substeps")
        return substeps

    def _settle(self, sim: _Sim) -> None:
        """Fly ``settle_s`` straight and level holding the start heading, then restart the position at the
        start's."""
        psi0 = _wrap_2pi(math.pi / 2.0 - self.start.heading_rad)
        substeps = round(self.spec.settle_s * self.spec.physics_rate_hz)
        self._fly(sim, substeps, 0.0, 0.0, heading_hold_rad=psi0)
        self._east_m = self.start.east_m
        self._north_m = self.start.north_m

    def _fly(
        self, sim: _Sim, substeps: int, yaw_rate_cmd_rad_s: float, accel_cmd_m_s2: float, heading_hold_rad: float | None
    ) -> None:
        """The physics loop: the inner loop every ``autopilot_every`` substeps, JSBSim, the position integral.
        ``yaw_rate_cmd_rad_s`` is clockwise (JSBSim's); with ``heading_hold_rad`` it is replaced by a heading hold."""
        run = sim.fdm.run
        loop = self._loop
        h_m_per_fps = self._h_s * FT_M * 0.5  # trapezoid: (v_before + v_after) / 2 * h, in metres from ft/s
        every = self.spec.autopilot_every
        dt_loop_s = self._h_s * every
        v_north, v_east = sim.v_north.get, sim.v_east.get
        vn_prev, ve_prev = v_north(), v_east()
        east, north = self._east_m, self._north_m
        for _ in range(substeps):
            if self._substep % every == 0:
                yaw_rate_cmd = yaw_rate_cmd_rad_s
                if heading_hold_rad is not None:
                    error = _wrap_pi(heading_hold_rad - sim.psi.get())
                    yaw_rate_cmd = loop.gains.settle_heading_gain_1_s * error
                sim.command(loop.update(yaw_rate_cmd, accel_cmd_m_s2, sim.measurements(), dt_loop_s))
            self._substep += 1
            run()
            vn, ve = v_north(), v_east()
            north += (vn + vn_prev) * h_m_per_fps
            east += (ve + ve_prev) * h_m_per_fps
            vn_prev, ve_prev = vn, ve
        self._east_m, self._north_m = east, north

    def _measure(self, sim: _Sim, before: AirframeState | None, dt_s: float) -> AirframeState:
        """The state now; the turn rate and acceleration are the course and groundspeed changes since ``before``
        over ``dt_s`` (0 without one)."""
        vn = sim.v_north.get() * FT_M
        ve = sim.v_east.get() * FT_M
        groundspeed = math.hypot(vn, ve)
        course = math.atan2(vn, ve)
        return AirframeState(
            time_s=self._time_s,
            east_m=self._east_m,
            north_m=self._north_m,
            alt_m=sim.alt.get() * FT_M,
            groundspeed_m_s=groundspeed,
            course_rad=course,
            airspeed_m_s=sim.vtrue.get() * FT_M,
            yaw_rad=_wrap_pi(sim.psi.get()),
            roll_rad=sim.phi.get(),
            pitch_rad=sim.theta.get(),
            roll_rate_rad_s=sim.p.get(),
            pitch_rate_rad_s=sim.q.get(),
            yaw_rate_rad_s=sim.r.get(),
            climb_m_s=-sim.v_down.get() * FT_M,
            turn_rate_rad_s=0.0 if before is None else _wrap_pi(course - before.course_rad) / dt_s,
            accel_m_s2=0.0 if before is None else (groundspeed - before.groundspeed_m_s) / dt_s,
            wind_east_m_s=sim.wind_east.get() * FT_M,
            wind_north_m_s=sim.wind_north.get() * FT_M,
            throttle=sim.throttle.get(),
        )
