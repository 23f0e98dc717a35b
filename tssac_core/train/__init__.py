"""Training: one run of an algorithm and a seed over the role curriculum (Algorithm 1).

``algorithms`` (the typed table of the algorithms; Algo, Selection) · ``config`` (TrainConfig and the learner
configs built from it) · ``preset`` (recipe files: configs/*.yaml) · ``arguments`` (the command's flags <->
TrainConfig) · ``rundir`` (config.json, metrics.csv, checkpoints, plots; what "finished" means) · ``loop`` (the
one training loop of a role, for every learner) · ``learners`` (its hooks: off-policy and on-policy) ·
``epoch`` (one epoch's figures, the role's worlds and teammates, shipping) · ``resume`` (the one resume format,
durable writes, fallback to the previous state) · ``validation`` (held-out missions after each epoch: the best
epoch is shipped) · ``legacy`` (what older runs' files mean) · ``cli`` (``python -m tssac_core.train``).
"""
