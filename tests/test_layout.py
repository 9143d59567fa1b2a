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
NOT_PACKAGE = {"tests", "examples", "docs", "build", "benchmarks"}

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


#: The modules every built-in method's package has: the contract (``method``), its knobs
#: and the interactive state; the physics and kernels beside them are the method's own.
METHOD_MODULES = ("__init__", "knobs", "method", "state")
BUILTIN_METHODS = ("prt", "radiosity", "splatting", "brdf_pca")


@pytest.mark.parametrize("name", BUILTIN_METHODS)
def test_every_method_is_a_package_of_the_same_shape(name):
    folder = ROOT / "fast" / name
    assert folder.is_dir(), f"fast/{name} is not a package"
    have = {path.stem for path in folder.glob("*.py")}
    assert set(METHOD_MODULES) <= have, f"fast/{name} lacks {set(METHOD_MODULES) - have}"
    # the contract lives in method.py: applies_to and precompute are defined there
    tree = ast.parse((folder / "method.py").read_text(encoding="utf-8"))
    defined = {node.name for node in tree.body if isinstance(node, ast.FunctionDef)}
    assert {"applies_to", "precompute"} <= defined, f"fast/{name}/method.py: {defined}"
    assert (ROOT / "docs" / f"{name}.md").is_file(), f"docs/{name}.md is missing"


def test_fast_holds_only_what_methods_share():
    # a loose module of fast/ serves several methods (or all): one that only one method
    # imports belongs in that method's package
    loose = [p for p in (ROOT / "fast").glob("*.py") if p.stem != "__init__"]
    for path in loose:
        module = f"translucent.fast.{path.stem}"
        users = {importer.split(".")[2] for importer, imported, _ in IMPORTS
                 if imported == module and importer.startswith("translucent.fast.")
                 and importer.count(".") >= 3 and importer.split(".")[2] in BUILTIN_METHODS}
        assert len(users) != 1, f"fast/{path.name} serves {users} alone: move it there"


def test_the_contract_tables_of_the_docs_are_made_from_the_contract():
    from translucent.fast.contract import contract_table

    page = (ROOT / "docs" / "methods.md").read_text(encoding="utf-8")
    assert contract_table(required=True) in page
    assert contract_table(required=False) in page


#: The report's orchestrator is called, not drawn from: only these import it (the command,
#: the package's functions and the report package, which offers make_report); the data
#: model, tasks and formatting have modules of their own that everything else imports.
REPORT_CALLERS = {"translucent.reports.commands.report", "translucent.api",
                  "translucent.reports.report"}


def test_only_the_reports_callers_import_the_orchestrator():
    importers = {importer for importer, imported, _ in IMPORTS
                 if imported == "translucent.reports.report.pipeline"}
    assert importers <= REPORT_CALLERS, sorted(importers - REPORT_CALLERS)


#: reports/ by concept: the metrics, the report, the benches, the stress sweeps, the
#: commands, each a subpackage; beside them only the command line and the pytest plugin.
REPORTS_MODULES = {"__init__", "cli", "pytest_plugin"}
REPORTS_PACKAGES = {"metrics", "report", "bench", "stress", "commands"}


def test_reports_is_split_by_concept():
    folder = ROOT / "reports"
    assert {p.stem for p in folder.glob("*.py")} == REPORTS_MODULES
    assert REPORTS_PACKAGES <= {p.name for p in folder.iterdir()
                                if (p / "__init__.py").is_file()}


#: The tables a metric's identity used to be spread over: each is made once, in the
#: metric registry, from the metrics' definitions.
METRIC_TABLES = {"METRIC_LABELS", "NOISE_FLOOR_FIELDS", "REPORTED_METRICS", "TOLERANCES"}


def test_each_metric_is_defined_once():
    from translucent.reports.metrics.registry import REGISTRY

    assigned = sorted((name, target.id) for name, path in MODULES.items()
                      for node in ast.parse(path.read_text()).body
                      if isinstance(node, (ast.Assign, ast.AnnAssign))
                      for target in (node.targets if isinstance(node, ast.Assign)
                                     else [node.target])
                      if isinstance(target, ast.Name) and target.id in METRIC_TABLES)
    assert {module for module, _ in assigned} == {"translucent.reports.metrics.registry"}, \
        assigned
    names = [spec.name for spec in REGISTRY]
    aliases = [alias for spec in REGISTRY for alias in spec.aliases]
    assert len(set(names + aliases)) == len(names) + len(aliases)


#: Lines a function of reports/ may have besides its docstring: a longer one does several
#: things (plan, run, judge, write) and is split.
MOST_FUNCTION_LINES = 80


def test_no_function_of_reports_is_over_80_lines():
    long = {}
    for name, path in MODULES.items():
        if not name.startswith("translucent.reports"):
            continue
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
                docstring = ast.get_docstring(node, clean=False)
                lines = node.end_lineno - node.lineno + 1
                if docstring:
                    lines -= docstring.count("\n") + 1
                if lines > MOST_FUNCTION_LINES:
                    long[f"{name}.{node.name}"] = lines
    assert not long, long
