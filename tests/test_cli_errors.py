"""No traceback reaches a user; inputs have bounds; nothing a user owns is destroyed.

One rule for every command: an error is one line on stderr starting ``error:``;
exit 1 refused input or data, 2 usage error, 3 ``ik`` target not reached, 70 a bug.
"""

from __future__ import annotations

import json
import math
import os
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import polars as pl
import pyarrow as pa
import pyarrow.ipc as ipc
import pytest
from recording_data import locked_elsewhere
from typer.testing import CliRunner, Result

from pipeline.cli import EXIT_INTERNAL, EXIT_NOT_REACHED, EXIT_REFUSED, EXIT_USAGE, app
from pipeline.errors import ArmsigError
from pipeline.identify import identify
from pipeline.rig.simulate import SimulationOptions, simulate_session
from pipeline.stages import compensate, features, triangulate

PIPELINE = Path(sys.executable).with_name("pipeline")
POSE = {"x_cm": 40.0, "y_cm": 20.0, "z_cm": 60.0, "rx_deg": 180.0, "ry_deg": 0.0, "rz_deg": 90.0}
FAR = ["9999", "0", "0", "0", "0", "0"]  # 100 m away: no Puma reaches it


def invoke(*args: str) -> Result:
    return CliRunner().invoke(app, list(args))


def assert_one_error(r: Result, code: int, *fragments: str) -> None:
    """Exit ``code`` with one ``error:`` line on stderr holding every fragment."""
    assert r.exit_code == code, (r.exit_code, r.output)
    lines = r.stderr.splitlines()
    assert len(lines) == 1 and lines[0].startswith("error: "), r.stderr
    for f in fragments:
        assert f in lines[0], (f, lines[0])
    assert "Traceback" not in r.output


