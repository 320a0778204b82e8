"""The identification report: contents from the stage tables, figures, errors."""

from __future__ import annotations

import re
import shutil
from pathlib import Path

import numpy as np
import pytest

from pipeline.errors import StageError
from pipeline.report.identification import write_report
from pipeline.rig.audit import audit
from pipeline.rig.simulate import SimulationOptions, simulate_session
from pipeline.signature.session import write_signature
from pipeline.stages.catalog import STAGE_MODULES
from pipeline.stages.runner import run, stage_path
from pipeline.stages.session import session_robot
from pipeline.stages.tables import read_provenance, read_table

PNG_MAGIC = b"\x89PNG\r\n\x1a\n"


@pytest.fixture(scope="module")
def session(tmp_path_factory: pytest.TempPathFactory) -> Path:
    sdir = tmp_path_factory.mktemp("robot")
    simulate_session(sdir, SimulationOptions(seed=2, points=12, repeats=2))
    run(sdir)
    write_signature(sdir)
    return sdir


@pytest.fixture(scope="module")
def report(session: Path) -> tuple[Path, str]:
    path = write_report(session, audit(session, configurations=20).to_dict())
    return path, path.read_text(encoding="utf-8")


def test_report_written_in_session(session: Path, report: tuple[Path, str]) -> None:
    path, text = report
    assert path == session / "report" / "report.md"
    assert text.startswith(f"# Arm signature identification: {session.name}")
    assert "puma560" in text and "simulated" in text
    # Atomic writes leave no temp files behind.
    assert not [p.name for p in path.parent.iterdir() if p.name.startswith(".")]


def test_sections_in_order(report: tuple[Path, str]) -> None:
    _, text = report
    headings = [
        "Denavit-Hartenberg parameters (as `pipeline export --format dh`)",
        "S-Model link parameters",
        "Feature accuracies",
        "### Warnings",
        "Residual variances",
        "## Figures",
        "## Data quality",
        "Control: convergence on this signature",
        "Audit against the simulator's truth",
        "Stage provenance",
    ]
    positions = [text.index(h) for h in headings]
    assert positions == sorted(positions)


def test_convergence_tables_reach_the_tolerance(report: tuple[Path, str]) -> None:
    """Both methods' tables (5-1, 5-2) end at a radial error below 1e-6 cm."""
    _, text = report
    block = text[text.index("Control: convergence") :].split("```")[1]
    tables = [t for t in block.strip().split("\n\n") if t.strip()]
    assert [t.splitlines()[0].split(" (")[0] for t in tables] == [
        "Newton-Raphson",
        "Jacobi iterative",
    ]
    for t in tables:
        last = t.splitlines()[-1].split()
        assert float(last[4]) <= 1e-6


def test_every_joint_and_dh_value(session: Path, report: tuple[Path, str]) -> None:
    _, text = report
    robot = session_robot(read_table(stage_path(session, "session")))
    for i, joint in enumerate(robot.joints, start=1):
        assert f"| {i} | {joint.name} |" in text
    # the D-H table export writes (issue 42: Hayati's β on parallel axes), from stage chain
    from pipeline.kinematics.dh_table import dh_table_from_chain
    from pipeline.stages.frames import chain_from_frames

    t = dh_table_from_chain(chain_from_frames(read_table(stage_path(session, "chain")),
                                              robot.prismatic))  # fmt: skip
    for i in range(robot.n_joints):
        assert f"{t.a[i]:.4f}" in text
        assert f"{np.degrees(t.alpha[i]):.3f}" in text
        assert f"{np.degrees(t.theta[i]):.3f}" in text
        assert f"{t.d[i]:.4f}" in text


def test_tables_come_from_stage_files(session: Path, report: tuple[Path, str]) -> None:
    _, text = report
    for row in read_table(stage_path(session, "smodel")).to_pylist():
        assert f"{row['b_cm']:.4f}" in text
    res = read_table(stage_path(session, "residuals")).to_pylist()
    normal = np.array([r["normal_cm"] for r in res if r["joint"] == 1])
    assert f"{np.var(normal, ddof=1):.6f}" in text
    tri = read_table(stage_path(session, "triangulate")).to_pylist()
    assert f"{sum(r['n_cycles'] for r in tri)} digitize cycles" in text
    for name in STAGE_MODULES:
        assert read_provenance(stage_path(session, name))["content_hash"][:12] in text


