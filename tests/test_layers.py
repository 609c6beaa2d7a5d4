"""The package's imports flow one way: spec -> scene -> model -> core -> simulate/analysis -> fmu
-> tooling -> api -> cli (docs/explanation/architecture.md, "Code map"). A static check over the source (every ``import``, also those
inside functions): no import cycle, no import of a higher layer, and the tooling imports nothing
of the scene loader or the engine. The checker itself is tested on synthetic graphs."""
from __future__ import annotations

import ast
from pathlib import Path

import pytest

PACKAGE = Path(__file__).resolve().parent.parent / "fmu_src" / "overcon"

LAYERS = (
    # 0: the vocabulary: data records and helpers that import nothing above them
    ("spec", ("overcon", "overcon.spec", "overcon.params", "overcon.argtypes", "overcon.kinematics",
              "overcon.friction_laws", "overcon.joints", "overcon.figures", "overcon.verdict", "overcon.plots")),
    ("scene", ("overcon.scene", "overcon.schema", "overcon.draw")),
    ("model", ("overcon.model",)),
    ("core", ("overcon.kernel",)),
    ("simulate/analysis", ("overcon.analysis", "overcon.checks", "overcon.precheck", "overcon.simulate",
                           "overcon.along", "overcon.paper", "overcon.converge")),
    ("fmu", ("overcon.fmu",)),
    ("tooling", ("overcon.tooling",)),
    ("api", ("overcon.api",)),
    ("cli", ("overcon.cli",)),
)
"""Layer order, lowest first; a module belongs to the layer of its longest listed prefix."""

BY_NAME = {"overcon": "api"}
"""Modules placed by their exact name, not as a prefix: the package's ``__init__`` is the public
facade (it hands out overcon.api's names on first use), so it sits in the api layer, while a new
module ``overcon.x`` without a listed prefix still falls to layer 0 as before."""

TOOLING_MUST_NOT_IMPORT = ("overcon.scene", "overcon.model", "overcon.paper", "overcon.simulate", "overcon.kernel",
                           "overcon.checks", "overcon.precheck")
"""The tooling treats FMUs as black boxes: no scene loader, no engine (its facts come from the FMU)."""


def module_names(root: Path) -> dict[str, tuple[Path, bool]]:
    """Dotted module name -> (file, is a package ``__init__``) for every .py file under ``root``."""
    mods = {}
    for path in sorted(root.rglob("*.py")):
        parts = [root.name, *path.relative_to(root).with_suffix("").parts]
        is_pkg = parts[-1] == "__init__"
        mods[".".join(parts[:-1] if is_pkg else parts)] = (path, is_pkg)
    return mods


def _targets(name: str, is_pkg: bool, node: ast.AST, mods) -> set[str]:
    """The package modules an import statement of module ``name`` loads."""
    if isinstance(node, ast.Import):
        candidates = [a.name for a in node.names]
    else:
        if node.level:
            base = name.split(".")[: len(name.split(".")) - (0 if is_pkg else 1)]
            base = base[: len(base) - (node.level - 1)]
            module = ".".join(base + ([node.module] if node.module else []))
        else:
            module = node.module or ""
        # ``from pkg import sub``: the submodule when it is one, else the package
        candidates = [f"{module}.{a.name}" if f"{module}.{a.name}" in mods else module for a in node.names]
    out = set()
    for target in candidates:
        while target and target not in mods:
            target = target.rpartition(".")[0]
        if target and target != name:
            out.add(target)
    return out


def import_graph(root: Path) -> dict[str, set[str]]:
    """Module -> the package modules it imports (statically, anywhere in the file)."""
    mods = module_names(root)
    graph = {}
    for name, (path, is_pkg) in mods.items():
        tree = ast.parse(path.read_text(encoding="utf-8"), str(path))
        graph[name] = set()
        for node in ast.walk(tree):
            if isinstance(node, (ast.Import, ast.ImportFrom)):
                graph[name] |= _targets(name, is_pkg, node, mods)
    return graph


def layer_of(module: str, layers=LAYERS) -> int | None:
    if layers is LAYERS and module in BY_NAME:
        return [name for name, _ in layers].index(BY_NAME[module])
    best, level = -1, None
    for k, (_, prefixes) in enumerate(layers):
        for p in prefixes:
            if (module == p or module.startswith(p + ".")) and len(p) > best:
                best, level = len(p), k
    return level


def cycles(graph: dict[str, set[str]]) -> list[list[str]]:
    """The strongly connected components of more than one module (Tarjan), each sorted."""
    index, low, stack, on, out = {}, {}, [], set(), []

    def visit(v):
        index[v] = low[v] = len(index)
        stack.append(v)
        on.add(v)
        for w in sorted(graph.get(v, ())):
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            comp = []
            while True:
                w = stack.pop()
                on.discard(w)
                comp.append(w)
                if w == v:
                    break
            if len(comp) > 1:
                out.append(sorted(comp))

    for v in sorted(graph):
        if v not in index:
            visit(v)
    return out


