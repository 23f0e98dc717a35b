"""The truth log's format, shared by its writer (:mod:`sim_vehicles.truth_log`) and its reader
(:mod:`mavlink_bridge.fly.mission_log`), which never import each other: JSON Lines, one object per line,
written as the mission runs.

Line types (key ``type``):

``header``  (first line) ``schema`` (:data:`SCHEMA_VERSION`; absent in version 1 logs), ``scenario`` name,
            ``digest`` (Scenario.digest()), ``seed``, ``dt_s``, ``clock`` ("realtime" / "lockstep"), ``speedup``,
            ``dynamics`` ("kinematic" / "jsbsim", with ``aircraft``; absent in version 1: kinematic), ``roles``
            (["decoy", "detect", "strike"]), ``sysids``, ``ports``, ``layout`` (the layout flown, in scenario-file
            form).
``step``    one per world step: ``step`` (1, 2, ...), ``t_s`` (simulated time after the step),
            ``radar_on``, ``identified``, ``hit`` (mission flags after the step) and ``vehicles``:
            {role: {``x_m``, ``y_m`` (east / north of the area's SW corner), ``v_m_s`` (ground speed),
            ``phi_rad`` (course over the ground, CCW from east), ``cost`` (eq. 11 cost of this step, 0/1),
            ``cost_total``, ``omega_cmd``, ``u_cmd`` (the action flown, in [-1, 1]), ``armed``, ``mode``
            ("MANUAL"/"GUIDED"), ``failsafe``, and from version 2 ``turn_rate_rad_s`` and ``accel_m_s2`` (the
            course's turn rate, CCW-positive, and the ground speed's change, measured over the step: under the
            kinematic model the commanded ones, under JSBSim what the airframe did), and ``air`` when the dynamics
            model the air (JSBSim, or wind): {``airspeed_m_s``, ``alt_m``, ``roll_rad`` (right wing down
            positive), ``pitch_rad``, ``heading_rad`` (the nose, CCW from east)}}} — true states, no sensor noise.
``event``   ``step``, ``t_s``, ``event`` (RADAR_ON, IDENT, HIT, HAZARD, FENCE, MSN_END — see
            ``sim_vehicles.autopilot.events``), ``value``, ``vehicle`` (role or null); and STATUSTEXT: a client's
            STATUSTEXT to the vehicle (e.g. the runtime-assurance monitor's hand-overs), ``value`` its
            severity, ``text`` its text, relayed to the vehicle's other clients.
``summary`` (last line) ``success`` (target hit), ``end`` ("success", "geofence", "episode_cap" or
            "stopped"), ``steps``, ``sim_time_s``, ``cost`` ({role: total eq. 11 cost}),
            ``cost_limit``, ``radar_on``, ``identified``, ``hit``, ``counters`` ({role: link and
            protocol counters}).
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any, NotRequired, TypedDict

SCHEMA_VERSION = 2
"""Version 2 added the header's ``schema`` and ``dynamics`` and each row's ``turn_rate_rad_s``, ``accel_m_s2`` and
``air``; version 1 logs (no ``schema`` key) read as before."""
HEADER, STEP, EVENT, SUMMARY = "header", "step", "event", "summary"
"""The line types (key ``type``)."""
ROLES_KEY, VEHICLES_KEY = "roles", "vehicles"
FLAGS = ("radar_on", "identified", "hit")
"""The mission flags of a ``step`` line (and of the ``summary``)."""


class AirRowJson(TypedDict):
    airspeed_m_s: float
    alt_m: float
    roll_rad: float
    pitch_rad: float
    heading_rad: float


class VehicleRowJson(TypedDict):
    """A vehicle's entry in a ``step`` line's ``vehicles`` (:meth:`VehicleRow.as_dict`)."""

    x_m: float
    y_m: float
    v_m_s: float
    phi_rad: float
    cost: float
    cost_total: float
    omega_cmd: float
    u_cmd: float
    armed: bool
    mode: str
    failsafe: bool
    turn_rate_rad_s: float
    accel_m_s2: float
    air: NotRequired[AirRowJson]


class EventLine(TypedDict):
    """An ``event`` line (see the module docstring); ``text`` only on a relayed STATUSTEXT."""

    type: str
    step: int
    t_s: float
    event: str
    value: int
    vehicle: str | None
    text: NotRequired[str]


@dataclass(frozen=True)
class VehicleRow:
    """One vehicle's true state after a step (see the module docstring for units)."""

    role: str
    x_m: float
    y_m: float
    v_m_s: float
    phi_rad: float
    cost: float
    cost_total: float
    omega_cmd: float
    u_cmd: float
    armed: bool
    mode: str
    failsafe: bool
    turn_rate_rad_s: float = 0.0
    accel_m_s2: float = 0.0
    air: AirRow | None = None

    def as_dict(self) -> VehicleRowJson:
        row: VehicleRowJson = {
            "x_m": round(self.x_m, 4),
            "y_m": round(self.y_m, 4),
            "v_m_s": round(self.v_m_s, 5),
            "phi_rad": round(self.phi_rad, 7),
            "cost": self.cost,
            "cost_total": self.cost_total,
            "omega_cmd": round(self.omega_cmd, 7),
            "u_cmd": round(self.u_cmd, 7),
            "armed": self.armed,
            "mode": self.mode,
            "failsafe": self.failsafe,
            "turn_rate_rad_s": round(self.turn_rate_rad_s, 7),
            "accel_m_s2": round(self.accel_m_s2, 5),
        }
        if self.air is not None:
            row["air"] = self.air.as_dict()
        return row


