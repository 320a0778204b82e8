"""Real measured data (../shared/realdata, or $ARMSIG_REALDATA): issue 14's acceptance.

Skipped, with the reason, when the folder is absent. The files are read from there and
never copied into the repository; derived files (a subset) are written to tmp_path.
Every number is explained in docs/import.md; the ones docs/import.md's "Real data" tables
and examples/README.md quote are compared with the text (issue 30, item 8).
"""

from __future__ import annotations

import os
import warnings
from pathlib import Path

import numpy as np
import pytest
from doc_quotes import assert_quoted
from import_data import TWO_LINK, sscanss2_text

from pipeline.evaluate.validate import validate_against
from pipeline.identify import identify
from pipeline.importers import import_file
from pipeline.stages.refine import refine_summary
from pipeline.stages.tables import read_table

ROOT = Path(__file__).resolve().parent.parent
REALDATA = Path(os.environ.get("ARMSIG_REALDATA", ROOT.parent / "shared" / "realdata"))
EXAMPLES = ROOT / "examples"
pytestmark = pytest.mark.skipif(
    not REALDATA.is_dir(),
    reason=f"real data folder {REALDATA} is absent (set ARMSIG_REALDATA to its path)",
)

#: SScanSS-2's tests/test_calibration.py: the 6-point subsets and the axes found on them.
SUBSETS = {
    1: [0, 100, 200, 300, 400, 500],
    2: [-180, -108, -36, 36, 108, 180],
    3: [-200, -120, -40, 40, 120, 200],
    4: [-200, -120, -40, 40, 120, 200],
}
SSCANSS2_AXES = np.array(
    [
        [-1.59357e-05, 1.25323e-05, 1],
        [-2.27729e-04, -6.01415e-04, -1],
        [7.59974e-05, 1, -7.83437e-04],
        [1, -1.37606e-06, -2.47331e-04],
    ]
)
SSCANSS2_LARGEST_MODEL_ERROR_CM = 0.018427


def _session(tmp: Path, name: str, src: Path, fmt: str, robot: Path, mp: Path | None = None):
    d = tmp / name
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # sparse sweeps: the warnings are the report's
        import_file(src, fmt, robot, d, mp)
        identify(d, report=False)
    return d


def _errors(d: Path, role: str, sweeps_only: bool = False) -> np.ndarray:
    rows = read_table(d / "stages" / "validation.arrow").to_pylist()
    return np.array(
        [r["error_cm"] for r in rows if r["role"] == role and (r["sweep"] > 0 or not sweeps_only)]
    )


def _e(x: float, digits: int = 2) -> str:
    """A small number as the documents write it: 7.50e-8."""
    mantissa, exponent = f"{x:.{digits}e}".split("e")
    return f"{mantissa}e{int(exponent)}"


def test_two_link_model_error(tmp_path: Path) -> None:
    d = _session(tmp_path, "two_link", REALDATA / "sscanss2" / "two_link.csv", "sscanss2",
                 EXAMPLES / "sscanss2" / "two_link.toml")  # fmt: skip
    e = _errors(d, "fit")
    # The file prints mm to 6 decimals: its points sit up to 5.4e-8 cm from the exact
    # geometry (docs/import.md), so no model can do better than that on it.
    assert e.max() <= 1e-7, e.max()
    rms = np.sqrt(np.mean(e**2))
    row = (
        f"| armsig model error on the file | 24 (22 rows + 2 home rows as tool) | {_e(e.max())} cm"
    )
    assert_quoted("docs/import.md", f"{row} | {_e(rms)} cm |")
    assert_quoted("examples/README.md", f"it is {_e(e.max(), 1)} cm, the file's own rounding")
    # The same geometry written without rounding: the identification is exact.
    values = {1: [], 2: []}  # type: dict[int, list[float]]
    for line in (REALDATA / "sscanss2" / "two_link.csv").read_text().split():
        cells = line.split(",")
        values[int(cells[0])].append(float(cells[4]))
    exact = tmp_path / "two_link_exact.csv"
    exact.write_text(sscanss2_text(TWO_LINK, [values[1], values[2]], ",", digits=15))
    d = _session(tmp_path, "two_link_exact", exact, "sscanss2", TWO_LINK)
    assert _errors(d, "fit").max() <= 1e-9


