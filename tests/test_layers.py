"""Layering of the package, read from the source with `ast`: imports point down only.

Every import counts, also those inside functions (deferred imports) and string imports through
``importlib.import_module`` / ``__import__``. One check runs instead: the classical margins
path (``bound-env margins --policy lqr``) never loads torch.
"""

import ast
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
PACKAGE = ROOT / "bound_env"


def _modules() -> dict[str, tuple[Path, bool]]:
    """Dotted module name -> (file, is a package ``__init__``)."""
    mods = {}
    for f in sorted(PACKAGE.rglob("*.py")):
        parts = list(f.relative_to(ROOT).with_suffix("").parts)
        is_pkg = parts[-1] == "__init__"
        mods[".".join(parts[:-1] if is_pkg else parts)] = (f, is_pkg)
    return mods


def _imported_names(mod: str, path: Path, is_pkg: bool) -> set[str]:
    """Every dotted name ``mod`` imports, absolute, including ``from X import submodule``."""
    names = set()
    for node in ast.walk(ast.parse(path.read_text(), filename=str(path))):
        if isinstance(node, ast.Import):
            names.update(a.name for a in node.names)
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = mod.split(".") if is_pkg else mod.split(".")[:-1]
                base = base[: len(base) - (node.level - 1)]
                module = ".".join(base + ([node.module] if node.module else []))
            else:
                module = node.module
            names.add(module)
            names.update(f"{module}.{a.name}" for a in node.names)
        elif isinstance(node, ast.Call):
            f = node.func
            fname = f.attr if isinstance(f, ast.Attribute) else getattr(f, "id", None)
            if fname in ("import_module", "__import__") and node.args:
                arg = node.args[0]
                if isinstance(arg, ast.Constant) and isinstance(arg.value, str):
                    names.add(arg.value)
    return names


def _graph():
    mods = _modules()
    imports = {m: _imported_names(m, *mods[m]) for m in mods}
    edges = {m: sorted(n for n in imports[m] if n in mods and n != m) for m in mods}
    return mods, imports, edges


def _cycles(edges: dict[str, list[str]]) -> list[list[str]]:
    """Strongly connected components with more than one module (Tarjan)."""
    index, low, stack, on_stack, found = {}, {}, [], set(), []

    def visit(v):
        index[v] = low[v] = len(index)
        stack.append(v)
        on_stack.add(v)
        for w in edges[v]:
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on_stack:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            comp = []
            while True:
                w = stack.pop()
                on_stack.discard(w)
                comp.append(w)
                if w == v:
                    break
            if len(comp) > 1:
                found.append(sorted(comp))

    for v in edges:
        if v not in index:
            visit(v)
    return found


def test_the_walker_sees_deferred_and_string_imports():
    mods, imports, edges = _graph()
    assert len(mods) > 10
    # deferred (function-level) imports count: stride is imported inside a function
    assert "bound_env.analysis.cli" in imports["bound_env.cli"]
    assert "bound_env.params" in edges["bound_env.dynamics"]
    assert _cycles({"a": ["b"], "b": ["c"], "c": ["a"], "d": ["a"]}) == [["a", "b", "c"]]
    assert _cycles({"a": ["b"], "b": []}) == []


def test_nothing_in_bound_env_imports_agents():
    _, imports, _ = _graph()
    offenders = {
        m: sorted(n for n in names if n == "agents" or n.startswith("agents."))
        for m, names in imports.items()
    }
    assert {m: v for m, v in offenders.items() if v} == {}


def test_no_import_cycle_inside_bound_env():
    _, _, edges = _graph()
    assert _cycles(edges) == []


# Runs ``bound-env margins`` in a fresh interpreter up to the point where the work starts (the
# first batch of tasks, `run_tasks`), then reports which heavy modules are loaded.
_UP_TO_THE_TASKS = """
import sys

from bound_env.analysis.margins import run


def stop(*args, **kwargs):
    heavy = sorted(m for m in ("torch", "stable_baselines3") if m in sys.modules)
    print("reached the tasks; heavy modules:", heavy)
    raise SystemExit(0)


run.run_tasks = stop
from bound_env.cli import main

sys.exit(main(sys.argv[1:]))
"""


@pytest.mark.parametrize("policy", ["lqr", "passive"])
def test_classical_margins_never_import_torch(policy, tmp_path):
    """The command line, the agents front, the controller (`bound_env.control` for lqr), the
    cycle scale and the cache key: everything ``margins`` loads before its first task."""
    argv = ["margins", "--policy", policy, "--budget", "test", "--workers", "1", "--no-cache"]
    res = subprocess.run(
        [sys.executable, "-c", _UP_TO_THE_TASKS, *argv, "--out", str(tmp_path / "m")],
        cwd=ROOT,
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert res.returncode == 0, res.stderr
    assert "reached the tasks; heavy modules: []" in res.stdout, res.stdout + res.stderr


@pytest.mark.parametrize(
    "low, high",
    [
        ("bound_env.params", "bound_env.dynamics"),
        ("bound_env.dynamics", "bound_env.events"),
        ("bound_env.events", "bound_env.fast"),
        ("bound_env.events", "bound_env.reference"),
        ("bound_env.fast", "bound_env.stride"),
        ("bound_env.reference", "bound_env.stride"),
        ("bound_env.reference", "bound_env.fast"),
        ("bound_env.stride", "bound_env.hybrid"),
        ("bound_env.stride", "bound_env.task"),
        ("bound_env.task", "bound_env.env"),
    ],
)
def test_simulator_layers_point_down(low, high):
    """A lower layer never imports a higher one, directly or through others."""
    _, _, edges = _graph()
    seen, todo = set(), [low]
    while todo:
        m = todo.pop()
        for n in edges[m]:
            if n not in seen:
                seen.add(n)
                todo.append(n)
    assert high not in seen


def test_flat_array_layouts_are_contiguous_and_exported():
    """Each family of offsets comes from one declaration: consecutive, non-overlapping fields,
    and the flat module constants equal the namespace's offsets."""
    import bound_env.dynamics as dynamics
    import bound_env.params as params
    import bound_env.task as task
    from bound_env.layout import Layout

    for module, layout in (
        (params, params.PARAM_LAYOUT),
        (params, params.AUX_LAYOUT),
        (task, task.STATE_LAYOUT),
        (task, task.CONFIG_LAYOUT),
    ):
        ns = layout.ns
        offsets = [getattr(ns, n) for n in layout.names]
        assert offsets[0] == layout.start and offsets == sorted(set(offsets))
        assert ns.SIZE == layout.size > offsets[-1]
        for name, value in layout.constants().items():
            assert getattr(module, name) == value
    assert params.AUX_LAYOUT.start == params.N_PARAMS
    assert dynamics.A_CB == params.A_CB and dynamics.N_AUX == params.N_AUX
    wide = Layout("X_", ("a", ("b", 3), "c"), "N_X", start=2)
    assert wide.constants() == {"X_A": 2, "X_B": 3, "X_C": 6, "N_X": 7}
    with pytest.raises(ValueError, match="unique"):
        Layout("X_", ("a", "A"), "N_X")
