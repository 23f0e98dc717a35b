"""The SITL vehicles as a fixed-wing autopilot: setpoint forms, refusals, LOITER / RTL, the datalink
failsafe and what ground stations expect (FTP NAK, missions, health, home). pymavlink clients over
real UDP on 127.0.0.1; every wait is bounded.
"""

from __future__ import annotations

import math
import struct
import time

import pytest

from sitl_helpers import GUIDED, MANUAL, Client, mavlink2, sitl
from sim_vehicles import navigation, setpoints
from sim_vehicles.modes import FlightMode

M = mavlink2
RTL, LOITER = int(FlightMode.RTL), int(FlightMode.LOITER)
VELOCITY_MASK = 1479  # MAVSDK's set_velocity_body: positions, accelerations and yaw ignored


def _positions(msgs: list) -> list[tuple[float, float, int]]:
    """(east, north, time_boot_ms) of every LOCAL_POSITION_NED (x north, y east)."""
    return [(m.y, m.x, m.time_boot_ms) for m in msgs if m.get_type() == "LOCAL_POSITION_NED"]


def _texts(msgs: list, part: str) -> list[str]:
    return [m.text for m in msgs if m.get_type() == "STATUSTEXT" and part in m.text]


def test_setpoint_parsing_forms_and_refusals_fit_a_statustext() -> None:
    mav = M.MAVLink(None)
    body = M.MAV_FRAME_BODY_NED
    vel = setpoints.parse_position_target(mav.set_position_target_local_ned_encode(0, 1, 1, body, 1479, 0, 0, 0, 260.0, 0, 0, 0, 0, 0, 0, 0.1))
    assert vel == setpoints.Demand(setpoints.SetpointForm.VELOCITY_YAW_RATE, pytest.approx(0.1), speed_m_s=260.0)
    acc = setpoints.parse_position_target(mav.set_position_target_local_ned_encode(0, 1, 1, 12, 1087, 0, 0, 0, 0, 0, 0, 2.0, 0, 0, 0, -0.05))
    assert acc == setpoints.Demand(setpoints.SetpointForm.ACCEL_YAW_RATE, pytest.approx(-0.05), accel_m_s2=2.0)
    att = setpoints.parse_attitude_target(mav.set_attitude_target_encode(0, 1, 1, 128, [1, 0, 0, 0], 0, 0, 0.05, 0.75))
    assert att == setpoints.Demand(setpoints.SetpointForm.THRUST_YAW_RATE, pytest.approx(0.05), thrust=0.75)
    # Speed: dead-beat within the bounds; thrust 0.5 holds, 1 is full acceleration.
    assert setpoints.accel_command(vel, 255.0, 10.0, 150.0, 300.0, 0.1) == pytest.approx(10.0)
    assert setpoints.accel_command(vel, 259.5, 10.0, 150.0, 300.0, 0.1) == pytest.approx(5.0)
    fast = setpoints.Demand(setpoints.SetpointForm.VELOCITY_YAW_RATE, 0.0, speed_m_s=1000.0)
    assert setpoints.accel_command(fast, 300.0, 10.0, 150.0, 300.0, 0.1) == 0.0  # clipped to SIM_SPD_MAX
    assert setpoints.accel_command(att, 250.0, 10.0, 150.0, 300.0, 0.1) == pytest.approx(5.0)
    refused = [
        setpoints.parse_position_target(mav.set_position_target_local_ned_encode(0, 1, 1, 1, 1479, 0, 0, 0, 1, 0, 0, 0, 0, 0, 0, 0)),
        setpoints.parse_position_target(mav.set_position_target_local_ned_encode(0, 1, 1, 8, 3576, 0, 0, 0, 1, 0, 0, 0, 0, 0, 0, 0)),
        setpoints.parse_position_target(mav.set_position_target_local_ned_encode(0, 1, 1, 8, 1479, 0, 0, 0, 250, 3.0, 0, 0, 0, 0, 0, 0)),
        setpoints.parse_position_target(mav.set_position_target_local_ned_encode(0, 1, 1, 8, 1479, 0, 0, 0, math.nan, 0, 0, 0, 0, 0, 0, 0)),
        setpoints.parse_attitude_target(mav.set_attitude_target_encode(0, 1, 1, 7, [1, 0, 0, 0], 0, 0, 0, 0.5)),
        setpoints.parse_attitude_target(mav.set_attitude_target_encode(0, 1, 1, 128, [1, 0, 0, 0], 0.2, 0, 0, 0.5)),
        setpoints.parse_attitude_target(mav.set_attitude_target_encode(0, 1, 1, 128, [1, 0, 0, 0], 0, 0, 0, 1.5)),
    ]
    kinds = [r.kind for r in refused if isinstance(r, setpoints.Refusal)]
    assert kinds == ["frame", "mask", "side", "finite", "att_mask", "att_rates", "thrust"]
    assert all(len(r.text) < 50 for r in refused if isinstance(r, setpoints.Refusal))
    assert "1479" in refused[1].text and "1087" in refused[1].text  # what to send instead


