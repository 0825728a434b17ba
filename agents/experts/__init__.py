"""Learning from an expert controller: DAgger students, PPO fine-tuning and residual policies."""
