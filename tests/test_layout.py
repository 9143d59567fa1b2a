"""The package's layout: imports point one way, no cycle, no private name imported across modules.

Read from the source with :mod:`ast` (nothing is imported): every ``import`` and ``from ...
import`` of a ``translucent`` module, at module level or inside a function, except those
under ``if TYPE_CHECKING:`` (annotations only).
"""

import ast
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]

#: Folders that are not the package.
NOT_PACKAGE = {"tests", "examples", "docs", "build"}

#: Concept -> the concepts it may import (the suite's top-level modules, such as errors,
#: image, cache and backend, are open to all). materials -> scenes -> reference | fast ->
#: reports; fitting -> materials.
MAY_IMPORT = {
    "materials": {"materials"},
    "scenes": {"materials", "scenes"},
    "reference": {"materials", "scenes", "reference"},
    "fast": {"materials", "scenes", "fast"},
    "fitting": {"materials", "fitting"},
    "reports": {"materials", "scenes", "reference", "fast", "fitting", "reports"},
}


def _modules() -> dict[str, Path]:
    found = {}
    for path in ROOT.rglob("*.py"):
        parts = path.relative_to(ROOT).parts
        if parts[0] in NOT_PACKAGE or any(p.startswith(".") for p in parts):
            continue
        name = ".".join(("translucent",) + path.relative_to(ROOT).with_suffix("").parts)
        found[name.removesuffix(".__init__")] = path
    return found


def _type_checking_nodes(tree) -> set[int]:
    skipped = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.If) and "TYPE_CHECKING" in ast.unparse(node.test):
            for inner in node.body:
                skipped |= {id(n) for n in ast.walk(inner)}
    return skipped


def _imports(modules):
    """Yield (importer, imported module, name or None) for every translucent import."""
    for name, path in modules.items():
        tree = ast.parse(path.read_text())
        skipped = _type_checking_nodes(tree)
        package = name if path.name == "__init__.py" else name.rsplit(".", 1)[0]
        for node in ast.walk(tree):
            if id(node) in skipped:
                continue
            if isinstance(node, ast.ImportFrom):
                if node.level:
                    base = package.split(".")[: len(package.split(".")) - node.level + 1]
                    target = ".".join(base + ([node.module] if node.module else []))
                else:
                    target = node.module or ""
                if target.split(".")[0] != "translucent":
                    continue
                for alias in node.names:
                    submodule = f"{target}.{alias.name}"
                    if submodule in modules:
                        yield name, submodule, None
                    else:
                        yield name, target, alias.name
            elif isinstance(node, ast.Import):
                for alias in node.names:
                    if alias.name.split(".")[0] == "translucent":
                        yield name, alias.name, None


MODULES = _modules()
IMPORTS = list(_imports(MODULES))


def _concept(module: str) -> str | None:
    parts = module.split(".")
    return parts[1] if len(parts) > 2 or (len(parts) == 2 and parts[1] in MAY_IMPORT) \
        else None


def test_the_layout_is_read():
    assert len(MODULES) > 100 and len(IMPORTS) > 300
    assert "translucent.fast.registry" in MODULES


@pytest.mark.parametrize("concept", sorted(MAY_IMPORT))
def test_imports_point_one_way(concept):
    wrong = sorted({(importer, imported) for importer, imported, _ in IMPORTS
                    if _concept(importer) == concept and _concept(imported) in MAY_IMPORT
                    and _concept(imported) not in MAY_IMPORT[concept]})
    assert not wrong, f"{concept} may import only {sorted(MAY_IMPORT[concept])}: {wrong}"


def test_no_private_name_is_imported_from_another_module():
    private = sorted({(importer, f"{imported}.{name}") for importer, imported, name in IMPORTS
                      if name and name.startswith("_") and not name.startswith("__")
                      and imported != importer})
    assert not private, private


def test_the_import_graph_has_no_cycle():
    graph = {name: set() for name in MODULES}
    for importer, imported, _ in IMPORTS:
        if imported in MODULES and imported != importer and \
                not importer.startswith(imported + "."):  # a package's own __init__ chain
            graph[importer].add(imported)
    state, cycles = {}, []

    def visit(node, path):
        state[node] = "open"
        for following in sorted(graph[node]):
            if state.get(following) == "open":
                cycles.append(path[path.index(following):] + [following])
            elif following not in state:
                visit(following, path + [following])
        state[node] = "done"

    for node in sorted(graph):
        if node not in state:
            visit(node, [node])
    assert not cycles, cycles[:5]


#: A file longer than this holds two concepts: split it (tests too).
MOST_LINES = 900


def test_no_file_holds_two_concepts():
    long = {}
    for path in ROOT.rglob("*.py"):
        parts = path.relative_to(ROOT).parts
        if "build" in parts or any(p.startswith(".") for p in parts):
            continue
        lines = len(path.read_text(encoding="utf-8").splitlines())
        if lines > MOST_LINES:
            long[str(path.relative_to(ROOT))] = lines
    assert not long, f"over {MOST_LINES} lines: {long}"
