"""Runtime assurance: the Simplex monitor and its backups (``monitor``), numpy only, below every other room.

The batched world (:mod:`tssac_core.sim.world_monitor`), the scenario's start check
(:mod:`tssac_core.sim.scenario`) and the MAVLink companion (``mavlink_bridge``) all call this one module;
it imports nothing from the project, so each of them can. The argument: ``docs/runtime_assurance.md``.
"""
