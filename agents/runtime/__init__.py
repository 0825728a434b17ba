"""Finding what a ``--policy`` name loads and running it as a controller."""
