"""The numba kernels' cache folder (pipeline.kinematics.kernel_cache): named for a digest
of every source the kernels are compiled from, so no source change serves stale code."""

import ast
import os
import shutil
import subprocess
import sys
import time
from pathlib import Path

import pytest

from pipeline.kinematics import kernel_cache as C

ROOT = Path(__file__).resolve().parent.parent
KERNEL_DECORATORS = {"jit", "jit_views", "inline_jit", "njit_cached"}


def _module(path: Path) -> str:
    return ".".join(path.relative_to(ROOT).with_suffix("").parts)


def _is_module(name: str) -> bool:
    return C.source_path(name, ROOT).is_file()


def _imports(module: str) -> set[str]:
    """armsig modules ``module`` imports at module level (``from pkg import mod`` as mod)."""
    tree = ast.parse(C.source_path(module, ROOT).read_text())
    out: set[str] = set()
    for node in tree.body:
        if isinstance(node, ast.Import):
            out |= {a.name for a in node.names if a.name.startswith("pipeline.")}
        elif isinstance(node, ast.ImportFrom) and (node.module or "").startswith("pipeline"):
            assert node.level == 0, f"{module}: relative import"
            for a in node.names:
                sub = f"{node.module}.{a.name}"
                out.add(sub if _is_module(sub) else node.module)
    return {m for m in out if _is_module(m)}  # package __init__s left out (docstring)


def _kernel_modules() -> set[str]:
    """Modules that decorate or compile a function with armsig's numba decorators."""
    found = set()
    for path in (ROOT / "pipeline").rglob("*.py"):
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.FunctionDef | ast.Call):
                names = node.decorator_list if isinstance(node, ast.FunctionDef) else [node.func]
                if any(isinstance(n, ast.Name) and n.id in KERNEL_DECORATORS for n in names):
                    found.add(_module(path))
    return found


def test_digest_covers_every_kernel_module_and_what_it_imports() -> None:
    kernels = _kernel_modules()
    assert {
        "pipeline.kinematics.ik_compiled",
        "pipeline.control.puma560_start",
        "pipeline.control.puma560_newton",
        "pipeline.control.puma560_jacobi",
    } <= kernels
    closure, todo = set(), list(kernels)
    while todo:
        m = todo.pop()
        if m not in closure:
            closure.add(m)
            todo += _imports(m)
    missing = closure - set(C.KERNEL_SOURCES)
    assert not missing, f"add to kernel_cache.KERNEL_SOURCES: {sorted(missing)}"
    assert all(_is_module(m) for m in C.KERNEL_SOURCES)


def test_numba_is_called_only_through_kernel_cache() -> None:
    """A numba.njit / numba.jit elsewhere would cache beside its file, keyed on it alone."""
    for path in (ROOT / "pipeline").rglob("*.py"):
        if path.name == "kernel_cache.py":
            continue
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.Attribute) and isinstance(node.value, ast.Name):
                assert not (node.value.id == "numba" and node.attr in {"njit", "jit"}), path
            if isinstance(node, ast.ImportFrom) and node.module == "numba":
                assert not {a.name for a in node.names} & {"njit", "jit"}, path


@pytest.mark.parametrize("module", C.KERNEL_SOURCES)
def test_a_change_to_any_source_changes_the_folder(tmp_path: Path, module: str) -> None:
    for m in C.KERNEL_SOURCES:
        dest = C.source_path(m, tmp_path)
        dest.parent.mkdir(parents=True, exist_ok=True)
        shutil.copy(C.source_path(m, ROOT), dest)
    digest = C.sources_digest(tmp_path)
    assert digest == C.sources_digest(ROOT)
    before = C.choose_cache_dir(digest, "", tmp_path / "cache")
    with C.source_path(module, tmp_path).open("a") as f:
        f.write("\n# a comment changes nothing compiled, but the folder all the same\n")
    after = C.choose_cache_dir(C.sources_digest(tmp_path), "", tmp_path / "cache")
    assert before is not None and after is not None and before != after
    assert not before.exists()  # the stale folder is removed when the new one is made


