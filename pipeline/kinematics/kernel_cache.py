"""Where numba caches armsig's compiled kernels: a folder named for a digest of
every source they are compiled from, so no change to any of them can leave
stale machine code in use.

Why: numba checks a cached kernel only against the file that *defines* it (its
index stores that file's stamp, ``numba/core/caching.py``). A kernel of
:mod:`pipeline.control.puma560_jacobi` calls (and LLVM inlines) kernels of
:mod:`pipeline.kinematics.ik_compiled` and :mod:`pipeline.control.puma560_start`
and freezes module globals (``STALL_RATIO``, ``JACOBI_SLOW_RATIO``, the Puma's
design lengths) into its machine code as constants; after a change to those
files alone numba would load the old code. Here every kernel of the
package is cached in one folder named for a sha256 of all those files, so a
change to any of them compiles afresh into a new folder.

Files in the digest (:data:`KERNEL_SOURCES`): the modules that define
:func:`~pipeline.kinematics.ik_compiled.jit` kernels and, transitively,
every armsig module they import at module level. A kernel can only reach names
of modules its module imports, and a constant it reads may be computed in a
module further down (``puma560.DESIGN_D_CM`` from ``chain``/``transforms``), hence
the transitive closure rather than the direct imports. Package ``__init__``
files are left out (they define nothing a kernel reads). The cost of the closure:
an edit of e.g. ``ik/jacobi.py`` recompiles the kernels (~20-25 s once); one of
``ik/newton.py`` or ``ik/safeguard.py`` (no kernel imports them) does not. The list
is written out, not computed at import (parsing ~18 modules would cost every
import); ``tests/test_kernel_cache.py`` recomputes the closure from the
package's sources and fails when a module is missing here.

Mechanism: numba's documented ``CACHE_DIR`` (``NUMBA_CACHE_DIR``), read by
``UserProvidedCacheLocator`` when a dispatcher enables caching, i.e. when
``numba.njit(cache=True)`` decorates the function; the locator keeps the path.
:func:`njit_cached` sets it (and ``CACHE_LOCATOR_CLASSES`` to that one locator,
so numba never falls back to ``__pycache__`` or its user-wide folder, both keyed
on the defining file only) just around the decoration and restores both: other
numba users in the process keep their configuration.

Location: inside a ``NUMBA_CACHE_DIR`` the user set, ``armsig-kernels-<digest>``;
otherwise ``numba-kernels-<digest>`` in this package's ``__pycache__`` (beside
the sources, as before). When a new folder is made in ``__pycache__`` the
other ``numba-kernels-*`` folders there are removed: they hold code of sources
this checkout no longer has. Inside a user's ``NUMBA_CACHE_DIR`` (which several
checkouts or versions may share) old folders are left to the user. Where
``__pycache__`` cannot be written (read-only install) the folder is made in the
user's cache, ``$XDG_CACHE_HOME/armsig`` or ``~/.cache/armsig`` (as numba itself
falls back to its user-wide folder; shared by installs, so not pruned either).
Where no folder can be written (or an unusable ``NUMBA_CACHE_DIR``) the kernels
are compiled in memory, once per process: slower to start, never stale.
"""

from __future__ import annotations

import hashlib
import os
import shutil
import sys
import tempfile
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from functools import cache
from pathlib import Path
from typing import Any

#: Every source the cached kernels are compiled from (see the module docstring).
KERNEL_SOURCES = (
    "pipeline.errors",
    "pipeline.kinematics.chain",
    "pipeline.kinematics.dh",
    "pipeline.kinematics.ik.batch",
    "pipeline.kinematics.ik.iterate",
    "pipeline.kinematics.ik.jacobi",
    "pipeline.kinematics.ik.result",
    "pipeline.kinematics.ik.steps",
    "pipeline.kinematics.ik.task",
    "pipeline.kinematics.ik_compiled",
    "pipeline.kinematics.ik_stall",
    "pipeline.kinematics.jacobian",
    "pipeline.kinematics.kernel_cache",
    "pipeline.kinematics.kernels",
    "pipeline.kinematics.nongeometric",
    "pipeline.kinematics.nongeometric_compiled",
    "pipeline.kinematics.transforms",
    "pipeline.robots.puma560",
    "pipeline.control.puma560_jacobi",
    "pipeline.control.puma560_newton",
    "pipeline.control.puma560_start",
)
#: Hex digits of the sha256 in the folder name: 64 bits, no collision in practice.
DIGEST_CHARS = 16
#: Folder-name prefixes: in this package's ``__pycache__`` and in a user's ``NUMBA_CACHE_DIR``.
TREE_PREFIX = "numba-kernels-"
USER_PREFIX = "armsig-kernels-"

#: The folder holding the ``pipeline`` package.
_ROOT = Path(__file__).resolve().parents[2]


