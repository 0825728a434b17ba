"""What every room shares: run configs, policy files and their schema, networks, wrappers."""
