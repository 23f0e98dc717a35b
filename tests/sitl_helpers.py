"""Test helpers for the SITL vehicles: an in-process SITL in a thread, and a pymavlink client.

Everything runs over real UDP sockets on 127.0.0.1 with OS-assigned ports, and every wait is bounded
on ``time.monotonic()``.
"""

from __future__ import annotations

import dataclasses
import os
import select
import socket
import threading
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path
from typing import Any

# The client speaks MAVLink 2 (signing needs it); pymavlink picks the wire version from this variable.
os.environ["MAVLINK20"] = "1"
from pymavlink import mavutil  # noqa: E402
from pymavlink.dialects.v20 import ardupilotmega as mavlink2  # noqa: E402

mavutil.set_dialect("ardupilotmega")

from sim_vehicles.world_runner import RunResult, WorldRunner  # noqa: E402
from tssac_core.sim.scenario import Layout, LinkModel, Radar, Scenario, Start, dump, load  # noqa: E402
from tssac_core.sim.sitl_config import ClockMode, LockstepStart, SitlConfig  # noqa: E402

REPO = Path(__file__).resolve().parents[1]
STRIKE = REPO / "scenarios" / "strike.yaml"
GUIDED = 15
MANUAL = 0
SETPOINT_MASK = 1087
EXACT_LINK = LinkModel(gps_position_sigma_m=0.0, gps_velocity_sigma_m_s=0.0)


def scenario(link: LinkModel = EXACT_LINK, **changes: Any) -> Scenario:
    """The strike scenario with another link model (default: noise-free GPS, ideal link)."""
    return dataclasses.replace(load(STRIKE), link=link, **changes)


@dataclass
class RunningSitl:
    runner: WorldRunner
    thread: threading.Thread
    error: list[BaseException]

    @property
    def ports(self) -> list[int]:
        return [ep.port for ep in self.runner.endpoints]

    def vehicle(self, index: int) -> Any:
        return self.runner.vehicles[index]

    def link(self, index: int) -> Any:
        """The vehicle's MAVLink side (:class:`sim_vehicles.protocol.vehicle_link.VehicleLink`)."""
        return self.runner.links[index]

    def endpoint(self, index: int) -> Any:
        """The vehicle's UDP endpoint (:class:`sim_vehicles.link.mavlink_io.MavEndpoint`)."""
        return self.runner.links[index].endpoint

    def stop(self, timeout_s: float = 5.0) -> RunResult | None:
        self.runner.request_stop()
        self.thread.join(timeout_s)
        assert not self.thread.is_alive(), "SITL thread did not stop"
        if self.error:
            raise self.error[0]
        return self.runner.result


@contextmanager
def sitl(scen: Scenario | None = None, **config: Any) -> Iterator[RunningSitl]:
    """Run a WorldRunner in a thread on OS-assigned ports; stop and join it on exit."""
    cfg = SitlConfig(scenario=scen if scen is not None else scenario(), base_port=0, host="127.0.0.1", **config)
    runner = WorldRunner(cfg)
    errors: list[BaseException] = []

    def target() -> None:
        try:
            runner.run()
        except BaseException as exc:  # surfaced by RunningSitl.stop
            errors.append(exc)

    thread = threading.Thread(target=target, name="sitl", daemon=True)
    thread.start()
    running = RunningSitl(runner, thread, errors)
    try:
        yield running
    finally:
        if thread.is_alive() or not errors:
            running.runner.request_stop()
            thread.join(5.0)


def lockstep(**config: Any) -> dict[str, Any]:
    return {"clock": ClockMode.LOCKSTEP, "lockstep_start": LockstepStart.ANY, **config}


