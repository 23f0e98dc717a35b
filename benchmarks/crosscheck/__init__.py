"""Reference cross-check of our CPO, PPO-Lagrangian and SAC-Lagrangian against OmniSafe's (issue #38, item 1):
both train the detect role beside the shipped decoy on the same budget and fly the same fresh layouts.

``settings`` (what is trained, and how: commands and OmniSafe's configuration) · ``rows`` (the checkpointed
results file, pooling and the markdown table) · ``actor_file`` (OmniSafe's deterministic actor as numpy arrays) ·
``evaluation`` (the detect UAV on the evaluation layouts) · ``driver`` (the command, in the project's environment) ·
``omnisafe_side`` (trains and exports in OmniSafe's own environment). Entry: benchmarks/crosscheck_omnisafe.py.
"""
