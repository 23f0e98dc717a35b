"""The paper's world and each role's constrained MDP (numpy; the gymnasium env is :mod:`tssac_core.sim.env`).

``scenario`` (the scenario file's schema, random feasible layouts) · ``world`` (eq. 5-6 kinematics, eq. 9
mission logic, eq. 11 cost; N worlds at once) · ``observation`` (the one observation function) · ``reward``
(eq. 10 and the terms we added) · ``routes`` (the way around the radars) · ``guidance`` (rule-based
controller) · ``team`` (who flies each UAV) · ``missions`` (whole three-UAV missions, scored) · ``time_left`` (how
long they will take) · ``role_task`` (RoleTask: the batched task training uses) · ``env`` (the gymnasium env) ·
``vector_env`` (``gym.make_vec``) · ``yaml_file``.
"""
