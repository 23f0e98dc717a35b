"""Real ground stations against the SITL vehicles over 127.0.0.1: MAVProxy 1.8 (its console driven through
a pipe) and MAVSDK 4 (the native binding, no server), as a drone developer would use them. Every wait is
bounded; each test stops its clients and the SITL by itself.
"""

from __future__ import annotations

import importlib.util
import math
import os
import subprocess
import sys
import threading
import time
from pathlib import Path

import pytest
from ground_station_helpers import MAVPROXY
from ground_station_helpers import MavProxyConsole as _Console
from ground_station_helpers import free_udp_port as _free_udp_port
from sitl_helpers import REPO, STRIKE, sitl

from sim_vehicles.autopilot.modes import FlightMode
from tssac_core.sim.scenario import DynamicsModel

mavsdk = pytest.importorskip("mavsdk", minversion="4.0")
from mavsdk import ComponentType, Configuration, Mavsdk  # noqa: E402
from mavsdk.plugins.action import Action, ActionError  # noqa: E402
from mavsdk.plugins.mission_raw import MissionRaw, MissionRawResult  # noqa: E402
from mavsdk.plugins.offboard import Offboard, VelocityBodyYawspeed  # noqa: E402
from mavsdk.plugins.param import Param, ParamError, ParamResult  # noqa: E402
from mavsdk.plugins.telemetry import FlightMode as SdkFlightMode  # noqa: E402
from mavsdk.plugins.telemetry import Telemetry  # noqa: E402


def _wait(predicate, timeout_s: float, interval_s: float = 0.02) -> bool:
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        if predicate():
            return True
        time.sleep(interval_s)
    return bool(predicate())


@pytest.mark.skipif(not MAVPROXY.exists(), reason="MAVProxy is a dev dependency (pip install -e .[dev])")
@pytest.mark.timeout(180)
@pytest.mark.parametrize("dynamics", [DynamicsModel.KINEMATIC, DynamicsModel.JSBSIM])
def test_mavproxy_lists_parameters_at_once_arms_and_switches_to_loiter(tmp_path: Path, dynamics: DynamicsModel) -> None:
    with sitl(speedup=1.0, dynamics_model=dynamics) as s:
        console = _Console(s.ports[0], tmp_path)
        try:
            detected = console.wait_line("Detected vehicle 1:1", 60.0)
            listed = console.wait_line("Received 16 parameters", 30.0)
            assert detected is not None and listed is not None, console.lines[-10:]
            print(
                f"MAVProxy: vehicle detected {detected:.2f} s after start, parameters listed {listed - detected:.2f} s "
                f"later"
            )
            # MAVLink FTP is NAKed and the parameter file answered by PARAM_VALUEs: about 1 s (MAVProxy's first
            # 1 Hz check) instead of its 12 s FTP time-out; the bound leaves room for a loaded machine.
            assert listed - detected < 5.0
            console.send("mode")
            assert console.wait_line("Available modes", 30.0) is not None
            console.send("arm throttle")
            console.send("mode LOITER")
            assert console.wait_line("Mode LOITER", 30.0) is not None, console.lines[-10:]
            assert s.vehicle(0).armed and s.vehicle(0).mode is FlightMode.LOITER
        finally:
            console.close()
        s.stop()


@pytest.mark.timeout(90)
def test_mavsdk_flies_a_jsbsim_f16_health_offboard_turn_and_rtl() -> None:
    """MAVSDK against a JSBSim F-16: healthy, an offboard 5 deg/s turn the airframe reaches after its roll-in (its
    bank then about atan(V omega / g), as ATTITUDE reports it), and RTL that it flies home."""
    with sitl(speedup=5.0, dynamics_model=DynamicsModel.JSBSIM) as s:
        sdk = _mavsdk_connect(f"udpout://127.0.0.1:{s.ports[2]}")
        try:
            system = sdk.first_autopilot(5.0)
            assert system is not None
            telemetry = Telemetry(system)
            assert _wait(telemetry.health_all_ok, 10.0), telemetry.health()
            Action(system).arm()
            offboard = Offboard(system)
            turn = VelocityBodyYawspeed(250.0, 0.0, 0.0, 5.0)
            offboard.set_velocity_body(turn)
            samples: list[tuple[float, float, float]] = []
            handle = telemetry.subscribe_attitude_euler(
                lambda e, *_: samples.append((e.timestamp_us * 1e-6, e.yaw_deg, e.roll_deg))
            )
            offboard.start()
            started = time.monotonic()
            while time.monotonic() - started < 4.0:  # 20 s simulated, MAVSDK's setpoints sent again (ArduPlane GUIDED)
                time.sleep(0.1)
                offboard.set_velocity_body(turn)
            telemetry.unsubscribe_attitude_euler(handle)
            Action(system).return_to_launch()
            assert _wait(lambda: telemetry.flight_mode() == SdkFlightMode.RETURN_TO_LAUNCH, 5.0)
            assert s.vehicle(2).mode is FlightMode.RTL
        finally:
            sdk.destroy()
        s.stop()
    steady = [x for x in samples if x[0] - samples[0][0] > 8.0]  # after the roll-in
    assert len(steady) > 50
    turned = sum(((b[1] - a[1] + 180) % 360) - 180 for a, b in zip(steady, steady[1:]))
    rate = turned / (steady[-1][0] - steady[0][0])
    bank = sum(x[2] for x in steady) / len(steady)
    print(f"MAVSDK on a JSBSim F-16: yaw rate {rate:.2f} deg/s, bank {bank:.1f} deg after the roll-in")
    assert rate == pytest.approx(5.0, rel=0.1)
    assert bank == pytest.approx(math.degrees(math.atan(250.0 * math.radians(5.0) / 9.80665)), abs=8.0)


