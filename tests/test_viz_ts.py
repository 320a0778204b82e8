"""viz.mcap read by the TypeScript MCAP reader (@mcap/core, tests/ts/check_viz.mjs): 0
unparsable messages, and every channel's schema equal to the published @foxglove/schemas.

The npm packages install once into tests/ts/node_modules (gitignored; reinstalled when
package-lock.json changes). Skipped, with the reason, without node and npm or when the
registry cannot be reached.
"""

from __future__ import annotations

import hashlib
import json
import shutil
import subprocess
from pathlib import Path
from typing import Any

import pytest
from mcap.writer import Writer

from pipeline.schemas import schema_dir
from pipeline.viz.write import viz

TS = Path(__file__).parent / "ts"
STAMP = TS / "node_modules" / ".armsig-installed"
NPM_TIMEOUT_S = 300  # a cold install took 4 s here; a registry that does not answer: skip


@pytest.fixture(scope="module")
def node() -> str:
    node, npm = shutil.which("node"), shutil.which("npm")
    if node is None or npm is None:
        pytest.skip("node or npm not installed (the TypeScript MCAP reader check needs both)")
    want = hashlib.sha256((TS / "package-lock.json").read_bytes()).hexdigest()
    if not (STAMP.is_file() and STAMP.read_text() == want):
        try:
            r = subprocess.run(
                [npm, "ci", "--no-audit", "--no-fund", "--loglevel=error"],
                cwd=TS, capture_output=True, text=True, timeout=NPM_TIMEOUT_S,
            )  # fmt: skip
        except subprocess.TimeoutExpired:
            pytest.skip(f"npm ci took over {NPM_TIMEOUT_S} s (npm registry unreachable?)")
        if r.returncode != 0:
            lines = [ln for ln in r.stderr.splitlines() if "error" in ln and "log" not in ln]
            why = (lines or ["no message"])[0]
            pytest.skip(f"npm ci failed (offline or npm registry unreachable?): {why}")
        STAMP.write_text(want)
    return node


def check(node: str, path: Path) -> dict[str, Any]:
    r = subprocess.run(
        [node, str(TS / "check_viz.mjs"), str(path)], capture_output=True, text=True, timeout=60
    )
    assert r.returncode == 0, r.stderr
    result: dict[str, Any] = json.loads(r.stdout)
    return result


def test_typescript_reader_parses_every_message(node: str, identified_session: Path,
                                                tmp_path: Path) -> None:  # fmt: skip
    out = viz(identified_session, out=tmp_path / "viz.mcap")
    r = check(node, out.path)
    assert r["unparsable"] == 0 and r["schemaMismatch"] == []
    assert r["messages"] == r["streamed"] == sum(out.topics.values())
    assert r["topics"] == out.topics


def test_the_check_counts_what_it_should(node: str, tmp_path: Path) -> None:
    """The counters can fail: a message that is not JSON and a schema that is not the
    published one are both counted."""
    path = tmp_path / "bad.mcap"
    edited = json.loads((schema_dir() / "foxglove" / "FrameTransform.json").read_bytes())
    edited["required"] = edited["required"][:-1]
    with path.open("wb") as fh:
        w = Writer(fh)
        w.start()
        data = json.dumps(edited).encode()
        sid = w.register_schema("foxglove.FrameTransform", "jsonschema", data)
        cid = w.register_channel("/tf", "json", sid)
        w.add_message(cid, 0, b'{"a": 1}', 0)
        w.add_message(cid, 1, b"{not json", 1)
        w.finish()
    r = check(node, path)
    assert r["messages"] == 2 and r["unparsable"] == 1
    assert r["schemaMismatch"] == ["foxglove.FrameTransform"]
