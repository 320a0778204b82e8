"""The console script starts the command line with one OpenBLAS thread (its idle pool
only spins: every stage pins one BLAS thread), unless the user set the variable."""

from __future__ import annotations

import os
import subprocess
import sys

import pytest

import pipeline.cli
from pipeline.console import main

#: A process that runs :func:`main` with ``pipeline.cli`` replaced by a probe printing
#: the thread counts of the OpenBLAS pools that numpy and scipy load (the real cli's
#: first import is numpy). ``pipeline.console`` itself must not load numpy.
PROBE = """
import sys, types
from pipeline.console import main
assert "numpy" not in sys.modules
def probe(prog_name):
    import numpy, scipy.linalg
    from threadpoolctl import threadpool_info
    pools = threadpool_info()
    print(sorted({p["num_threads"] for p in pools if p["internal_api"] == "openblas"}))
cli = types.ModuleType("pipeline.cli")
cli.app = probe
sys.modules["pipeline.cli"] = cli
main()
"""


def _probe(env: dict[str, str]) -> str:
    out = subprocess.run(
        [sys.executable, "-c", PROBE], env=env, capture_output=True, text=True, check=True
    )
    return out.stdout.strip()


def test_console_starts_openblas_with_one_thread() -> None:
    env = {k: v for k, v in os.environ.items() if k != "OPENBLAS_NUM_THREADS"}
    assert _probe(env) == "[1]"


def test_console_keeps_the_users_setting() -> None:
    env = {k: v for k, v in os.environ.items() if k != "OPENBLAS_NUM_THREADS"}
    assert _probe({**env, "OPENBLAS_NUM_THREADS": "2"}) == "[2]"


def test_main_runs_the_app(monkeypatch: pytest.MonkeyPatch) -> None:
    called: list[str] = []
    monkeypatch.setattr(pipeline.cli, "app", lambda prog_name: called.append(prog_name))
    monkeypatch.setenv("OPENBLAS_NUM_THREADS", "3")
    main()
    assert called == ["pipeline"] and os.environ["OPENBLAS_NUM_THREADS"] == "3"


#: Ctrl-C while ``pipeline.cli`` loads: a finder that interrupts its own process when the
#: import starts (the first ~0.5 s of every command, issue 44).
INTERRUPTED_LOADING = """
import os, signal, sys
class Interrupt:
    def find_spec(self, name, path=None, target=None):
        if name == "pipeline.cli":
            os.kill(os.getpid(), signal.SIGINT)
        return None
sys.meta_path.insert(0, Interrupt())
from pipeline.console import main
sys.argv = ["pipeline", "status", "nowhere"]
main()
"""
#: Ctrl-C inside a command, outside typer's own handling (as the main group starts).
INTERRUPTED_RUNNING = """
import sys
import pipeline.cli
from typer.core import TyperGroup
def interrupted(self, *args, **kw):
    raise KeyboardInterrupt
TyperGroup.main = interrupted
sys.argv = ["pipeline", "status", "nowhere"]
from pipeline.console import main
main()
"""


@pytest.mark.parametrize("code", [INTERRUPTED_LOADING, INTERRUPTED_RUNNING])
def test_ctrl_c_exits_130_without_a_traceback(code: str) -> None:
    """Before: a KeyboardInterrupt traceback of an import, exit 1."""
    env = {**os.environ, "PYTHONPATH": os.pathsep.join(sys.path)}
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                       env=env, timeout=120, check=False)  # fmt: skip
    assert r.returncode == 130 and "Traceback" not in r.stderr, (r.returncode, r.stderr)
    assert r.stderr.strip() == ""
