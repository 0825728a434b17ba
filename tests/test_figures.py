"""Figures a reader can read, and the numbers beside them: intervals inside a quantity's
range, basin maps on the range the returns use, training plots that say what was kept, the
wide results table split with the headline columns first."""

from __future__ import annotations

import math
import re
from pathlib import Path

import numpy as np
import pytest

from agents.results.table_split import HEADLINE_LABELS, base_label, split_table
from bound_env.analysis.basin import return_scale
from bound_env.analysis.margins.stats import bounded_t_interval, t_interval

ROOT = Path(__file__).resolve().parent.parent


# ------------------------------------------------------------------ intervals within a range


def test_bounded_interval_never_goes_below_zero():
    effort = [0.4, 1.1, 21.0]  # three seeds, one far off: the t interval goes below 0
    ti = t_interval(effort)
    assert ti["low"] < 0
    bi = bounded_t_interval(effort)
    assert bi["mean"] == ti["mean"]  # the estimate is unchanged
    assert 0 < bi["low"] <= bi["mean"] <= bi["high"]
    assert bi["method"] == "t, log scale"
    # a t interval inside the range is returned as it is
    tight = [10.0, 10.5, 11.0]
    assert bounded_t_interval(tight) == t_interval(tight)
    # a value at the bound has no logarithm: the interval is cut there
    cut = bounded_t_interval([0.0, 0.1, 9.0])
    assert cut["low"] == 0.0 and cut["method"] == "t, cut at the bound"
    assert bounded_t_interval([3.0])["low"] == 3.0  # one seed: no spread
    with pytest.raises(ValueError, match="below the bound"):
        bounded_t_interval([-1.0, 5.0, 20.0])
    assert math.isnan(bounded_t_interval([])["mean"])


# ------------------------------------------------------------------ basin maps


def test_basin_colour_scale_follows_the_returns():
    returns = np.r_[np.arange(5, 16), np.full(50, np.nan)]  # returns in 5-15 strides of 100
    assert return_scale(returns, 100) == 15
    assert return_scale([1, 2, 3], 100) == 5  # at least 5
    assert return_scale([np.nan, np.nan], 100) == 100  # nothing returned: the whole range
    assert return_scale(np.arange(1, 300), 100) == 100  # never past the strides run


# ------------------------------------------------------------------ comparison plots


def _result(label: str, k: int) -> dict:
    z = ("y_g", "theta1", "theta2", "xdot_g", "theta1dot", "theta2dot")
    basin = {c: {s: {"rel": 0.1 * (k + 1)} for s in "+-"} for c in z}
    sizes = [0.01, 0.1, 0.3]
    return {
        "label": label,
        "policy": label,
        "basin": basin,
        "basin_curve": {
            "sizes": sizes,
            "success": [1.0, 0.5, 0.0],
            "ci_low": [0.9, 0.4, 0.0],
            "ci_high": [1.0, 0.6, 0.1],
        },
        "push": {kind: {"sizes": [0.1, 0.2], "success": [1.0, 0.5]} for kind in ("xdot", "th1dot")},
    }


def test_comparison_plots_are_wide_with_legends_outside(tmp_path, monkeypatch):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.image as mpimg
    import matplotlib.pyplot as plt

    from bound_env.analysis.margins.report import plot_margins

    figs = []
    close = plt.close
    monkeypatch.setattr(plt, "close", lambda fig=None: (figs.append(fig), close(fig)))
    labels = ["passive", "fine-tuned", "lqr", "mpc", "step-ppo", "deadbeat", "extra"]
    paths = plot_margins([_result(lab, k) for k, lab in enumerate(labels)], tmp_path)
    for p in paths:
        assert mpimg.imread(p).shape[1] >= 900, p.name  # at least 900 px wide
    for fig in figs:
        fig.canvas.draw()
        legends = [ax.get_legend() for ax in fig.axes if ax.get_legend() is not None]
        assert legends
        for leg in legends:  # the legend lies right of its axes: outside the data
            assert leg.get_window_extent().x0 >= leg.axes.get_window_extent().x1
    curve = figs[1].axes[0]
    widths = {line.get_label(): line.get_linewidth() for line in curve.get_lines()}
    assert widths["mpc"] > widths["extra"]  # headline columns bold, the others thinner


def test_headline_columns_have_distinct_colours():
    from agents.results.compare import COLUMN_STYLES, default_entries
    from bound_env.analysis.margins import column_styles

    labels = [e[0] for e in default_entries()]
    st = column_styles(labels, COLUMN_STYLES)
    heads = [lab for lab in labels if lab in HEADLINE_LABELS]
    assert len(heads) >= 4
    assert len({st[lab]["color"] for lab in heads}) == len(heads)
    assert st["step-ppo"]["color"] not in ("#aec7e8",)  # not a light tint of fine-tuned's blue


# ------------------------------------------------------------------ training plots


def _eval_csv(folder: Path, noise: str, reward: float) -> Path:
    folder.mkdir(parents=True, exist_ok=True)
    rows = [
        "timesteps,mean_reward,std_reward,mean_length,mean_strides,fall_rate,noise_scale,wall_time_s"
    ]
    for k in range(1, 4):
        rows.append(f"{k * 1000},{reward * k},{reward},{800},{20},{0.1},{noise},{k}")
    (folder / "eval.csv").write_text("\n".join(rows) + "\n")
    (folder / "basin_validation.csv").write_text(
        "timesteps,score\n1000,0.02\n2000,0.05\n3000,0.04\n"
    )
    return folder / "eval.csv"


