"""The defaults and bounds of `bound_env.analysis.basin`, in a module that imports nothing:
``bound-env basin-map``'s arguments are parsed before the simulator is imported."""

DEFAULT_STRIDES = 100  # strides allowed to return (margins' quick budget)
DEFAULT_GRID = 64
# Bounds of the command line (a grid of 10^5 per axis grew by 40 MB/s with no output, as sweep's
# --step is bounded): at most 1000 x 1000 = 10^6 starts, 10^4 strides each.
MAX_GRID = 1000
MAX_STRIDES = 10_000
DEFAULT_CHUNK = 128  # starts per task
