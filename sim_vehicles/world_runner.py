"""The SITL loop: one world (tssac_core.sim.world.World, n = 1), three vehicles, time, lockstep, events.

Single-threaded: one ``select`` over the three vehicles' sockets, then in each iteration

1. every vehicle drains its socket into its incoming link channel and handles what the channel
   delivers (commands, setpoints, parameters, ...);
2. the world advances by as many steps as its clock policy allows (:mod:`sim_vehicles.clock`, one per
   mode, which the loop asks and which this docstring's Time section describes); after each step every vehicle
   gets its true state, takes its GPS fix and sends its due telemetry, and mission events are
   announced to every vehicle's clients;
3. every vehicle sends what its outgoing link channel delivers.

Time
----
All MAVLink timestamps (``time_boot_ms``, SYSTEM_TIME) are simulated time: step k is at k * dt.

* Real time (default) and ``--speedup X``: step k is due at wall time start + k dt / X. If the
  machine falls more than 1 s of simulated time behind, the schedule is re-anchored (logged)
  instead of racing to catch up.
* ``--lockstep``: the world holds at step 0 until every vehicle (``--lockstep-start all``, default)
  or any vehicle (``any``) is armed in GUIDED. From then on it takes a step as soon as every vehicle
  *in the loop* — armed, in GUIDED, not in failsafe — has a setpoint for the current step: one
  stamped with ``time_boot_ms`` >= the current step's time (echo the newest ``time_boot_ms`` you
  received), or stamped 0 and received during the current step. Vehicles that are disarmed, in
  MANUAL or in failsafe never hold the world. A vehicle in the loop that sends nothing for
  ``GUID_TIMEOUT`` seconds of *wall* time enters its failsafe and stops holding the world (its
  setpoint timeout is measured on the wall clock there, because simulated time stands still while
  the world waits for it); its next setpoint brings it back into the loop. While nobody is in the
  loop (all disarmed, in MANUAL or in failsafe) the world runs at real time (times ``speedup``).
  "Current step" means the newest step tick (SYSTEM_TIME) the vehicle's datalink has delivered: with
  link latency the world runs that many steps ahead of what its clients have seen, as a real vehicle
  flies on while its telemetry and the answers travel, and a setpoint counts as an answer when it
  reaches the socket, whatever the link model then does to it (a lost setpoint: the step is flown on
  the previous command).
* ``--hold-start`` (real time): the same start gate as lockstep, then real time x ``speedup``.
  After every lockstep step each vehicle sends SYSTEM_TIME (the step "tick"), so a client sees every
  step even when its other streams are slower than the step rate. While the world holds still,
  each vehicle sends a snapshot (heartbeat, status, flags, position) once per wall second.

The link models (latency, reordering hold) run on the *link clock*: wall time times ``speedup``
(simulated seconds while the simulation keeps up) in real-time mode; under lockstep simulated time
while the world steps in lockstep or lingers, and wall time times ``speedup`` while it runs paced (nobody in the
loop). While a lockstep world holds at the start no simulated time passes, and what the links carry crosses at
once, in order (each frame still lost as the link model draws it): the clients' handshake costs no wall time for
the link's latency. So a lockstep mission with a lossy, slow link runs at lockstep speed and repeats: what it
draws is keyed by the frame, and nothing of its start depends on the wall clock but a client's retry of a command
the link lost.

Mission end (world terminated or truncated): the end is announced (STATUSTEXT + NAMED_VALUE_INT
MSN_END), the vehicles keep serving ``linger_s`` more simulated seconds (world frozen; paced at
real time times ``speedup``, under lockstep at once), then the run ends; :meth:`WorldRunner.run` returns
and the truth log gets its summary. :meth:`WorldRunner.request_stop` (SIGINT / SIGTERM in the CLI) ends
the run early.
"""

from __future__ import annotations

import dataclasses
import logging
import select
import threading
import time
from collections.abc import Hashable
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any, BinaryIO

import numpy as np