@dataclass(frozen=True)
class AirRow:
    """What the airframe does, in a row of a log whose dynamics model the air (units as the names say)."""

    airspeed_m_s: float
    alt_m: float
    roll_rad: float
    pitch_rad: float
    heading_rad: float

    def as_dict(self) -> AirRowJson:
        return {
            "airspeed_m_s": round(self.airspeed_m_s, 4),
            "alt_m": round(self.alt_m, 3),
            "roll_rad": round(self.roll_rad, 6),
            "pitch_rad": round(self.pitch_rad, 6),
            "heading_rad": round(self.heading_rad, 6),
        }


def encode(record: dict[str, Any]) -> str:
    """One line of the log (compact JSON, with its newline)."""
    return json.dumps(record, separators=(",", ":")) + "\n"


def encode_step(step: int, t_s: float, flags: dict[str, bool], rows: list[VehicleRow]) -> str:
    """A ``step`` line: the bytes :func:`encode` makes of ``{"type": "step", "step", "t_s", **flags, "vehicles":
    {role: row.as_dict()}}``, written without building the dicts (one line per world step, on the lockstep's
    critical path)."""
    head = f'{{"type":"{STEP}","step":{_scalar(step)},"t_s":{_scalar(round(t_s, 6))}'
    flag_items = "".join([f",{_quoted(k)}:{_scalar(v)}" for k, v in flags.items()])
    vehicles = ",".join([f"{_quoted(r.role)}:{_row_json(r)}" for r in rows])
    return f'{head}{flag_items},"{VEHICLES_KEY}":{{{vehicles}}}}}\n'


_ROW = (
    '{"x_m":%s,"y_m":%s,"v_m_s":%s,"phi_rad":%s,"cost":%s,"cost_total":%s,"omega_cmd":%s,"u_cmd":%s,'
    '"armed":%s,"mode":%s,"failsafe":%s,"turn_rate_rad_s":%s,"accel_m_s2":%s%s}'
)
_TEN_FLOATS = (float,) * 10


def _row_json(r: VehicleRow) -> str:
    """``json.dumps(r.as_dict(), separators=(",", ":"))``, key for key."""
    numbers = (
        round(r.x_m, 4),
        round(r.y_m, 4),
        round(r.v_m_s, 5),
        round(r.phi_rad, 7),
        r.cost,
        r.cost_total,
        round(r.omega_cmd, 7),
        round(r.u_cmd, 7),
        round(r.turn_rate_rad_s, 7),
        round(r.accel_m_s2, 5),
    )
    # Plain finite floats (the usual row) are written as json writes them, float.__repr__, without a call per value.
    plain = tuple(map(type, numbers)) == _TEN_FLOATS and math.isfinite(sum(numbers))
    texts = list(map(float.__repr__ if plain else _scalar, numbers))
    air = "" if r.air is None else ',"air":' + json.dumps(r.air.as_dict(), separators=(",", ":"))
    return _ROW % (*texts[:8], _scalar(r.armed), _quoted(r.mode), _scalar(r.failsafe), *texts[8:], air)


def _scalar(value: object) -> str:
    """What json.dumps writes for one number or bool (finite floats by float.__repr__, as json does)."""
    if value is True:
        return "true"
    if value is False:
        return "false"
    if type(value) is float and math.isfinite(value):
        return float.__repr__(value)
    if type(value) is int:
        return int.__repr__(value)
    return json.dumps(value)  # NaN, infinities, numpy scalars: json's own spelling


_QUOTED: dict[str, str] = {}


def _quoted(text: str) -> str:
    """json.dumps of a key or name (roles, modes, flags: a handful of strings, each quoted once)."""
    quoted = _QUOTED.get(text)
    if quoted is None:
        quoted = _QUOTED[text] = json.dumps(text)
    return quoted


def read_truth_log(path: str | Path) -> list[dict[str, Any]]:
    """All records of a truth log (for tests and analysis)."""
    with open(path, encoding="utf-8") as f:
        return [json.loads(line) for line in f if line.strip()]
