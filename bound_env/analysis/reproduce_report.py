"""Old home of the reproduction's figures and report: `bound_env.analysis.reproduce.figures`
and `bound_env.analysis.reproduce.report` (kept importable)."""

from .reproduce.figures import write_figures
from .reproduce.report import write_report

__all__ = ["write_figures", "write_report"]
