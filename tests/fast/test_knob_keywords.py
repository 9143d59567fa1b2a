"""Every call of a method's ``precompute`` in the source passes only knobs its spec declares.

A keyword a method does not declare is an :class:`~translucent.errors.InputError` at run
time (``KNOBS.resolve``), so a caller that still passes a retired keyword (``progress=``
once) breaks only when it runs. This test reads every Python file of the repository and
checks each literal keyword of ``<method>.precompute(...)`` (the method module imported
under any name) and of ``translucent.approx("<method>", ...)`` against the method's
declared knobs, so the break fails here, in the fast tier, whatever runs the call.
"""

from __future__ import annotations

import ast
from pathlib import Path

import pytest
from translucent.fast.registry import BUILTIN_METHODS, method

ROOT = Path(__file__).resolve().parents[2]

#: Keywords of ``translucent.approx`` that are not knobs.
APPROX_OWN_KEYWORDS = {"lights", "material"}

#: Folders that are not the project's source; the tests pass unknown knobs on purpose (to
#: see them refused) and run every call they make anyway.
SKIPPED = {".tox", ".git", ".asv", "build", "dist", ".venv", "__pycache__", "report", "tests"}


def _sources() -> list[Path]:
    return sorted(path for path in ROOT.rglob("*.py")
                  if not SKIPPED.intersection(path.relative_to(ROOT).parts))


def _method_aliases(tree: ast.AST) -> dict[str, str]:
    """Local name -> method name, for every import of a built-in method's module."""
    modules = {module.rsplit(".", 1)[-1]: name for name, module in BUILTIN_METHODS.items()}
    aliases = {}
    for node in ast.walk(tree):
        if isinstance(node, ast.ImportFrom) and (node.module or "").split(".")[-1] == "fast":
            for alias in node.names:
                if alias.name in modules:
                    aliases[alias.asname or alias.name] = modules[alias.name]
        elif isinstance(node, ast.Import):
            for alias in node.names:
                parts = alias.name.split(".")
                if len(parts) >= 2 and parts[-2] == "fast" and parts[-1] in modules \
                        and alias.asname:
                    aliases[alias.asname] = modules[parts[-1]]
    return aliases


def knob_calls(tree: ast.AST) -> list[tuple[str, int, list[str]]]:
    """``(method, line, literal keywords)`` of each precompute / approx call in ``tree``."""
    aliases = _method_aliases(tree)
    calls = []
    for node in ast.walk(tree):
        if not isinstance(node, ast.Call):
            continue
        function = node.func
        keywords = [keyword.arg for keyword in node.keywords if keyword.arg is not None]
        if isinstance(function, ast.Attribute) and function.attr == "precompute" \
                and isinstance(function.value, ast.Name) and function.value.id in aliases:
            calls.append((aliases[function.value.id], node.lineno, keywords))
        name = function.attr if isinstance(function, ast.Attribute) else \
            function.id if isinstance(function, ast.Name) else None
        if name == "approx" and node.args and isinstance(node.args[0], ast.Constant) \
                and node.args[0].value in BUILTIN_METHODS:
            calls.append((node.args[0].value, node.lineno,
                          [k for k in keywords if k not in APPROX_OWN_KEYWORDS]))
    return calls


def _declared(name: str) -> set[str]:
    module = method(name)
    knobs = getattr(module, "KNOBS", None)
    return {knob.name for knob in knobs} if knobs is not None else set(module.DEFAULT_KNOBS)


def test_every_literal_knob_keyword_in_the_source_is_declared():
    declared = {name: _declared(name) for name in BUILTIN_METHODS}
    checked, undeclared = 0, []
    for path in _sources():
        tree = ast.parse(path.read_text(encoding="utf-8"), filename=str(path))
        for name, line, keywords in knob_calls(tree):
            checked += 1
            undeclared += [f"{path.relative_to(ROOT)}:{line}: {name} has no knob {keyword!r}"
                           for keyword in keywords if keyword not in declared[name]]
    assert not undeclared, "\n".join(undeclared)
    # the scan finds the benches' and the stress tests' calls (it is not looking nowhere)
    assert checked >= 15


@pytest.mark.parametrize("source, expected", [
    ("from ...fast import prt\nprt.precompute(s, samples=1, progress=True)",
     [("prt", 2, ["samples", "progress"])]),
    ("from translucent.fast import splatting as sp\nsp.precompute(s, **k, frames=2)",
     [("splatting", 2, ["frames"])]),
    ("import translucent.fast.radiosity as rad\nrad.precompute(s, rays=3)",
     [("radiosity", 2, ["rays"])]),
    ("import translucent\ntranslucent.approx('brdf_pca', s, lights=(), gamma=2)",
     [("brdf_pca", 2, ["gamma"])]),
    ("other.precompute(s, progress=True)", []),
])
def test_the_scan_finds_a_call_however_the_method_is_imported(source, expected):
    assert knob_calls(ast.parse(source)) == expected


def test_an_undeclared_keyword_is_what_the_method_refuses_at_run_time():
    from translucent.errors import InputError

    assert "progress" not in _declared("prt")
    with pytest.raises(InputError, match="progress"):
        method("prt").KNOBS.resolve({"progress": True})
