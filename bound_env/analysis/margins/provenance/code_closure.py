"""The code a controller runs, found by following its imports within the project
(`closure_hashes`), and the code of a source file as it runs (`code_text`).

`code_text` is a module's syntax tree without its docstrings (and without bare string
statements), printed back: an edited docstring or comment, or a reformatted line, does not
change it; any code or constant edit, an import included, does. Every code hash of the margins
reads through it: the cache key's `keys.source_hash` and the closure below, and every file
through `read_source` (the one place a test edits a source without touching the file).

The closure is per object, definition by definition: its roots are the classes of a
controller and of every project object it holds (`object_roots`: an MPC's LQR and stride map,
a wrapper's inner controller, a residual's base), and from each definition (a class, a
function, a module-level assignment) it follows every name the definition uses: a definition
of the same module, or a name imported (at the top or inside a function) from a module of the
project (a ``.py`` file under `ROOT`), across re-exports and ``module.NAME`` attributes. Two
classes of one module have two closures: editing ``MLPController`` leaves the zero
controller's closure as it was. A module used as a value (not through an attribute) counts
whole. Names of other packages (numpy, the standard library) are not followed: they are not
the project's code.
"""

from __future__ import annotations

import ast
import hashlib
import types
from pathlib import Path

from .... import MOVED

ROOT = Path(__file__).resolve().parents[4]  # the project: bound_env/ and its sibling packages
DEPTH = 3  # levels of held objects `object_roots` follows
MODULE_BODY = "<module>"  # a module's top-level statements that bind no name (run at import)


def read_source(path) -> str:
    """The text of a source file: every code hash reads here."""
    return Path(path).read_text(encoding="utf-8")


def _is_text(node) -> bool:
    return (
        isinstance(node, ast.Expr)
        and isinstance(node.value, ast.Constant)
        and isinstance(node.value.value, str)
    )


def _strip(tree: ast.AST) -> ast.AST:
    """``tree`` without docstrings and bare string statements (they run nothing)."""
    for node in ast.walk(tree):
        for name in ("body", "orelse", "finalbody"):
            body = getattr(node, name, None)
            if isinstance(body, list) and body and isinstance(body[0], ast.stmt):
                kept = [n for n in body if not _is_text(n)]
                setattr(node, name, kept or ([ast.Pass()] if name == "body" else []))
    return tree


# memos, by the text's sha256 (a tree) or by a node of a memoized tree (its text, its names):
# the trees live as long as the process, so a node's id is its own
_TREES: dict[str, ast.Module] = {}
_TEXTS: dict[int, str] = {}
_CHAINS: dict[int, tuple] = {}


def _tree(source: str) -> ast.Module:
    key = hashlib.sha256(source.encode()).hexdigest()
    if key not in _TREES:
        _TREES[key] = _strip(ast.parse(source))
    return _TREES[key]


def code_text(source: str) -> str:
    """The code of ``source`` (module docstring): its syntax tree without docstrings, printed."""
    return _unparse(_tree(source))


def _unparse(node) -> str:
    if id(node) not in _TEXTS:
        _TEXTS[id(node)] = ast.unparse(node)
    return _TEXTS[id(node)]


def file_code_hash(path) -> str:
    """sha256 of a file's code: `code_text` of a ``.py`` file (through `read_source`), the
    bytes of any other file."""
    path = Path(path)
    if path.suffix == ".py":
        data = code_text(read_source(path)).encode()
    else:
        data = path.read_bytes()
    return hashlib.sha256(data).hexdigest()


def canonical(name: str) -> str:
    """The name of module ``name`` now: an old name of a module that moved into a room
    (`bound_env.MOVED`, as older code and recorded roots spell it) is its module's, so that a
    closure is the same whichever name reaches it."""
    return MOVED.get(name, name)


def module_file(name: str) -> Path | None:
    """The project file of module ``name`` (``a.b`` -> ``ROOT/a/b.py`` or its package's
    ``__init__.py``; an old name, `canonical`), None for a module outside the project."""
    if not name or name.startswith("."):
        return None
    base = ROOT.joinpath(*canonical(name).split("."))
    for p in (base.with_name(base.name + ".py"), base / "__init__.py"):
        if p.is_file():
            return p
    return None


