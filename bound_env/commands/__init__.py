"""The ``bound-env`` command line: its entry point and sub-command registry, the shared
arguments, and the analysis and rendering commands."""
