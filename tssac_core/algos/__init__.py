"""Learners of the paper's comparison: SAC, SAC with a hazard penalty, SAC-Lagrangian and TSSAC.

Independent of the environment: observation and action sizes are constructor arguments.
`sac_lagrangian` holds the learner and `transfer`, `sac_config` its settings (no torch), `losses` the paper's
eq. 12-17 as pure functions, `lagrange` the (damped) multiplier, `budget` the cost limit on Q^c's scale,
`networks` the actor and critics, `replay` the buffer; `onpolicy/` the on-policy baselines (`config`: their
settings, no torch). Importing the package imports none of them (nor torch): a command reads its configuration
and answers ``--help`` before torch is loaded.
"""