def source_path(module: str, root: Path = _ROOT) -> Path:
    """The file of ``module`` (dotted name, a plain module) under ``root``."""
    return root.joinpath(*module.split(".")).with_suffix(".py")


def sources_digest(root: Path = _ROOT, modules: tuple[str, ...] = KERNEL_SOURCES) -> str:
    """sha256 over the names and bytes of ``modules``' files under ``root``, shortened."""
    h = hashlib.sha256()
    for module in modules:
        data = source_path(module, root).read_bytes()
        h.update(f"{module}\0{len(data)}\0".encode())
        h.update(data)
    return h.hexdigest()[:DIGEST_CHARS]


def _writable(folder: Path) -> bool:
    """Whether ``folder`` exists or can be made and takes a file (numba's own check)."""
    try:
        folder.mkdir(parents=True, exist_ok=True)
        tempfile.TemporaryFile(dir=folder).close()
    except OSError:
        return False
    return True


def choose_cache_dir(
    digest: str, user_dir: str, tree_dir: Path, home_dir: Path | None = None
) -> Path | None:
    """The kernels' cache folder for ``digest`` (None: compile in memory).

    ``user_dir``: numba's ``CACHE_DIR`` as the user set it ("" when unset);
    ``tree_dir``: the ``__pycache__`` beside the sources; ``home_dir``: the user's
    cache, used where ``tree_dir`` cannot be written. A folder newly made in
    ``tree_dir`` removes its stale ``numba-kernels-*`` siblings.
    """
    if user_dir:
        folder = Path(user_dir) / f"{USER_PREFIX}{digest}"
        return folder if _writable(folder) else None
    folder = tree_dir / f"{TREE_PREFIX}{digest}"
    fresh = not folder.is_dir()
    if not _writable(folder):
        if home_dir is None:
            return None
        folder = home_dir / f"{USER_PREFIX}{digest}"
        return folder if _writable(folder) else None
    if fresh:
        for old in tree_dir.glob(f"{TREE_PREFIX}*"):
            if old != folder:
                shutil.rmtree(old, ignore_errors=True)
    return folder


@cache
def cache_dir() -> Path | None:
    """This process's cache folder for the kernels (None: compile in memory)."""
    import numba

    # numba.config's names are set from the environment at runtime: unknown to mypy.
    user_dir = str(numba.config.CACHE_DIR)  # type: ignore[attr-defined]
    tree_dir = Path(__file__).resolve().parent / "__pycache__"
    try:
        home = Path(os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache")
        home_dir: Path | None = home / "armsig"
    except RuntimeError:  # no home directory to be found
        home_dir = None
    try:
        digest = sources_digest()
    except OSError:  # sources not readable as files (e.g. a zip import): no digest, no cache
        return None
    folder = choose_cache_dir(digest, user_dir, tree_dir, home_dir)
    _say_first_compile(folder)
    return folder


def _say_first_compile(folder: Path | None) -> None:
    """One line on a terminal's stderr when the kernels are not compiled yet (a fresh
    checkout, an upgrade, or no cache folder): the first ``ik`` or ``identify`` then
    spends ~20 s compiling before it answers (issue 30); later runs load them. Not on a
    pipe or in a test, whose output stays the command's own."""
    if folder is not None and any(folder.glob("**/*.nbi")):  # numba: a folder per package
        return
    if not sys.stderr.isatty():
        return
    where = f"cached in {folder}" if folder is not None else "in memory: no cache folder"
    print(
        f"note: compiling armsig's numerical kernels for this checkout (~20-60 s, once; "
        f"{where}; `pipeline warmup` does it ahead)",
        file=sys.stderr,
    )


@contextmanager
def _numba_config(**values: str) -> Iterator[None]:
    import numba

    saved = {name: getattr(numba.config, name) for name in values}
    for name, value in values.items():
        setattr(numba.config, name, value)
    try:
        yield
    finally:
        for name, value in saved.items():
            setattr(numba.config, name, value)


def njit_cached(func: Callable[..., Any], **options: Any) -> Any:
    """``numba.njit(**options)(func)`` cached in :func:`cache_dir`, or in memory
    where that folder cannot be used. numba is imported here, not with this module
    (:mod:`pipeline.kinematics.kernels`: a process that runs no kernel compiled needs none)."""
    import numba

    folder = cache_dir()
    if folder is None:
        return numba.njit(cache=False, **options)(func)
    with _numba_config(CACHE_DIR=str(folder), CACHE_LOCATOR_CLASSES="UserProvidedCacheLocator"):
        try:
            return numba.njit(cache=True, **options)(func)
        except RuntimeError:  # numba found no locator: the folder went away since
            return numba.njit(cache=False, **options)(func)
