"""Layering of the packages, read from the source with `ast`: imports point down only.

Every import counts, also those inside functions (deferred imports), those of a file's
``if __name__ == "__main__":`` block (they count as the module's own: a script block that
imports from above would hide a circle), and imports by name at run time: through
``importlib.import_module`` / ``__import__`` with a literal, with an f-string whose literal
prefix and one of the module's string constants name a module (``f"agents.{module}"``), and
through `agents.common.config.get_class_by_name` / `agents.common.config.preprocess`, which import
the classes the run configs name (``env_wrapper``, ``callback``, ``policy`` in configs/ and in the
shipped policies' config.yaml): the module that calls them imports those modules. Neither
`bound_env` nor `agents` has an import cycle, `bound_env` never imports `agents`,
`bound_env.analysis` never imports `bound_env.control` (the stride protocol they share is
`bound_env.sim.stride_protocol`, below both), the rooms of both packages point down, and no
module imports another one's private
(underscore) name. One check runs a command instead of reading
imports: the classical margins path (``bound-env margins --policy lqr``) never loads torch.
"""

import ast
import functools
import json
import subprocess
import sys
from pathlib import Path

import pytest

import bound_env
from agents import MOVED

ROOT = Path(__file__).resolve().parent.parent
PACKAGES = ("bound_env", "agents")
# Where the run configs live whose class paths `agents.common.config` imports by name
CONFIG_GLOBS = ("configs/**/*.yaml", "agents/policies/**/config.yaml")
# Functions of agents.common.config that import classes by name: the caller imports those modules
# (env_wrapper entries only for get_class_by_name's callers outside agents.common.config, which
# resolve a run's wrappers; every kind for preprocess, which builds a whole training run).
# agents.common.config itself is the resolver, not a user: its own calls count for its callers.
BY_NAME = {
    "get_class_by_name": ("env_wrapper",),
    "preprocess": ("env_wrapper", "callback", "policy"),
}


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


@functools.cache  # each file is parsed once per session (the checks walk the same trees)
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


@functools.cache
def _imported_names(mod: str, path: Path, is_pkg: bool) -> frozenset[str]:
    """Every dotted name ``mod`` imports, absolute, including ``from X import submodule``,
    its script block's and its imports by name (module docstring)."""
    tree = _tree(path)
    names = set()
    constants = {
        n.value for n in ast.walk(tree) if isinstance(n, ast.Constant) and isinstance(n.value, str)
    }
    for node in ast.walk(tree):
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
                elif isinstance(arg, ast.JoinedStr) and arg.values:
                    first = arg.values[0]
                    if isinstance(first, ast.Constant) and isinstance(first.value, str):
                        names.update(first.value + c for c in constants)  # f"agents.{x}"
            if fname in BY_NAME and mod != "agents.common.config":
                names.update(_config_modules(BY_NAME[fname]))
    return frozenset(names)


def _config_entries(value, key=None):
    """(config key, class path) of every ``env_wrapper``, ``callback`` and ``policy`` entry in
    a loaded YAML value."""
    if isinstance(value, dict):
        for k, v in value.items():
            if k in ("env_wrapper", "callback"):
                for entry in v if isinstance(v, list) else [v]:
                    for name in entry if isinstance(entry, dict) else [entry]:
                        if isinstance(name, str):
                            yield k, name
            elif k == "policy" and isinstance(v, str) and "." in v:
                yield k, v
            else:
                yield from _config_entries(v, k)
    elif isinstance(value, list):
        for v in value:
            yield from _config_entries(v, key)


