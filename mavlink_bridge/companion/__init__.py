"""The companion computer of one UAV: MAVLink telemetry in -> Kalman filter -> observation -> pilot -> setpoint out.

``python -m mavlink_bridge.companion --connect udpout:127.0.0.1:PORT --role decoy --pilot guidance --scenario FILE``

States (:class:`Phase`)::

    CONNECT --heartbeat--> ENGAGE --arm ACK, GUIDED ACK--> FLY --HIT / MSN_END--> END
                             ^                              |  ^
                             |   vehicle restart (clock     |  | armed in GUIDED again
                             +---- jumps back) or link      v  |
                                   back after a gap       PAUSED (operator took the vehicle
                                                                   out of GUIDED / disarmed it)

Each control step is one new 0.1 s tick of the *vehicle's* clock (``time_boot_ms`` of its
telemetry), never of the wall clock, so real time, ``--speedup`` and lockstep all work: the
position fix of the tick is applied to the filter (with its own timestamp), the filter is
predicted to the tick, the estimate and the mission flags are mirrored into a one-world
:class:`tssac_core.sim.world.World`, the observation is built by :func:`tssac_core.sim.observation.observe`
(the function training uses), the pilot (a trained policy holding each action for its
``action_repeat`` ticks, or the guidance controller) gives [omega, u] in [-1, 1], and the setpoint
(yaw rate, forward acceleration) goes out stamped with the tick's ``time_boot_ms``.

Failsafes:

* Position fixes missing for more than ``hold_after_s`` of vehicle time (a telemetry gap; the
  filter predicts through shorter ones), or a non-finite action: the hold setpoint (zero yaw rate,
  zero acceleration), said once per episode in a STATUSTEXT to the vehicle and in the log.
* No message at all: without lockstep, the vehicle's clock is extrapolated at its measured rate
  (vehicle seconds per wall second) and control steps go on, predicting, until the gap rule above
  holds. Under ``--lockstep`` (the vehicle's clock stands still while it waits for us) nothing is
  extrapolated; after ``silence_hold_s`` wall seconds the hold setpoint is sent (once a second).
* No message for ``lost_after_s`` wall seconds: the vehicle is given up (exit status ``lost``).
* The vehicle's clock jumps back by more than ``restart_jump_s``: it restarted; the filter, the
  flags and the pilot are reset and the vehicle is armed and put in GUIDED again. After a gap, a
  vehicle found disarmed or out of GUIDED is re-engaged too; without a gap that is an operator's
  decision, and the companion waits (PAUSED) instead of fighting it.

Exit statuses (one ``end ...`` line on stdout, ``--status-json`` for the details): ``success``
(the world's HIT, or MSN_END 1), ``geofence`` / ``episode_cap`` (MSN_END 2 / 3), ``duration``
(``--duration-s`` of vehicle time flown), ``stopped`` (SIGINT / SIGTERM), all with exit code 0;
``lost`` / ``no_vehicle`` / ``refused`` exit 3; bad input exits 2 with one line.

Modules: ``config`` (CompanionConfig and the constants) · ``held_pilot`` (a trained policy, the
guidance controller, or a test pilot: ``straight`` and the adversaries of :mod:`tssac_core.sim.adversaries`) ·
``shield`` (the monitor on one vehicle) · ``pilot_step`` (a tick's pilot side: the estimate to the pilot, what is
amiss, every tick through the monitor) · ``mission_end`` (when a mission's end heard is believed) · ``grants``
(how far a lockstep answer reaches) · ``tick_clock`` (the vehicle's clock followed: when a control step is due, how
long to wait) · ``clock_rate`` (the vehicle clock's rate, off lockstep) · ``status`` (counters, mission flags, the
result) · ``machine`` (the state machine: connect, engage, receive, control, end) · ``cli``
(``python -m mavlink_bridge.companion``).
"""