def _plot_texts(monkeypatch, **kwargs) -> str:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from agents.common.run_files import plot_eval

    figs = []
    close = plt.close
    monkeypatch.setattr(plt, "close", lambda fig=None: (figs.append(fig), close(fig)))
    plot_eval(**kwargs)
    (fig,) = figs
    texts = [t.get_text() for t in fig.findobj(matplotlib.text.Text)]
    return "\n".join(texts)


def test_training_plot_titles_and_markers(tmp_path, monkeypatch):
    csv = _eval_csv(tmp_path / "a", "nan", 0.0)  # a task without start noise, reward 0
    text = _plot_texts(monkeypatch, csv_path=csv, png_path=tmp_path / "a.png", kept="final")
    assert "nan" not in text and "PPO evaluation" in text
    assert "kept" not in text and "final model (exported; no selection)" in text
    assert "reward is 0 for this task" in text
    csv = _eval_csv(tmp_path / "b", "2.5", 500.0)
    text = _plot_texts(monkeypatch, csv_path=csv, png_path=tmp_path / "b.png")
    assert "start noise 2.5" in text and "best validation (kept in best/)" in text
    with pytest.raises(ValueError, match="kept must be"):
        _plot_texts(monkeypatch, csv_path=csv, png_path=tmp_path / "c.png", kept="x")


# ------------------------------------------------------------------ the wide table, split


def _wide_table() -> tuple[list[str], list[tuple[str, list[str]]]]:
    """The default page's columns (labels as the page writes them) and a few rows."""
    from agents.results.compare import default_entries

    labels = [
        f"{e[0]} (3 seeds)" if len(e[1]) > 1 else e[0] for e in default_entries()
    ]  # e.g. "fine-tuned (3 seeds)"
    rows = [(f"measure {k}", [f"{lab.split()[0]}-{k}" for lab in labels]) for k in range(4)]
    return labels, rows


def test_split_table_puts_the_headline_first():
    labels, rows = _wide_table()
    assert len(labels) > len(HEADLINE_LABELS)  # wider than the headline
    md = split_table(labels, rows)
    tables = re.findall(r"^\| measure \| (.*) \|$", md, re.M)
    first = [base_label(c) for c in tables[0].split(" | ")]
    assert first == [h for h in HEADLINE_LABELS if h in {base_label(lab) for lab in labels}]
    assert len(tables) >= 2 and all(len(t.split(" | ")) <= 6 for t in tables[1:])
    assert md.startswith("**Headline columns**") and "**More columns" in md
    # every cell once, under its own column
    shown = sum(len(t.split(" | ")) for t in tables)
    assert shown == len(labels)
    title, cells = rows[1]
    k = labels.index(next(lab for lab in labels if base_label(lab) == "mpc"))
    assert f"| {title} | " in md and cells[k] in md


def test_split_table_small_and_wrong_inputs():
    md = split_table(["a", "lqr"], [("x", ["1", "2"])], per_table=1)
    assert md == (
        "**Headline columns**\n\n| measure | lqr |\n| --- | --- |\n| x | 2 |\n\n"
        "**More columns**\n\n| measure | a |\n| --- | --- |\n| x | 1 |"
    )
    assert split_table(["a", "b"], [("x", ["1", "2"])]).startswith("**Columns**")
    with pytest.raises(ValueError, match="row 'x' has 1 cells for 2"):
        split_table(["a", "b"], [("x", ["1"])])
    with pytest.raises(ValueError, match="per_table"):
        split_table(["a"], [], per_table=0)


# ------------------------------------------------------------------ the images of docs/
def test_every_image_in_docs_is_shown_and_none_is_a_copy():
    """No PNG in docs/ that no page (or the site's config) shows, and no two that are the same
    bytes (compare removes the training curves of columns it no longer has)."""
    import hashlib

    docs = ROOT / "docs"
    text = "\n".join(p.read_text() for p in [*docs.rglob("*.md"), ROOT / "mkdocs.yml"])
    pngs = sorted(docs.rglob("*.png"))
    assert pngs
    unused = [str(p.relative_to(docs)) for p in pngs if p.name not in text]
    assert unused == []
    seen: dict = {}
    for p in pngs:
        seen.setdefault(hashlib.sha256(p.read_bytes()).hexdigest(), []).append(p.name)
    assert [names for names in seen.values() if len(names) > 1] == []


def test_a_training_plot_with_no_evaluation_reward_shows_episode_lengths(tmp_path, monkeypatch):
    """A task whose evaluation env's own reward is 0 (step-ppo's) is drawn as the evaluation
    episodes' lengths, not as a flat line at zero."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from agents.common.run_files import plot_eval

    csv = tmp_path / "eval.csv"
    csv.write_text(
        "timesteps,mean_reward,std_reward,mean_length,mean_strides,fall_rate,noise_scale,"
        "wall_time_s\n1000,0.0,0.0,10,2.5,0.4,nan,1\n2000,0.0,0.0,20,4.0,0.3,nan,2\n"
    )
    drawn = {}
    monkeypatch.setattr(plt.Figure, "savefig", lambda self, *a, **k: drawn.setdefault("f", self))
    plot_eval(csv, tmp_path / "eval.png", kept="final")
    ax = drawn["f"].axes[0]
    assert list(ax.lines[0].get_ydata()) == [2.5, 4.0]
    assert "strides" in ax.get_ylabel()