@functools.cache
def _config_modules(keys: tuple[str, ...]) -> frozenset[str]:
    """The modules of the classes the run configs name under ``keys``."""
    import yaml

    out = set()
    for pattern in CONFIG_GLOBS:
        for f in sorted(ROOT.glob(pattern)):
            for k, name in _config_entries(yaml.safe_load(f.read_text())):
                if k in keys:
                    module = name.rsplit(".", 1)[0]
                    old = {**MOVED, **bound_env.MOVED}
                    out.add(old.get(module, module))  # an old flat name: its module now
    return frozenset(out)


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
    """Modules, their imported names and their edges (an old name of `MOVED` or
    `bound_env.MOVED`, imported through its alias, is an edge to the module it names)."""
    mods = _modules(*packages)
    imports = {m: _imported_names(m, *mods[m]) for m in mods}
    old = {**MOVED, **bound_env.MOVED}
    edges = {
        m: sorted({old.get(n, n) for n in names} & set(mods) - {m}) for m, names in imports.items()
    }
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
    assert "bound_env.commands.analysis_cli" in imports["bound_env.commands.cli"]
    assert "bound_env.model.params" in edges["bound_env.model.dynamics"]
    assert _cycles({"a": ["b"], "b": ["c"], "c": ["a"], "d": ["a"]}) == [["a", "b", "c"]]
    assert _cycles({"a": ["b"], "b": []}) == []
    # agents: deferred imports, script blocks and imports by name
    _, _, edges = _graph("agents")
    # inside the stride kind's load
    assert "agents.runtime.stride_policy" in edges["agents.runtime.kinds.stride"]
    assert "agents.common.config" in edges["agents.runtime.stride_policy"]  # inside wrapper_kwargs
    assert "agents.runtime.policy" in edges["agents.experts.stride_validation"]
    learned = {"agents.experts.distill", "agents.experts.finetune"}
    assert learned <= set(edges["agents.experts.learn_cli"])  # f-string
    # the controller wrapper agents.runtime.residual.ResidualOver, named in
    # configs/ppo-residual.yaml: get_class_by_name in controller_wrapper
    assert "agents.runtime.residual" in edges["agents.runtime.kinds.step"]
    assert {"agents.runtime.stride", "agents.training.train", "agents.runtime.residual"} <= set(
        edges["agents.training.train"] + ["agents.training.train"]
    )
    # the resolver: counted for its callers
    assert "agents.runtime.residual" not in edges["agents.common.config"]
    tree = ast.parse("if __name__ == '__main__':\n    import agents.runtime.policy\n")
    assert _script_blocks(tree)  # and such a block's imports are the module's own


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


# An import of bound_env.control that bound_env.analysis keeps until the module that has it is
# changed by its owner (the names it imports are those of bound_env.sim.stride_protocol, re-exported
# by bound_env.control.controllers): the test checks that this is all it takes from control.
PENDING: dict[str, set[str]] = {}  # analysis modules still importing the protocol through control


def test_analysis_never_imports_control():
    """bound_env.analysis (the Poincaré tools and the margins) never imports bound_env.control
    (the numerics both use live in bound_env.model), directly or through other modules."""
    import bound_env.control.controllers as controllers
    import bound_env.sim.stride_protocol as protocol

    _, imports, edges = _graph()
    for m, names in PENDING.items():
        assert {n for n in imports[m] if n.startswith("bound_env.control")} <= names | {
            n.rsplit(".", 1)[0] for n in names
        }
        for n in names:  # a re-export of the protocol, nothing of control's own
            assert getattr(controllers, n.rsplit(".", 1)[1]) is getattr(
                protocol, n.rsplit(".", 1)[1]
            )
        edges[m] = [e for e in edges[m] if not e.startswith("bound_env.control")]
    import bound_env.control.mpc as mpc

    assert mpc.DECISION_KINDS == protocol.DECISION_KINDS  # mpc.py's own copy, until it imports
    for start in (m for m in edges if m.startswith("bound_env.analysis")):
        seen, todo = set(), [start]
        while todo:
            for n in edges[todo.pop()]:
                if n not in seen:
                    seen.add(n)
                    todo.append(n)
        assert not [n for n in seen if n.startswith("bound_env.control")], start


@pytest.mark.parametrize("package", PACKAGES)
def test_no_import_cycle(package):
    _, _, edges = _graph(package)
    assert _cycles(edges) == []


def test_no_private_name_is_imported_across_modules():
    """A name another module needs is public; ``_name`` stays in its module."""
    assert _all_private_imports() == {}


# Runs each ``bound-env margins`` command line (JSON, argv[1]) in one fresh interpreter up to
# the point where the work starts (the first batch of tasks, `run_tasks`), and reports after
# each which heavy modules are loaded.
_UP_TO_THE_TASKS = """
import json
import sys

from bound_env.analysis.margins import run


class Reached(BaseException):  # not an Exception: nothing on the way catches it
    pass


def stop(*args, **kwargs):
    raise Reached


run.run_tasks = stop
from bound_env.commands.cli import main

for argv in json.loads(sys.argv[1]):
    try:
        main(argv)
    except Reached:
        heavy = sorted(m for m in ("torch", "stable_baselines3") if m in sys.modules)
        print(argv[2], "reached the tasks; heavy modules:", heavy)
"""


