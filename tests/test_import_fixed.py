"""Issue 42: base reflectors register the poses only when their readings move beyond
their noise (``fixed_correction = "auto"``, an F test at 1 % false alarms), or as the map
forces it (``"always"``, ``"never"``). A driftless session with reflectors imports the
plain session's points bit for bit (docs/import.md, Fixed targets)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from import_data import UR10
from layout_data import BASE_MM, drifting, fixed_map, one_file, one_file_all, pose_set
from test_import_layouts import _refused, imported, messages

from pipeline.importers import Imported, import_file
from pipeline.importers.fixed_motion import FALSE_ALARM, motion_test

DOC = Path(__file__).resolve().parent.parent / "docs" / "import.md"
NOT = "poses.csv: fixed targets b1, b2, b3: no drift beyond their noise, not corrected (F = "
DONE = "poses.csv: fixed targets b1, b2, b3: drift beyond their noise, corrected (F = "


def _session(tmp: Path, drift_mm: float, how: str | None = None) -> tuple[Imported, Path]:
    """60 UR10 poses and three base reflectors (0.01 mm noise, seed 5) in one file, the
    reflectors fixed and each pose registered by windows of 5; and the file."""
    tmp.mkdir(parents=True, exist_ok=True)
    ps = pose_set(n=60)
    text = one_file(ps, tmp)[1]
    src = one_file_all(drifting(ps, drift_mm), tmp)  # the same name: the arm-only file replaced
    head = "fixed_block = 5\n" + ("" if how is None else f'fixed_correction = "{how}"\n')
    (tmp / "fixed.toml").write_text(head + fixed_map(text))
    (tmp / "plain.toml").write_text(text)
    return import_file(str(src), "table", UR10, tmp / "s", tmp / "fixed.toml"), src


def test_a_driftless_session_with_reflectors_imports_the_plain_points(tmp_path: Path) -> None:
    out, _ = _session(tmp_path / "fixed", 0.0)
    (note,) = out.rows.notes
    assert note.startswith(NOT) and "<= 1.5, the 1% false-alarm level of F(66, 465)" in note
    assert "; every pose used uncorrected; drift median" in note, note
    assert f"warning: {note}\n" in DOC.read_text()  # docs/import.md quotes it
    plain = imported(tmp_path / "plain", one_file, pose_set(n=60))
    got = messages(tmp_path / "fixed" / "s")
    for m in got["/robot/joint_state"]:  # the drift per pose stays; no residual: not applied
        assert m.pop("tracker_drift_cm") > 0.0 and "tracker_residual_cm" not in m
    assert got == messages(plain)


@pytest.mark.parametrize(
    ("drift_mm", "how", "corrected"),
    [(0.0, "auto", False), (0.0, "always", True), (0.0, "never", False),
     (0.05, None, True), (0.05, "always", True), (0.05, "never", False)],
)  # fmt: skip
def test_fixed_correction_auto_always_never(
    tmp_path: Path, drift_mm: float, how: str | None, corrected: bool
) -> None:
    out, src = _session(tmp_path, drift_mm, how)
    plain = import_file(str(src), "table", UR10, tmp_path / "p", tmp_path / "plain.toml")
    moved = not np.array_equal(out.rows.targets["tmac"], plain.rows.targets["tmac"])
    assert moved == corrected
    assert np.isfinite(out.rows.residual_cm).all() == corrected  # type: ignore[arg-type]
    assert np.isfinite(out.rows.drift_cm).all()  # type: ignore[arg-type]
    (note,) = out.rows.notes
    if how in (None, "auto"):
        assert note.startswith(DONE if corrected else NOT), note
    else:
        assert note.startswith(f'poses.csv: fixed targets b1, b2, b3: fixed_correction = "{how}" '
                               "(F = "), note  # fmt: skip
    assert ("registered 60 poses by their own readings (windows of 5 poses)" in note) == corrected


def test_a_bad_fixed_correction_is_one_line(tmp_path: Path) -> None:
    ps = pose_set(n=20)
    text = fixed_map(one_file(ps, tmp_path)[1])
    src = one_file_all(drifting(ps, 0.05), tmp_path)
    line = _refused(tmp_path, [src], 'fixed_correction = "sometimes"\n' + text)
    assert line.startswith("error: map.toml: fixed_correction: "), line
    assert "expected 'auto' | 'always' | 'never'" in line, line


@pytest.mark.parametrize("key", ['fixed_correction = "always"', "fixed_block = 5"])
def test_a_fixed_key_without_fixed_targets_is_one_line(tmp_path: Path, key: str) -> None:
    """A drift setting in a map whose targets are all on the arm would do nothing."""
    ps = pose_set(n=20)
    paths, text = one_file(ps, tmp_path)
    line = _refused(tmp_path, paths, f"{key}\n" + text)
    assert line.startswith(f"error: map.toml: {key.split()[0]}: is given, but no "), line
    assert "fixed = true on the base's reflectors" in line, line


def _readings(rng: np.random.Generator, n: int = 60, sigma_cm: float = 0.001) -> np.ndarray:
    """Three base reflectors read at ``n`` poses, no drift (cm)."""
    base = np.array(list(BASE_MM.values())) / 10.0
    return base + rng.normal(0.0, sigma_cm, (n, len(base), 3))


def test_the_motion_test_false_alarms_at_its_level() -> None:
    """Readings that hold still: F(d1, d2) whatever their σ, so about 1 % are taken for
    drift (400 sets: expected 4; more than 12 has a chance of 1e-4) and F averages
    d2 / (d2 − 2) ≈ 1 (its spread over 400 sets ±0.01 at k = 5)."""
    rng = np.random.default_rng(3)
    for k, sigma in ((5, 0.001), (1, 0.004)):
        tests = []
        for _ in range(400):
            fixed = _readings(rng, sigma_cm=sigma)
            test = motion_test(fixed, np.median(fixed, axis=0), k)
            assert test is not None
            tests.append(test)
        assert sum(t.moved for t in tests) <= 12, (k, sum(t.moved for t in tests))
        assert abs(np.mean([t.f for t in tests]) - 1.0) < 0.05, k
        assert abs(np.median([t.sigma_cm for t in tests]) / sigma - 1.0) < 0.05
    assert FALSE_ALARM == 0.01


def test_the_motion_test_sees_a_drift_and_takes_missing_readings() -> None:
    """A shift of 0.02 mm (twice the readings' σ) halfway through 60 poses is seen; readings
    missing at some poses (a block of two reflectors: a motion of 5 degrees of freedom)
    leave the test well defined."""
    rng = np.random.default_rng(4)
    fixed = _readings(rng)
    fixed[30:] += [0.002, 0.0, 0.0]
    fixed[[3, 4, 40], 2] = np.nan
    fixed[5:10, 2] = np.nan
    test = motion_test(fixed, np.nanmedian(fixed, axis=0), 5)
    assert test is not None and test.moved and test.d1 == 6 * 12 - 1 - 6, test
    assert motion_test(fixed[:4], np.nanmedian(fixed, axis=0), 5) is None  # one block


def test_the_report_says_when_the_points_were_not_corrected() -> None:
    import pyarrow as pa

    from pipeline.report.validation import drift_text

    def joints(residual: float | None) -> pa.Table:  # two joint rows per configuration
        return pa.Table.from_pylist(
            [{"sweep": -2, "step": s, "tracker_drift_cm": 0.001 * (s + 1),
              "tracker_residual_cm": residual} for s in range(3) for _ in range(2)],
            pa.schema([("sweep", pa.int32()), ("step", pa.int32()),
                       ("tracker_drift_cm", pa.float64()), ("tracker_residual_cm", pa.float64())]),
        )  # fmt: skip

    text = drift_text(joints(None))
    assert "median 0.002 cm, max 0.003 cm before the correction. Not corrected" in text, text
    assert "the points above are as measured" in text
    text = drift_text(joints(0.0005))
    assert "after registering each pose by them, median 0.0005 cm" in text, text
    assert text.endswith("The points above are the registered ones.")


def test_noiseless_readings_are_not_tested_and_registered() -> None:
    """No scatter to judge the motion by: ``auto`` registers, as before, and says so."""
    from pipeline.importers.fixed import _decided

    fixed = _readings(np.random.default_rng(5), sigma_cm=0.0)
    assert motion_test(fixed, np.median(fixed, axis=0), 5) is None
    assert _decided("auto", None) == (True, "corrected (not tested: too few readings, or "
                                      "none scattered)")  # fmt: skip
    assert _decided("never", None)[0] is False
