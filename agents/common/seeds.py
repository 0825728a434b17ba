"""The validation seed: the random directions every design choice of a learned controller is
made on (distillation, fine-tuning, residual recipe, checkpoint selection, the demo's start).
Never the test set's seed (12345, `bound_env.analysis.margins.DEFAULT_SEED`)."""

VALIDATION_SEED = 777
