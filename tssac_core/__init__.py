"""TSSAC: transfer-safe soft actor-critic for a team of cooperating UAVs.

Subpackages: ``sim`` (the paper's world, observation, reward, the batched task and the gymnasium env),
``algos`` (the learners), ``train`` (``python -m tssac_core.train``), ``deploy`` (what flies a trained
policy, and the frames and logs that the SITL and the bridge share), ``experiments`` (the paper's grid),
``assurance`` (the runtime-assurance monitor), ``parallel`` (the work on Ray), ``reporting`` (figures, films, time
left) and ``common`` (durable files, shared errors, statistics). Modules: ``evaluate`` (``python -m
tssac_core.evaluate``) and ``cli`` (what every command line shares).
Importing the package imports none of them (nor gymnasium or torch); the gymnasium environments
``tssac/Decoy-v0``, ``tssac/Detect-v0`` and ``tssac/Strike-v0`` are registered by importing
:mod:`tssac_core.sim.env`.
"""

__version__ = "0.1.0"