def _mavsdk_connect(url: str) -> Mavsdk:
    sdk = Mavsdk(Configuration.create_with_component_type(ComponentType.GROUND_STATION))
    sdk.add_any_connection(url)
    return sdk


@pytest.mark.timeout(60)
def test_mavsdk_health_mission_offboard_yaw_rate_and_stop() -> None:
    with sitl(speedup=10.0) as s:
        sdk = _mavsdk_connect(f"udpout://127.0.0.1:{s.ports[2]}")
        try:
            t0 = time.monotonic()
            system = sdk.first_autopilot(5.0)
            assert system is not None
            telemetry = Telemetry(system)
            assert _wait(telemetry.health_all_ok, 5.0), telemetry.health()
            healthy_s = time.monotonic() - t0
            assert telemetry.in_air() and telemetry.flight_mode() == SdkFlightMode.MANUAL
            assert MissionRaw(system).download_mission() == []
            Action(system).arm()
            offboard = Offboard(system)
            offboard.set_velocity_body(VelocityBodyYawspeed(250.0, 0.0, 0.0, 5.0))
            samples: list[tuple[float, float]] = []
            handle = telemetry.subscribe_attitude_euler(
                lambda e, *_: samples.append((e.timestamp_us * 1e-6, e.yaw_deg))
            )
            offboard.start()
            started = time.monotonic()
            # MAVSDK streams setpoints for 3 s after start(): it counts only PX4's or ArduCopter's
            # offboard modes as offboard, not ArduPlane's GUIDED (see docs/mavlink.md).
            _wait(lambda: time.monotonic() - started > 2.5, 3.0)
            telemetry.unsubscribe_attitude_euler(handle)
            offboard.stop()
            assert _wait(lambda: telemetry.flight_mode() == SdkFlightMode.HOLD, 3.0)
            assert s.vehicle(2).mode is FlightMode.LOITER
        finally:
            sdk.destroy()
        s.stop()
    # The turn rate over the samples where the vehicle turned at a steady rate (simulated time).
    turning = [
        (t, y) for (t, y), (t2, y2) in zip(samples, samples[1:]) if t2 > t and abs(((y2 - y + 180) % 360) - 180) > 1e-3
    ]
    assert len(turning) > 50
    ta, tb = turning[5][0], turning[-5][0]
    unwrapped = sum(((b[1] - a[1] + 180) % 360) - 180 for a, b in zip(turning[5:-4], turning[6:-4]))
    rate = unwrapped / (tb - ta)
    print(
        f"MAVSDK: health_all_ok after {healthy_s:.2f} s; offboard yaw rate {rate:.3f} deg/s over {tb - ta:.1f} s "
        f"simulated"
    )
    assert healthy_s < 5.0 and rate == pytest.approx(5.0, rel=0.05)


def _example(name: str):
    spec = importlib.util.spec_from_file_location(name, REPO / "examples" / f"{name}.py")
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


@pytest.mark.timeout(90)
def test_the_readme_offboard_example_keeps_turning_past_mavsdks_3_s() -> None:
    """examples/mavsdk_offboard_turn.py (the README's): 9 wall seconds at 5x, three times MAVSDK's 3 s stream;
    the vehicle turns at 5 deg/s from start to end and never falls back to its setpoint-timeout hold."""
    example = _example("mavsdk_offboard_turn")
    with sitl(speedup=5.0) as s:
        v = s.vehicle(2)
        errors: list[BaseException] = []

        def fly() -> None:
            try:
                example.turn(f"udpout://127.0.0.1:{s.ports[2]}", 9.0)
            except BaseException as exc:
                errors.append(exc)

        thread = threading.Thread(target=fly, daemon=True)
        thread.start()
        samples: list[tuple[float, float, float]] = []  # (wall, simulated time, heading phi)
        while thread.is_alive() and len(samples) < 2000:
            if v.mode is FlightMode.GUIDED:
                samples.append((time.monotonic(), s.runner.clock.sim_s, v.truth.phi_rad))
            time.sleep(0.05)
        thread.join(30.0)
        assert not errors, errors
        assert v.counters.failsafes == 0 and v.mode is FlightMode.LOITER
        s.stop()
    t_wall0 = samples[0][0]
    late = [(t, phi) for w, t, phi in samples if w - t_wall0 > 4.0]  # after MAVSDK's own stream has ended
    assert late[-1][0] - late[0][0] > 15.0, "too little simulated time after 4 wall seconds"
    turned = sum(((a[1] - b[1] + math.pi) % (2 * math.pi)) - math.pi for a, b in zip(late, late[1:]))
    rate_deg_s = math.degrees(turned) / (late[-1][0] - late[0][0])  # phi is CCW: a right turn lowers it
    print(f"README example: {rate_deg_s:.3f} deg/s over {late[-1][0] - late[0][0]:.1f} s simulated after 4 s wall")
    assert rate_deg_s == pytest.approx(5.0, rel=0.05)


