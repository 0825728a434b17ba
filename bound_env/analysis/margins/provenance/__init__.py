"""What decided a margins result: the task cache's keys, the fingerprint of a column or of a
script's row, and the code closure of a controller."""
