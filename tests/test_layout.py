"""Layout of the package: no import cycle among fingerfit's modules.

Every import counts, wherever it is: at the top of a module, inside a function (a lazy
import) or under ``if TYPE_CHECKING:``. A cycle of any of them means two modules that
each need the other, so data no longer flow one way.
"""

from __future__ import annotations

import ast
from pathlib import Path

import fingerfit

SRC = Path(fingerfit.__file__).resolve().parent.parent

#: Cycles known and accepted, each as the sorted modules of one strongly connected
#: component, with the reason (none today).
KNOWN_CYCLES: set[tuple[str, ...]] = set()


def module_names(src: Path, package: str) -> dict[str, tuple[Path, bool]]:
    """Every module of ``package`` under ``src``: dotted name -> (file, is a package)."""
    out = {}
    for path in sorted((src / package).rglob("*.py")):
        parts = list(path.relative_to(src).with_suffix("").parts)
        is_package = parts[-1] == "__init__"
        if is_package:
            parts = parts[:-1]
        out[".".join(parts)] = (path, is_package)
    return out


def _absolute(module: str | None, level: int, here: str, is_package: bool) -> str:
    """The absolute name of ``from <level dots><module> import ...`` in module ``here``."""
    if level == 0:
        return module or ""
    base = here.split(".") if is_package else here.split(".")[:-1]
    base = base[: len(base) - (level - 1)]
    return ".".join([*base, *([module] if module else [])])


def import_graph(src: Path, package: str) -> dict[str, set[str]]:
    """Module -> the modules of ``package`` it imports (anywhere in its file).

    ``from X import name`` is an edge to ``X.name`` when that is a module, else to ``X``.
    """
    modules = module_names(src, package)
    graph: dict[str, set[str]] = {}
    for here, (path, is_package) in modules.items():
        deps: set[str] = set()
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
            if isinstance(node, ast.Import):
                deps.update(alias.name for alias in node.names)
            elif isinstance(node, ast.ImportFrom):
                target = _absolute(node.module, node.level, here, is_package)
                for alias in node.names:
                    sub = f"{target}.{alias.name}"
                    deps.add(sub if sub in modules else target)
        graph[here] = {d for d in deps if d in modules and d != here}
    return graph


def import_cycles(graph: dict[str, set[str]]) -> set[tuple[str, ...]]:
    """The strongly connected components of more than one module (Tarjan, iterative),
    each as its sorted module names."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    found: set[tuple[str, ...]] = set()
    for root in sorted(graph):
        if root in index:
            continue
        work = [(root, iter(sorted(graph[root])))]
        index[root] = low[root] = len(index)
        stack.append(root)
        on_stack.add(root)
        while work:
            node, children = work[-1]
            child = next(children, None)
            if child is not None:
                if child not in index:
                    index[child] = low[child] = len(index)
                    stack.append(child)
                    on_stack.add(child)
                    work.append((child, iter(sorted(graph[child]))))
                elif child in on_stack:
                    low[node] = min(low[node], index[child])
                continue
            work.pop()
            if work:
                parent = work[-1][0]
                low[parent] = min(low[parent], low[node])
            if low[node] == index[node]:
                component = []
                while True:
                    member = stack.pop()
                    on_stack.discard(member)
                    component.append(member)
                    if member == node:
                        break
                if len(component) > 1:
                    found.add(tuple(sorted(component)))
    return found


def test_no_import_cycle_among_fingerfit_modules() -> None:
    graph = import_graph(SRC, "fingerfit")
    assert "fingerfit.evaluate.study" in graph  # the package was found
    new = import_cycles(graph) - KNOWN_CYCLES
    assert not new, "import cycles: " + "; ".join(" <-> ".join(c) for c in sorted(new))


def test_the_study_imports_the_report_and_not_the_reverse() -> None:
    graph = import_graph(SRC, "fingerfit")
    assert "fingerfit.evaluate.report" in graph["fingerfit.evaluate.study"]
    assert "fingerfit.evaluate.study" not in graph["fingerfit.evaluate.report"]


def test_a_cycle_is_found_lazy_and_type_only_imports_included(tmp_path) -> None:
    pkg = tmp_path / "pkg"
    (pkg / "sub").mkdir(parents=True)
    (pkg / "__init__.py").write_text("")
    (pkg / "sub" / "__init__.py").write_text("from .b import B\n")
    (pkg / "a.py").write_text("def f():\n    from .sub import b\n")
    (pkg / "sub" / "b.py").write_text(
        "from typing import TYPE_CHECKING\nif TYPE_CHECKING:\n    from ..a import f\nB = 1\n"
    )
    (pkg / "c.py").write_text("from . import a\n")
    graph = import_graph(tmp_path, "pkg")
    assert graph["pkg.c"] == {"pkg.a"} and graph["pkg.sub"] == {"pkg.sub.b"}
    assert import_cycles(graph) == {("pkg.a", "pkg.sub.b")}


def test_the_view_imports_nothing_above_it() -> None:
    """The view draws what lower layers compute: no module of ``fingerfit.view`` imports
    the capture or the command line (the capture's evidence type lives in
    ``fingerfit.estimate.evidence``, which both use)."""
    graph = import_graph(SRC, "fingerfit")
    above = ("fingerfit.capture", "fingerfit.cli")
    arrows = sorted(
        (m, d)
        for m, deps in graph.items()
        if m == "fingerfit.view" or m.startswith("fingerfit.view.")
        for d in deps
        if d.startswith(above)
    )
    assert not arrows, arrows
    assert "fingerfit.estimate.evidence" in graph["fingerfit.view.evidence"]