class _Module:
    """A project module's top-level definitions (name -> statements that bind it), its
    imports (alias -> (module, attribute or None)), star imports and other statements
    (``body``: what its import runs, its import statements included, so that a name imported
    from elsewhere is another closure)."""

    def __init__(self, name: str, path: Path):
        self.name = name
        self.package = name if path.name == "__init__.py" else name.rpartition(".")[0]
        self.defs: dict[str, list] = {}
        self.imports: dict[str, tuple] = {}
        self.stars: list[str] = []
        self.body: list = []
        self._read(_tree(read_source(path)).body)

    def _read(self, stmts) -> None:
        for s in stmts:
            if isinstance(s, (ast.FunctionDef, ast.AsyncFunctionDef, ast.ClassDef)):
                self.defs.setdefault(s.name, []).append(s)
            elif isinstance(s, (ast.Import, ast.ImportFrom)):  # hashed with the module's body
                self.imports.update(imports_of(s, self.package, self.stars))
                self.body.append(s)
            elif isinstance(s, (ast.Assign, ast.AnnAssign, ast.AugAssign)):
                targets = s.targets if isinstance(s, ast.Assign) else [s.target]
                names = [n.id for t in targets for n in ast.walk(t) if isinstance(n, ast.Name)]
                for n in names or [MODULE_BODY]:
                    self.defs.setdefault(n, []).append(s)
            elif isinstance(s, (ast.If, ast.Try)):  # `if TYPE_CHECKING:`, `try: import x`
                self.body.append(s)
                for part in ("body", "orelse", "finalbody"):
                    self._read(getattr(s, part, []))
                for h in getattr(s, "handlers", []):
                    self._read(h.body)
            else:
                self.body.append(s)


def _absolute(module: str | None, level: int, package: str) -> str:
    if not level:
        return module or ""
    base = package.split(".")
    base = base[: len(base) - (level - 1)] if level > 1 else base
    return ".".join(base + ([module] if module else []))


def imports_of(stmt, package: str, stars: list | None = None) -> dict:
    """{alias: (module, attribute or None)} of one import statement, the project's only."""
    out = {}
    if isinstance(stmt, ast.Import):
        for a in stmt.names:
            if a.asname:
                if module_file(a.name):
                    out[a.asname] = (canonical(a.name), None)
            else:
                top = a.name.split(".")[0]
                if module_file(top):
                    out[top] = (top, None)
        return out
    mod = canonical(_absolute(stmt.module, stmt.level, package))
    if not module_file(mod):
        return out
    for a in stmt.names:
        if a.name == "*":
            if stars is not None:
                stars.append(mod)
        else:
            out[a.asname or a.name] = (mod, a.name)
    return out


class Closure:
    """The definitions reachable from some roots ((module, name) pairs): `items`."""

    def __init__(self):
        self.modules: dict[str, _Module | None] = {}
        self.items: set[tuple[str, str]] = set()
        self._todo: list[tuple[str, str]] = []

    def module(self, name: str) -> _Module | None:
        if name not in self.modules:
            path = module_file(name)
            self.modules[name] = _Module(name, path) if path else None
        return self.modules[name]

    def add(self, module: str, name: str) -> None:
        if (module, name) not in self.items:
            self.items.add((module, name))
            self._todo.append((module, name))
            if (module, MODULE_BODY) not in self.items:  # what the import runs
                self.add(module, MODULE_BODY)

    def run(self, roots) -> Closure:
        for module, name in roots:
            self.in_module(canonical(module), [name])
        while self._todo:
            module, name = self._todo.pop()
            self._follow(self.module(module), name)
        return self

    def nodes(self, module: str, name: str) -> list:
        m = self.module(module)
        if m is None:
            return []
        return m.body if name == MODULE_BODY else m.defs.get(name, [])

    def _follow(self, mod: _Module | None, name: str) -> None:
        if mod is None:
            return
        nodes = self.nodes(mod.name, name)
        local: dict = {}
        for node in nodes:
            local.update(_local_imports(node, mod.package))
        for node in nodes:
            for chain in _chains(node):
                self.resolve(mod, chain, local)

    def resolve(self, mod: _Module, chain: list[str], local: dict) -> None:
        head, rest = chain[0], chain[1:]
        target = local.get(head) or mod.imports.get(head)
        if target is not None:
            m, attr = target
            self.in_module(m, ([attr] if attr else []) + rest)
        elif head in mod.defs:
            self.add(mod.name, head)
        else:
            for star in mod.stars:
                s = self.module(star)
                if s is not None and (head in s.defs or head in s.imports):
                    self.in_module(star, chain)

    def in_module(self, module: str, rest: list[str], depth: int = 0) -> None:
        m = self.module(module)
        if m is None or depth > 20:
            return
        if not rest:  # the module itself, used as a value: all of it
            for name in list(m.defs) + [MODULE_BODY]:
                self.add(module, name)
            return
        x = rest[0]
        if x in m.defs:
            self.add(module, x)
        elif x in m.imports:
            m2, attr = m.imports[x]
            self.add(module, MODULE_BODY)
            self.in_module(m2, ([attr] if attr else []) + rest[1:], depth + 1)
        elif module_file(f"{module}.{x}"):
            self.in_module(canonical(f"{module}.{x}"), rest[1:], depth + 1)
        else:
            for star in m.stars:
                self.in_module(star, rest, depth + 1)
            if not m.stars:
                self.in_module(module, [], depth + 1)  # not found: the whole module


