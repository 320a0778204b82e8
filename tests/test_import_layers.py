"""No import circles in the package: a lower floor never imports a higher one.

Read with ``ast``, so imports inside functions count too (a circle hidden in a
function still ties the two modules together). Issue 16 broke the last two:
``evaluation/evaluate.py`` (now ``evaluate/__init__.py``) ↔ ``report/evaluation.py`` and
``kinematics/ik.py`` (now ``kinematics/ik/newton.py``) ↔ ``kinematics/ik_compiled.py``.
"""

from __future__ import annotations

import ast
import os
import shutil
import subprocess
import sys
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


# Issue 31 item 3: the math floor takes arrays and dataclasses; stage modules adapt tables to it.
OPTIM = ("pipeline.optim",)
MATH = (*OPTIM, "pipeline.kinematics", "pipeline.sensor", "pipeline.features", "pipeline.refine")
#: The stage, I/O and product packages (and modules) above the math.
ABOVE_MATH = tuple(
    f"pipeline.{p}"
    for p in (
        *("stages", "contract", "rig", "importers", "identify", "evaluation", "report"),
        *("export", "viz", "fleet", "montecarlo", "cli", "signature", "control", "atomic"),
    )
)


def _under(module: str, packages: tuple[str, ...]) -> bool:
    return any(module == p or module.startswith(p + ".") for p in packages)


def test_math_imports_no_stage_or_io_module() -> None:
    graph = import_graph()
    upward = sorted(
        f"{m} -> {d}"
        for m, deps in graph.items()
        if _under(m, MATH)
        for d in deps
        if _under(d, ABOVE_MATH)
    )
    assert upward == []


def test_optimiser_imports_only_the_foundations() -> None:
    graph = import_graph()  # pipeline.optim: numpy, scipy, pipeline.errors, pipeline.units
    deps = {d for m, ds in graph.items() if _under(m, OPTIM) for d in ds}
    assert {d for d in deps if not _under(d, OPTIM)} <= {"pipeline.errors", "pipeline.units"}
    assert {"pipeline.optim.lm", "pipeline.optim.block"} <= graph.keys()


def test_math_packages_form_no_circle() -> None:
    graph = import_graph()  # by package: refine -> sensor -> refine (the blocks) was one
    pkg = {m: m.split(".")[1] for m in graph if _under(m, MATH)}
    edges = {(pkg[m], pkg[d]) for m in pkg for d in graph[m] if d in pkg and pkg[d] != pkg[m]}
    by_pkg = {p: {b for a, b in edges if a == p} for p in set(pkg.values())}
    assert sorted(p for p in by_pkg if p in _reachable(by_pkg, p)) == []


# --- The layer contract (pyproject.toml [tool.importlinter], docs/architecture.md) ---------

_LINT = (
    "import sys; from importlinter.cli import lint_imports; "
    "sys.exit(lint_imports(config_filename='pyproject.toml', no_cache=True, no_logo=True))"
)


def _lint_imports(root: Path) -> subprocess.CompletedProcess[str]:
    """import-linter on the package under ``root`` with ``root/pyproject.toml``'s contracts."""
    env = {**os.environ, "PYTHONPATH": str(root)}
    argv = [sys.executable, "-c", _LINT]
    return subprocess.run(argv, cwd=root, env=env, capture_output=True, text=True, timeout=300)


def test_layer_contract_is_kept() -> None:
    out = _lint_imports(ROOT)
    assert out.returncode == 0, out.stdout + out.stderr


def test_layer_contract_fails_on_an_upward_import(tmp_path: Path) -> None:
    """A copy of the package with one upward import (math -> stages, inside a function)."""
    shutil.copytree(
        ROOT / "pipeline", tmp_path / "pipeline", ignore=shutil.ignore_patterns("__pycache__")
    )
    shutil.copy(ROOT / "pyproject.toml", tmp_path)
    low = tmp_path / "pipeline" / "kinematics" / "transforms.py"
    low.write_text(
        low.read_text(encoding="utf-8")
        + "\n\ndef _upward():\n    from pipeline.stages.runner import run\n\n    return run\n",
        encoding="utf-8",
    )
    out = _lint_imports(tmp_path)
    assert out.returncode != 0
    assert "pipeline.kinematics.transforms -> pipeline.stages.runner" in out.stdout


def test_every_bench_module_imports() -> None:
    """`make bench` imports every benchmark module first (bench/__main__.py); a name moved
    or removed in the package or in another benchmark must fail here, not in `make bench`
    (regression: bench/evaluate.py imported a `_wall` that bench/identify.py no longer had)."""
    names = sorted(p.stem for p in (ROOT / "bench").glob("*.py") if p.stem != "__main__")
    code = "import importlib\n" + "".join(f"importlib.import_module('bench.{n}')\n" for n in names)
    out = subprocess.run(
        [sys.executable, "-c", code.replace("bench.__init__", "bench")],
        cwd=ROOT,
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert out.returncode == 0, out.stderr
