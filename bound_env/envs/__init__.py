"""What ``gymnasium.make`` returns and what wraps it: the step, vector, stride and rescue envs,
their wrappers and their rendering."""