def test_orbit_guidance_converges_onto_the_circle() -> None:
    """The vector field brings a 250 m/s vehicle with a 5 deg/s limit from 20 km out onto its circle."""
    w_max, v, dt = math.radians(5.0), 250.0, 0.1
    radius = navigation.orbit_radius_m(60.0, v, w_max)
    assert radius == pytest.approx(v / (0.8 * w_max))
    x, y, phi = 20_000.0, 5_000.0, 0.3
    dist = []
    for _ in range(int(400 / dt)):
        theta = navigation.orbit_turn_rate(x, y, phi, v, (0.0, 0.0), radius, False, w_max) * dt
        x += v * dt * math.cos(phi + theta / 2)
        y += v * dt * math.sin(phi + theta / 2)
        phi = navigation.wrap_pi(phi + theta)
        dist.append(math.hypot(x, y))
    assert max(abs(d - radius) for d in dist[-1000:]) < 0.01 * radius


@pytest.mark.timeout(30)
def test_velocity_body_and_attitude_target_fly_speed_and_turn_rate() -> None:
    with sitl(speedup=20.0) as s, Client(s.ports[0]) as c:
        v = s.vehicle(0)
        c.connect()
        c.arm()
        assert c.set_mode(GUIDED).result == M.MAV_RESULT_ACCEPTED
        deadline = time.monotonic() + 0.6  # 12 s simulated: 250 -> 280 m/s takes 3 s at 10 m/s^2
        while time.monotonic() < deadline:
            c.mav.set_position_target_local_ned_send(0, 1, 1, M.MAV_FRAME_BODY_NED, VELOCITY_MASK, 0, 0, 0, 280.0, 0, 0, 0, 0, 0, 0, math.radians(3.0))
            c.collect(0.02)
        assert v.truth.speed_m_s == pytest.approx(280.0, abs=1e-6)
        assert -v.truth.turn_rate_rad_s == pytest.approx(math.radians(3.0), rel=1e-6)  # clockwise in NED
        # SET_ATTITUDE_TARGET: body yaw rate and thrust (0.5 holds the speed).
        deadline = time.monotonic() + 0.3
        while time.monotonic() < deadline:
            c.mav.set_attitude_target_send(0, 1, 1, 128, [1, 0, 0, 0], 0, 0, -0.04, 0.5)
            c.collect(0.02)
        assert v.truth.turn_rate_rad_s == pytest.approx(0.04, rel=1e-6) and v.truth.speed_m_s == pytest.approx(280.0, abs=1e-6)
        assert v.counters.setpoints_rejected == 0 and not v.failsafe
        s.stop()