@pytest.mark.timeout(60)
def test_mavsdk_clears_missions_hears_refusals_at_once_and_a_refused_goto_leaves_the_mode() -> None:
    with sitl(speedup=5.0) as s:
        sdk = _mavsdk_connect(f"udpout://127.0.0.1:{s.ports[0]}")
        try:
            system = sdk.first_autopilot(5.0)
            assert system is not None
            telemetry = Telemetry(system)
            assert MissionRaw(system).clear_mission() == MissionRawResult.SUCCESS  # raised MissionRawError before
            param = Param(system)
            for name, value, code in (
                ("FS_LONG_TIMEOUT", 1000.5, ParamResult.VALUE_OUT_OF_RANGE),
                ("SIM_DT", 0.2, ParamResult.PERMISSION_DENIED),
            ):
                t0 = time.monotonic()
                with pytest.raises(ParamError) as refused:
                    param.set_param_float(name, value)
                assert refused.value.result == code and time.monotonic() - t0 < 0.5
            assert s.vehicle(0).param("FS_LONG_TIMEOUT") == 5.0
            assert _wait(lambda: telemetry.battery().voltage_v > 0, 3.0), telemetry.battery()
            battery = telemetry.battery()
            assert battery.voltage_v == pytest.approx(12.6) and battery.remaining_percent == pytest.approx(100.0)
            home = telemetry.home()
            with pytest.raises(ActionError):
                Action(system).goto_location(home.latitude_deg, home.longitude_deg, 1000.0, 0.0)
            assert _wait(lambda: s.vehicle(0).mode is FlightMode.MANUAL, 2.0)  # GUIDED for the goto was undone
            assert s.vehicle(0).counters.failsafes == 0
        finally:
            sdk.destroy()
        s.stop()


@pytest.mark.skipif(not MAVPROXY.exists(), reason="MAVProxy is a dev dependency (pip install -e .[dev])")
@pytest.mark.timeout(180)
def test_listening_mavsdk_and_mavproxy_see_all_three_vehicles_through_out(tmp_path: Path) -> None:
    """Two ground stations that only listen, one --out each: both see sysids 1-3; commands go through."""
    sdk_port, proxy_port = _free_udp_port(), _free_udp_port()
    sdk = _mavsdk_connect(f"udpin://127.0.0.1:{sdk_port}")
    console = _Console(proxy_port, tmp_path, master=f"udpin:127.0.0.1:{proxy_port}")
    outs = ["--out", f"udpout:127.0.0.1:{sdk_port}", "--out", f"udpout:127.0.0.1:{proxy_port}"]
    proc = subprocess.Popen(
        [sys.executable, "-m", "sim_vehicles", "--scenario", str(STRIKE), "--base-port", "0", "--speedup", "5", *outs],
        cwd=REPO,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        env={**os.environ, "PYTHONPATH": str(REPO)},
    )
    try:
        t0 = time.monotonic()
        assert _wait(lambda: len(sdk.get_systems()) == 3, 60.0), "the listening MAVSDK did not see three vehicles"
        seen_s = time.monotonic() - t0
        systems = {system.get_system_id(): system for system in sdk.get_systems()}
        assert set(systems) == {1, 2, 3}
        Action(systems[2]).arm()  # a command through the --out link reaches the detect UAV only
        assert _wait(Telemetry(systems[2]).armed, 3.0) and not Telemetry(systems[1]).armed()
        for sysid in (1, 2, 3):
            assert console.wait_line(f"Detected vehicle {sysid}:1", 60.0) is not None, console.lines[-10:]
        print(f"--out: MAVSDK (udpin) saw three vehicles {seen_s:.2f} s after the SITL started; MAVProxy (udpin) too")
    finally:
        sdk.destroy()
        console.close()
        proc.terminate()
        out, err = proc.communicate(timeout=10)
    assert proc.returncode == 0 and "end reason=stopped" in out, err
