"""No import circles in the package: a lower floor never imports a higher one.

Read with ``ast``, so imports inside functions count too (a circle hidden in a
function still ties the two modules together). Issue 16 broke the last two:
``evaluation/evaluate.py`` (now ``evaluate/__init__.py``) ↔ ``report/evaluation.py`` and
``kinematics/ik.py`` (now ``kinematics/ik/newton.py``) ↔ ``kinematics/ik_compiled.py``.
"""

from __future__ import annotations

import ast
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent


def _modules() -> dict[str, Path]:
    out = {}
    for p in sorted((ROOT / "pipeline").rglob("*.py")):
        parts = p.relative_to(ROOT).with_suffix("").parts
        out[".".join(parts[:-1] if parts[-1] == "__init__" else parts)] = p
    return out


def import_graph() -> dict[str, set[str]]:
    """``module -> the package modules it imports`` (at any level of the file)."""
    mods = _modules()
    graph: dict[str, set[str]] = {}
    for name, path in mods.items():
        deps: set[str] = set()
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
            if isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
                for alias in node.names:
                    full = f"{node.module}.{alias.name}"  # `from pkg import module`
                    deps |= {full} if full in mods else {node.module} & mods.keys()
            elif isinstance(node, ast.Import):
                deps |= {a.name for a in node.names} & mods.keys()
        graph[name] = deps - {name}
    return graph


def _reachable(graph: dict[str, set[str]], start: str) -> set[str]:
    seen: set[str] = set()
    todo = list(graph[start])
    while todo:
        m = todo.pop()
        if m not in seen:
            seen.add(m)
            todo.extend(graph[m])
    return seen


def test_no_import_circles() -> None:
    graph = import_graph()
    circles = sorted(m for m in graph if m in _reachable(graph, m))
    assert circles == []


def test_graph_sees_function_level_imports() -> None:
    graph = import_graph()  # the test above can fail: it sees these edges
    assert "pipeline.kinematics.ik_compiled" in graph["pipeline.kinematics.ik.newton"]
    assert "pipeline.report.evaluation" in graph["pipeline.evaluate"]
    assert "pipeline.kinematics.ik_stall" in graph["pipeline.kinematics.ik_compiled"]