@pytest.fixture(scope="module")
def table_subset(tmp_path_factory: pytest.TempPathFactory) -> Path:
    tmp = tmp_path_factory.mktemp("table")
    lines = (REALDATA / "sscanss2" / "table.txt").read_text().splitlines()
    keep = [ln for ln in lines if ln.strip() and float(ln.split("\t")[4]) in
            SUBSETS[int(ln.split("\t")[0])]]  # fmt: skip
    assert len(keep) == 24
    src = tmp / "table_subset.txt"
    src.write_text("\n".join(keep) + "\n")
    return _session(tmp, "table_subset", src, "sscanss2", EXAMPLES / "sscanss2" / "table.toml")


def test_table_subset_axes_match_sscanss2(table_subset: Path) -> None:
    feats = read_table(table_subset / "stages" / "features.arrow").to_pylist()
    ref = SSCANSS2_AXES / np.linalg.norm(SSCANSS2_AXES, axis=1)[:, None]
    for r in feats:
        axis = np.array([r["axis_x"], r["axis_y"], r["axis_z"]])
        angle = np.arccos(min(1.0, abs(float(axis @ ref[r["joint"] - 1]))))  # sign aside
        assert angle <= 1e-6, (r["joint"], angle)


def test_table_subset_model_error(table_subset: Path) -> None:
    e = _errors(table_subset, "fit", sweeps_only=True)
    assert len(e) == 24
    assert e.max() <= 0.0184, e.max()  # SScanSS-2: 0.018427 cm on the same 24 points
    quoted = (
        f"**{10 * e.max():.4f} mm** (RMS {10 * np.sqrt(np.mean(e**2)):.4f} mm, 24 sweep points)"
    )
    assert_quoted("docs/import.md", quoted)


def test_table_all_44_points(table_subset: Path, tmp_path: Path) -> None:
    r = validate_against(table_subset, REALDATA / "sscanss2" / "table.txt", "sscanss2")
    assert r["n"] == 44
    assert r["max_cm"] <= 0.025 and r["rms_cm"] <= 0.012, r
    assert_quoted(
        "docs/import.md",
        f"the signature of the 24-point subset predicts them with a largest error of "
        f"{10 * r['max_cm']:.4f} mm and an RMS of {10 * r['rms_cm']:.4f} mm",
    )
    d = _session(tmp_path, "table", REALDATA / "sscanss2" / "table.txt", "sscanss2",
                 EXAMPLES / "sscanss2" / "table.toml")  # fmt: skip
    e = _errors(d, "fit", sweeps_only=True)
    largest, rms = 10 * e.max(), 10 * np.sqrt(np.mean(e**2))
    assert len(e) == 44 and largest <= 0.2 and rms <= 0.1
    assert_quoted(
        "docs/import.md", f"the largest model error is {largest:.4f} mm, RMS {rms:.4f} mm"
    )
    assert_quoted("examples/README.md", f"largest {largest:.4f} mm, RMS {rms:.4f} mm")


RCT = REALDATA / "rct_positioner" / "positioner_kinematic_measurements.yaml"