def test_classical_margins_never_import_torch(tmp_path):
    """The command line, the agents front, the controller (`bound_env.control` for lqr), the
    cycle scale and the cache key: everything ``margins`` loads before its first task, for lqr
    and then passive (one interpreter: the report after lqr is lqr's alone)."""
    runs = [
        ["margins", "--policy", policy, "--budget", "test", "--workers", "1", "--no-cache"]
        + ["--out", str(tmp_path / policy)]
        for policy in ("lqr", "passive")
    ]
    res = subprocess.run(
        [sys.executable, "-c", _UP_TO_THE_TASKS, json.dumps(runs)],
        cwd=ROOT,
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert res.returncode == 0, res.stderr
    for policy in ("lqr", "passive"):
        want = f"{policy} reached the tasks; heavy modules: []"
        assert want in res.stdout.splitlines(), res.stdout + res.stderr


@pytest.mark.parametrize(
    "low, high",
    [
        ("bound_env.model.params", "bound_env.model.dynamics"),
        ("bound_env.model.dynamics", "bound_env.model.events"),
        ("bound_env.model.events", "bound_env.model.fast"),
        ("bound_env.model.events", "bound_env.model.reference"),
        ("bound_env.model.fast", "bound_env.model.stride"),
        ("bound_env.model.reference", "bound_env.model.stride"),
        ("bound_env.model.reference", "bound_env.model.fast"),
        ("bound_env.model.stride", "bound_env.model.hybrid"),
        ("bound_env.model.stride", "bound_env.sim.task"),
        ("bound_env.sim.task", "bound_env.envs.env"),
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
    import bound_env.model.dynamics as dynamics
    import bound_env.model.params as params
    import bound_env.sim.task as task
    from bound_env.files.layout import Layout

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


# The longest a module may be, per package: a module longer than that holds more than one
# concept and is split along them (agents/compare.py was 1,147 lines, agents/stride.py 724;
# bound_env/sim/task.py 779 and rescue_env.py 659, split by their jobs: issue 39 asks <= 700)
MAX_LINES = {"agents": 600, "bound_env": 700}


@pytest.mark.parametrize("package", sorted(MAX_LINES))
def test_no_module_is_too_long(package):
    lines = {
        str(f.relative_to(ROOT)): len(f.read_text().splitlines())
        for f in sorted((ROOT / package).rglob("*.py"))
    }
    long = {f: n for f, n in lines.items() if n > MAX_LINES[package]}
    assert long == {}, f"over {MAX_LINES[package]} lines: split them along their concepts"


# agents/ in rooms by job, lowest first: a module imports its own room's modules and the rooms
# below it, never one above nor a sibling of its rank (training and experts are independent).
# The package itself (`agents/__init__.py`: `register_envs`, the old names' aliases) is below all.
ROOMS = {
    "agents": 0,
    "agents.common": 1,
    "agents.runtime": 2,
    "agents.training": 3,
    "agents.experts": 3,
    "agents.results": 4,
    "agents.multiseed": 5,
    "agents.cli": 6,
}
MAX_MODULES = 15  # per folder of agents/


def _room(module: str) -> str:
    """The room of a module: its subpackage (``agents.runtime``, ``bound_env.sim``), or the
    top-level module itself."""
    parts = module.split(".")
    return ".".join(parts[:2])


def _arrows_up(edges: dict[str, list[str]], rooms: dict[str, int] = ROOMS) -> list[str]:
    """Every import of ``edges`` from a room to another room not below it (in ``rooms``)."""
    bad = []
    for m, targets in edges.items():
        for n in targets:
            a, b = _room(m), _room(n)
            if a != b and rooms[b] >= rooms[a]:
                bad.append(f"{m} -> {n}")
    return bad


def test_the_room_check_sees_an_arrow_up():
    edges = {
        "agents.runtime.names": ["agents.experts.distill", "agents.common.schema"],
        "agents.training.train": ["agents.experts.distill", "agents.results.page"],
        "agents.results.page": ["agents.runtime.policy", "agents.results.prose"],
        "agents.common.schema": ["agents"],
    }
    assert _arrows_up(edges) == [
        "agents.runtime.names -> agents.experts.distill",
        "agents.training.train -> agents.experts.distill",  # siblings
        "agents.training.train -> agents.results.page",
    ]


def test_agents_rooms_point_down():
    """results -> training, experts -> runtime -> common (and the package root): training never
    imports the results page, runtime neither training nor experts; no circle (above)."""
    mods, _, edges = _graph("agents")
    assert {_room(m) for m in mods} == set(ROOMS)  # every module lives in a room
    assert _arrows_up(edges) == []


def test_agents_rooms_are_small_and_say_their_job():
    """No folder of agents/ with more than `MAX_MODULES` modules; each room's ``__init__`` says
    its job in one sentence."""
    for folder in [
        ROOT / "agents",
        *sorted(p.parent for p in (ROOT / "agents").glob("*/__init__.py")),
    ]:
        modules = [f for f in folder.glob("*.py") if f.name != "__init__.py"]
        assert len(modules) <= MAX_MODULES, folder
    for room in (r for r in ROOMS if r.count(".") == 1 and (ROOT / r.replace(".", "/")).is_dir()):
        doc = ast.get_docstring(_tree(ROOT / room.replace(".", "/") / "__init__.py"))
        assert doc and doc.count(". ") == 0 and doc.endswith("."), room


def test_old_flat_names_are_aliases_of_the_moved_modules():
    """``agents.policy`` & co. (run configs, shipped policies' pickled classes, users' scripts)
    name the module that moved, the same object; every alias points at a module that exists."""
    import importlib
    import importlib.util

    mods = _modules("agents")
    assert set(MOVED.values()) <= set(mods)
    assert all(not (ROOT / (old.replace(".", "/") + ".py")).exists() for old in MOVED)
    import agents.policy_files

    import agents.common.schema as schema

    assert importlib.import_module("agents.schema") is schema
    assert agents.policy_files is importlib.import_module("agents.common.policy_files")
    assert agents.policy_files.__spec__.name == "agents.common.policy_files"
    # the class paths of every run config (also the shipped ones, which are fingerprinted):
    # modules of agents, or of bound_env (an env wrapper of the simulator's, RandomizedPlant)
    named = _config_modules(("env_wrapper", "callback", "policy"))
    assert {m for m in named if not m.startswith("bound_env.")} <= set(mods)
    assert all(importlib.util.find_spec(m) for m in named if m.startswith("bound_env."))


# bound_env/ in rooms by job, lowest first, with the same rule as agents'. The package itself
# (`bound_env/__init__.py`: the env ids, their registration, the old names' aliases) sits on
# `files` (it chooses the Numba cache through `files.resources` before anything compiles);
# `analysis` and `control` are siblings on `sim` (the numerics and the exact Jacobian that both
# use live in `model`): neither imports the other; the envs sit on `control` (the rescue task
# designs its LQR, `LibraryActions` takes the MPC's profile library).
CORE_ROOMS = {
    "bound_env.files": 0,
    "bound_env": 1,
    "bound_env.model": 2,
    "bound_env.sim": 3,
    "bound_env.analysis": 4,
    "bound_env.control": 4,
    "bound_env.envs": 5,
    "bound_env.commands": 6,
}
# the rooms issue 47 made: each says its job in one sentence
NEW_CORE_ROOMS = (
    "files",
    "model",
    "sim",
    "envs",
    "commands",
    "analysis/margins/provenance",
    "analysis/margins/model_error",
    "analysis/reproduce/document",
)
# The crowded folders of the analysis in rooms of their own, lowest first: the folder's own
# modules (rank 0: the margins' measures and their closed loop; the reproduction's stages),
# its subpackages, then its front, the module that runs them all (and above it the package's
# ``__init__``, which re-exports it). The margins' cache key reads every measure's settings,
# the model error's included: provenance sits on model_error.
FOLDER_ROOMS = {
    "bound_env.analysis.margins": {"model_error": 1, "provenance": 2, "run": 3},
    "bound_env.analysis.reproduce": {"document": 1, "pipeline": 2},
}
# every module name that moved (the flat core's 33, the analysis commands and the numerics that
# analysis and control share): configs,
# fingerprints, pickles, Gymnasium entry points and older console scripts name them
OLD_CORE_NAMES = (
    "_dop853 cache cli cli_args dynamics env events fast hybrid layout mismatch parallel params "
    "randomized reference render render_cli rescue_common rescue_env rescue_v0 rescue_v1 "
    "resources schema stride stride_env stride_map stride_protocol stride_task task "
    "task_kernels terrain vector wrappers"
).split()
# the modules that moved into rooms of analysis/margins and analysis/reproduce
OLD_MARGINS_NAMES = (
    "code_closure fingerprint keys hold_delta mismatch_report mismatch_tasks".split()
)
OLD_REPRODUCE_NAMES = "report report_format report_numbers report_table".split()


def _in(module: str, folder: str) -> bool:
    return module == folder or module.startswith(folder + ".")


def _folder_room(module: str, folder: str, rooms: dict[str, int]) -> str:
    """The room of ``module`` inside ``folder``: its subpackage or front module of ``rooms``,
    ``__init__`` for the package itself, else ``folder`` (the folder's own modules)."""
    if module == folder:
        return "__init__"
    part = module[len(folder) + 1 :].split(".")[0]
    return part if part in rooms else folder


def _folder_arrows_up(edges: dict[str, list[str]], folder: str, rooms: dict[str, int]):
    """Every import between two rooms of ``folder`` (`FOLDER_ROOMS`) that does not point down."""
    ranks = {folder: 0, **rooms, "__init__": max(rooms.values()) + 1}
    bad = []
    for m, targets in edges.items():
        for n in (t for t in targets if _in(m, folder) and _in(t, folder)):
            a, b = _folder_room(m, folder, rooms), _folder_room(n, folder, rooms)
            if a != b and ranks[b] >= ranks[a]:
                bad.append(f"{m} -> {n}")
    return bad


def test_the_folder_room_check_sees_an_arrow_up():
    f = "bound_env.analysis.margins"
    edges = {
        f"{f}.basin": [f"{f}.provenance.keys", f"{f}.budget", "bound_env.model.params"],
        f"{f}.provenance.keys": [f"{f}.model_error.mismatch_tasks", f"{f}.basin", f"{f}.run"],
        f"{f}.model_error.mismatch_tasks": [f"{f}.provenance.fingerprint", f"{f}"],
        f"{f}.run": [f"{f}.provenance.keys", f"{f}.model_error.hold_delta"],
        f"{f}": [f"{f}.run"],
    }
    assert _folder_arrows_up(edges, f, FOLDER_ROOMS[f]) == [
        f"{f}.basin -> {f}.provenance.keys",
        f"{f}.provenance.keys -> {f}.run",
        f"{f}.model_error.mismatch_tasks -> {f}.provenance.fingerprint",
        f"{f}.model_error.mismatch_tasks -> {f}",
    ]


@pytest.mark.parametrize("folder", sorted(FOLDER_ROOMS))
def test_analysis_folder_rooms_point_down(folder):
    """margins: the measures -> model_error -> provenance -> run; reproduce: the stages ->
    document -> pipeline: no module of a folder imports a room of it above its own."""
    mods, _, edges = _graph("bound_env")
    rooms = FOLDER_ROOMS[folder]
    for room in rooms:  # every room of the table exists: a subpackage or a module
        assert f"{folder}.{room}" in mods, room
    assert _folder_arrows_up(edges, folder, rooms) == []


def test_the_room_check_sees_an_arrow_up_in_the_core():
    edges = {
        "bound_env.sim.parallel": ["bound_env.commands.cli_args", "bound_env.model.params"],
        "bound_env.analysis.margins.run": ["bound_env.control.spec", "bound_env.sim.task"],
        "bound_env.control.design": ["bound_env.analysis.numerics", "bound_env.model.numerics"],
        "bound_env.files.schema": ["bound_env"],
        "bound_env.envs.env": ["bound_env.envs.render", "bound_env.control.mpc"],
    }
    assert _arrows_up(edges, CORE_ROOMS) == [
        "bound_env.sim.parallel -> bound_env.commands.cli_args",
        "bound_env.analysis.margins.run -> bound_env.control.spec",  # siblings
        "bound_env.control.design -> bound_env.analysis.numerics",
        "bound_env.files.schema -> bound_env",
    ]


def test_core_rooms_point_down():
    """files -> the package -> model -> sim -> analysis, control (side by side) -> envs ->
    commands: the model never imports the simulation, the simulation never the command line,
    the analysis never the envs nor control; every module lives in a room."""
    mods, _, edges = _graph("bound_env")
    assert {_room(m) for m in mods} == set(CORE_ROOMS)
    assert _arrows_up(edges, CORE_ROOMS) == []


def test_core_rooms_are_small_and_say_their_job():
    """No folder of bound_env/, at any depth, with more than `MAX_MODULES` modules (bound_env/
    itself holds only the package); each new room's ``__init__`` says its job in one
    sentence."""
    assert sorted(f.name for f in (ROOT / "bound_env").glob("*.py")) == ["__init__.py"]
    folders = sorted(p.parent for p in (ROOT / "bound_env").rglob("*/__init__.py"))
    assert ROOT / "bound_env" / "analysis" / "margins" / "provenance" in folders
    for folder in folders:
        modules = [f for f in folder.glob("*.py") if f.name != "__init__.py"]
        assert len(modules) <= MAX_MODULES, folder
    for room in NEW_CORE_ROOMS:
        doc = ast.get_docstring(_tree(ROOT / "bound_env" / room / "__init__.py"))
        assert doc and doc.count(". ") == 0 and doc.endswith("."), room


def test_old_core_names_are_aliases_of_the_moved_modules():
    """``bound_env.task`` & co. name the module that moved, the same object, through every way
    in: ``import``, ``from ... import``, attributes of the package, Gymnasium's
    ``module:Name`` entry points and pickles. A name missing from `bound_env.MOVED` fails."""
    import importlib
    import pickle

    from gymnasium.envs.registration import load_env_creator

    old = {f"bound_env.{m}" for m in OLD_CORE_NAMES} | {
        f"bound_env.analysis.{m}" for m in ("cli", "numerics", "variational")
    }
    old |= {f"bound_env.analysis.margins.{m}" for m in OLD_MARGINS_NAMES}
    old |= {f"bound_env.analysis.reproduce.{m}" for m in OLD_REPRODUCE_NAMES}
    assert set(bound_env.MOVED) == old
    mods = _modules("bound_env")
    assert set(bound_env.MOVED.values()) <= set(mods)
    for name, now in bound_env.MOVED.items():
        assert not (ROOT / (name.replace(".", "/") + ".py")).exists(), name
        module = importlib.import_module(name)
        assert module is importlib.import_module(now), name
        assert module.__name__ == module.__spec__.name == now, name
    import bound_env.stride_map as old_map
    from bound_env.stride_map import StrideMap

    assert old_map is bound_env.stride_map is bound_env.sim.stride_map
    assert StrideMap is bound_env.sim.stride_map.StrideMap
    assert (
        load_env_creator("bound_env.task:PassiveBoundTask") is bound_env.sim.task.PassiveBoundTask
    )
    assert load_env_creator("bound_env.env:PassiveBoundEnv") is bound_env.envs.env.PassiveBoundEnv
    # a pickle written before the move names the old module
    old_pickle = pickle.dumps(bound_env.sim.task.TaskConfig, protocol=0).replace(
        b"bound_env.sim.task", b"bound_env.task"
    )
    assert b"bound_env.task" in old_pickle
    assert pickle.loads(old_pickle) is bound_env.sim.task.TaskConfig
    # a nested old name: ``from`` its package, and as a code closure's root (fingerprints)
    from bound_env.analysis.margins import keys
    from bound_env.analysis.margins.provenance.code_closure import closure_hashes

    assert keys is bound_env.analysis.margins.provenance.keys
    assert keys.setup_key is importlib.import_module("bound_env.analysis.margins.keys").setup_key
    for old_root, root in [
        ("bound_env.task:PassiveBoundTask", "bound_env.sim.task:PassiveBoundTask"),
        (
            "bound_env.analysis.margins.mismatch_tasks:task_mm_hold",
            "bound_env.analysis.margins.model_error.mismatch_tasks:task_mm_hold",
        ),
    ]:
        assert closure_hashes([old_root]) == closure_hashes([root]) != closure_hashes([])


def test_old_core_names_import_first_in_a_fresh_interpreter():
    """The old name as the first import of a process (an older ``bound-env`` console script,
    ``bound_env.cli:main``; a worker unpickling a task): the package's finder is in place."""
    code = (
        "import bound_env.cli as old, bound_env.commands.cli as now, sys\n"
        "assert old is now and old.main is now.main, (old, now)\n"
        "from bound_env.stride_map import StrideMap\n"
        "assert sys.modules['bound_env.stride_map'] is sys.modules['bound_env.sim.stride_map']\n"
        "from bound_env.analysis.margins.keys import setup_key\n"
        "from bound_env.analysis.margins.provenance import keys\n"
        "assert setup_key is keys.setup_key\n"
        "print('ok')\n"
    )
    res = subprocess.run(
        [sys.executable, "-c", code], cwd=ROOT, capture_output=True, text=True, timeout=300
    )
    assert res.returncode == 0 and res.stdout.strip() == "ok", res.stderr