@pytest.mark.timeout(30)
def test_refusals_say_what_to_send_each_second_not_once() -> None:
    with sitl(speedup=5.0) as s, Client(s.ports[1]) as c:
        c.connect()
        msgs = []
        deadline = time.monotonic() + 1.5  # a 20 Hz stream of a mask nobody flies
        while time.monotonic() < deadline:
            c.mav.set_position_target_local_ned_send(0, 2, 1, M.MAV_FRAME_BODY_NED, 3576, 0, 0, 0, 100, 0, 0, 0, 0, 0, 0, 0)
            msgs += c.collect(0.05)
        texts = _texts(msgs, "SP mask 3576")
        assert len(texts) == 2, texts  # at t = 0 and t = 1 s: rate-limited, and repeated
        assert all(len(t) < 50 and "1479" in t for t in texts)
        assert s.vehicle(1).counters.refusal_texts_suppressed >= 15
        s.stop()


@pytest.mark.timeout(40)
def test_loiter_circles_where_it_is_and_rtl_flies_home_then_circles() -> None:
    with sitl(speedup=50.0) as s, Client(s.ports[0]) as loiter, Client(s.ports[2]) as rtl:
        for c in (loiter, rtl):
            c.connect()
            c.arm()
        home = (s.vehicle(2).setup.home_east_m, s.vehicle(2).setup.home_north_m)
        # LOITER at once: the circle passes through where the decoy is.
        assert loiter.set_mode(LOITER).result == M.MAV_RESULT_ACCEPTED
        orbit = s.vehicle(0).orbit
        assert orbit is not None and orbit.center is not None
        # The strike UAV flies out straight (MANUAL) for > 60 s, then RTL.
        out = rtl.wait(lambda m: m.get_type() == "LOCAL_POSITION_NED" and math.hypot(m.y - home[0], m.x - home[1]) > 15_000.0, 5.0, 0.2)
        assert out is not None
        assert rtl.set_mode(RTL).result == M.MAV_RESULT_ACCEPTED
        radius = s.vehicle(2).orbit.radius_m
        track: list[tuple[float, float, float, float]] = []  # (t, distance from home, heading) of the strike UAV
        circle: list[float] = []  # the decoy's distance from its loiter centre
        deadline = time.monotonic() + 4.0  # 200 s simulated
        while time.monotonic() < deadline:
            rtl.collect(0.02)
            loiter.collect(0.005)
            t2, t0 = s.vehicle(2).truth, s.vehicle(0).truth
            track.append((s.runner.clock.sim_s, math.hypot(t2.east_m - home[0], t2.north_m - home[1]), t2.phi_rad, 0.0))
            circle.append(math.hypot(t0.east_m - orbit.center[0], t0.north_m - orbit.center[1]))
        s.stop()
    # LOITER: on its circle all the time.
    assert max(abs(d - orbit.radius_m) for d in circle) < 0.02 * orbit.radius_m
    # RTL: from > 15 km out back over home, then on the circle round it for the last 60 s.
    assert track[0][1] > 15_000.0
    last = [(d, phi) for t, d, phi, _ in track if t >= track[-1][0] - 60.0]
    assert track[-1][0] - track[0][0] > 150.0 and max(abs(d - radius) for d, _ in last) < 0.02 * radius
    turned = sum(abs(navigation.wrap_pi(b[1] - a[1])) for a, b in zip(last, last[1:]))
    assert turned > math.pi  # circling, not passing through


@pytest.mark.timeout(30)
def test_datalink_failsafe_switches_to_rtl_after_fs_long_timeout() -> None:
    with sitl(speedup=10.0) as s, Client(s.ports[0]) as on, Client(s.ports[1]) as off:
        for c, sysid in ((on, 1), (off, 2)):
            c.connect()
            c.arm()
        on.mav.param_set_send(1, 1, b"FS_GCS_ENABL", 1, M.MAV_PARAM_TYPE_INT32)
        on.mav.param_set_send(1, 1, b"FS_LONG_TIMEOUT", 1.0, M.MAV_PARAM_TYPE_REAL32)
        assert on.wait_type("PARAM_VALUE", 1.0, param_id="FS_LONG_TIMEOUT") is not None
        silent_from = time.monotonic()  # neither client sends anything now
        text = on.wait(lambda m: m.get_type() == "STATUSTEXT" and m.text.startswith("Failsafe: no link"), 3.0)
        lost_after = time.monotonic() - silent_from
        assert text is not None and "RTL" in text.text and 1.0 <= lost_after < 1.6
        assert on.wait(lambda m: m.get_type() == "HEARTBEAT" and m.custom_mode == RTL, 1.0) is not None
        assert off.wait(lambda m: m.get_type() == "HEARTBEAT", 1.0).custom_mode == MANUAL  # FS_GCS_ENABL 0 (default)
        on.heartbeat()
        assert on.wait(lambda m: m.get_type() == "STATUSTEXT" and "restored" in m.text, 1.0) is not None
        assert s.vehicle(0).mode is FlightMode.RTL and s.vehicle(0).counters.datalink_failsafes == 1
        s.stop()


