"""The paper's on-policy baselines: PPO and PPO-Lagrangian (``ppo``), CPO (``cpo``), and GAE (``gae``)."""