def test_figures_are_linked_pngs(report: tuple[Path, str]) -> None:
    path, text = report
    links = re.findall(r"!\[[^\]]*\]\(([^)]+)\)", text)
    assert [Path(link).name for link in links] == [
        "uncertainty.png",  # the verdict's error map, first
        "residuals.png",
        "hist_normal.png",
        "hist_radial.png",
    ]
    for link in links:
        png = path.parent / link
        assert not Path(link).is_absolute() and png.is_file()
        assert png.read_bytes()[:8] == PNG_MAGIC


def test_audit_optional_and_rewrite(session: Path, report: tuple[Path, str]) -> None:
    path = write_report(session)
    text = path.read_text(encoding="utf-8")
    assert "Audit against the simulator's truth" not in text
    assert "Audit against the simulator's truth" in report[1]


def test_missing_stage_names_session_and_fix(session: Path, tmp_path: Path) -> None:
    with pytest.raises(StageError, match="pipeline identify") as err:
        write_report(tmp_path)
    assert str(tmp_path) in str(err.value)
    partial = tmp_path / "partial"
    shutil.copytree(session / "stages", partial / "stages")
    stage_path(partial, "features").unlink()
    with pytest.raises(StageError, match="features.*pipeline identify"):
        write_report(partial)
    assert not (partial / "report").exists()


def test_a_report_write_error_is_one_line_and_loses_nothing(
    identified_session: Path, tmp_path: Path
) -> None:
    """Issue 44: a file size limit (``ulimit -f``) or a full disk while the report was
    written exited 70. The signature and the stages are written before it; the error is one
    line naming the report folder and how to finish, and leaves no temp file."""
    import resource
    import subprocess
    import sys

    d = shutil.copytree(identified_session, tmp_path / "s")
    before = {p: p.read_bytes() for p in d.rglob("*") if p.is_file()}
    limit = 16 * 1024  # under any figure (> 20 kB), over the stages already written

    def small_files() -> None:
        resource.setrlimit(resource.RLIMIT_FSIZE, (limit, limit))

    argv = [sys.executable, "-m", "pipeline", "identify", str(d)]
    r = subprocess.run(argv, text=True, capture_output=True, preexec_fn=small_files,
                       timeout=600, check=False)  # fmt: skip
    (line,) = [x for x in r.stderr.splitlines() if not x.startswith("identify ")]  # progress
    assert r.returncode == 1 and "Traceback" not in r.stderr, r.stderr
    assert line.startswith(f"error: {d / 'report'}: File too large; try: the signature is")
    assert line.endswith(f"then `pipeline identify {d}` writes the report")
    kept = {p: p.read_bytes() for p in d.rglob("*") if p.is_file() and p.parent.name != "report"}
    assert kept == before
    assert not [p.name for p in (d / "report").iterdir() if p.name.endswith(".tmp")]


REPRO = Path(__file__).resolve().parents[2] / "shared" / "repro" / "report_convergence_crash"
REPRO = REPRO / "recording.mcap"


@pytest.mark.skipif(not REPRO.is_file(), reason=f"{REPRO} is absent (a shared reproduction)")
def test_a_restart_into_the_limits_keeps_the_convergence_table(tmp_path: Path) -> None:
    """Issue 44: a 300-pose Puma-like pose set of another implementation of the recording
    contract (../shared/repro/report_convergence_crash): ``identify`` wrote the signature,
    then the report stacked 7 iterations (a restart into the joint limits included) against
    a history of 4 and exited 70. The table now holds the 4 iterations recorded."""
    from pipeline.control.convergence import realistic_tables
    from pipeline.identify import identify

    d = tmp_path / "s"
    d.mkdir()
    shutil.copy(REPRO, d / "recording.mcap")
    result = identify(d)
    assert result.report is not None and result.signature is not None
    (table,) = realistic_tables(d)
    assert table.rows.shape == (4, 5)
    assert table.rows[-1, 4] <= 1e-6  # the recorded solve converged
    assert "Newton-Raphson (cf. Table 5-1), realistic signature" in result.report.read_text()


def test_the_table_holds_the_iterations_the_history_recorded(
    robot3_identified: Path, monkeypatch
) -> None:
    """The same, without the shared file: a solve whose restarts add iterations that its
    history (the first solve's) does not hold."""
    from dataclasses import replace

    from pipeline.control import convergence
    from pipeline.control.controller import Controller

    solve = Controller.solve

    def restarted(self, *args, **kw):  # type: ignore[no-untyped-def]
        res = solve(self, *args, **kw)
        return replace(res, iterations=res.iterations + 3)  # as control.limits' restarts

    d = robot3_identified
    plain = convergence.realistic_tables(d)
    monkeypatch.setattr(Controller, "solve", restarted)
    for a, b in zip(plain, convergence.realistic_tables(d), strict=True):
        np.testing.assert_array_equal(a.rows, b.rows)