def test_new_tree_folder_prunes_only_stale_kernel_folders(tmp_path: Path) -> None:
    tree = tmp_path / "__pycache__"
    (tree / "numba-kernels-old").mkdir(parents=True)
    (tree / "numba-kernels-old" / "x.nbi").write_text("")
    (tree / "ik.cpython-311.pyc").write_text("")
    folder = C.choose_cache_dir("new", "", tree)
    assert folder == tree / "numba-kernels-new" and folder.is_dir()
    assert sorted(p.name for p in tree.iterdir()) == ["ik.cpython-311.pyc", "numba-kernels-new"]
    # Inside a user's NUMBA_CACHE_DIR (maybe shared by checkouts) old folders stay.
    user = tmp_path / "user"
    (user / "armsig-kernels-old").mkdir(parents=True)
    assert C.choose_cache_dir("new", str(user), tree) == user / "armsig-kernels-new"
    assert (user / "armsig-kernels-old").is_dir()


def test_unwritable_folder_means_no_disk_cache(tmp_path: Path) -> None:
    blocker = tmp_path / "a-file"
    blocker.write_text("")
    assert C.choose_cache_dir("d", str(blocker / "cache"), tmp_path) is None
    assert C.choose_cache_dir("d", "", blocker / "__pycache__") is None
    assert C.choose_cache_dir("d", "", blocker / "__pycache__", blocker / "home") is None
    # A read-only tree: the user's cache folder, named for the digest too.
    home = C.choose_cache_dir("d", "", blocker / "__pycache__", tmp_path / "home")
    assert home == tmp_path / "home/armsig-kernels-d" and home.is_dir()


def test_unreadable_sources_mean_no_disk_cache(monkeypatch: pytest.MonkeyPatch) -> None:
    def unreadable(*_: object) -> str:
        raise FileNotFoundError("ik.py")  # e.g. the package imported from a zip

    monkeypatch.setattr(C, "sources_digest", unreadable)
    C.cache_dir.cache_clear()
    try:
        assert C.cache_dir() is None
    finally:
        C.cache_dir.cache_clear()


_PROBE = """
import numpy as np
from pipeline.kinematics import ik_compiled as K, kernel_cache as C
from pipeline.control import puma560_start as S
assert S._wrap(7.0) < 3.15
a, out = np.eye(4), np.empty(6)
K._delta(a, a, out)
print(C.cache_dir(), type(S._wrap._cache).__name__, type(K._delta._cache).__name__)
"""


def _run(code: str, env: dict[str, str], cwd: Path = ROOT) -> str:
    """stdout of ``code`` in a fresh interpreter, ``NUMBA_CACHE_DIR`` unset unless in ``env``."""
    env = {k: v for k, v in os.environ.items() if k != "NUMBA_CACHE_DIR"} | env
    argv = [sys.executable, "-c", code]
    out = subprocess.run(argv, env=env, cwd=cwd, capture_output=True, text=True, timeout=300)
    assert out.returncode == 0, out.stderr
    return out.stdout


def _probe(env: dict[str, str]) -> list[str]:
    return _run(_PROBE, env).split()


def _index_files(folder: Path) -> set[str]:
    return {p.name.split("-")[0] for p in folder.rglob("*.nbi")}


def test_kernels_cache_in_the_digest_folder_of_numba_cache_dir(tmp_path: Path) -> None:
    folder, *caches = _probe({"NUMBA_CACHE_DIR": str(tmp_path)})
    assert Path(folder) == tmp_path / f"armsig-kernels-{C.sources_digest()}"
    assert caches == ["FunctionCache", "FunctionCache"]
    assert {p.parent.parent for p in tmp_path.rglob("*.nbi")} == {Path(folder)}
    assert {"puma560_start._wrap", "ik_compiled._delta"} <= _index_files(Path(folder))


def test_kernels_cache_in_the_digest_folder_beside_the_sources() -> None:
    start = time.time() - 1.0
    folder, *caches = _probe({})
    tree = ROOT / "pipeline/kinematics/__pycache__"
    assert Path(folder) == tree / f"numba-kernels-{C.sources_digest()}"
    assert caches == ["FunctionCache", "FunctionCache"]
    assert {"puma560_start._wrap", "ik_compiled._delta"} <= _index_files(Path(folder))
    # Nothing written where numba caches by default (keyed on the defining file alone).
    for p in (ROOT / "pipeline").glob("*/__pycache__/*.nbi"):
        assert p.stat().st_mtime < start, p


