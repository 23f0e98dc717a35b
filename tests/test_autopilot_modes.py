"""The SITL vehicles as a fixed-wing autopilot: setpoint forms, refusals, LOITER / RTL, the datalink
failsafe and what ground stations expect (FTP NAK, missions, health, home). pymavlink clients over
real UDP on 127.0.0.1; every wait is bounded.
"""

from __future__ import annotations

import math
import struct
import time

import pytest
from sitl_helpers import GUIDED, MANUAL, Client, mavlink2, scenario, sitl, wait_until

from sim_vehicles.autopilot import navigation, setpoints
from sim_vehicles.autopilot.modes import FlightMode
from tssac_core.sim.sitl_config import LockstepStart

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
    vel = setpoints.parse_position_target(
        mav.set_position_target_local_ned_encode(0, 1, 1, body, 1479, 0, 0, 0, 260.0, 0, 0, 0, 0, 0, 0, 0.1)
    )
    assert vel == setpoints.Demand(setpoints.SetpointForm.VELOCITY_YAW_RATE, pytest.approx(0.1), speed_m_s=260.0)
    acc = setpoints.parse_position_target(
        mav.set_position_target_local_ned_encode(0, 1, 1, 12, 1087, 0, 0, 0, 0, 0, 0, 2.0, 0, 0, 0, -0.05)
    )
    assert acc == setpoints.Demand(setpoints.SetpointForm.ACCEL_YAW_RATE, pytest.approx(-0.05), accel_m_s2=2.0)
    att = setpoints.parse_attitude_target(mav.set_attitude_target_encode(0, 1, 1, 128, [1, 0, 0, 0], 0, 0, 0.05, 0.75))
    assert att == setpoints.Demand(setpoints.SetpointForm.THRUST_YAW_RATE, pytest.approx(0.05), thrust=0.75)
    # Speed: dead-beat within the bounds; thrust 0.5 holds, 1 is full acceleration.
    assert setpoints.accel_command(vel, 255.0, 10.0, 150.0, 300.0, 0.1) == pytest.approx(10.0)
    assert setpoints.accel_command(vel, 259.5, 10.0, 150.0, 300.0, 0.1) == pytest.approx(5.0)
    fast = setpoints.Demand(setpoints.SetpointForm.VELOCITY_YAW_RATE, 0.0, speed_m_s=1000.0)
    assert setpoints.accel_command(fast, 300.0, 10.0, 150.0, 300.0, 0.1) == 0.0  # clipped to SIM_SPD_MAX
    assert setpoints.accel_command(att, 250.0, 10.0, 150.0, 300.0, 0.1) == pytest.approx(5.0)
    ned = setpoints.parse_position_target(
        mav.set_position_target_local_ned_encode(0, 1, 1, 1, 2503, 0, 0, 0, 0, 260.0, 0, 0, 0, 0, 1.0, 0)
    )
    assert ned.form is setpoints.SetpointForm.VELOCITY_NED and ned.speed_m_s == pytest.approx(260.0)
    assert ned.course_rad == pytest.approx(0.0)  # due east (the world's heading convention); yaw 1.0 not used
    refused = [
        setpoints.parse_position_target(
            mav.set_position_target_local_ned_encode(0, 1, 1, 6, 1479, 0, 0, 0, 1, 0, 0, 0, 0, 0, 0, 0)
        ),
        setpoints.parse_position_target(
            mav.set_position_target_local_ned_encode(0, 1, 1, 1, 1479, 0, 0, 0, 1, 0, 0, 0, 0, 0, 0, 0)
        ),
        setpoints.parse_position_target(
            mav.set_position_target_local_ned_encode(0, 1, 1, 8, 3576, 0, 0, 0, 1, 0, 0, 0, 0, 0, 0, 0)
        ),
        setpoints.parse_position_target(
            mav.set_position_target_local_ned_encode(0, 1, 1, 8, 1479, 0, 0, 0, 250, 3.0, 0, 0, 0, 0, 0, 0)
        ),
        setpoints.parse_position_target(
            mav.set_position_target_local_ned_encode(0, 1, 1, 8, 1479, 0, 0, 0, math.nan, 0, 0, 0, 0, 0, 0, 0)
        ),
        setpoints.parse_attitude_target(mav.set_attitude_target_encode(0, 1, 1, 7, [1, 0, 0, 0], 0, 0, 0, 0.5)),
        setpoints.parse_attitude_target(mav.set_attitude_target_encode(0, 1, 1, 128, [1, 0, 0, 0], 0.2, 0, 0, 0.5)),
        setpoints.parse_attitude_target(mav.set_attitude_target_encode(0, 1, 1, 128, [1, 0, 0, 0], 0, 0, 0, 1.5)),
    ]
    kinds = [r.kind for r in refused if isinstance(r, setpoints.Refusal)]
    assert kinds == ["frame", "ned_mask", "mask", "side", "finite", "att_mask", "att_rates", "thrust"]
    assert all(len(r.text) < 50 for r in refused if isinstance(r, setpoints.Refusal))
    assert "1479" in refused[2].text and "1087" in refused[2].text  # what to send instead


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