class Client:
    """A ground-station / companion-style pymavlink client (``udpout:127.0.0.1:PORT``)."""

    def __init__(
        self, port: int, key: bytes | None = None, source_system: int = 255, source_component: int = 190
    ) -> None:
        self.conn = mavutil.mavlink_connection(
            f"udpout:127.0.0.1:{port}", source_system=source_system, source_component=source_component
        )
        # Telemetry at 20x real time is ~1000 datagrams/s, and a lockstep linger sends a minute's in a burst: leave room
        # for a test thread that is slow to read on a loaded machine (the kernel caps it at net.core.rmem_max).
        self.conn.port.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 1 << 22)
        if key is not None:
            self.conn.setup_signing(key, sign_outgoing=True)
        self.mav: mavlink2.MAVLink = self.conn.mav
        self.latest_ms = 0
        self.log: list[mavlink2.MAVLink_message] = []

    def close(self) -> None:
        self.conn.close()

    def __enter__(self) -> Client:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def heartbeat(self) -> None:
        self.mav.heartbeat_send(mavlink2.MAV_TYPE_GCS, mavlink2.MAV_AUTOPILOT_INVALID, 0, 0, 0)

    def poll(self, timeout_s: float) -> mavlink2.MAVLink_message | None:
        """The next message (waiting up to ``timeout_s``), None if none came."""
        deadline = time.monotonic() + timeout_s
        while True:
            msg = self.conn.recv_msg()
            if msg is not None:
                if msg.get_type() == "BAD_DATA":
                    continue
                ms = getattr(msg, "time_boot_ms", None)
                if ms is not None and msg.get_type() != "SET_POSITION_TARGET_LOCAL_NED":
                    self.latest_ms = max(self.latest_ms, ms)
                self.log.append(msg)
                return msg
            remaining = deadline - time.monotonic()
            if remaining <= 0:
                return None
            select.select([self.conn.fd], [], [], min(remaining, 0.05))

    def wait(
        self,
        predicate: Callable[[mavlink2.MAVLink_message], bool],
        timeout_s: float,
        heartbeat_every_s: float | None = None,
    ) -> mavlink2.MAVLink_message | None:
        """The first message satisfying ``predicate`` within ``timeout_s``."""
        deadline = time.monotonic() + timeout_s
        next_hb = time.monotonic()
        while (remaining := deadline - time.monotonic()) > 0:
            if heartbeat_every_s is not None and time.monotonic() >= next_hb:
                self.heartbeat()
                next_hb = time.monotonic() + heartbeat_every_s
            msg = self.poll(min(remaining, 0.05))
            if msg is not None and predicate(msg):
                return msg
        return None

    def wait_type(self, mtype: str, timeout_s: float, **fields: Any) -> mavlink2.MAVLink_message | None:
        return self.wait(
            lambda m: m.get_type() == mtype and all(getattr(m, k) == v for k, v in fields.items()), timeout_s
        )

    def connect(self, timeout_s: float = 5.0) -> mavlink2.MAVLink_message:
        """Send heartbeats until the vehicle's heartbeat arrives (the vehicle learns us from ours)."""
        hb = self.wait(
            lambda m: m.get_type() == "HEARTBEAT" and m.get_srcComponent() == 1, timeout_s, heartbeat_every_s=0.2
        )
        assert hb is not None, "no heartbeat from the vehicle"
        return hb

    def command(
        self, command: int, *params: float, target: int = 0, timeout_s: float = 1.0, retries: int = 3
    ) -> mavlink2.MAVLink_message | None:
        """COMMAND_LONG, retried until its COMMAND_ACK arrives; the ACK or None."""
        p = list(params) + [0.0] * (7 - len(params))
        for attempt in range(retries):
            self.mav.command_long_send(target, 0, command, attempt, *p)
            ack = self.wait(lambda m: m.get_type() == "COMMAND_ACK" and m.command == command, timeout_s)
            if ack is not None:
                return ack
        return None

    def arm(self, target: int = 0) -> None:
        ack = self.command(mavlink2.MAV_CMD_COMPONENT_ARM_DISARM, 1, target=target)
        assert ack is not None and ack.result == mavlink2.MAV_RESULT_ACCEPTED, ack

    def set_mode(self, mode: int, target: int = 0) -> mavlink2.MAVLink_message | None:
        return self.command(
            mavlink2.MAV_CMD_DO_SET_MODE, mavlink2.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED, mode, target=target
        )

    def setpoint(
        self,
        yaw_rate_rad_s: float,
        accel_m_s2: float,
        stamp_ms: int | None = None,
        target: int = 0,
        mask: int = SETPOINT_MASK,
        frame: int = mavlink2.MAV_FRAME_BODY_FRD,
    ) -> None:
        """Heading-rate (NED, clockwise +) / forward-acceleration setpoint, stamped with the latest vehicle time by
        default."""
        stamp = self.latest_ms if stamp_ms is None else stamp_ms
        self.mav.set_position_target_local_ned_send(
            stamp, target, 0, frame, mask, 0, 0, 0, 0, 0, 0, accel_m_s2, 0, 0, 0, yaw_rate_rad_s
        )

    def send_together(self, *msgs: mavlink2.MAVLink_message) -> None:
        """Several messages in one datagram, each packed (and signed) with its own sequence number."""
        frames = []
        for msg in msgs:
            frames.append(msg.pack(self.mav))
            self.mav.seq = (self.mav.seq + 1) % 256
        self.conn.write(b"".join(frames))

    def collect(self, duration_s: float) -> list[mavlink2.MAVLink_message]:
        """Everything received in the next ``duration_s`` seconds."""
        out = []
        deadline = time.monotonic() + duration_s
        while (remaining := deadline - time.monotonic()) > 0:
            msg = self.poll(min(remaining, 0.05))
            if msg is not None:
                out.append(msg)
        return out

    def drain(self, quiet_s: float = 0.3, max_s: float = 10.0) -> None:
        """Read until nothing has come for ``quiet_s`` (a backlog in the socket buffer included), ``max_s`` at most."""
        deadline = time.monotonic() + max_s
        while time.monotonic() < deadline and self.collect(min(quiet_s, deadline - time.monotonic())):
            pass


