"""signature.json: a product of the runner, checked on every read (schema, self-digest,
rigid matrices, robot description), rewritten whenever it does not match the committed
stages, and refused by its users while it does not."""

from __future__ import annotations

import json
import shutil
from collections.abc import Callable
from pathlib import Path
from typing import Any

import jsonschema
import numpy as np
import pytest
from committed import committed_sessions
from typer.testing import CliRunner

from pipeline.cli import app
from pipeline.control.session import session_controller
from pipeline.errors import ArmsigError
from pipeline.identify import identify
from pipeline.schemas import schema_dir
from pipeline.signature.file import load_signature, signature_text
from pipeline.stages.catalog import EVALUATE_STAGE_MODULES, STAGE_MODULES
from pipeline.stages.runner import run, status

Doc = dict[str, Any]


def _doc(sdir: Path) -> Doc:
    return json.loads((sdir / "signature.json").read_text())


def _set(path: str, value: Any) -> Callable[[Doc], None]:
    """Set ``doc[a][b]...`` for a dotted path with integer list indices."""

    def edit(doc: Doc) -> None:
        *head, last = (int(k) if k.isdigit() else k for k in path.split("."))
        node: Any = doc
        for k in head:
            node = node[k]
        node[last] = value

    return edit


def _scale_rotation(doc: Doc) -> None:
    doc["smodel"]["links"][2][0][0] *= 1.001


def _limit(doc: Doc) -> None:
    doc["robot_description"]["joints"][0]["limits"][1] += 1.0


