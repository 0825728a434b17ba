"""A wide results table as several narrow ones, the headline columns first (`split_table`).

The results page's full table has a column per controller (13 on the default page): too wide
for a screen, so the columns a reader looks for first (passive, lqr, mpc, the best learned
controller) end up off-screen. `split_table` renders the same cells as one table of the
headline columns, then the other columns in tables of at most ``per_table`` columns, each
table with the row titles. Pure: labels and cells in, Markdown out.
"""

from __future__ import annotations

# The results page's headline columns, by label (agents.results.compare.HEADLINE's second field)
HEADLINE_LABELS = ("passive", "lqr", "mpc", "fine-tuned", "step-ppo")
PER_TABLE = 6  # value columns per table after the headline's


def base_label(label: str) -> str:
    """A column's label without its suffix: ``"fine-tuned (3 seeds)"`` -> ``"fine-tuned"``."""
    return label.split(" (")[0].strip()


def _table(stub: str, labels: list[str], rows: list[tuple[str, list[str]]], cols) -> str:
    head = f"| {stub} | " + " | ".join(labels[c] for c in cols) + " |"
    sep = "| --- |" + " --- |" * len(cols)
    body = [f"| {title} | " + " | ".join(cells[c] for c in cols) + " |" for title, cells in rows]
    return "\n".join([head, sep, *body])


def split_table(
    labels,
    rows,
    headline=HEADLINE_LABELS,
    per_table: int = PER_TABLE,
    stub: str = "measure",
) -> str:
    """Markdown of the table (``labels``: the column labels; ``rows``: (row title, one cell
    per label) pairs) as two or more tables: first the columns whose `base_label` is in
    ``headline``, in ``headline``'s order, then the others in their own order, ``per_table``
    to a table. Each table is preceded by a bold caption ("Headline columns", "More columns",
    numbered when there are several). A table without any headline column is split the same
    way, its first table captioned "Columns"."""
    labels = [str(lab) for lab in labels]
    rows = [(str(title), [str(c) for c in cells]) for title, cells in rows]
    if per_table < 1:
        raise ValueError(f"per_table must be at least 1, got {per_table}")
    for title, cells in rows:
        if len(cells) != len(labels):
            raise ValueError(
                f"row {title!r} has {len(cells)} cells for {len(labels)} column labels"
            )
    order = {name: k for k, name in enumerate(headline)}
    first = sorted(
        (c for c, lab in enumerate(labels) if base_label(lab) in order),
        key=lambda c: order[base_label(labels[c])],
    )
    rest = [c for c in range(len(labels)) if c not in first]
    chunks = [rest[k : k + per_table] for k in range(0, len(rest), per_table)]
    parts = []
    if first:
        parts.append(("Headline columns", first))
    more = "More columns" if first else "Columns"
    for k, cols in enumerate(chunks):
        caption = more if len(chunks) == 1 else f"{more} ({k + 1} of {len(chunks)})"
        parts.append((caption, cols))
    return "\n\n".join(f"**{cap}**\n\n{_table(stub, labels, rows, cols)}" for cap, cols in parts)
