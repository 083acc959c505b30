"""No import cycles among tactile_exp's modules (data flows one way: docs/development.md).

Every import statement counts, wherever it stands: a deferred import inside a function still
ties the two modules together (``config.check_components`` importing ``modalities`` while
``modalities.base`` imported ``config`` was such a circle), and so does one under
``TYPE_CHECKING``. Importing ``a.b`` is read as depending on ``a.b`` alone, not on ``a``'s
``__init__`` (Python runs it first, but a package importing its own modules is no cycle).
"""

from __future__ import annotations

import ast
from pathlib import Path

import tactile_exp

Edges = dict[str, dict[str, int]]  # module -> imported module -> line of the first such import


def modules(root: Path, package: str) -> dict[str, Path]:
    """Dotted name -> file of every module of ``package`` under ``root``."""
    out = {}
    for path in sorted((root / package).rglob("*.py")):
        parts = path.relative_to(root).with_suffix("").parts
        out[".".join(parts[:-1] if parts[-1] == "__init__" else parts)] = path
    return out


def import_graph(root: Path, package: str) -> Edges:
    """Which of the package's modules each module imports (every import statement)."""
    found = modules(root, package)

    graph: Edges = {}
    for name, path in found.items():
        here = name if path.name == "__init__.py" else name.rpartition(".")[0]
        edges = graph.setdefault(name, {})
        for node in ast.walk(ast.parse(path.read_text(), str(path))):
            if isinstance(node, ast.Import):
                wanted = [alias.name for alias in node.names]
            elif isinstance(node, ast.ImportFrom):
                base = node.module or ""
                if node.level:
                    anchor = here.split(".")[: len(here.split(".")) - node.level + 1]
                    base = ".".join([*anchor, base] if base else anchor)
                # ``from a import b``: module a.b when there is one, else a name in a
                wanted = [f"{base}.{alias.name}" for alias in node.names]
                wanted = [w if w in found else base for w in wanted]
            else:
                continue
            for imported in wanted:  # a module not there (another package's) is no edge
                if imported in found and imported != name:
                    edges.setdefault(imported, node.lineno)
    return graph


def cycles(graph: Edges) -> list[list[str]]:
    """The strongly connected components with more than one module (Tarjan), each sorted."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    found = []

    def visit(v: str) -> None:
        index[v] = low[v] = len(index)
        stack.append(v)
        for w in graph.get(v, {}):
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in stack:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            component = []
            while True:
                w = stack.pop()
                component.append(w)
                if w == v:
                    break
            if len(component) > 1:
                found.append(sorted(component))

    for v in sorted(graph):
        if v not in index:
            visit(v)
    return sorted(found)


def describe(graph: Edges, component: list[str]) -> str:
    """``a -> b (line 12)`` for every import inside one cycle."""
    inside = set(component)
    return "; ".join(
        f"{a} -> {b} (line {line})"
        for a in component
        for b, line in sorted(graph[a].items())
        if b in inside
    )


def test_tactile_exp_has_no_import_cycles():
    root = Path(tactile_exp.__file__).resolve().parents[1]
    graph = import_graph(root, "tactile_exp")
    assert len(graph) > 50 and "tactile_exp.config" in graph["tactile_exp.experiment"]
    found = [describe(graph, c) for c in cycles(graph)]
    assert found == [], "import cycles:\n" + "\n".join(found)


def folder_graph(graph: Edges, found: dict[str, Path], package: str) -> Edges:
    """The imports between folders: each subpackage one node (its modules together), each
    module at the package's root its own node (the root holds the bottom, ``registry``, and
    the top, ``experiment``, so as one node it would be a circle by construction)."""

    def folder(name: str) -> str:
        here = name if found[name].name == "__init__.py" else name.rpartition(".")[0]
        return name if here == package else here

    out: Edges = {}
    for a, edges in graph.items():
        for b, line in edges.items():
            if folder(a) != folder(b):
                out.setdefault(folder(a), {}).setdefault(folder(b), line)
    return out


def test_tactile_exp_has_no_import_cycles_between_folders():
    """``runtime`` stays the bottom (the Hydra callback lives in ``app``), ``models`` and
    ``baselines`` one way: a folder that imports another is never imported back."""
    root = Path(tactile_exp.__file__).resolve().parents[1]
    graph = folder_graph(
        import_graph(root, "tactile_exp"), modules(root, "tactile_exp"), "tactile_exp"
    )
    assert {"tactile_exp.runtime", "tactile_exp.models", "tactile_exp.app"} <= set(graph)
    found = [describe(graph, c) for c in cycles(graph)]
    assert found == [], "import cycles between folders:\n" + "\n".join(found)


def test_deferred_relative_and_type_checking_imports_make_cycles(tmp_path):
    """The finder itself: each kind of import closes a circle, a package's own __init__ not."""
    files = {
        "__init__.py": "",
        "a.py": "def f():\n    from pkg.b import g\n",  # deferred
        "b.py": "from . import c\n",  # relative, a module
        "c.py": "from typing import TYPE_CHECKING\nif TYPE_CHECKING:\n    import pkg.a\n",
        "d.py": "import pkg.sub.e\n",
        "sub/__init__.py": "from pkg.sub.e import E\n",
        "sub/e.py": "from ..d import x\nE = 1\n",  # relative, a name in a module
        "leaf.py": "import os\nfrom pkg import sub\nfrom pkg.gone import x\n",  # no way back
    }
    for name, text in files.items():
        (tmp_path / "pkg" / name).parent.mkdir(parents=True, exist_ok=True)
        (tmp_path / "pkg" / name).write_text(text)
    graph = import_graph(tmp_path, "pkg")
    assert cycles(graph) == [["pkg.a", "pkg.b", "pkg.c"], ["pkg.d", "pkg.sub.e"]]
    assert graph["pkg.leaf"] == {"pkg.sub": 2} and graph["pkg.sub"] == {"pkg.sub.e": 1}
    assert describe(graph, ["pkg.d", "pkg.sub.e"]) == (
        "pkg.d -> pkg.sub.e (line 1); pkg.sub.e -> pkg.d (line 1)"
    )
    folders = folder_graph(graph, modules(tmp_path, "pkg"), "pkg")
    assert cycles(folders) == [["pkg.a", "pkg.b", "pkg.c"], ["pkg.d", "pkg.sub"]]  # root modules
    assert folders["pkg.leaf"] == {"pkg.sub": 2}  # a folder is one node


def test_the_engine_reaches_mlflow_through_three_modules():
    """Recording (writes), the MLflow model cache and the finished-job reader import the
    tracking layer; fitting and scoring (``core``, ``pipeline``, ``experiment``) never do. The
    report reads runs (its own folder), and ``search`` runs studies (an Optuna storage)."""
    root = Path(tactile_exp.__file__).resolve().parents[1]
    graph = import_graph(root, "tactile_exp")
    importers = {
        m for m, edges in graph.items() if "tactile_exp.tracking" in edges and ".report" not in m
    }
    engine = importers - {"tactile_exp.search"}
    assert engine == {"tactile_exp.recording", "tactile_exp.store", "tactile_exp.jobs"}