def layer_problems(graph: dict[str, set[str]], layers=LAYERS) -> list[str]:
    """Modules without a layer, and imports of a higher layer ("a (tooling) -> b (cli)")."""
    problems = []
    for a in sorted(graph):
        la = layer_of(a, layers)
        if la is None:
            problems.append(f"{a}: in no layer (add it to LAYERS)")
            continue
        for b in sorted(graph[a]):
            lb = layer_of(b, layers)
            if lb is not None and lb > la:
                problems.append(f"{a} ({layers[la][0]}) imports {b} ({layers[lb][0]}): upward")
    return problems


# ------------------------------------------------------------------------------- the checker

def test_checker_finds_a_synthetic_cycle_and_an_upward_import():
    graph = {"p.a": {"p.b"}, "p.b": {"p.c"}, "p.c": {"p.a"}, "p.d": {"p.e"}, "p.e": set()}
    assert cycles(graph) == [["p.a", "p.b", "p.c"]]
    layers = (("low", ("p.a", "p.b", "p.c", "p.d")), ("high", ("p.e",)))
    assert layer_problems(graph, layers) == ["p.d (low) imports p.e (high): upward"]
    assert layer_problems({"q.x": set()}, layers) == ["q.x: in no layer (add it to LAYERS)"]
    assert cycles({"p.a": {"p.b"}, "p.b": set()}) == []


def test_checker_reads_relative_and_lazy_imports(tmp_path):
    pkg = tmp_path / "pkg"
    (pkg / "sub").mkdir(parents=True)
    (pkg / "__init__.py").write_text("")
    (pkg / "low.py").write_text("def f():\n    from .sub import top  # lazy, inside a function\n")
    (pkg / "sub" / "__init__.py").write_text("")
    (pkg / "sub" / "top.py").write_text("from .. import low\nfrom ..low import f\n")
    graph = import_graph(pkg)
    assert graph["pkg.low"] == {"pkg.sub.top"} and graph["pkg.sub.top"] == {"pkg.low"}
    assert cycles(graph) == [["pkg.low", "pkg.sub.top"]]
    layers = (("low", ("pkg",)), ("high", ("pkg.sub",)))
    assert layer_problems(graph, layers) == ["pkg.low (low) imports pkg.sub.top (high): upward"]


# ------------------------------------------------------------------------------- the package

@pytest.fixture(scope="module")
def graph():
    g = import_graph(PACKAGE)
    assert "overcon.cli" in g and "overcon.tooling.fmus" in g and "overcon.model" in g
    return g


def test_no_import_cycle(graph):
    assert cycles(graph) == []


def test_imports_flow_one_way(graph):
    assert layer_problems(graph) == []


def test_nothing_imports_the_cli(graph):
    assert [a for a, deps in graph.items() if "overcon.cli" in deps] == []


def test_compiling_never_evaluates(graph):
    assert graph["overcon.model"].isdisjoint({"overcon.evaluation", "overcon.analysis", "overcon.dynamics",
                                              "overcon.kernel", "overcon.checks"})


def test_tooling_imports_no_scene_loader_and_no_engine(graph):
    bad = {a: sorted(deps & set(TOOLING_MUST_NOT_IMPORT)) for a, deps in graph.items()
           if a.startswith("overcon.tooling")}
    assert {a: d for a, d in bad.items() if d} == {}


# ------------------------------------------------------------------------------- unit size

MAX_FUNCTION_LINES = 80
LONG_FUNCTIONS_ALLOWED: set[tuple[str, str]] = set()  # none: every function fits


def long_functions(root: Path, limit: int = MAX_FUNCTION_LINES) -> list[tuple[str, str, int]]:
    """(file relative to root's parent, function name, lines) of every function longer than
    ``limit`` lines (decorators excluded, docstring included)."""
    out = []
    for path in sorted(root.rglob("*.py")):
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"), str(path))):
            if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
                n = node.end_lineno - node.lineno + 1
                if n > limit:
                    out.append((path.relative_to(root.parent).as_posix(), node.name, n))
    return out


def test_long_functions_are_found(tmp_path):
    pkg = tmp_path / "pkg"
    pkg.mkdir()
    body = "\n".join(f"    x{k} = {k}" for k in range(80))
    (pkg / "m.py").write_text(f"def long():\n{body}\n\n\ndef short():\n    return 1\n")
    assert long_functions(pkg) == [("pkg/m.py", "long", 81)]


def test_every_function_fits_on_a_screen():
    too_long = [f for f in long_functions(PACKAGE) if f[:2] not in LONG_FUNCTIONS_ALLOWED]
    assert too_long == []
