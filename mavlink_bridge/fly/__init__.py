"""``python -m mavlink_bridge.fly``: fly whole three-UAV missions over MAVLink against SITL vehicles.

Examples::

    python -m mavlink_bridge.fly --scenario scenarios/strike.yaml --pilot guidance --json out.json --plot mission.png
    python -m mavlink_bridge.fly --scenario scenarios/random.yaml --models models/tssac --episodes 10 --seed 3 --tlog
    tlogs/
    python -m mavlink_bridge.fly --scenario scenarios/random.yaml --seed 3 --mission 7 --plot m7.png   # mission 7
    again, alone
    python -m mavlink_bridge.fly --scenario layout.yaml --pilot guidance --connect udpout:127.0.0.1:14560
    udpout:127.0.0.1:14570 udpout:127.0.0.1:14580

For each mission: the layout is the scenario's fixed one, or a random one drawn with
``sample_layout(scenario, numpy.random.default_rng(seed + mission index))``; it is written as a
fixed-layout scenario file that the SITL world and the companions both read. The world starts as
its own process (``python -m sim_vehicles``, OS-assigned ports, lockstep by default) and one
companion process per UAV (``python -m mavlink_bridge.companion``) connects to its vehicle. When the
world ends (target hit, a UAV leaving the area, or the episode cap) the outcome is read from the
world's truth log: success, hazard cost per UAV, mission time in simulated seconds. The JSON and the
printout carry the keys of ``tssac_core.evaluate`` (mission k of seed S is the same layout in both worlds):
the success rate with its 95% Wilson interval, the mean cost per UAV with its 95% bootstrap interval over
missions, per role the fraction within C, the worst cost and CVaR_0.95, and the costliest UAV-missions
(``worst_missions``: index, seed, role, cost), each of which ``--seed S --mission K`` flies again.

Every child runs in its own process group; Ctrl-C, SIGTERM, a crash of any child or a mission
timeout stops them all (SIGTERM, then SIGKILL after a grace period) and the results of the missions
that finished are still written. With ``--connect`` the companions fly vehicles that are already
running (one connection string per role, decoy detect strike); there is then no truth log, so the
outcome comes from the companions (the vehicles' HIT / MSN_END notices) and the cost is unknown.

Exit status: 0 when every mission was flown (whatever its outcome), 2 on bad input (one line), 1
when a child crashed or a mission timed out, 130 when interrupted.

``--workers N`` flies N missions at once: N crews side by side in the fly process (``side_by_side``), or with
``--executor ray`` / ``--address`` N Ray tasks (``workers``); either way the rows are the serial run's.

``--resume`` with ``--json FILE`` flies on from a campaign FILE holds (stopped part-way, or asked for more missions):
only the missions it lacks, FILE's settings checked against the command's first (``resume``).

Modules: ``config`` (FlyConfig, the command line's arguments) · ``mission_runner`` (starts and watches one
mission's processes) · ``crew`` (the processes kept across a campaign) · ``side_by_side`` and ``workers``
(missions at once) · ``scoring`` (a mission's outcome and the results JSON) · ``report`` (the printed
summary and the plot) · ``pool`` (campaigns pooled) · ``resume`` (a campaign flown on) · ``cli``
(``python -m mavlink_bridge.fly``).
"""