from sim_vehicles.autopilot.clock import Clock
from sim_vehicles.autopilot.events import EventKind, WorldFlags, events_from_step
from sim_vehicles.autopilot.telemetry import VehicleTruth
from sim_vehicles.autopilot.vehicle import Vehicle, VehicleSetup
from sim_vehicles.clock import ClockPolicy, Phase, clock_policy
from sim_vehicles.dynamics.backend import DynamicsError, VehicleDynamics, make_dynamics
from sim_vehicles.link.mavlink_io import EndpointError, MavEndpoint
from sim_vehicles.link.serial_port import PtySerialPort
from sim_vehicles.protocol.commands import CommandHandler
from sim_vehicles.protocol.vehicle_link import VehicleLink
from sim_vehicles.truth_log import TruthLog
from tssac_core.common.files import create_exclusively
from tssac_core.sim.airframe_response import ResponseFileError
from tssac_core.sim.lagged_starts import response_start_check
from tssac_core.sim.scenario import ROLES, Layout, Role, Scenario, ScenarioError, dump, sample_layout, to_dict
from tssac_core.sim.sitl_config import ClockMode, SitlConfig
from tssac_core.sim.world import World
from tssac_core.wire.mission_events import MissionEnd
from tssac_core.wire.signing import StreamKey
from tssac_core.wire.truth_log_schema import SCHEMA_VERSION, AirRow, VehicleRow
from tssac_core.wire.vehicle_limits import Achievable

_log = logging.getLogger(__name__)

MAX_SELECT_S = 0.05
"""Upper bound of one wait, so a stop request is seen within this time."""


def _row(v: Vehicle, truth: VehicleTruth, cost: float, cost_total: float) -> VehicleRow:
    """Vehicle ``v``'s truth-log row after a step, with the step's cost and its total."""
    air = truth.air
    return VehicleRow(
        role=v.role,
        x_m=truth.east_m,
        y_m=truth.north_m,
        v_m_s=truth.speed_m_s,
        phi_rad=truth.phi_rad,
        cost=cost,
        cost_total=cost_total,
        omega_cmd=v.last_action[0],
        u_cmd=v.last_action[1],
        armed=v.armed,
        mode=v.mode.name,
        failsafe=v.failsafe,
        turn_rate_rad_s=truth.turn_rate_rad_s,
        accel_m_s2=truth.accel_m_s2,
        air=None if air is None else AirRow(air.airspeed_m_s, air.alt_m, air.roll_rad, air.pitch_rad, air.heading_rad),
    )


class SitlError(Exception):
    """The SITL cannot start (port in use, unwritable log, ...); ``str()`` is one line."""


@dataclass(frozen=True)
class Endpoint:
    """Where a client finds a vehicle."""

    role: str
    sysid: int
    host: str
    port: int
    serial: str | None = None
    """The vehicle's serial port (``--serial``): ``DEVICE,BAUD``."""

    @property
    def connection_string(self) -> str:
        """pymavlink / MAVProxy connection string of a client: the serial port's ``DEVICE,BAUD`` with ``--serial``,
        else ``udpout:HOST:PORT`` (a wildcard bind reads as loopback)."""
        if self.serial is not None:
            return self.serial
        host = "127.0.0.1" if self.host in ("0.0.0.0", "") else self.host
        return f"udpout:{host}:{self.port}"


@dataclass(frozen=True)
class RunResult:
    """How a run ended."""

    end: str
    """"success", "geofence", "episode_cap" or "stopped"."""
    success: bool
    steps: int
    sim_time_s: float
    cost: dict[str, float]
    """Total eq. 11 hazard cost per role."""


