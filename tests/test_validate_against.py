"""Issue 29, item 4: `validate --against` matches the file's target with the session's tool
point by id, takes a plain list of poses, and shows the registered design model beside
the signature."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from conftest import random_rigid
from import_data import UR10, pose_set_map, pose_set_table

from pipeline.errors import ArmsigError
from pipeline.evaluate.validate import design_errors, validate_against
from pipeline.identify import identify
from pipeline.importers import import_file
from pipeline.kinematics.chain import link_frames
from pipeline.signature.file import FILE_NAME
from pipeline.signature.session import load_session_signature
from pipeline.units import joints_to_internal


@pytest.fixture(scope="module")
def session(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A noiseless UR10 pose set (tool point ``tmac``), identified."""
    tmp = tmp_path_factory.mktemp("validate")
    src, _ = pose_set_table(tmp / "poses.csv")
    mp = tmp / "map.toml"
    mp.write_text(pose_set_map())
    import_file(src, "table", UR10, tmp / "s", mp)
    identify(tmp / "s", report=False)
    return tmp / "s"


def _other(tmp: Path, map_text: str) -> tuple[Path, Path]:
    src, _ = pose_set_table(tmp / "other.csv", n=25, seed=2)
    mp = tmp / "other.toml"
    mp.write_text(map_text)
    return src, mp


def test_a_file_of_another_reflector_is_refused(session: Path, tmp_path: Path) -> None:
    """Before: compared with the session's tool point ("mean 24.41 cm" on the issue's
    file), exit 0."""
    text = pose_set_map().replace('tool_target = "tmac"', 'tool_target = "r2"')
    text = text[: text.index('[[targets]]\nid = "tmac"')] + text[text.index("[[joints]]") :]
    src, mp = _other(tmp_path, text)
    with pytest.raises(ArmsigError, match="no target 'tmac', the session's tool point") as e:
        validate_against(session, src, "table", mp)
    assert "\n" not in str(e.value) and "got 'r2'" in str(e.value)


def test_a_plain_list_of_poses(session: Path, tmp_path: Path) -> None:
    """No `sweep = "poses"`, no [sweeps]: before, the rows were refused for sweep
    inference ("no single joint moves here")."""
    src, mp = _other(tmp_path, pose_set_map().replace('sweep = "poses"\n', ""))
    out = validate_against(session, src, "table", mp)
    assert out["target"] == "tmac" and out["n"] == 25 and out["max_cm"] <= 1e-6
    assert out["design_registered_rms_cm"] <= 1e-6  # the data are the design model's


def test_the_design_baseline_registers_base_and_tool(rng: np.random.Generator) -> None:
    """Points of the design model under a random base and tool point: 0 from it; points of
    an arm whose joint 2 reads 1° off: the design's error is what is left."""
    from pipeline.robots.description import load_description
    from pipeline.signature.file import Signature

    robot = load_description(UR10)
    chain = robot.design_chain()
    q = rng.uniform(-170.0, 170.0, (30, 6))
    tool = np.array([3.0, -2.0, 12.0])
    B = random_rigid(rng, 1)[0]

    def measured(offset_deg: float) -> np.ndarray:
        F = link_frames(chain, joints_to_internal(q + [0, offset_deg, 0, 0, 0, 0], robot.prismatic))
        p = np.einsum("kij,j->ki", F[:, 6, :3, :3], tool) + F[:, 6, :3, 3]
        return p @ B[:3, :3].T + B[:3, 3]

    sig = Signature(robot, chain, np.eye(4), np.eye(4))
    assert design_errors(sig, q, measured(0.0)).max() <= 1e-8
    assert design_errors(sig, q, measured(1.0)).mean() > 0.1


def test_the_cli_shows_the_design_baseline(session: Path, tmp_path: Path) -> None:
    from typer.testing import CliRunner

    from pipeline.cli import app

    src, mp = _other(tmp_path, pose_set_map())
    r = CliRunner().invoke(
        app,
        ["validate", str(session), "--against", str(src), "--format", "table", "--map", str(mp)],
    )
    assert r.exit_code == 0, r.output
    assert "design model, base and tool registered:" in r.stdout
    assert load_session_signature(session / FILE_NAME).robot.name == "ur10"