def wait_until(predicate: Callable[[], bool], timeout_s: float, interval_s: float = 0.01) -> bool:
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        if predicate():
            return True
        time.sleep(interval_s)
    return predicate()


def cmdline(pid: int) -> bytes:
    """A process's command line from /proc (empty once it is gone)."""
    try:
        return Path(f"/proc/{pid}/cmdline").read_bytes()
    except OSError:
        return b""


def parent_pid(pid: int) -> int:
    """A running process's parent's pid (/proc)."""
    return int(Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[1])


def running(pid: int) -> bool:
    """The process is alive and not a zombie (/proc)."""
    try:
        return Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0] != "Z"
    except OSError:
        return False


def kept_out(results: dict[str, Any]) -> tuple[dict[str, Any], dict[str, Any]]:
    """A shielded ``fly`` JSON's first mission and its monitor's figures, after checking the guarantee: no cost for any
    UAV, none out of the area, and the monitor's counts saying so."""
    mission = results["missions"][0]
    assert all(c == 0 for c in mission["cost"].values()), mission["cost"]
    assert not any(mission["left_area"].values()), mission["left_area"]
    shield = results["shield"]
    assert shield["uav_missions_with_cost"] == 0 and shield["uavs_left_area"] == 0, shield
    return mission, shield


def quick_strike_scenario(tmp: Path, strike_km: float = 8.0) -> Path:
    """The strike scenario with the UAVs starting in their zones (the strike UAV ``strike_km`` east of the SAM): short
    missions for fly's tests, written to ``tmp``."""
    base = load(Path(__file__).resolve().parents[1] / "scenarios" / "strike.yaml")
    layout = Layout(
        sam_km=(65.0, 65.0),
        target_km=(66.0, 64.0),
        radars=(Radar((20.0, 20.0), 12.0), Radar((15.0, 85.0), 12.0), Radar((88.0, 15.0), 10.0)),
        starts={
            "decoy": Start((46.5, 65.0), 90.0),
            "detect": Start((65.0, 53.5), 0.0),
            "strike": Start((65.0 + strike_km, 65.0), 180.0),
        },
    )
    path = tmp / f"quick-{strike_km:g}.yaml"
    dump(dataclasses.replace(base, name="quick", layout=layout), path)
    return path