def test_unusable_numba_cache_dir_compiles_in_memory(tmp_path: Path) -> None:
    blocker = tmp_path / "a-file"
    blocker.write_text("")
    assert _probe({"NUMBA_CACHE_DIR": str(blocker / "cache")}) == ["None", "NullCache", "NullCache"]


_ERROR_AT = """
import numpy as np
from pipeline.control import puma560_jacobi as S
from pipeline.robots import puma560
c, T = puma560.simulator_chain(), np.eye(4)
T[:3, 3] = [10.0, 20.0, 30.0]
arrays = [np.ascontiguousarray(a) for a in (c.base, c.links, c.tool, c.joint_offsets, c.prismatic)]
print(S._error_at(*arrays, T, np.zeros(6), np.empty((4, 4)), np.empty(6), 1.0,
                 np.empty((2, 6)))[0])
"""


def test_a_change_to_an_inlined_kernel_of_another_file_recompiles(tmp_path: Path) -> None:
    """puma560_jacobi._error_at inlines ik_compiled._errors: an edit of ik_compiled.py
    alone must reach it (numba alone keeps the code cached for control/puma560_jacobi.py)."""
    skip = shutil.ignore_patterns("__pycache__")
    shutil.copytree(ROOT / "pipeline", tmp_path / "pipeline", ignore=skip)

    def error() -> float:
        return float(_run(_ERROR_AT, {"PYTHONPATH": str(tmp_path)}, tmp_path))

    before = error()
    source = tmp_path / "pipeline/kinematics/ik_compiled.py"
    text = source.read_text()
    assert text.count("np.sqrt(d[0] * d[0]") == 1
    source.write_text(text.replace("np.sqrt(d[0] * d[0]", "2.0 * np.sqrt(d[0] * d[0]"))
    assert error() == 2.0 * before


def test_read_only_tree_caches_in_the_user_cache_or_in_memory(tmp_path: Path) -> None:
    """A ``__pycache__`` that cannot be written (here a file: the tests run as root,
    where permissions would not stop a write) sends the cache to the user's cache."""
    skip = shutil.ignore_patterns("__pycache__")
    shutil.copytree(ROOT / "pipeline", tmp_path / "pipeline", ignore=skip)
    (tmp_path / "pipeline/kinematics/__pycache__").write_text("")
    home = tmp_path / "home"
    env = {"PYTHONPATH": str(tmp_path), "XDG_CACHE_HOME": str(home)}
    folder, *caches = _run(_PROBE, env, tmp_path).split()
    assert Path(folder) == home / f"armsig/armsig-kernels-{C.sources_digest()}"
    assert caches == ["FunctionCache", "FunctionCache"]
    assert {"puma560_start._wrap", "ik_compiled._delta"} <= _index_files(Path(folder))
    env["XDG_CACHE_HOME"] = str(tmp_path / "pipeline/kinematics/__pycache__")
    assert _run(_PROBE, env, tmp_path).split() == ["None", "NullCache", "NullCache"]


def test_a_terminal_is_told_once_that_the_kernels_compile(tmp_path, monkeypatch, capsys) -> None:
    """Issue 30 item 4: the first `ik` or `identify` compiles for ~20 s; a terminal hears
    why in one line, a pipe or a cached run does not."""
    import io

    from pipeline.kinematics import kernel_cache

    class Terminal(io.StringIO):
        def isatty(self) -> bool:
            return True

    term = Terminal()
    monkeypatch.setattr(kernel_cache.sys, "stderr", term)
    kernel_cache._say_first_compile(tmp_path)
    assert term.getvalue().startswith("note: compiling armsig's numerical kernels")
    assert len(term.getvalue().splitlines()) == 1
    (tmp_path / "kinematics_0").mkdir()
    (tmp_path / "kinematics_0" / "kernel.nbi").write_bytes(b"")
    quiet = Terminal()
    monkeypatch.setattr(kernel_cache.sys, "stderr", quiet)
    kernel_cache._say_first_compile(tmp_path)  # compiled already
    assert quiet.getvalue() == ""
    monkeypatch.setattr(kernel_cache.sys, "stderr", io.StringIO())  # a pipe
    kernel_cache._say_first_compile(tmp_path / "empty")
    assert capsys.readouterr().err == ""