@pytest.mark.timeout(30)
def test_ground_station_chores_ftp_nak_missions_health_home_modes() -> None:
    with sitl(speedup=10.0) as s, Client(s.ports[2]) as c:
        c.connect()
        # MAVLink FTP: OpenFileRO (4) is NAKed at once, so clients fall back to the parameter protocol.
        request = struct.pack("<HBBBBBBI", 7, 0, 4, 19, 0, 0, 0, 0) + b"@PARAM/param.pck?wd"
        c.mav.file_transfer_protocol_send(0, 3, 1, list(request.ljust(251, b"\0")))
        ftp = c.wait_type("FILE_TRANSFER_PROTOCOL", 1.0)
        seq, _, opcode, size, req_opcode = struct.unpack_from("<HBBBB", bytes(ftp.payload))
        assert (seq, opcode, size, req_opcode, ftp.payload[12]) == (8, 129, 1, 4, 7)
        # Missions: the capability, an empty download, an upload refused with a reason.
        assert c.command(M.MAV_CMD_REQUEST_MESSAGE, M.MAVLINK_MSG_ID_AUTOPILOT_VERSION).result == M.MAV_RESULT_ACCEPTED
        version = c.wait_type("AUTOPILOT_VERSION", 1.0)
        assert version is not None and version.capabilities & M.MAV_PROTOCOL_CAPABILITY_MISSION_INT
        c.mav.mission_request_list_send(3, 1, M.MAV_MISSION_TYPE_FENCE)
        assert c.wait_type("MISSION_COUNT", 1.0, count=0, mission_type=M.MAV_MISSION_TYPE_FENCE) is not None
        c.mav.mission_count_send(3, 1, 2, M.MAV_MISSION_TYPE_MISSION)
        assert c.wait_type("MISSION_ACK", 1.0, type=M.MAV_MISSION_UNSUPPORTED) is not None
        assert any("upload refused" in t for t in _texts(c.log, "Mission"))
        # Health, in-air state and home, streamed.
        msgs = c.collect(0.5)  # 5 s simulated
        status = next(m for m in msgs if m.get_type() == "SYS_STATUS")
        inertial = M.MAV_SYS_STATUS_SENSOR_3D_GYRO | M.MAV_SYS_STATUS_SENSOR_3D_ACCEL | M.MAV_SYS_STATUS_SENSOR_3D_MAG
        for field in ("onboard_control_sensors_present", "onboard_control_sensors_enabled", "onboard_control_sensors_health"):
            assert getattr(status, field) & inertial == inertial and getattr(status, field) & M.MAV_SYS_STATUS_SENSOR_GPS
        assert [m.landed_state for m in msgs if m.get_type() == "EXTENDED_SYS_STATE"][:1] == [M.MAV_LANDED_STATE_IN_AIR]
        assert sum(1 for m in msgs if m.get_type() == "HOME_POSITION") >= 3
        # Modes: RTL by command, AUTO refused with a reason.
        assert c.command(M.MAV_CMD_NAV_RETURN_TO_LAUNCH).result == M.MAV_RESULT_ACCEPTED
        assert s.vehicle(2).mode is FlightMode.RTL
        assert c.set_mode(10).result == M.MAV_RESULT_DENIED
        assert _texts(c.log, "AUTO: no mission")  # sent before the COMMAND_ACK
        s.stop()