def _fly_until(c: Client, send, done, timeout_s: float = 15.0) -> bool:
    """Send a setpoint every 20 ms of wall time until ``done()`` (bounded): robust to a slow machine."""
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        send()
        c.collect(0.02)
        if done():
            return True
    return False


def _guided(c: Client, sysid: int) -> None:
    """Armed in GUIDED, with a setpoint timeout long enough for a loaded machine's scheduling gaps."""
    c.mav.param_set_send(sysid, 1, b"GUID_TIMEOUT", 10.0, M.MAV_PARAM_TYPE_REAL32)
    assert c.wait_type("PARAM_VALUE", 2.0, param_id="GUID_TIMEOUT") is not None
    c.arm()
    assert c.set_mode(GUIDED).result == M.MAV_RESULT_ACCEPTED


@pytest.mark.timeout(60)
def test_velocity_body_attitude_target_and_velocity_ned_fly_speed_and_turn() -> None:
    with sitl(speedup=10.0) as s, Client(s.ports[0]) as c:
        v = s.vehicle(0)
        c.connect()
        _guided(c, 1)
        # Velocity body (MAVSDK's form): 250 -> 280 m/s at 10 m/s^2 (3 s), yaw rate 3 deg/s clockwise.
        rate = math.radians(3.0)
        assert _fly_until(
            c,
            lambda: c.mav.set_position_target_local_ned_send(
                0, 1, 1, M.MAV_FRAME_BODY_NED, VELOCITY_MASK, 0, 0, 0, 280.0, 0, 0, 0, 0, 0, 0, rate
            ),
            lambda: (
                v.truth.speed_m_s == pytest.approx(280.0, abs=1e-6)
                and -v.truth.turn_rate_rad_s == pytest.approx(rate, rel=1e-6)
            ),
        )
        # SET_ATTITUDE_TARGET: body yaw rate and thrust (0.5 holds the speed).
        assert _fly_until(
            c,
            lambda: c.mav.set_attitude_target_send(0, 1, 1, 128, [1, 0, 0, 0], 0, 0, -0.04, 0.5),
            lambda: v.truth.turn_rate_rad_s == pytest.approx(0.04, rel=1e-6),
        )
        assert v.truth.speed_m_s == pytest.approx(280.0, abs=1e-6)
        # Velocity NED: a course 0.5 rad left of the current heading at 260 m/s, reached and held.
        course = v.truth.phi_rad + 0.5
        vn, ve = 260.0 * math.sin(course), 260.0 * math.cos(course)
        assert _fly_until(
            c,
            lambda: c.mav.set_position_target_local_ned_send(
                0, 1, 1, M.MAV_FRAME_LOCAL_NED, 2503, 0, 0, 0, vn, ve, 0, 0, 0, 0, 0, 0
            ),
            lambda: (
                abs(navigation.wrap_pi(v.truth.phi_rad - course)) < 1e-3
                and v.truth.speed_m_s == pytest.approx(260.0, abs=1e-3)
            ),
            timeout_s=30.0,
        )
        assert v.counters.setpoints_rejected == 0 and not v.failsafe
        s.stop()


@pytest.mark.timeout(30)
def test_refusals_say_what_to_send_each_second_not_once() -> None:
    with sitl(speedup=5.0) as s, Client(s.ports[1]) as c:
        c.connect()
        msgs = []
        deadline = time.monotonic() + 3.0  # a 20 Hz stream of a mask nobody flies
        while time.monotonic() < deadline:
            c.mav.set_position_target_local_ned_send(
                0, 2, 1, M.MAV_FRAME_BODY_NED, 3576, 0, 0, 0, 100, 0, 0, 0, 0, 0, 0, 0
            )
            msgs += c.collect(0.05)
        texts = _texts(msgs, "SP mask 3576")
        assert 2 <= len(texts) <= 4, texts  # about one a second of ~60 refused: repeated, and rate-limited
        assert all(len(t) < 50 and "1479" in t for t in texts)
        assert s.vehicle(1).counters.refusal_texts_suppressed >= 20
        s.stop()