def _local_imports(node, package: str) -> dict:
    key = (id(node), package, "imports")
    if key not in _CHAINS:
        local: dict = {}
        for n in ast.walk(node):
            if isinstance(n, (ast.Import, ast.ImportFrom)):
                local.update(imports_of(n, package))
        _CHAINS[key] = local
    return _CHAINS[key]


def _chains(node) -> tuple:
    """Every dotted name the node uses (``a.b.c`` as [a, b, c]; a bare name as [a])."""
    if id(node) not in _CHAINS:
        _CHAINS[id(node)] = tuple(_find_chains(node))
    return _CHAINS[id(node)]


def _find_chains(node) -> list[list[str]]:
    out, inner = [], set()
    for n in ast.walk(node):
        if isinstance(n, ast.Attribute) and id(n) not in inner:
            parts, cur = [], n
            while isinstance(cur, ast.Attribute):
                inner.add(id(cur))
                parts.append(cur.attr)
                cur = cur.value
            if isinstance(cur, ast.Name):
                inner.add(id(cur))
                out.append([cur.id, *reversed(parts)])
    for n in ast.walk(node):
        if isinstance(n, ast.Name) and id(n) not in inner:
            out.append([n.id])
    return out


def _defined_in_project(obj) -> tuple[str, str] | None:
    module = getattr(obj, "__module__", None)
    name = getattr(obj, "__qualname__", None)
    if module and name and module_file(module):
        return module, name.split(".")[0]
    return None


def object_roots(obj, depth: int = DEPTH) -> list[str]:
    """``module:Name`` of the project classes (and functions) of ``obj`` and of the objects it
    holds, ``depth`` levels deep (attributes, list/tuple/dict items), sorted."""
    roots, seen, todo = set(), set(), [(obj, 0)]
    while todo:
        o, d = todo.pop()
        if id(o) in seen or isinstance(o, (str, bytes, int, float, bool, type(None))):
            continue
        seen.add(id(o))
        if isinstance(o, (types.FunctionType, type)):
            r = _defined_in_project(o)
            if r:
                roots.add(r)
            continue
        if hasattr(o, "func") and callable(getattr(o, "func", None)):  # functools.partial
            todo.append((o.func, d))
        for cls in type(o).__mro__:
            r = _defined_in_project(cls)
            if r:
                roots.add(r)
        if d >= depth:
            continue
        values = []
        if isinstance(o, dict):
            values = list(o.values())
        elif isinstance(o, (list, tuple, set, frozenset)):
            values = list(o)
        elif hasattr(o, "__dict__") and _defined_in_project(type(o)):
            values = list(vars(o).values())
        todo.extend((v, d + 1) for v in values[:1000])
    return sorted(f"{m}:{n}" for m, n in roots)


def closure_hashes(roots) -> dict:
    """{"code": ..., "constants": ...}: sha256 (16 hex digits) of the closure of ``roots``
    (``module:Name`` strings): the definitions that are module-level assignments
    (constants), and the others (classes, functions, import-time statements), each named by
    its module and name and printed by `code_text`'s rules."""
    pairs = [tuple(r.split(":", 1)) for r in roots]
    c = Closure().run(pairs)
    code, constants = hashlib.sha256(), hashlib.sha256()
    for module, name in sorted(c.items):
        nodes = c.nodes(module, name)
        is_constant = bool(nodes) and all(
            isinstance(n, (ast.Assign, ast.AnnAssign, ast.AugAssign)) for n in nodes
        )
        h = constants if is_constant and name != MODULE_BODY else code
        h.update(f"{module}:{name}\0".encode())
        for n in nodes:
            h.update(_unparse(n).encode() + b"\0")
    return {"code": code.hexdigest()[:16], "constants": constants.hexdigest()[:16]}


def closure_items(roots) -> list[str]:
    """The closure's definitions as ``module:name`` (what `closure_hashes` hashes), sorted."""
    c = Closure().run([tuple(r.split(":", 1)) for r in roots])
    return sorted(f"{m}:{n}" for m, n in c.items)


def code_parts(roots) -> dict:
    """``roots`` (sorted ``module:Name``), ``code`` and ``constants`` of their closure."""
    roots = sorted(str(r) for r in roots)
    return {"roots": roots, **closure_hashes(roots)}
