"""Training: one run of an algorithm and a seed over the role curriculum (Algorithm 1).

``config`` (TrainConfig, the algorithms, the learner configs built from them) · ``arguments`` (the
command's flags <-> TrainConfig) · ``rundir`` (config.json, metrics.csv, checkpoints, resume states,
plots) · ``epoch`` (what every loop shares) · ``loop`` (off-policy: the SAC family) · ``onpolicy_loop``
(PPO, PPO-Lagrangian, CPO) · ``validation`` (held-out missions after each epoch: the best epoch is
shipped) · ``legacy`` (what older runs' files mean) · ``cli`` (``python -m tssac_core.train``).
"""