@pytest.fixture(scope="module")
def session(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A small noiseless Puma session, identified (signature.json, no report)."""
    d = tmp_path_factory.mktemp("cli") / "s"
    simulate_session(d, SimulationOptions(seed=2, noiseless=True, points=12, repeats=1))
    identify(d, report=False)
    return d


def write_arrow(path: Path, table: pa.Table) -> Path:
    with ipc.new_file(str(path), table.schema) as w:
        w.write_table(table)
    return path


def targets(tmp_path: Path, **columns: object) -> Path:
    """A one-target file of POSE with ``columns`` added or replaced."""
    cols: dict[str, object] = {k: [v] for k, v in POSE.items()}
    cols.update(columns)
    return write_arrow(tmp_path / "t.arrow", pa.table(cols))


# --- one CLI rule ---------------------------------------------------------------------


def test_usage_errors_are_one_line_with_exit_2_from_the_installed_command() -> None:
    for args, fragment in (
        ([], "Missing command"),
        (["bogus"], "No such command 'bogus'"),
        (["ik"], "Missing argument"),
        (["audit", "x", "--configurations", "many"], "'--configurations'"),
        (["simulate", "x", "--seed", "-1"], "'--seed'"),
    ):
        r = subprocess.run([str(PIPELINE), *args], capture_output=True, text=True, timeout=60)
        lines = r.stderr.splitlines()
        assert r.returncode == EXIT_USAGE, (args, r.stderr)
        assert len(lines) == 1 and lines[0].startswith("error: ") and fragment in lines[0]
        assert "try: pipeline" in lines[0] and "--help" in lines[0]
    # Refused input: exit 1, one line; help: exit 0.
    r = subprocess.run([str(PIPELINE), "fk", "nope", "--q", "0"], capture_output=True, text=True)
    assert r.returncode == EXIT_REFUSED and r.stderr.startswith("error: unknown robot")
    assert len(r.stderr.splitlines()) == 1
    r = subprocess.run([str(PIPELINE), "--help"], capture_output=True, text=True)
    assert r.returncode == 0 and "simulate" in r.stdout


def test_usage_error_in_process_is_one_line(tmp_path: Path) -> None:
    assert_one_error(invoke("ik"), EXIT_USAGE, "Missing argument 'session'", "pipeline ik --help")
    assert_one_error(invoke("fk", "puma560"), EXIT_USAGE, "'--q'")
    # Option ranges: NaN and out-of-range values are usage errors, not a recording of NaN.
    bad = {"--max-sweep-deg": "nan", "--wac-error-cm": "1e9", "--sigma-p": "-1", "--points": "0"}
    for option, value in bad.items():
        r = invoke("simulate", str(tmp_path / "s"), option, value)
        assert_one_error(r, EXIT_USAGE, f"'{option}'")
    assert not (tmp_path / "s").exists()


def test_numpy_warnings_do_not_precede_an_error() -> None:
    # The real stderr of the command (pytest would capture warnings in process).
    code = (
        "import numpy as np, pipeline.robots as r\n"
        "from pipeline.errors import ArmsigError\n"
        "def names():\n"
        "    np.float64(0.0) / 0.0; np.log(np.zeros(1)); np.mean(np.zeros(0))\n"
        "    raise ArmsigError('refused')\n"
        "r.builtin_names = names\n"
        "from pipeline.cli import app\n"
        "app(['robots'])\n"
    )
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=60)
    assert r.returncode == EXIT_REFUSED and r.stderr == "error: refused\n", r.stderr
    debug = {**os.environ, "ARMSIG_DEBUG": "1"}
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=debug)
    assert "RuntimeWarning" in r.stderr  # shown when debugging


def test_an_unexpected_exception_is_one_line_exit_70(monkeypatch: pytest.MonkeyPatch) -> None:
    import pipeline.robots

    def broken() -> list[str]:
        raise TypeError("unsupported operand\nsecond line")

    monkeypatch.setattr(pipeline.robots, "builtin_names", broken)
    monkeypatch.delenv("ARMSIG_DEBUG", raising=False)
    r = invoke("robots")
    assert_one_error(
        r,
        EXIT_INTERNAL,
        "internal error (a bug in armsig): TypeError: unsupported operand second line",
        "ARMSIG_DEBUG=1 pipeline robots",
    )
    monkeypatch.setenv("ARMSIG_DEBUG", "1")
    r = invoke("robots")
    assert r.exit_code == EXIT_INTERNAL and "Traceback" in r.stderr
    assert r.stderr.splitlines()[-1].startswith("error: internal error")


# --- stage parameters -----------------------------------------------------------------


@pytest.mark.parametrize(
    ("param", "message"),
    [
        ("triangulate.reject_k=-1", "parameter triangulate.reject_k must be >= 1"),
        ("triangulate.reject_k=nan", "parameter triangulate.reject_k must be"),
        ("triangulate.floor_cm=-1", "parameter triangulate.floor_cm must be >= 0"),
        ("triangulate.pair_max_cm=0", "parameter triangulate.pair_max_cm must be > 0"),
        ("compensate.max_iter=0", "parameter compensate.max_iter must be >= 1"),
        ("compensate.tol_cm=nan", "parameter compensate.tol_cm must be > 0"),
        ("compensate.tol_cm=1", "parameter compensate.tol_cm must be > 0 and <= 0.01"),
        ("features.plane_method=foo", "parameter features.plane_method must be lsq or eigen"),
    ],
)
def test_bad_stage_parameter_is_refused_where_it_enters(
    session: Path, param: str, message: str
) -> None:
    before = (session / "signature.json").read_bytes()
    r = invoke("identify", str(session), "--param", param, "--no-report")
    assert_one_error(r, EXIT_REFUSED, message, "(the default)")
    assert "re-record" not in r.output
    assert (session / "signature.json").read_bytes() == before


def test_params_check_their_bounds_on_construction() -> None:
    with pytest.raises(ArmsigError, match=r"reject_k must be >= 1 and finite; got -1"):
        triangulate.Params(reject_k=-1.0)
    with pytest.raises(ArmsigError, match="got inf"):
        triangulate.Params(pair_max_cm=math.inf)
    with pytest.raises(ArmsigError, match="max_iter"):
        compensate.Params(max_iter=0)
    with pytest.raises(ArmsigError, match="got 'foo'"):
        features.Params(plane_method="foo")
    assert triangulate.Params(reject_k=1.0, floor_cm=0.0).reject_k == 1.0  # the bounds hold


# --- simulate never destroys a recording ----------------------------------------------


def test_simulate_refuses_an_existing_session(tmp_path: Path) -> None:
    d = tmp_path / "real"
    d.mkdir()
    (d / "recording.mcap").write_bytes(b"a real recording")
    small = ["--points", "12", "--repeats", "1"]
    r = invoke("simulate", str(d), *small)
    assert_one_error(r, EXIT_REFUSED, "already holds a recording", "--force")
    assert (d / "recording.mcap").read_bytes() == b"a real recording"
    assert not (d / "rig-truth.json").exists()
    with pytest.raises(ArmsigError, match="already holds a recording"):
        simulate_session(d, SimulationOptions(points=12, repeats=1))
    r = invoke("simulate", str(d), *small, "--force")
    assert r.exit_code == 0 and (d / "recording.mcap").read_bytes() != b"a real recording"


def test_simulate_into_a_file_is_one_line(tmp_path: Path) -> None:
    (tmp_path / "f").write_text("")
    for target in ("f", "f/s"):
        r = invoke("simulate", str(tmp_path / target), "--points", "12", "--repeats", "1")
        assert_one_error(r, EXIT_REFUSED, str(tmp_path / "f"))


# --- ik --targets -----------------------------------------------------------------------


def test_ik_missing_targets_file_says_so(session: Path, tmp_path: Path) -> None:
    r = invoke("ik", str(session), "--targets", str(tmp_path / "nope.arrow"), "--out", "q.arrow")
    assert_one_error(r, EXIT_REFUSED, "no such file")
    assert "not an Arrow IPC file" not in r.output


@pytest.mark.parametrize(
    ("columns", "fragment"),
    [
        ({"x_cm": pa.array([[40.0]])}, "column 'x_cm' is not numeric"),
        ({"y_cm": ["20"]}, "column 'y_cm' is not numeric"),
        ({"z_cm": pa.array([None], pa.float64())}, "column 'z_cm' has 1 null"),
        ({"rx_deg": [math.nan]}, "column 'rx_deg' has 1 value(s) that are not finite"),
        ({"ry_deg": [math.inf]}, "column 'ry_deg' has 1 value(s) that are not finite"),
        ({"rz_deg": [True]}, "column 'rz_deg' is not numeric"),
        ({"branch": [3]}, "column 'branch' is not text"),
    ],
    ids=["list", "string", "null", "nan", "inf", "bool", "branch"],
)
def test_ik_bad_target_column_names_it(
    session: Path, tmp_path: Path, columns: dict, fragment: str
) -> None:
    out = tmp_path / "q.arrow"
    t = targets(tmp_path, **columns)
    r = invoke("ik", str(session), "--targets", str(t), "--out", str(out))
    assert_one_error(r, EXIT_REFUSED, fragment)
    assert not out.exists()


def test_ik_wrong_column_set_names_the_column(session: Path, tmp_path: Path) -> None:
    cols = {k: [v] for k, v in POSE.items() if k != "ry_deg"}
    t = write_arrow(tmp_path / "t.arrow", pa.table(cols))
    r = invoke("ik", str(session), "--targets", str(t), "--out", str(tmp_path / "q.arrow"))
    assert_one_error(r, EXIT_REFUSED, "missing column(s) ry_deg")
    twice = pa.Table.from_arrays(
        [pa.array([v]) for v in [*POSE.values(), 1.0]], names=[*POSE, "x_cm"]
    )
    t = write_arrow(tmp_path / "t2.arrow", twice)
    r = invoke("ik", str(session), "--targets", str(t), "--out", str(tmp_path / "q.arrow"))
    assert_one_error(r, EXIT_REFUSED, "column 'x_cm' appears more than once")


def test_ik_unwritable_out_is_refused_before_the_solve(
    session: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    import pipeline.control.controller
    import pipeline.control.targets  # holds its own name of solve_poses: patched too

    def no_solve(*args: object, **kwargs: object) -> None:
        raise AssertionError("solved before --out was checked")

    # both names, and targets imported before: imported while only the controller's name
    # was patched, targets kept no_solve for the rest of the worker's tests
    monkeypatch.setattr(pipeline.control.controller, "solve_poses", no_solve)
    monkeypatch.setattr(pipeline.control.targets, "solve_poses", no_solve)
    t = str(targets(tmp_path))
    (tmp_path / "file").write_text("")
    for out, fragment in (
        (tmp_path, "is a folder"),
        (tmp_path / "missing" / "q.arrow", "does not exist"),
        (tmp_path / "file" / "q.arrow", "is not a folder"),
    ):
        r = invoke("ik", str(session), "--targets", t, "--out", str(out))
        assert_one_error(r, EXIT_REFUSED, "--out", fragment)
    assert not (tmp_path / "missing").exists()


def test_ik_read_only_out_folder_is_refused(
    session: Path, tmp_path: Path, read_only_dir: Path
) -> None:
    t = str(targets(tmp_path))
    r = invoke("ik", str(session), "--targets", t, "--out", str(read_only_dir / "q.arrow"))
    assert_one_error(r, EXIT_REFUSED, "cannot write in")


def test_ik_pose_and_targets_together_are_refused(session: Path, tmp_path: Path) -> None:
    t = str(targets(tmp_path))
    pose = [str(v) for v in POSE.values()]
    r = invoke(
        "ik", str(session), "--targets", t, "--out", str(tmp_path / "q.arrow"), "--pose", *pose
    )
    assert_one_error(r, EXIT_REFUSED, "--pose and --targets both given")


def test_ik_out_over_its_own_targets_file_is_refused(session: Path, tmp_path: Path) -> None:
    t = targets(tmp_path)
    before = t.read_bytes()
    r = invoke("ik", str(session), "--targets", str(t), "--out", str(t))
    assert_one_error(r, EXIT_REFUSED, "is the --targets file")
    assert t.read_bytes() == before


def test_ik_output_columns_in_the_input_are_replaced_not_repeated(
    session: Path, tmp_path: Path
) -> None:
    out = tmp_path / "q.arrow"
    t = targets(tmp_path, status=["stale"], converged=[7], q1_deg=["x"], note=["kept"])
    r = invoke("ik", str(session), "--targets", str(t), "--out", str(out))
    assert r.exit_code == 0, r.output
    df = pl.read_ipc(out)  # polars panics on repeated column names
    assert len(df.columns) == len(set(df.columns))
    assert df["status"][0] == "converged" and df["converged"][0] is True
    assert df["note"][0] == "kept" and df.schema["q1_deg"] == pl.Float64
    # Its own output as input: the same columns again.
    out2 = tmp_path / "q2.arrow"
    assert invoke("ik", str(session), "--targets", str(out), "--out", str(out2)).exit_code == 0
    assert pl.read_ipc(out2).columns == df.columns


def test_no_output_replaces_a_users_file_or_a_sessions_measurements(
    session: Path, tmp_path: Path
) -> None:
    """Regression (issue 32): ``ik --out FILE`` overwrote any file without ``--force``, the
    session's ``recording.mcap`` included; ``export --force`` could overwrite it too."""
    t = str(targets(tmp_path))
    mine = tmp_path / "mine.arrow"
    mine.write_bytes(b"a user's file")
    r = invoke("ik", str(session), "--targets", t, "--out", str(mine))
    assert_one_error(r, EXIT_REFUSED, f"--out {mine} already exists", "--force")
    assert mine.read_bytes() == b"a user's file"
    assert invoke("ik", str(session), "--targets", t, "--out", str(mine), "--force").exit_code == 0
    assert pl.read_ipc(mine)["converged"][0] is True
    recording = (session / "recording.mcap").read_bytes()
    for name in ("recording.mcap", "evaluation.mcap"):
        for argv in (
            ("ik", str(session), "--targets", t, "--out", str(session / name), "--force"),
            ("export", str(session), "--format", "dh", "--out", str(session / name), "--force"),
        ):
            r = invoke(*argv)
            assert_one_error(r, EXIT_REFUSED, f"{session / name} is a session's measurements")
    assert (session / "recording.mcap").read_bytes() == recording
    assert not (session / "evaluation.mcap").exists()


def test_force_replaces_an_output_never_an_input_or_a_sessions_own_files(
    session: Path, tmp_path: Path
) -> None:
    """Issue 44: ``plan OUT --robot OUT --force`` replaced the robot description it read
    with the plan; ``--force`` let ``plan``, ``export`` and ``ik`` write over a session's
    ``signature.json`` or a stage table."""
    robot = tmp_path / "arm.toml"
    shutil.copy(Path(__file__).resolve().parents[1] / "examples" / "ur10_ipa" / "ur10.toml", robot)
    before = robot.read_bytes()
    for extra in (("--poses", "20"), ("--sweeps",)):
        r = invoke("plan", str(robot), "--robot", str(robot), "--force", *extra)
        assert_one_error(r, EXIT_REFUSED, f"{robot} is an input of this command")
    assert robot.read_bytes() == before
    own = [session / "signature.json", *sorted((session / "stages").glob("*.arrow"))[:2]]
    kept = {p: p.read_bytes() for p in own}
    t = str(targets(tmp_path))
    for path in own:
        for argv in (
            ("plan", str(path), "--robot", "puma560", "--poses", "20", "--force"),
            ("export", str(session), "--format", "dh", "--out", str(path), "--force"),
            ("ik", str(session), "--targets", t, "--out", str(path), "--force"),
        ):
            r = invoke(*argv)
            assert_one_error(r, EXIT_REFUSED, "which only `pipeline identify` writes")
    assert {p: p.read_bytes() for p in own} == kept


def test_non_finite_joint_values_and_poses_are_refused(session: Path) -> None:
    # fk printed a NaN pose with exit 0; ik blamed the design inverse.
    r = invoke("fk", "puma560", "--q", "nan 0 0 0 0 0")
    assert_one_error(r, EXIT_REFUSED, "--q must hold finite numbers")
    r = invoke("ik", str(session), "--pose", "nan", "0", "0", "0", "0", "0")
    assert_one_error(r, EXIT_REFUSED, "--pose must hold finite numbers")
    r = invoke("ik", str(session), "--pose", *map(str, POSE.values()), "--near", "0 inf 0 0 0 0")
    assert_one_error(r, EXIT_REFUSED, "--near must hold finite numbers")


def test_ik_target_not_reached_exits_3(session: Path, tmp_path: Path) -> None:
    r = invoke("ik", str(session), "--pose", *FAR)
    assert r.exit_code == EXIT_NOT_REACHED and "q = " in r.stdout
    far = dict(zip(POSE, map(float, FAR), strict=True))
    t = write_arrow(tmp_path / "t.arrow", pa.table({k: [POSE[k], far[k]] for k in POSE}))
    out = tmp_path / "q.arrow"
    r = invoke("ik", str(session), "--targets", str(t), "--out", str(out))
    assert r.exit_code == EXIT_NOT_REACHED and "1 of 2 targets converged" in r.stdout
    assert pl.read_ipc(out)["converged"].to_list() == [True, False]
    r = invoke("ik", str(session), "--pose", *map(str, POSE.values()))
    assert r.exit_code == 0, r.output


# --- audit, montecarlo ------------------------------------------------------------------


@pytest.mark.parametrize(
    ("truth", "fragment"),
    [
        ('{"true_kinematics": ', "not a readable JSON file"),
        ("[1, 2]", "not a JSON object"),
        ('{"robot": "puma560"}', "no field 'true_kinematics'"),
        ('{"true_kinematics": {"joint_types": "RRR"}}', "'true_kinematics.joint_types'"),
        (
            '{"true_kinematics": {"joint_types": ["revolute"], "links": [[1]], "base": 1}}',
            "'true_kinematics.links'",
        ),
    ],
    ids=["truncated", "list", "no-kinematics", "types", "links"],
)
def test_audit_bad_truth_is_one_line(
    session: Path, tmp_path: Path, truth: str, fragment: str
) -> None:
    d = tmp_path / "s"
    shutil.copytree(session, d)
    (d / "rig-truth.json").write_text(truth)
    assert_one_error(invoke("audit", str(d)), EXIT_REFUSED, fragment)


def test_audit_truth_for_another_joint_count(session: Path, tmp_path: Path) -> None:
    d = tmp_path / "s"
    shutil.copytree(session, d)
    eye = np.eye(4).tolist()
    one = {"joint_types": ["revolute"], "links": [eye], "base": eye}
    (d / "rig-truth.json").write_text(json.dumps({"true_kinematics": one}))
    assert_one_error(invoke("audit", str(d)), EXIT_REFUSED, "the true robot has 1 joints")


@pytest.mark.parametrize("n", ["0", "-3", "100001"])
def test_audit_configurations_out_of_range(session: Path, n: str) -> None:
    r = invoke("audit", str(session), f"--configurations={n}")
    assert_one_error(r, EXIT_REFUSED, "--configurations", "1 to 100000")


def test_audit_of_the_session_still_works(session: Path) -> None:
    r = invoke("audit", str(session), "--configurations", "50")
    assert r.exit_code == 0 and "signature" in r.stdout


def test_montecarlo_out_file_is_refused_before_computing(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    import pipeline.montecarlo.studies as studies

    def no_study(*args: object, **kwargs: object) -> None:
        raise AssertionError("computed before --out was checked")

    monkeypatch.setattr(studies, "run_study", no_study)
    f = tmp_path / "results.txt"
    f.write_text("mine")
    r = invoke("montecarlo", "--study", "noise", "--robots", "2", "--out", str(f))
    assert_one_error(r, EXIT_REFUSED, "--out", "is a file")
    r = invoke("montecarlo", "--study", "noise", "--robots", "2", "--out", str(f / "sub"))
    assert_one_error(r, EXIT_REFUSED, "is not a folder")
    assert f.read_text() == "mine"


@pytest.mark.parametrize(
    "opts",
    [
        SimulationOptions(noise_factor=math.nan),
        SimulationOptions(max_sweep_deg=math.nan),
        SimulationOptions(max_sweep_deg=0.0),
        SimulationOptions(wac_error_cm=math.inf),
    ],
    ids=["noise_nan", "sweep_nan", "sweep_zero", "wac_inf"],
)
def test_simulate_session_refuses_bad_options_from_python(tmp_path: Path, opts) -> None:
    """Before: the CLI refused these, but simulate_session wrote a recording with them."""
    with pytest.raises(ArmsigError, match="simulation option"):
        simulate_session(tmp_path / "s", opts)
    assert not (tmp_path / "s" / "recording.mcap").exists()


def test_simulate_refuses_a_locked_session(tmp_path: Path) -> None:
    """simulate --force writes under the session lock: a run holding it makes it refuse."""
    from pipeline.errors import SessionLockedError

    d = tmp_path / "s"
    simulate_session(d, SimulationOptions(seed=2, noiseless=True, points=12, repeats=1))
    before = (d / "recording.mcap").read_bytes()
    with locked_elsewhere(d), pytest.raises(SessionLockedError):
        simulate_session(d, SimulationOptions(seed=3, points=12, repeats=1), force=True)
    assert (d / "recording.mcap").read_bytes() == before


@pytest.mark.parametrize("name", ["", ".", "..", "x/..", "sessions/.."])
def test_a_session_name_of_no_folder_of_its_own_is_refused(
    name: str, tmp_path, monkeypatch
) -> None:
    """Regression (issue 32): NAME '' or '..' wrote into sessions/ or the current folder."""
    monkeypatch.chdir(tmp_path)
    assert_one_error(invoke("simulate", name, "--points", "5"), EXIT_REFUSED, repr(name))
    assert list(tmp_path.iterdir()) == []
