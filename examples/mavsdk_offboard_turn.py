"""Turn a SITL UAV at 5 deg/s for 30 s with MAVSDK 4's offboard plugin (the README's example).

MAVSDK streams an offboard setpoint for only 3 s after ``start()`` or ``set_velocity_body()`` when the vehicle is
an ArduPlane in GUIDED (it does not count ArduPlane's GUIDED as offboard): without a new setpoint the vehicle's
setpoint timeout then holds heading and speed. So the setpoint is sent again every 0.1 s, inside the vehicle's
``GUID_TIMEOUT`` (1 s of simulated time: 0.2 wall seconds at ``--speedup 5``).

    python -m sim_vehicles --scenario scenarios/strike.yaml      # in another terminal
    python examples/mavsdk_offboard_turn.py                      # the strike UAV on 14580
"""

from __future__ import annotations

import sys
import time

from mavsdk import ComponentType, Configuration, Mavsdk
from mavsdk.plugins.action import Action
from mavsdk.plugins.offboard import Offboard, VelocityBodyYawspeed

TURN = VelocityBodyYawspeed(250.0, 0.0, 0.0, 5.0)
"""250 m/s forward, 5 deg/s to the right."""
RESEND_S = 0.1


def turn(url: str = "udpout://127.0.0.1:14580", duration_s: float = 30.0) -> None:
    """Arm the vehicle at ``url``, fly TURN in GUIDED for ``duration_s`` wall seconds, then LOITER."""
    sdk = Mavsdk(Configuration.create_with_component_type(ComponentType.GROUND_STATION))
    sdk.add_any_connection(url)
    try:
        system = sdk.first_autopilot(5.0)
        if system is None:
            raise RuntimeError(f"no autopilot at {url} within 5 s")
        Action(system).arm()
        offboard = Offboard(system)
        offboard.set_velocity_body(TURN)
        offboard.start()  # GUIDED
        end = time.monotonic() + duration_s
        while time.monotonic() < end:
            time.sleep(min(RESEND_S, max(0.0, end - time.monotonic())))
            offboard.set_velocity_body(TURN)  # MAVSDK's stream stops after 3 s: send the setpoint again
        offboard.stop()  # LOITER (MAVSDK's Hold)
    finally:
        sdk.destroy()


if __name__ == "__main__":
    turn(*sys.argv[1:2])
