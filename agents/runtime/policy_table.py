"""The shipped policies' names: ONE table for the loader, ``--help`` and the docs.

A shipped policy is a folder of ``agents/policies/`` (package data): ``<name>/`` or, one per
training seed, ``<group>/s<k>/`` (named ``group/sk``). On top of the folders:

- `ALIASES`: a name that points at a seed folder (``default`` is ``finetuned/s0``: the learned
  controller chosen on validation), never a copy of it;
- `GROUP_ALIASES`: a name for a group of seed folders, ``NAME/sK`` being ``GROUP/sK``
  (``student-mpc-adaptive/s0`` is ``adaptive/s0``: the learned adaptive controller, a student of
  the mpc expert, not the classical ``mpc-adaptive``); the folders keep their old names, which
  stay names too;
- `ARCHIVED`: superseded policies, moved to ``agents/policies/archive/<name>/`` with their
  files unchanged: they are no longer names (`archived_message` says where each went, in one
  line) but load by their path; docs/learned.md ("History") keeps their last measured numbers.

`shipped_names` is what the loader resolves (`agents.runtime.names.resolve_policy`), `names_text`
the list that ``--policy``'s help and docs/learned.md print (tests/test_docs.py checks both).
Light to import (no NumPy): the help is built on every start of ``bound-env``.
"""

from __future__ import annotations

from importlib import resources
from pathlib import Path

SHIPPED_DIR = Path(str(resources.files("agents") / "policies"))
ARCHIVE_DIR = SHIPPED_DIR / "archive"
# name -> (the seed folder it points at, why that one)
ALIASES = {
    "default": (
        "finetuned/s0",
        "the learned controller: the fine-tuned variant, chosen over the distilled one on the "
        "validation seed 777 (96 random directions, r = 0.15-0.35); seed 0 by convention, no "
        "choice among seeds",
    ),
}
# name -> (the group of seed folders it names, why): ``NAME/sK`` is ``GROUP/sK``
GROUP_ALIASES = {
    "student-mpc-adaptive": (
        "adaptive",
        "the learned adaptive controller, distilled from the mpc expert (DAgger, a privileged "
        "teacher); the classical controller that adapts is mpc-adaptive",
    ),
    "student-mpc-adaptive-nohist": ("adaptive-nohist", "its ablation without history"),
    "student-mpc-adaptive-nominal": (
        "adaptive-nominal",
        "its ablation trained on the nominal plant",
    ),
}
# name -> why it left the shipped set (its folder is agents/policies/archive/<name>)
ARCHIVED = {
    "ppo-v1": "a checkpoint of ppo-v1's recipe selected on axis basins; the recipe's final "
    "models are ppo-v1-final/s0..s2",
    "stride-residual": "a PPO residual on the LQR, trained on the retired stride map v0",
    "warm-started": "step-level PPO cloned from default first, superseded by step-ppo",
    "distilled": "the DAgger students of mpc, the inputs of finetuned/s0..s2 (finetune "
    "--student takes their path)",
}


def shipped_folders(root: Path = SHIPPED_DIR) -> dict[str, Path]:
    """{name: folder} of the policy folders under ``root`` (``<name>/`` and one level of
    groups, ``<group>/<name>/`` named ``group/name``), the archive left out."""
    if not root.is_dir():
        return {}
    out = {}
    marks = ("model.zip", "choice.npz", "adaptive.npz")  # a PPO model or a student: a policy
    for p in sorted(root.iterdir()):
        if p.is_dir() and any((p / f).exists() for f in marks):
            out[p.name] = p
        elif p.is_dir() and p.name != ARCHIVE_DIR.name:
            for q in sorted(p.iterdir()):
                if q.is_dir() and any((q / f).exists() for f in marks):
                    out[f"{p.name}/{q.name}"] = q
    return out


def shipped_names() -> dict[str, Path]:
    """{name: folder} of every shipped name: the aliases (`ALIASES`, then `GROUP_ALIASES`)
    first, then the folders."""
    folders = shipped_folders()
    aliases = {a: folders[t] for a, (t, _) in ALIASES.items() if t in folders}
    return {**aliases, **group_aliased(folders), **folders}


def group_aliased(folders: dict[str, Path]) -> dict[str, Path]:
    """{``NAME/sK``: folder} of every `GROUP_ALIASES` name over the folders of its group."""
    out = {}
    for alias, (group, _) in GROUP_ALIASES.items():
        for name, folder in folders.items():
            head, _, seed = name.rpartition("/")
            if head == group:
                out[f"{alias}/{seed}"] = folder
    return out


def archived_message(name: str) -> str | None:
    """One line saying where an archived name (``ppo-v1``, ``distilled/s0``) went; None for a
    name that is not archived."""
    group = str(name).split("/", 1)[0]
    if group not in ARCHIVED:
        return None
    where = ARCHIVE_DIR / str(name)
    if not ARCHIVE_DIR.is_dir():  # an installed wheel: the archive stays in the repository
        return (
            f"policy {name!r} was archived ({ARCHIVED[group]}): it is in the repository's "
            f"agents/policies/archive/{name}, not in the installed package"
        )
    return (
        f"policy {name!r} was archived ({ARCHIVED[group]}): it is {where} now; give that "
        "path to load it"
    )


def names_text(quote: str = "`") -> str:
    """The shipped names as a list: an alias with its target, a group of seeds as
    ``group/s0..s2``; quoted with ``quote``."""

    def q(text: str) -> str:
        return f"{quote}{text}{quote}"

    folders = shipped_folders()
    items = [f"{q(a)} (= {q(t)})" for a, (t, _) in ALIASES.items() if t in folders]
    groups: dict[str, list[str]] = {}
    for name in folders:
        group, _, seed = name.rpartition("/")
        groups.setdefault(group or name, []).append(seed)
    for alias, (group, _) in GROUP_ALIASES.items():
        seeds = groups.get(group, [])
        if len(seeds) == 1 and seeds != [group]:
            items.append(f"{q(f'{alias}/{seeds[0]}')} (= {q(f'{group}/{seeds[0]}')})")
        elif len(seeds) > 1:
            items.append(
                f"{q(f'{alias}/{seeds[0]}')}..{q(seeds[-1])} "
                f"(= {q(f'{group}/{seeds[0]}')}..{q(seeds[-1])})"
            )
    for group, seeds in groups.items():
        if seeds == [group]:
            items.append(q(group))
        elif len(seeds) == 1:
            items.append(q(f"{group}/{seeds[0]}"))
        else:
            items.append(f"{q(f'{group}/{seeds[0]}')}..{q(seeds[-1])}")
    return ", ".join(items)