@pytest.fixture(scope="module")
def rct(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The RCT positioner imported with examples/rct_positioner's map (stated σ) and identified."""
    return _session(tmp_path_factory.mktemp("rct"), "rct", RCT, "rct",
                    EXAMPLES / "rct_positioner" / "positioner.toml",
                    EXAMPLES / "rct_positioner" / "map.toml")  # fmt: skip


def _table_row(label: str, n: int, mean: float, rms: float, largest: float, reg: float) -> str:
    """A row of docs/import.md's RCT table (errors in cm, written in mm)."""
    return (
        f"| {label} | {n} | "
        + " | ".join(f"{10 * v:.3f} mm" for v in (mean, rms, largest, reg))
        + " |"
    )


def _stats(rows: list[dict]) -> tuple[float, float, float, float]:
    """Mean, RMS and largest error (cm) of validation rows, and their registered mean."""
    e = np.array([r["error_cm"] for r in rows])
    reg = float(np.mean([r["registered_error_cm"] for r in rows]))
    return float(e.mean()), float(np.sqrt(np.mean(e**2))), float(e.max()), reg


def test_rct_positioner_validated_on_all_poses(rct: Path) -> None:
    rows = read_table(rct / "stages" / "validation.arrow").to_pylist()
    check = [r for r in rows if r["role"] == "check"]
    fit = [r for r in rows if r["role"] == "fit"]
    assert len(check) == 205 - 16 - 13 + 1  # the home pose is in both sweeps
    every = validate_against(rct, RCT, "rct")
    assert every["n"] == 205
    check_mean = _stats(check)[0]
    assert max(check_mean, every["mean_cm"]) < 0.174  # robot_cal_tools' calibration: 1.74 mm
    # What docs/import.md's table and examples/README.md quote.
    label = "validation configurations (never used by the fit)"
    assert_quoted("docs/import.md", _table_row(label, len(check), *_stats(check)))
    assert_quoted(
        "docs/import.md", _table_row("fit data (sweeps and tool)", len(fit), *_stats(fit))
    )
    every_stats = (every[k] for k in ("mean_cm", "rms_cm", "max_cm", "registered_mean_cm"))
    label = "all 205 poses (`pipeline validate --against`)"
    assert_quoted("docs/import.md", _table_row(label, 205, *every_stats))
    assert_quoted(
        "examples/README.md",
        f"The 177 validation poses are predicted with a mean error of {10 * check_mean:.3f} mm, "
        f"all 205 with {10 * every['mean_cm']:.3f} mm",
    )


def _verdict(d: Path) -> dict:
    return read_table(d / "stages" / "verdict.arrow").to_pylist()[0]


def test_stated_sigma_on_sscanss2_and_rct(tmp_path: Path, rct: Path) -> None:
    """Issue 29: with the examples' stated σ the verdict judges χ² (0.00 before, no σ).
    SScanSS-2's table at its measured 0.006 mm: χ²/dof 33.9, the rigid chain leaves
    0.069 mm; the RCT positioner at its radial 0.2 mm: 0.77 (docs/import.md)."""
    table = _session(tmp_path, "table", REALDATA / "sscanss2" / "table.txt", "sscanss2",
                     EXAMPLES / "sscanss2" / "table.toml",
                     EXAMPLES / "sscanss2" / "table_sigma.toml")  # fmt: skip
    v = _verdict(table)
    assert v["stated_sigma_cm"] == pytest.approx(0.0006) and 25 < v["chi2_per_dof"] < 45, v
    assert_quoted("docs/import.md", f"**χ²/dof {v['chi2_per_dof']:.1f}, {v['verdict']}**")
    # issue 41: a χ² beyond the stated noise is a CHECK in numbers (chi2_fail was a FAIL)
    assert v["verdict"] == "CHECK" and "chi2_check" in v["reason_rules"], v["reasons"]
    assert "(stated σ 0.0006 cm)" in v["line"]
    v = _verdict(rct)
    assert v["stated_sigma_cm"] == pytest.approx(0.02) and 0.5 < v["chi2_per_dof"] < 1.2, v
    assert "χ²/dof 0.77 (stated σ 0.02 cm)" in v["line"], v["line"]
    assert_quoted(
        "docs/import.md",
        f"χ²/dof {v['chi2_per_dof']:.2f} (0.00 before, no σ), verdict {v['verdict']} (the "
        f"measured gain over the registered design\non the 177 validation poses, {v['gain']:.2f}×)",
    )


UR10_DATA = REALDATA / "ur10_ipa"
UR10_EXAMPLE = EXAMPLES / "ur10_ipa"
needs_ur10 = pytest.mark.skipif(
    not UR10_DATA.is_dir(), reason=f"UR10 data {UR10_DATA} is absent (issue 26)"
)


@pytest.fixture(scope="module")
def ur10_c70(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """Series C, a seeded 70 % identified, 30 % held out (examples/ur10_ipa)."""
    d = tmp_path_factory.mktemp("ur10") / "c70"
    import_file(UR10_DATA / "Series_C" / "measurements_random_poses.csv", "table",
                UR10_EXAMPLE / "ur10.toml", d, UR10_EXAMPLE / "series_c_holdout.toml")  # fmt: skip
    verdict = identify(d, report=False).verdict or ""
    # issue 41: a CHECK that states the unmodelled error, not a FAIL (README)
    assert (
        verdict.startswith("c70: CHECK")
        and "accuracy limited by unmodelled error: 0.48 mm RMS held out, 9.7× the stated σ"
        in verdict
    ), verdict
    return d


@needs_ur10
def test_ur10_verdict_on_a_real_arm(ur10_c70: Path) -> None:
    """Issue 41's acceptance on the UR10: the measured gain 2.0× on the held-out 30 %
    (design registered as validate registers it), the prediction at those poses within
    1.25× of their error, PASS at a 1 mm requirement and FAIL at 0.3 mm."""
    v = read_table(ur10_c70 / "stages" / "verdict.arrow").to_pylist()[0]
    assert v["gain"] == pytest.approx(v["holdout_design_rms_cm"] / v["holdout_rms_cm"])
    assert 1.9 < v["gain"] < 2.2 and "2.0× the design model held out" in v["line"]
    assert 0.8 < v["holdout_rms_cm"] / v["holdout_expected_rms_cm"] < 1.25
    assert v["unmodelled_rms_cm"] == pytest.approx(0.0473, abs=5e-4)
    for req, level in ((1.0, "PASS"), (0.3, "FAIL")):
        params = {"verdict": {"required_rms_mm": req}}
        line = identify(ur10_c70, report=False, overrides=params).verdict or ""
        assert line.startswith(f"c70: {level}"), line
        d = read_table(ur10_c70 / "stages" / "verdict.arrow").to_pylist()[0]
        assert d["decided_by"] == "required_rms_mm"
    identify(ur10_c70, report=False)  # the defaults again, for the module's other tests


#: SHA-256 of Series C's recording (series_c.toml) as imported before issue 42, every
#: message's JSON (sorted keys, with its topic and time) but the rows' source fields.
SERIES_C_MESSAGES = "19f0b43ec769f87ee7739ef9f72bcba7763cc7a703484267ae353eaa55650934"


@needs_ur10
def test_ur10_series_c_import_unchanged(tmp_path: Path) -> None:
    """Issue 42: the three-column-group layout imports to the same messages, bit for bit
    (the joint states gain only source_line); every row names line and file. Issue 45: the
    pose set is written in blocks, which stand for these messages exactly."""
    import hashlib
    import json

    from pipeline.contract.blocks import row_messages
    from pipeline.contract.channels import POINT_BLOCK_CHANNELS
    from pipeline.contract.mcap_read import read_mcap

    src = UR10_DATA / "Series_C" / "measurements_random_poses.csv"
    import_file(
        src, "table", UR10_EXAMPLE / "ur10.toml", tmp_path / "c", UR10_EXAMPLE / "series_c.toml"
    )
    path = tmp_path / "c" / "recording.mcap"
    content = read_mcap(path, POINT_BLOCK_CHANNELS, "test")
    assert content.messages["/points/block"]  # issue 45: a pose set's rows in blocks
    messages = row_messages(path, content.messages)  # the per-row messages they stand for
    h = hashlib.sha256()
    for topic in sorted(messages):
        for t, m in messages[topic]:
            m = {k: v for k, v in m.items() if k not in ("source_file", "source_line")}
            h.update(json.dumps([topic, t, m], sort_keys=True).encode())
    assert h.hexdigest() == SERIES_C_MESSAGES
    lines = [m["source_line"] for _, m in messages["/robot/joint_state"]]
    assert sorted(lines) == list(range(2, 2775))  # a header, then 2,773 poses


@needs_ur10
def test_ur10_series_c_held_out(ur10_c70: Path) -> None:
    held = read_table(ur10_c70 / "stages" / "holdout.arrow").to_pylist()
    assert len(held) == 832 and {r["sweep"] for r in held} == {-1}  # the 30 %: sweep check
    rms = np.sqrt(np.mean(np.square([r["error_cm"] for r in held])))
    assert rms <= 0.050, rms  # issues 26, 27: ≤ 0.50 mm
    mm = f"{10 * rms:.3f}"
    assert_quoted("README.md", f"| Series C, 832 held-out poses | {mm} mm RMS |")
    assert_quoted("README.md", f"the UR10 trained on 70 % of Series C: C {mm}, A")
    assert_quoted("docs/import.md", f"| C held out (`holdout` stage) | 832 | **{mm} mm** |")
    check = _errors(ur10_c70, "check")
    assert len(check) == 832 and np.sqrt(np.mean(check**2)) <= 0.051
    summary = refine_summary(read_table(ur10_c70 / "stages" / "refine.arrow"))
    assert summary["status"] == "converged"
    # the T-Mac sits 0.09 mm off the flange axis: joint 6's direction is below the noise
    held_names = {h["name"] for h in summary["identifiability"]["held"]}
    assert held_names == {"joint6.rx", "joint6.ry"}, held_names
    # issue 27: joint compliance by default on a pose set, the independent terms only. From
    # the UR10's D-H: joint 1's axis is along gravity (no lever); the origins of frames 3
    # and 4 lie on a line parallel to the parallel axes 2, 3, 4 (one lever for both); a
    # joint's own frame origin on its own axis (4, 5, 6) has none: per joint 2-5, 4, 3,
    # 2 and 1 terms.
    terms = summary["nongeometric"]["terms"]
    per_joint = {j: sum(t.startswith(f"compliance.j{j}.") for t in terms) for j in range(1, 7)}
    assert per_joint == {1: 0, 2: 4, 3: 3, 4: 2, 5: 1, 6: 0}, terms


#: Where the README and docs/import.md quote each number ({v}: in mm, 3 decimals).
B_MEASURED = (
    ("README.md", "C's tracker placement), as measured / registered | {v} /"),
    ("README.md", "B {v}, D"),
    ("docs/import.md", "| B as measured | 1,495 | **{v} mm** |"),
)
B_REGISTERED = (
    ("README.md", " / {v} mm | 1."),
    ("docs/import.md", "| B registered | 1,495 | {v} mm |"),
)
A_REGISTERED = (
    ("README.md", "(11,911 poses, tracker moved), registered | {v} mm |"),
    ("README.md", "A {v}, B"),
    ("docs/import.md", "| A registered | 11,911 | {v} mm |"),
)
D_REGISTERED = (
    ("README.md", "(632 poses, tracker moved), registered | {v} mm |"),
    ("README.md", "D {v} mm;"),
    ("docs/import.md", "| D registered | 632 | {v} mm |"),
)


@needs_ur10
@pytest.mark.parametrize(
    ("series", "file", "key", "bound_cm", "quotes"),
    [
        ("b", "Series_B/measurements_joint_configurations.csv", "rms_cm", 0.085, B_MEASURED),
        ("b", "Series_B/measurements_joint_configurations.csv", "registered_rms_cm", 0.06,
         B_REGISTERED),
        ("a", "Series_A/measurements_grid.csv", "registered_rms_cm", 0.075, A_REGISTERED),
        ("d", "Series_D/measurements_iso_cubes.csv", "registered_rms_cm", 0.065, D_REGISTERED),
    ],
)  # fmt: skip
def test_ur10_other_series(
    ur10_c70: Path, series: str, file: str, key: str, bound_cm: float, quotes: tuple
) -> None:
    """B shares C's tracker placement (as measured); A and D were measured from elsewhere
    (base registered). Issue 27's goals (B ≤ 0.85 mm as measured, A ≤ 0.75, D ≤ 0.65);
    measured with joint compliance (README): B 0.820 mm, registered 0.588 mm; A 0.636 mm;
    D 0.579 mm (rigid: B 1.543, A 0.892, D 0.847)."""
    r = validate_against(
        ur10_c70, UR10_DATA / file, "table", UR10_EXAMPLE / f"series_{series}.toml"
    )
    assert r["target"] == "tmac" and r["rows_skipped"] == 0
    assert r[key] <= bound_cm, r
    for doc, quote in quotes:
        assert_quoted(doc, quote.format(v=f"{10 * r[key]:.3f}"))
    # validate's own baseline beside the signature: the design, base and tool registered
    design = f"{10 * r['design_registered_rms_cm']:.3f} mm"
    assert_quoted("README.md", f"{series.upper()} {design}")  # "... points: B 1.085 mm, A ..."


@needs_ur10
def test_ur10_orientation_convention_on_the_hand_eye_file() -> None:
    """The maps' Euler convention (intrinsic x-y-z) is the one under which the T-Mac's
    measured orientations turn between poses as the controller's flange does: R_meas =
    X · R_flange · Y, so R_meas,i⁻¹ R_meas,j = Y⁻¹ (R_flange,i⁻¹ R_flange,j) Y for constant
    X, Y. Y is fitted to the rotation vectors; the other conventions leave degrees."""
    import csv
    import itertools

    from scipy.spatial.transform import Rotation

    rows = list(
        csv.reader((UR10_DATA / "Series_C" / "calibration_handeye.csv").open(), delimiter=";")
    )
    head = rows[0]
    data = np.array([[float(c.replace(",", ".")) for c in r] for r in rows[1:] if r])
    col = {h: data[:, k] for k, h in enumerate(head)}
    flange = Rotation.from_quat(np.c_[[col[f"flange_q{a}"] for a in "xyzw"]].T)
    angles = np.c_[[col[f"measurement_r{a}"] for a in "xyz"]].T

    def misfit(seq: str) -> float:
        meas = Rotation.from_euler(seq, angles, degrees=True)
        pairs = list(itertools.combinations(range(len(data)), 2))
        a = np.array([(flange[i].inv() * flange[j]).as_rotvec() for i, j in pairs])
        b = np.array([(meas[i].inv() * meas[j]).as_rotvec() for i, j in pairs])
        y, _ = Rotation.align_vectors(b, a)
        return float(np.degrees(np.sqrt(np.mean(np.sum((y.apply(a) - b) ** 2, axis=1)))))

    assert misfit("XYZ") < 0.1  # measured 0.080 deg
    assert min(misfit(s) for s in ("xyz", "ZYX", "XZY", "zxy", "YXZ")) > 5.0


@needs_ur10
def test_ur10_plan_from_series_c_beats_random_subsets(tmp_path: Path) -> None:
    """Issue 28: 60 poses chosen by `plan --from` the identified Series C give a lower
    held-out RMS on the remaining poses than the median of 20 seeded random 60-pose
    subsets. Measured: 0.528 mm against a median 0.532 mm (0.503-0.550): the robot's
    0.48 mm floor, which no choice of poses lowers, dominates both (docs/plan.md)."""
    from pipeline.planning import plan_from_session

    src = UR10_DATA / "Series_C" / "measurements_random_poses.csv"
    lines = src.read_text().splitlines()
    head, rows = lines[0], [line for line in lines[1:] if line.strip()]
    robot, mp = UR10_EXAMPLE / "ur10.toml", UR10_EXAMPLE / "series_c.toml"
    import_file(src, "table", robot, tmp_path / "full", mp)
    identify(tmp_path / "full", report=False)
    chosen = np.array(plan_from_session(tmp_path / "full", 60)[1].source_steps)

    def held_out(train: np.ndarray, tag: str) -> float:
        rest = np.setdiff1d(np.arange(len(rows)), train)
        for name, idx in ((f"{tag}.csv", train), (f"{tag}_rest.csv", rest)):
            (tmp_path / name).write_text("\n".join([head, *(rows[i] for i in idx)]) + "\n")
        import_file(tmp_path / f"{tag}.csv", "table", robot, tmp_path / tag, mp)
        identify(tmp_path / tag, report=False)
        r = validate_against(tmp_path / tag, tmp_path / f"{tag}_rest.csv", "table", mp)
        return float(r["rms_cm"])

    planned = held_out(chosen, "plan")
    rng = np.random.default_rng(28)
    random = [held_out(np.sort(rng.choice(len(rows), 60, replace=False)), f"r{k}")
              for k in range(20)]  # fmt: skip
    assert planned < np.median(random), (planned, np.median(random))