# (how the file is damaged, resealed with a valid digest?, what the one-line error says)
SEALED: dict[str, tuple[Callable[[Doc], None], str]] = {
    "format_version_99": (_set("format_version", 99), "unsupported signature format_version"),
    "format_version_3": (_set("format_version", 3), "unsupported signature format_version"),
    "foreign_format": (_set("format", "other.tool"), "not an armsig signature"),
    "links_empty": (_set("smodel.links", []), "does not match signature.schema.json"),
    "links_null": (_set("smodel.links", None), "does not match signature.schema.json"),
    "link_3x3": (_set("smodel.links.1", np.eye(3).tolist()), "signature.schema.json"),
    "base_string": (_set("smodel.base", "eye(4)"), "signature.schema.json"),
    "tool_null": (_set("smodel.tool", None), "signature.schema.json"),
    "links_strings": (_set("smodel.links.0.0.0", "1"), "signature.schema.json"),
    "one_link_short": (lambda d: d["smodel"]["links"].pop(), "smodel.links has 5 entries"),
    "non_rigid": (_scale_rotation, "smodel.links[2] is not a rigid transform"),
    "mirror": (
        _set("design_alignment.sensor_from_design_base", np.diag([1.0, 1, -1, 1]).tolist()),
        "sensor_from_design_base is not a rigid transform",
    ),
    "last_row": (_set("pseudo_dh_tool.3", [0.0, 0.0, 0.1, 1.0]), "pseudo_dh_tool is not a rigid"),
    "robot_mismatch": (_limit, "joint_limits does not match robot_description"),
    "robot_renamed": (_set("robot", "stanford"), "robot does not match robot_description"),
    "pseudo_dh_type": (_set("pseudo_dh.0.type", "prismatic"), "signature.schema.json"),
    "unknown_key": (_set("extra", 1), "signature.schema.json"),
    "digest_missing": (lambda d: None, "signature.schema.json"),
}
RAW: dict[str, tuple[Callable[[str], str], str]] = {
    "empty_list": (lambda t: "[]", "expected a JSON object; got list"),
    "null": (lambda t: "null", "expected a JSON object; got null"),
    "nan": (lambda t: t.replace('"rms_misfit_cm": ', '"rms_misfit_cm": NaN, "x": ', 1), "NaN"),
    "infinity": (lambda t: t.replace("[\n   [\n    1.0", "[\n   [\n    Infinity", 1), "Infinity"),
    "overflow": (lambda t: t.replace("[\n   [\n    1.0", "[\n   [\n    1e999", 1), "overflows"),
    "truncated": (lambda t: t[: len(t) // 2], "not valid JSON"),
    "edited": (
        lambda t: t.replace('"b_cm": ', '"b_cm": 1', 1),
        "content differs from its sha256 (edited or corrupt)",
    ),
}


def _seal(doc: Doc, case: str) -> str:
    text = signature_text(doc)
    if case == "digest_missing":
        reparsed = json.loads(text)
        del reparsed["sha256"]
        text = json.dumps(reparsed, indent=1)
    return text


@pytest.mark.parametrize("case", list(SEALED) + list(RAW))
def test_damaged_signature_is_refused_with_one_line(
    identified_session: Path, tmp_path: Path, case: str
) -> None:
    path = tmp_path / "signature.json"
    original = (identified_session / "signature.json").read_text()
    if case in SEALED:
        edit, expected = SEALED[case]
        doc = json.loads(original)
        del doc["sha256"]
        edit(doc)
        path.write_text(_seal(doc, case))
    else:
        mutate, expected = RAW[case]
        text = mutate(original)
        assert text != original
        path.write_text(text)
    with pytest.raises(ArmsigError) as exc:
        load_signature(path)
    msg = str(exc.value)
    assert expected in msg and "\n" not in msg and str(path) in msg, msg


def test_intact_signature_loads_and_matches_the_schema(identified_session: Path) -> None:
    doc = _doc(identified_session)
    schema = json.loads((schema_dir() / "signature.schema.json").read_text())
    jsonschema.Draft202012Validator.check_schema(schema)
    jsonschema.Draft202012Validator(schema).validate(doc)  # a second validator agrees
    assert doc["format_version"] == 4 and len(doc["sha256"]) == 64
    assert load_signature(identified_session / "signature.json").chain.links.shape == (6, 4, 4)


def test_corrupt_signature_with_intact_provenance_is_rewritten(
    identified_session: Path, tmp_path: Path
) -> None:
    d = shutil.copytree(identified_session, tmp_path / "s")
    good = _doc(d)
    doc = _doc(d)
    doc["smodel"]["links"][1][0][3] += 0.05  # provenance untouched, digest now wrong
    (d / "signature.json").write_text(json.dumps(doc, indent=1))
    st = {s.name: s for s in status(d)}["signature"]
    assert st.state == "stale" and "differs from its sha256" in st.reason
    runs = {r.name: r.action for r in identify(d, report=False).runs}
    assert runs["signature"] == "written"
    assert _doc(d)["smodel"] == good["smodel"]


def test_force_rewrites_a_matching_signature(identified_session: Path, tmp_path: Path) -> None:
    d = shutil.copytree(identified_session, tmp_path / "s")
    assert {r.name: r.action for r in identify(d, report=False).runs}["signature"] == "cached"
    (d / "signature.json").write_text(signature_text(_strip(_doc(d), created="x")))
    runs = {r.name: r.action for r in identify(d, force=True, report=False).runs}
    assert runs["signature"] == "written" and _doc(d)["provenance"]["created"] != "x"


def _strip(doc: Doc, created: str) -> Doc:
    del doc["sha256"]
    doc["provenance"]["created"] = created
    return doc


def _kill_between_commit_and_signature(d: Path, monkeypatch) -> None:
    """New stage outputs committed, then the process dies before signature.json."""

    def killed(*args: Any, **kwargs: Any) -> Any:
        raise KeyboardInterrupt  # stands for kill -9: nothing after this point runs

    monkeypatch.setattr("pipeline.signature.session.write_signature", killed)
    with pytest.raises(KeyboardInterrupt):
        run(d, overrides={"features": {"plane_method": "eigen"}})
    monkeypatch.undo()


def test_kill_between_commit_and_signature(
    identified_session: Path, tmp_path: Path, monkeypatch
) -> None:
    d = shutil.copytree(identified_session, tmp_path / "s")
    old = (d / "signature.json").read_bytes()
    _kill_between_commit_and_signature(d, monkeypatch)
    assert (d / "signature.json").read_bytes() == old  # the old file is still there...
    over = {"features": {"plane_method": "eigen"}}
    st = {s.name: s for s in status(d, over)}
    assert all(st[n].state == "fresh" for n in STAGE_MODULES)  # ...the new stages committed
    assert st["signature"].state == "stale" and "other stage outputs" in st["signature"].reason
    with pytest.raises(ArmsigError, match="does not match the session's stages") as exc:
        session_controller(d)
    assert "\n" not in str(exc.value) and "pipeline identify" in str(exc.value)
    r = CliRunner().invoke(app, ["ik", str(d), "--pose", "40", "20", "60", "180", "0", "90"])
    assert r.exit_code == 1 and r.output.count("\n") == 1
    assert "does not match the session's stages" in r.output
    # The next run writes it; every user takes it again.
    runs = {r.name: r.action for r in identify(d, overrides=over, report=False).runs}
    assert runs["signature"] == "written" and set(runs.values()) == {"cached", "written"}
    assert {s.state for s in status(d, over)} == {"fresh"}
    session_controller(d)


@pytest.fixture(scope="module")
def evaluated(identified_session: Path, tmp_path_factory: pytest.TempPathFactory) -> Path:
    from pipeline.evaluate import evaluate

    d = shutil.copytree(identified_session, tmp_path_factory.mktemp("evaluated") / "s")
    evaluate(d, report=False)
    return d


def test_evaluate_stages_refuse_a_stale_signature(
    evaluated: Path, tmp_path: Path, monkeypatch
) -> None:
    d = shutil.copytree(evaluated, tmp_path / "s")
    _kill_between_commit_and_signature(d, monkeypatch)
    over = {"features": {"plane_method": "eigen"}}
    st = {s.name: s for s in status(d, over, STAGE_MODULES + EVALUATE_STAGE_MODULES)}
    assert st["signature"].state == "stale"
    assert st["evaluate_program"].reason == "input signature is stale or missing"
    before = (d / "stages" / "evaluate_program.arrow").read_bytes()
    with pytest.raises(ArmsigError, match="does not match the session's stages") as exc:
        run(d, modules=EVALUATE_STAGE_MODULES)  # without the identify that evaluate runs first
    assert "\n" not in str(exc.value)
    assert (d / "stages" / "evaluate_program.arrow").read_bytes() == before


def test_only_leaves_the_signature_unwritten_while_stages_are_stale(
    identified_session: Path, tmp_path: Path
) -> None:
    d = shutil.copytree(identified_session, tmp_path / "s")
    old = (d / "signature.json").read_bytes()
    over = {"features": {"plane_method": "eigen"}}
    result = identify(d, only="features", overrides=over, report=False)
    assert result.signature is None and "not written" in result.warnings[0]
    assert (d / "signature.json").read_bytes() == old
    st = {s.name: s for s in status(d, over)}
    assert st["frames"].state == "stale" and st["signature"].state == "stale"
    with pytest.raises(ArmsigError, match="does not match the session's stages"):
        session_controller(d)


COMMITTED = [d / "recording.mcap" for d in committed_sessions()]


@pytest.mark.parametrize("recording", COMMITTED, ids=[p.parent.name for p in COMMITTED])
def test_every_committed_session_signature_matches_the_schema(recording: Path, tmp_path) -> None:
    """Issue 16: the signature of every committed session validates against
    schemas/signature.schema.json, checked by jsonschema (armsig itself uses fastjsonschema)."""
    d = tmp_path / recording.parent.name
    d.mkdir()
    shutil.copy(recording, d / "recording.mcap")
    identify(d, report=False)
    schema = json.loads((schema_dir() / "signature.schema.json").read_text())
    jsonschema.Draft202012Validator(schema).validate(_doc(d))


def test_users_refuse_a_signature_of_another_recording(
    identified_session: Path, tmp_path: Path
) -> None:
    """Regression (issue 32): after the recording changed (``import --force``, a recording
    copied in, an ``identify`` that fails on the new data) ``status`` said stale, yet fk,
    ik, export, viz and validate used the old signature with exit 0."""
    d = shutil.copytree(identified_session, tmp_path / "s")
    mine = (d / "recording.mcap").read_bytes()
    other = next(p for p in COMMITTED if p.read_bytes() != mine)
    shutil.copy(other, d / "recording.mcap")
    assert {s.name: s for s in status(d)}["session"].reason == "input recording changed"
    with pytest.raises(ArmsigError, match="identified from another recording.mcap") as exc:
        session_controller(d)
    assert "\n" not in str(exc.value) and f"pipeline identify {d}" in str(exc.value)
    for argv in (
        ["fk", str(d), "--q", "0 -45 180 0 45 90"],
        ["ik", str(d), "--pose", "40", "20", "60", "180", "0", "90"],
        ["export", str(d), "--format", "dh", "--out", str(tmp_path / "dh.txt")],
        ["viz", str(d), "--out", str(tmp_path / "viz.mcap")],
    ):
        r = CliRunner().invoke(app, argv)
        assert r.exit_code == 1 and r.output.count("\n") == 1, (argv, r.output)
        assert "identified from another recording.mcap" in r.output, argv
    assert not (tmp_path / "dh.txt").exists() and not (tmp_path / "viz.mcap").exists()
    shutil.copy(identified_session / "recording.mcap", d / "recording.mcap")
    session_controller(d)  # the recording it was identified from: served again
