"""Layering of the packages, read from the source with `ast`: imports point down only.

Every import counts, also those inside functions (deferred imports) and string imports through
``importlib.import_module`` / ``__import__``. A file's ``if __name__ == "__main__":`` block runs
only when the file is executed as a script (``python -m``), as the module ``__main__``, never
when the module is imported: its imports belong to a node of their own, ``<module> as
__main__``, that imports the module (nothing imports a script). Neither `bound_env` nor
`agents` has an import cycle, `bound_env` never imports `agents`, and no module imports
another one's private (underscore) name. One check runs a command instead of reading
imports: the classical margins path (``bound-env margins --policy lqr``) never loads torch.
"""

import ast
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
PACKAGES = ("bound_env", "agents")
SCRIPT = " as __main__"  # the node of a module's ``if __name__ == "__main__":`` block


def _modules(*packages: str) -> dict[str, tuple[Path, bool]]:
    """Dotted module name -> (file, is a package ``__init__``), of ``packages`` (default:
    `bound_env`)."""
    mods = {}
    files = [f for p in packages or ("bound_env",) for f in sorted((ROOT / p).rglob("*.py"))]
    for f in files:
        parts = list(f.relative_to(ROOT).with_suffix("").parts)
        is_pkg = parts[-1] == "__init__"
        mods[".".join(parts[:-1] if is_pkg else parts)] = (f, is_pkg)
    return mods


def _from_module(mod: str, is_pkg: bool, node: ast.ImportFrom) -> str:
    """The absolute module of ``from X import ...`` in ``mod``."""
    if not node.level:
        return node.module
    base = mod.split(".") if is_pkg else mod.split(".")[:-1]
    base = base[: len(base) - (node.level - 1)]
    return ".".join(base + ([node.module] if node.module else []))


def _tree(path: Path) -> ast.AST:
    return ast.parse(path.read_text(), filename=str(path))


def _script_blocks(tree: ast.Module) -> list[ast.If]:
    """The module's top-level ``if __name__ == "__main__":`` blocks."""
    return [
        n
        for n in tree.body
        if isinstance(n, ast.If)
        and isinstance(n.test, ast.Compare)
        and isinstance(n.test.left, ast.Name)
        and n.test.left.id == "__name__"
        and len(n.test.comparators) == 1
        and isinstance(n.test.comparators[0], ast.Constant)
        and n.test.comparators[0].value == "__main__"
    ]


def _imported_names(mod: str, path: Path, is_pkg: bool, script: bool = False) -> set[str]:
    """Every dotted name ``mod`` imports, absolute, including ``from X import submodule``;
    with ``script``, those of its ``if __name__ == "__main__":`` block instead."""
    tree = _tree(path)
    in_script = {id(n) for block in _script_blocks(tree) for n in ast.walk(block)}
    names = set()
    for node in ast.walk(tree):
        if (id(node) in in_script) != script:
            continue
        if isinstance(node, ast.Import):
            names.update(a.name for a in node.names)
        elif isinstance(node, ast.ImportFrom):
            module = _from_module(mod, is_pkg, node)
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


def _private_imports(mod: str, tree: ast.AST, is_pkg: bool, mods) -> list[str]:
    """``from X import _name`` in ``mod``, X another module of ``mods`` and ``_name`` not a
    module (a package may import its own private submodules, e.g. ``_dop853``)."""
    found = []
    for node in ast.walk(tree):
        if isinstance(node, ast.ImportFrom):
            module = _from_module(mod, is_pkg, node)
            if module not in mods or module == mod:
                continue
            for a in node.names:
                private = a.name.startswith("_") and not a.name.startswith("__")
                if private and f"{module}.{a.name}" not in mods:
                    found.append(f"line {node.lineno}: from {module} import {a.name}")
    return found


def _all_private_imports() -> dict[str, list[str]]:
    mods = _modules(*PACKAGES)
    found = {m: _private_imports(m, _tree(f), is_pkg, mods) for m, (f, is_pkg) in mods.items()}
    return {m: v for m, v in found.items() if v}


def _graph(*packages: str):
    mods = _modules(*packages)
    imports = {m: _imported_names(m, *mods[m]) for m in mods}
    for m in mods:  # a script runs its module's code, then its own block
        block = _imported_names(m, *mods[m], script=True)
        if block:
            imports[m + SCRIPT] = block | {m}
    edges = {m: sorted(n for n in names if n in mods and n != m) for m, names in imports.items()}
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
    # agents: deferred imports, and a script block on a node of its own
    _, _, edges = _graph("agents")
    assert "agents.stride" in edges["agents.policy"]  # inside load_controller
    assert "agents.config" in edges["agents.stride"]  # inside wrapper_kwargs
    assert "agents.policy" in edges["agents.stride" + SCRIPT]  # python -m agents.stride
    assert "agents.policy" not in edges["agents.stride"]
    assert "agents.stride" in edges["agents.stride" + SCRIPT]  # it runs the module's code too


def test_the_walker_sees_private_imports():
    mods = {"p": None, "p.a": None, "p.b": None, "p._c": None}
    code = (
        "from .b import _x, y\n"
        "from . import _c\n"  # a private submodule of the package: allowed
        "from .a import _own\n"  # its own name
        "def f():\n    from p.b import _z\n"
        "from numpy import _private_but_not_ours\n"
    )
    found = _private_imports("p.a", ast.parse(code), False, mods)
    assert found == ["line 1: from p.b import _x", "line 5: from p.b import _z"]


def test_nothing_in_bound_env_imports_agents():
    _, imports, _ = _graph()
    offenders = {
        m: sorted(n for n in names if n == "agents" or n.startswith("agents."))
        for m, names in imports.items()
    }
    assert {m: v for m, v in offenders.items() if v} == {}


@pytest.mark.parametrize("package", PACKAGES)
def test_no_import_cycle(package):
    _, _, edges = _graph(package)
    assert _cycles(edges) == []


def test_no_private_name_is_imported_across_modules():
    """A name another module needs is public; ``_name`` stays in its module."""
    assert _all_private_imports() == {}


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
