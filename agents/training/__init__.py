"""Training a PPO policy from a run config: the run, its callbacks, checkpoints and resume."""
