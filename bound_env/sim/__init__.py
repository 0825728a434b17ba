"""Batched, compiled simulation: the task and its kernels, the stride map, the stride task and
protocol, and the process pool that runs them."""
