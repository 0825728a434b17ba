"""What a ``--policy`` name or path is, and the folder it names read once (`PolicyFolder`).

Names come first (`CONTROLLERS`: ``passive`` and the classical controllers of
`bound_env.control`, one per spec in ``configs/controllers/``), then the shipped policies
(`shipped_policies`: ``agents/policies/<name>/`` and ``<group>/<name>/``), then paths.

`read_folder` resolves a name or path once and returns a `PolicyFolder`: the resolved path, the
files found in it and, read on first use and kept, its PPO files and run-config section. The
kinds of `agents.runtime.kinds` recognise, check and load a policy from it.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from functools import cached_property, partial
from pathlib import Path

from bound_env.control.offset_free import SUFFIX as OF_SUFFIX
from bound_env.files.resources import controllers_dir

from ...common.policy_files import PolicyFiles, find_policy_files, read_policy_section
from ...common.schema import policy_kind
from ..controllers import ZeroController
from ..policy_table import ARCHIVE_DIR, SHIPPED_DIR, archived_message, shipped_names  # noqa: F401

# Built-in controllers by name: name -> (factory(gait) -> controller, one-line description).
# ``--policy NAME`` in ``margins``, ``rollout`` and ``compare`` looks names up here first, then
# among the shipped policies, and only then reads NAME as a path. Modules that add classical
# controllers call `register_controller`.
CONTROLLERS: dict[str, tuple[Callable, str]] = {}


def register_controller(name: str, factory: Callable, description: str) -> None:
    """Make ``--policy name`` build ``factory(gait=...)`` (gait: name or path, or None)."""
    CONTROLLERS[name] = (factory, description)


register_controller("passive", lambda gait=None: ZeroController(), "zero spine torque")


def classical_controller(name: str, gait=None):
    """A classical controller of `bound_env.control` (a name or a spec .yaml), designed for
    ``gait`` (default: the spec's)."""
    from bound_env.control import load_controller as load_classical

    return load_classical(name, gait=None if gait is None else str(gait))


# the classical stride-level controllers: every spec in configs/controllers/ (the wheel's copy
# when installed), by its file name
_CLASSICAL_WHAT = {
    "lqr": "stride-to-stride LQR on the linearized stride map",
    "deadbeat": "one-stride deadbeat on the linearized stride map",
    "damping": "extra spine damping tau = -c theta2dot",
}
for _name in list(_CLASSICAL_WHAT) + sorted(
    p.stem for p in controllers_dir().glob("*.yaml") if p.stem not in _CLASSICAL_WHAT
):
    register_controller(
        _name,
        partial(classical_controller, _name),
        _CLASSICAL_WHAT.get(_name, f"controller spec {_name}"),
    )


def shipped_policies() -> dict[str, Path]:
    """{name: folder} of the policies shipped in ``agents/policies/``: the aliases
    (``default`` -> ``finetuned/s0``), ``<name>/`` and one level of groups, ``<group>/<name>/``
    named ``group/name`` (e.g. ``finetuned/s0``, one folder per training seed); the archive
    is not among them (`agents.runtime.policy_table`)."""
    return shipped_names()


def policy_names() -> list[str]:
    """Every name ``--policy`` accepts besides a path."""
    return list(CONTROLLERS) + [n for n in shipped_policies() if n not in CONTROLLERS]


def unwrapped_name(spec: str | Path) -> str | Path:
    """The policy ``NAME+of`` wraps (`bound_env.control.offset_free`), else ``spec``. A folder
    or file whose own name ends in ``+of`` is itself, unless what it would wrap is a policy's
    name (``default+of`` is always ``default`` held offset-free)."""
    text = str(spec)
    if not text.endswith(OF_SUFFIX) or text == OF_SUFFIX:
        return spec
    inner = text[: -len(OF_SUFFIX)]
    if _on_disk(text) and not _a_name(inner):
        return spec  # runs/x+of: that folder, not runs/x held offset-free
    return inner


def wrapped_policy(text: str) -> str:
    """What ``NAME+of`` holds offset-free (`unwrapped_name`); FileNotFoundError (one line)
    when neither ``text`` nor ``NAME`` is a policy, rather than a word about a ``NAME`` the
    user never gave alone."""
    inner = str(unwrapped_name(text))
    if not (
        _a_name(inner) or _on_disk(inner) or archived_message(inner) or inner.endswith(OF_SUFFIX)
    ):
        raise FileNotFoundError(
            f"policy {text!r} does not exist, nor {inner!r}, which {text!r} would hold "
            "offset-free (give a name, e.g. default+of, or a path)"
        )
    return inner


def _a_name(text: str) -> bool:
    """Whether ``text`` names a policy (possibly wrapped): a built-in or shipped name, a
    classical spec file."""
    inner = unwrapped_name(text)
    if inner != text:
        return _a_name(str(inner))
    return (
        text in CONTROLLERS or text in shipped_policies() or Path(text).suffix in (".yaml", ".yml")
    )


def _on_disk(text: str) -> bool:
    try:
        return Path(text).exists()
    except (OSError, ValueError):  # a name the OS refuses (too long, a NUL byte)
        return False


def resolve_policy(spec: str | Path) -> str | Path:
    """A built-in controller's name (returned as is), a shipped policy's folder, or a path.
    TypeError for what is not a name or path, ValueError for an empty one, FileNotFoundError
    (an archived name: where it went) for one that does not exist."""
    if not isinstance(spec, (str, Path)):
        raise TypeError(
            f"policy must be a name ({', '.join(policy_names())}) or a run or policy "
            f"folder's path, got {spec!r} ({type(spec).__name__})"
        )
    if not str(spec).strip():
        raise ValueError(
            f"policy {str(spec)!r} is empty: give a name ({', '.join(policy_names())}) or a run "
            "or policy folder's path"
        )
    text = str(spec)
    if text in CONTROLLERS:
        return text
    shipped = shipped_policies()
    if text in shipped:
        return shipped[text]
    p = Path(spec)
    if not _on_disk(text) and archived_message(text):
        raise FileNotFoundError(archived_message(text))
    if not _on_disk(text):
        for near in (SHIPPED_DIR / text, ARCHIVE_DIR / text, ARCHIVE_DIR / Path(text).name):
            if near.is_dir() and Path(text).name not in ("", ".", ".."):  # the folder's name
                raise FileNotFoundError(
                    f"policy {text!r} does not exist here; did you mean {near}? (an archived "
                    "policy loads by its path)"
                )
        raise FileNotFoundError(
            f"policy {text!r} does not exist (give a name: {', '.join(policy_names())}; or a "
            "run or policy directory with model.zip, or a model .zip)"
        )
    return p


@dataclass(eq=False)
class PolicyFolder:
    """A ``--policy`` name or path, resolved once (`resolve_policy`), with what the loaders
    read from it, each read once: the file names in its folder, its PPO files
    (`find_policy_files`) and its run config's section (`read_policy_section`)."""

    given: str | Path  # as the user gave it
    path: str | Path  # a built-in name (str), or a path (a spec .yaml: as given)
    names: frozenset = field(default_factory=frozenset)  # file names in the folder (a dir)

    @property
    def is_dir(self) -> bool:
        return bool(self.names) or (not isinstance(self.path, str) and Path(self.path).is_dir())

    def has(self, name: str) -> bool:
        """Whether the folder holds ``name``."""
        return name in self.names

    def kind_of_files(self) -> str | None:
        """`agents.common.schema.policy_kind` of the folder (a dir), refusing a folder with
        both a ``choice.npz`` and a ``model.zip``."""
        return policy_kind(self.path) if self.is_dir else None

    def kind_in(self, kinds, wrapped=None):
        """The first of ``kinds`` (modules of `agents.runtime.kinds`) whose ``RECOGNISED_BY``
        rule the folder meets (`meets`), or None; ``wrapped(section)`` decides the rule
        ``("wrapper",)`` (`agents.runtime.kinds.residual.wrapped`)."""
        for kind in kinds:
            rule = kind.RECOGNISED_BY
            if wrapped(self.section) if rule == ("wrapper",) else self.meets(rule):
                return kind
        return None

    def meets(self, rule: tuple) -> bool:
        """Whether the folder meets a kind's ``RECOGNISED_BY`` rule: ``("name",)`` a built-in
        name or spec, ``("file", NAME)`` a folder holding NAME, ``("files", KIND)`` a folder
        whose `policy_kind` is KIND, ``("env_id", IDS)`` a run config naming one of IDS,
        ``("any",)`` anything on disk."""
        what = rule[0]
        if what == "name":
            return isinstance(self.path, str)
        if what == "file":
            return self.has(rule[1]) and (Path(self.path) / rule[1]).is_file()
        if what == "files":
            return self.kind_of_files() == rule[1]
        if what == "env_id":
            return self.env_id in rule[1]
        return what == "any" and not isinstance(self.path, str)

    @cached_property
    def files(self) -> PolicyFiles:
        """The PPO files (`find_policy_files`); a ``choice.npz`` beside the model is refused."""
        files = find_policy_files(self.path)
        policy_kind(files.model.parent)  # a choice.npz beside the model: ambiguous, refused
        return files

    @cached_property
    def run(self) -> tuple[dict, str, int | None]:
        """(section, env id, seed) of the run config (`read_policy_section`)."""
        return read_policy_section(self.files)

    @property
    def section(self) -> dict | None:
        """The run config's section, None without a ``config.yaml``."""
        return self.run[0] if self.files.config is not None else None

    @property
    def env_id(self) -> str | None:
        """The env id the run config names, None without a ``config.yaml``."""
        return self.run[1] if self.files.config is not None else None


def read_folder(spec: str | Path) -> PolicyFolder:
    """The `PolicyFolder` of a name or path: a classical spec ``.yaml`` as given, else
    `resolve_policy` (its errors), and the file names of a folder."""
    if Path(str(spec)).suffix in (".yaml", ".yml"):  # a classical controller's spec file
        return PolicyFolder(spec, str(spec))
    path = resolve_policy(spec)
    names = frozenset()
    if not isinstance(path, str) and Path(path).is_dir():
        names = frozenset(p.name for p in Path(path).iterdir())
    return PolicyFolder(spec, path, names)