@pytest.mark.timeout(240)
def test_loiter_circles_where_it_is_and_rtl_flies_home_then_circles() -> None:
    # The world holds at t = 0 until the decoy is armed in GUIDED, so nobody flies off while the clients
    # connect (at 50x a slow start would be minutes of flight); every UAV then circles: no geofence end.
    config = {"speedup": 50.0, "hold_start": True, "lockstep_start": LockstepStart.ANY}
    with (
        sitl(scenario(episode_steps=8000), **config) as s,
        Client(s.ports[0]) as loiter,
        Client(s.ports[1]) as circle_c,
        Client(s.ports[2]) as rtl,
    ):
        for c in (loiter, circle_c, rtl):
            c.connect()
            c.arm()
        assert circle_c.set_mode(int(FlightMode.CIRCLE)).result == M.MAV_RESULT_ACCEPTED
        home = (s.vehicle(2).setup.home_east_m, s.vehicle(2).setup.home_north_m)
        assert loiter.set_mode(GUIDED).result == M.MAV_RESULT_ACCEPTED  # the world starts
        # LOITER at once: the circle passes through where the decoy is.
        assert loiter.set_mode(LOITER).result == M.MAV_RESULT_ACCEPTED
        orbit = s.vehicle(0).orbit
        assert orbit is not None and orbit.center is not None
        # The strike UAV flies out straight (MANUAL) for about 50 s, then RTL.
        strike, clock = s.vehicle(2), s.runner.clock

        def from_home() -> float:
            return math.hypot(strike.truth.east_m - home[0], strike.truth.north_m - home[1])

        assert wait_until(lambda: from_home() > 12_000.0, 60.0), (from_home(), clock.sim_s)
        assert rtl.set_mode(RTL).result == M.MAV_RESULT_ACCEPTED
        radius, rtl_from_s, out_m = strike.orbit.radius_m, clock.sim_s, from_home()
        # Back in (out_m - radius) / v, settled within about two minutes more (the turn-limited approach).
        until_s = rtl_from_s + (out_m - radius) / strike.truth.speed_m_s + 180.0
        track: list[tuple[float, float, float]] = []  # (t, distance from home, heading) of the strike UAV
        circle: list[float] = []  # the decoy's distance from its loiter centre
        turns: list[float] = []  # the detect UAV's turn rate in CIRCLE
        deadline = time.monotonic() + 150.0  # ~4 s of wall time on an idle machine; bounded for a starved one
        while time.monotonic() < deadline and clock.sim_s < until_s:
            time.sleep(0.02)  # sample the true states; the clients need not read their telemetry
            t0, t1 = s.vehicle(0).truth, s.vehicle(1).truth
            turns.append(t1.turn_rate_rad_s)
            track.append((clock.sim_s, from_home(), strike.truth.phi_rad))
            circle.append(math.hypot(t0.east_m - orbit.center[0], t0.north_m - orbit.center[1]))
        s.stop()
    print(f"RTL from {out_m / 1000:.1f} km: {track[-1][0] - rtl_from_s:.0f} s simulated")
    assert clock.sim_s >= until_s, "the world did not fly long enough"
    # CIRCLE: a constant clockwise turn at v / R.
    assert turns and all(w == pytest.approx(-s.vehicle(1).truth.speed_m_s / s.vehicle(1).orbit.radius_m) for w in turns)
    # LOITER: on its circle all the time.
    assert max(abs(d - orbit.radius_m) for d in circle) < 0.02 * orbit.radius_m
    # RTL: from > 12 km out back over home, then on the circle round it for the last 60 s.
    assert out_m > 12_000.0
    last = [(d, phi) for t, d, phi in track if t >= until_s - 60.0]
    assert max(abs(d - radius) for d, _ in last) < 0.02 * radius
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
        assert text is not None and "RTL" in text.text and 0.9 <= lost_after < 3.0
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
        msgs, start_ms = [], c.latest_ms
        deadline = time.monotonic() + 30.0
        while c.latest_ms < start_ms + 3500 and time.monotonic() < deadline:  # 3.5 s simulated
            msgs += c.collect(0.05)
        status = next(m for m in msgs if m.get_type() == "SYS_STATUS")
        inertial = M.MAV_SYS_STATUS_SENSOR_3D_GYRO | M.MAV_SYS_STATUS_SENSOR_3D_ACCEL | M.MAV_SYS_STATUS_SENSOR_3D_MAG
        for field in (
            "onboard_control_sensors_present",
            "onboard_control_sensors_enabled",
            "onboard_control_sensors_health",
        ):
            assert (
                getattr(status, field) & inertial == inertial and getattr(status, field) & M.MAV_SYS_STATUS_SENSOR_GPS
            )
        assert [m.landed_state for m in msgs if m.get_type() == "EXTENDED_SYS_STATE"][:1] == [M.MAV_LANDED_STATE_IN_AIR]
        assert sum(1 for m in msgs if m.get_type() == "HOME_POSITION") >= 3
        # Modes: RTL by command, AUTO refused with a reason.
        assert c.command(M.MAV_CMD_NAV_RETURN_TO_LAUNCH).result == M.MAV_RESULT_ACCEPTED
        assert s.vehicle(2).mode is FlightMode.RTL
        assert c.set_mode(10).result == M.MAV_RESULT_DENIED
        assert _texts(c.log, "AUTO: no mission")  # sent before the COMMAND_ACK
        s.stop()