class WorldRunner:
    """Owns the world, the vehicles and the loop (see the module docstring)."""

    def __init__(self, config: SitlConfig) -> None:
        self._stop = threading.Event()
        self._closed = False
        self._endpoints: list[MavEndpoint] = []
        self.serial_ports: list[PtySerialPort] = []
        """With ``--serial``: serial_ports[i] is vehicle i's serial line (:mod:`sim_vehicles.link.serial_port`)."""
        self._truth: TruthLog | None = None
        self._tlogs: list[BinaryIO] = []
        self.dynamics: VehicleDynamics | None = None
        """The physics backend of the mission (a new one each mission)."""
        self.vehicles: list[Vehicle] = []
        self.links: list[VehicleLink] = []
        """links[i] is vehicles[i]'s MAVLink side."""
        try:
            self._open_endpoints(config)
            self._begin(config)
        except BaseException:
            self.close()
            raise

    # ------------------------------------------------------------------------------- set-up

    def _open_endpoints(self, config: SitlConfig) -> None:
        """The vehicles' UDP endpoints: bound once, kept across the missions of a persistent world."""
        # One key, one table of accepted signing streams for the three vehicles: a frame accepted by one is
        # a replay at another once its stream has moved on (docs/mavlink.md, Security).
        run_sysids = frozenset(range(1, len(ROLES) + 1))
        shared_streams: dict[StreamKey, tuple[int, Hashable]] = {}
        for i in range(len(ROLES)):
            try:
                self._endpoints.append(
                    MavEndpoint(
                        config.host,
                        config.port_for(i),
                        i + 1,
                        1,
                        config.signing_key,
                        config.unsigned_monitors,
                        run_sysids,
                        shared_streams,
                    )
                )
            except EndpointError as exc:
                raise SitlError(str(exc.strerror)) from None
        if config.serial_baud is not None:
            seeds = np.random.SeedSequence([config.seed, 59]).spawn(len(ROLES))  # the lines' byte loss
            for endpoint, seed in zip(self._endpoints, seeds, strict=True):
                try:
                    self.serial_ports.append(
                        PtySerialPort(
                            (endpoint.host, endpoint.port),
                            config.serial_baud,
                            config.serial_byte_loss,
                            np.random.default_rng(seed),
                            time.monotonic(),
                        )
                    )
                except OSError as exc:
                    raise SitlError(f"cannot open a pseudo-terminal for --serial: {exc.strerror or exc}") from None

    def next_mission(self, scenario: Scenario, seed: int, truth_log: Path | None, tlog_dir: Path | None) -> None:
        """Reset for another mission, as an autopilot reboots: a new layout, world, clock and vehicles on the same
        sockets, which forget their clients (see :mod:`tssac_core.wire.mission_reset`). The last mission must have
        ended (:meth:`run_mission` returned)."""
        if self._closed:
            raise SitlError("the world is closed")
        self._close_mission_files()
        for endpoint in self._endpoints:
            endpoint.new_session()
        for port in self.serial_ports:
            port.new_session()
        config = dataclasses.replace(
            self.config, scenario=scenario, seed=seed, truth_log=truth_log, tlog_dir=tlog_dir, layout_out=None
        )
        self._begin(config)

    def _begin(self, config: SitlConfig) -> None:
        """Everything of one mission: the layout, the world, the clock, the vehicles and the mission's files."""
        self.config = config
        s = config.scenario
        self.scenario = s
        self.dt_s = s.dt_s
        self.lockstep = config.clock is ClockMode.LOCKSTEP
        try:
            starts = response_start_check(s, config.monitor_response)
            self.layout: Layout = sample_layout(s, np.random.default_rng(config.seed), start_check=starts)
        except (ResponseFileError, ScenarioError) as exc:
            raise SitlError(f"cannot fly this layout for the monitors' airframe response: {exc}") from None
        self.world = World(s, n=1)
        self.world.reset([0], [self.layout])
        self._close_dynamics()
        try:
            self.dynamics = make_dynamics(config.dynamics, self.world, config.seed, config.monitor_response)
        except DynamicsError as exc:
            raise SitlError(f"cannot fly {config.dynamics.model.value} dynamics: {exc}") from None
        self.flags = WorldFlags()
        self.clock = Clock(unix_start_s=time.time(), lockstep=self.lockstep)
        self._end: MissionEnd | None = None
        self._first_step_cpu_s: float | None = None
        """This process's CPU clock at the first world step (the summary reports the flight's CPU)."""
        self.vehicles = []
        self.links = []
        self.result: RunResult | None = None
        if config.layout_out is not None:
            try:
                dump(dataclasses.replace(s, layout=self.layout, random=None), config.layout_out)
            except OSError as exc:
                raise SitlError(f"cannot write layout file {config.layout_out}: {exc.strerror or exc}") from None
        if config.tlog_dir is not None:
            try:
                Path(config.tlog_dir).mkdir(parents=True, exist_ok=True)
            except OSError as exc:
                raise SitlError(f"cannot create tlog directory {config.tlog_dir}: {exc.strerror or exc}") from None
        seeds = np.random.SeedSequence(config.seed).spawn(len(ROLES))
        initial = self.dynamics.truths()
        for i, role in enumerate(ROLES):
            vehicle, link = self._make_vehicle(
                i, role, seeds[i], initial[i], self.dynamics.achievable[i], self.dynamics.bank_limits_deg[i]
            )
            self.vehicles.append(vehicle)
            self.links.append(link)
        self.clock_policy: ClockPolicy = clock_policy(config, self.clock, self.links, self._step)
        """When the world steps, how long the loop waits, and how the link clock runs (:mod:`sim_vehicles.clock`)."""
        if config.truth_log is not None:
            self._open_truth_log(config, Path(config.truth_log), self.dynamics.name)

    def _make_vehicle(
        self,
        i: int,
        role: Role,
        seed: np.random.SeedSequence,
        truth: VehicleTruth,
        achievable: Achievable,
        bank_limit_deg: float,
    ) -> tuple[Vehicle, VehicleLink]:
        """Vehicle ``i`` of the mission (:meth:`_begin`), at its start state ``truth``, with its link (its random
        streams from ``seed``: what goes out, what comes in, its GPS), its tlog, and what it achieves (``achievable``:
        its ACHV_* parameters; ``bank_limit_deg``: its ROLL_LIMIT_DEG)."""
        config, s, c = self.config, self.scenario, self.world.c
        endpoint = self._endpoints[i]
        start = self.layout.starts[role.value]
        setup = VehicleSetup(
            index=i,
            role=role.value,
            sysid=i + 1,
            turn_rate_max_rad_s=float(c.turn_rate_max_rad_s[i]),
            accel_max_m_s2=float(c.accel_max_m_s2[i]),
            speed_min_m_s=float(c.speed_min_m_s[i]),
            speed_max_m_s=float(c.speed_max_m_s[i]),
            dt_s=s.dt_s,
            origin=s.origin,
            home_east_m=start.position_km[0] * 1000.0,
            home_north_m=start.position_km[1] * 1000.0,
            link=s.link,
            setpoint_timeout_s=config.setpoint_timeout_s,
            achievable=achievable,
            bank_limit_deg=bank_limit_deg,
        )
        tx, rx, gps = (np.random.default_rng(q) for q in seed.spawn(3))
        tlog = None
        if config.tlog_dir is not None:
            path = Path(config.tlog_dir) / f"{role.value}.tlog"
            try:
                tlog = open(create_exclusively(path), "wb")  # ours, never a file or link planted there
            except OSError as exc:
                raise SitlError(f"cannot write tlog {path}: {exc.strerror or exc}") from None
            self._tlogs.append(tlog)
        vehicle = Vehicle(setup, self.clock, self.flags, gps, self._vehicle_event)
        link = VehicleLink(vehicle, endpoint, tx, rx, tlog)
        link.add_outputs(config.outputs)
        link.handler = CommandHandler(vehicle, link)
        vehicle.observe(truth)
        return vehicle, link

    def _open_truth_log(self, config: SitlConfig, path: Path, dynamics: str) -> None:
        """The mission's truth log at ``path``, its header saying what flies (SitlError, one line, if it cannot be
        written)."""
        s = self.scenario
        header = {
            "schema": SCHEMA_VERSION,
            "scenario": s.name,
            "digest": s.digest(),
            "seed": config.seed,
            "dt_s": s.dt_s,
            "clock": config.clock.value,
            "speedup": config.speedup,
            "dynamics": {"model": config.dynamics.model.value, "name": dynamics},
            "roles": [r.value for r in ROLES],
            "sysids": [v.sysid for v in self.vehicles],
            "ports": [link.endpoint.port for link in self.links],
            "layout": to_dict(dataclasses.replace(s, layout=self.layout, random=None))["layout"],
        }
        try:
            self._truth = TruthLog(path, header)
        except OSError as exc:
            raise SitlError(f"cannot write truth log {config.truth_log}: {exc.strerror or exc}") from None

    @property
    def endpoints(self) -> list[Endpoint]:
        serial: list[str | None] = [port.connection_string for port in self.serial_ports] or [None] * len(self.links)
        return [
            Endpoint(v.role, v.sysid, link.endpoint.host, link.endpoint.port, device)
            for v, link, device in zip(self.vehicles, self.links, serial, strict=True)
        ]

    def request_stop(self) -> None:
        """End the run at the next loop iteration (safe from another thread or a signal handler)."""
        self._stop.set()

    # ---------------------------------------------------------------------------------- loop

    def run(self) -> RunResult:
        """Serve until the mission has ended and lingered, or a stop is requested; then close."""
        try:
            return self.run_mission()
        finally:
            self.close()

    def run_mission(self) -> RunResult:
        """Serve until the mission has ended and lingered, or a stop is requested; the sockets stay open for
        :meth:`next_mission`."""
        try:
            self._loop()
        finally:
            self._finish()
        assert self.result is not None
        return self.result

    @property
    def stop_requested(self) -> bool:
        return self._stop.is_set()

    def _loop(self) -> None:
        policy = self.clock_policy
        wall0 = time.monotonic()
        self.clock.wall_s = wall0
        for link in self.links:
            link.publish(tick=policy.ticks)  # t = 0: first GPS fix, stream schedules start
        policy.start(wall0)
        fds = [(link, link.endpoint.fileno()) for link in self.links]
        sockets = [fd for _, fd in fds] + [fd for port in self.serial_ports for fd in port.fds()]
        readable: list[int] = sockets  # the first pass reads every socket, then those select saw readable
        while not self._stop.is_set() and policy.phase is not Phase.DONE:
            now = time.monotonic()
            policy.tick(now)
            for port in self.serial_ports:  # what the companions wrote on the lines, to the vehicles
                port.pump(now)
            for link, fd in fds:
                link.poll_socket(receive=fd in readable)
            for link in self.links:
                link.process_incoming()
            deadline = policy.advance(now)
            for link in self.links:
                link.flush()
            for port in self.serial_ports:  # and what the vehicles sent, onto the lines
                port.pump(time.monotonic())
            if policy.phase is Phase.DONE:
                break
            readable = select.select(sockets, [], [], self._wait_s(time.monotonic(), deadline))[0]

    def _wait_s(self, now_wall: float, deadline_wall: float | None) -> float:
        """How long the loop may wait on its sockets: until the policy's next planned action, the serial lines' next
        bytes or the links' next delivery, :data:`MAX_SELECT_S` at most."""
        waits = [MAX_SELECT_S]
        if deadline_wall is not None:
            waits.append(deadline_wall - now_wall)
        for port in self.serial_ports:  # bytes waiting for the line
            due = port.next_due_s(now_wall)
            if due is not None:
                waits.append(due)
        link_wait_s = self.clock_policy.link_wait_s()
        if link_wait_s is not None:
            waits.append(link_wait_s)
        return max(0.0, min(waits))

    # ---------------------------------------------------------------------------------- step

    def _step(self) -> int | None:
        """One world step: the commands flown, the mission's events announced, each vehicle's telemetry sent, the
        truth log written. The step the mission ended at, or None while it goes on."""
        w = self.world
        if self._first_step_cpu_s is None:
            self._first_step_cpu_s = time.process_time()
        commands = [(0.0, 0.0)] * len(ROLES)
        for v in self.vehicles:
            commands[v.index] = v.action()
        actions = np.array([commands], dtype=np.float64)
        assert self.dynamics is not None
        truths = self.dynamics.advance(actions)  # the physics, then the mission on the states it flew
        result = w.mission_step()
        step = int(w.steps[0])
        self.clock_policy.at_sim_time(step * self.dt_s)
        self.flags.radar_on = bool(w.radar_on[0])
        self.flags.identified = bool(w.identified[0])
        self.flags.hit = bool(w.hit[0])
        tick_ms = self.clock.time_boot_ms
        for v in self.vehicles:
            v.observe(truths[v.index])
        # The step's events leave before its telemetry and its tick: a client that answers the tick knows them (the
        # radar's switch is part of what a companion decides on).
        events = events_from_step(result, self.flags.radar_on, step, self.clock.sim_s)
        for event in events:
            _log.info("t=%.1f s: %s", event.time_s, event.statustext()[1])
            if event.kind is EventKind.MISSION_END:
                self._end = MissionEnd(event.value)
                self.flags.end = self._end
            for v, link in zip(self.vehicles, self.links, strict=True):
                v.mission_event(event)
                link.announce(event)
        for link in self.links:
            # Each vehicle's telemetry leaves before the next vehicle's is built and before the
            # bookkeeping below: its client starts on the step while the world finishes it. A tick its
            # client has granted leaves with the next one it has not (one datagram, one wake-up for many
            # ticks; the loop sends whatever is left after its steps).
            link.publish(tick=self.clock_policy.ticks)
            if not link.granted(tick_ms):
                link.flush()
        if self._truth is not None:
            flags = {"radar_on": self.flags.radar_on, "identified": self.flags.identified, "hit": self.flags.hit}
            cost, total = result.cost[0].tolist(), w.cost_total[0].tolist()
            rows = [_row(v, truths[v.index], cost[v.index], total[v.index]) for v in self.vehicles]
            self._truth.step(step, self.clock.sim_s, flags, rows)
            for event in events:
                self._truth.event(event.as_dict())
        return step if result.terminated[0] or result.truncated[0] else None

    def _vehicle_event(self, role: str, name: str, value: int, text: str | None = None) -> None:
        if self._truth is not None:
            self._truth.vehicle_event(int(self.world.steps[0]), self.clock.sim_s, role, name, value, text)

    # ------------------------------------------------------------------------------- finish

    def _finish(self) -> None:
        w = self.world
        end = "stopped" if self._end is None else self._end.status
        cost = {v.role: float(w.cost_total[0, v.index]) for v in self.vehicles}
        steps = int(w.steps[0])
        self.result = RunResult(
            end=end, success=bool(w.hit[0]), steps=steps, sim_time_s=round(steps * self.dt_s, 6), cost=cost
        )
        _log.info("run ended: %s after %d steps (%.1f s simulated)", end, self.result.steps, self.result.sim_time_s)
        if self._truth is not None:
            self._truth.summary(
                {
                    "success": self.result.success,
                    "end": end,
                    "steps": self.result.steps,
                    "sim_time_s": round(self.result.sim_time_s, 6),
                    "cost": cost,
                    "cost_limit": self.scenario.cost_limit,
                    "radar_on": bool(w.radar_on[0]),
                    "identified": bool(w.identified[0]),
                    "hit": bool(w.hit[0]),
                    "counters": {
                        v.role: self.counters_of(v, link, self.serial_ports[i] if self.serial_ports else None)
                        for i, (v, link) in enumerate(zip(self.vehicles, self.links, strict=True))
                    },
                    "flight_cpu_s": None
                    if self._first_step_cpu_s is None
                    else round(time.process_time() - self._first_step_cpu_s, 4),
                }
            )
        self._close_mission_files()

    @staticmethod
    def counters_of(v: Vehicle, link: VehicleLink, port: PtySerialPort | None = None) -> dict[str, Any]:
        """Every counter of a vehicle (protocol, framing, signing, link, GPS; its serial line's) as plain data."""
        serial = {} if port is None else {"serial": asdict(port.counters)}
        return {
            "protocol": asdict(v.counters),
            "rx": asdict(link.endpoint.rx),
            "tx": asdict(link.endpoint.tx),
            "link_out": asdict(link.tx.counters),
            "link_in": asdict(link.rx.counters),
            "gps": {"fixes": v.gps.fixes, "dropouts": v.gps.dropouts},
            "peers": len(link.endpoint.peers),
            "monitors": len(link.endpoint.monitors),
            **serial,
        }

    def _close_mission_files(self) -> None:
        """Close the mission's tlogs and truth log (idempotent)."""
        for f in self._tlogs:
            try:
                f.close()
            except OSError as exc:
                _log.error("closing a tlog failed: %s", exc)
        self._tlogs = []
        if self._truth is not None:
            try:
                self._truth.close()
            except OSError as exc:
                _log.error("closing the truth log failed: %s", exc)
            self._truth = None

    def _close_dynamics(self) -> None:
        if self.dynamics is not None:
            self.dynamics.close()
            self.dynamics = None

    def close(self) -> None:
        """Close sockets, logs and the physics backend (idempotent)."""
        if self._closed:
            return
        self._closed = True
        for endpoint in self._endpoints:
            endpoint.close()
        for port in self.serial_ports:
            port.close()
        self._close_mission_files()
        self._close_dynamics()
