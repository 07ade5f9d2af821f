"""The package's layering, as a test: core → models → tasks → design → report → explore → studies → cli.

Every ``import`` in fsdvs_hw — at module level *and* inside functions — is read with :mod:`ast`
(no code runs), resolved to the fsdvs_hw module it names, and checked: no module imports from a
higher layer, and no two modules import each other, directly or round a longer loop (a
function-level cycle is still a cycle: it only moves the failure to run time).

The design layer (:mod:`fsdvs_hw.design`: a design file's schema, validation and the ``Design``
object) is the input every layer above reads, so it sits below the report and the exploration
pipeline and may use the tasks and models below it, never explore.
"""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

PACKAGE = Path(__file__).resolve().parents[1] / "fsdvs_hw"

#: Layers, lowest first. A module may import from its own layer and the ones below.
LAYERS: tuple[str, ...] = ("core", "models", "tasks", "design", "report", "explore", "studies", "cli")

#: Top-level modules of the core layer (kernels, spectra, CSF, statistics and their helpers).
_CORE = {
    "errors",
    "paths",
    "resources",
    "validation",
    "schema",
    "limits",
    "kernels",
    "spectra",
    "csf",
    "stats",
    "workers",
    "prefetch",
    "allocator",
    "plots",
    "analysis",
    "_lazy",
    "progress",
    "provenance",
    "mutual_information",
    "environment",
    "fingerprints",
}
_MODELS = {"sensor", "scenes", "realise", "records", "costs", "process"}

#: Import cycles known and owned elsewhere (none).
KNOWN_CYCLES: tuple[frozenset[str], ...] = ()


def layer_of(module: str) -> str:
    """The layer of a dotted fsdvs_hw module name."""
    parts = module.split(".")
    if len(parts) == 1:
        return "core"  # the package itself: version and the lazy public-name map
    top, leaf = parts[1], parts[-1]
    if top == "cli" or leaf.endswith("_cli") or top.endswith("_cli"):
        return "cli"
    if top in _CORE:
        return "core"
    if top in _MODELS:
        return "models"
    if top == "tasks":
        return "tasks"
    if top == "design":
        return "design"
    if top == "report":
        return "report"
    if top == "explore":
        return "explore"
    if top == "studies":
        return "studies"
    raise AssertionError(f"{module}: no layer assigned; add it to tests/test_layering.py")


def _modules() -> dict[str, tuple[Path, bool]]:
    out: dict[str, tuple[Path, bool]] = {}
    for path in sorted(PACKAGE.rglob("*.py")):
        parts = list(path.relative_to(PACKAGE.parent).with_suffix("").parts)
        is_pkg = parts[-1] == "__init__"
        out[".".join(parts[:-1] if is_pkg else parts)] = (path, is_pkg)
    return out


def _targets(module: str, is_pkg: bool, node: ast.Import | ast.ImportFrom, known: set[str]) -> list[str]:
    """The fsdvs_hw modules one import statement loads (``from pkg import sub`` → ``pkg.sub``)."""
    if isinstance(node, ast.Import):
        return [a.name for a in node.names if a.name.split(".")[0] == "fsdvs_hw"]
    if node.level:
        base = module.split(".") if is_pkg else module.split(".")[:-1]
        base = base[: len(base) - (node.level - 1)]
        target = ".".join(base + ([node.module] if node.module else []))
    else:
        target = node.module or ""
    if target.split(".")[0] != "fsdvs_hw":
        return []
    return [f"{target}.{a.name}" if f"{target}.{a.name}" in known else target for a in node.names]


def import_graph() -> dict[str, dict[str, int]]:
    """module → {imported fsdvs_hw module: line of the first import}, function-level imports included."""
    mods = _modules()
    known = set(mods)
    graph: dict[str, dict[str, int]] = {m: {} for m in mods}
    for module, (path, is_pkg) in mods.items():
        tree = ast.parse(path.read_text(encoding="utf-8"), filename=str(path))
        # imports under ``if TYPE_CHECKING:`` never run (the lazy public names, listed for IDEs)
        static_only = {
            id(n)
            for block in ast.walk(tree)
            if isinstance(block, ast.If) and ast.unparse(block.test) in ("TYPE_CHECKING", "typing.TYPE_CHECKING")
            for stmt in block.body
            for n in ast.walk(stmt)
        }
        for node in ast.walk(tree):
            if id(node) in static_only:
                continue
            if isinstance(node, (ast.Import, ast.ImportFrom)):
                for target in _targets(module, is_pkg, node, known):
                    if target != module:
                        graph[module].setdefault(target, node.lineno)
    return graph


def cycles(graph: dict[str, dict[str, int]]) -> list[frozenset[str]]:
    """Strongly connected components of more than one module (Tarjan), i.e. the import cycles."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    found: list[frozenset[str]] = []
    counter = 0

    def visit(v: str) -> None:
        nonlocal counter
        index[v] = low[v] = counter
        counter += 1
        stack.append(v)
        on_stack.add(v)
        for w in graph.get(v, {}):
            if w not in graph:
                continue
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on_stack:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            comp = set()
            while True:
                w = stack.pop()
                on_stack.discard(w)
                comp.add(w)
                if w == v:
                    break
            if len(comp) > 1:
                found.append(frozenset(comp))

    for v in graph:
        if v not in index:
            visit(v)
    return found


def test_every_module_has_a_layer():
    for module in _modules():
        assert layer_of(module) in LAYERS


def test_no_module_imports_from_a_higher_layer():
    graph = import_graph()
    upward = [
        f"{m} ({layer_of(m)}) imports {t} ({layer_of(t)}) at line {line}"
        for m, targets in graph.items()
        for t, line in targets.items()
        if t in graph and LAYERS.index(layer_of(t)) > LAYERS.index(layer_of(m))
    ]
    assert not upward, "imports against the layer order:\n" + "\n".join(upward)


def test_no_import_cycles_function_level_included():
    found = [c for c in cycles(import_graph()) if c not in KNOWN_CYCLES]
    assert not found, "import cycles: " + "; ".join(" <-> ".join(sorted(c)) for c in found)


def test_the_known_cycle_list_is_not_stale():
    """A listed cycle that no longer exists must be removed from KNOWN_CYCLES (so it cannot come back)."""
    found = set(cycles(import_graph()))
    stale = [c for c in KNOWN_CYCLES if c not in found]
    assert not stale, f"fixed cycles still listed as known: {stale}"


@pytest.mark.parametrize(
    "source,expected",
    [
        ("from ..explore.scoring import score\n", {"fsdvs_hw.explore.scoring"}),
        ("def f():\n    from fsdvs_hw.cli import main\n", {"fsdvs_hw.cli"}),
        ("import fsdvs_hw.explore.sweep as sweep\n", {"fsdvs_hw.explore.sweep"}),
    ],
)
def test_the_walker_sees_module_and_function_level_imports(source, expected):
    """The checker itself: an upward import at module level or inside a function is found."""
    tree = ast.parse(source)
    known = set(_modules())
    got = {
        t
        for node in ast.walk(tree)
        if isinstance(node, (ast.Import, ast.ImportFrom))
        for t in _targets("fsdvs_hw.report.tables", False, node, known)
    }
    assert got == expected
    assert all(LAYERS.index(layer_of(t)) > LAYERS.index("report") for t in got)
