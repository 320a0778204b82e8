"""Bad import input: one line naming the file, the line and the fix; nothing written."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

import pytest
from import_data import TWO_LINK, TWO_LINK_MAP, TWO_LINK_VALUES, sscanss2_text, two_link_table
from typer.testing import CliRunner

from pipeline.cli import EXIT_REFUSED, app


def _sscanss2(edit: Callable[[list[str]], list[str]]) -> Callable[[Path], list[str]]:
    def make(tmp: Path) -> list[str]:
        lines = sscanss2_text(TWO_LINK, TWO_LINK_VALUES).splitlines()
        (tmp / "f.txt").write_text("\n".join(edit(lines)) + "\n")
        return [str(tmp / "f.txt"), "--format", "sscanss2"]

    return make


def _table(
    edit_csv: Callable[[list[str]], list[str]], edit_map: Callable[[str], str] = str
) -> Callable[[Path], list[str]]:
    def make(tmp: Path) -> list[str]:
        src = two_link_table(tmp / "f.csv")
        src.write_text("\n".join(edit_csv(src.read_text().splitlines())) + "\n")
        (tmp / "map.toml").write_text(edit_map(TWO_LINK_MAP))
        return [str(src), "--format", "table", "--map", str(tmp / "map.toml")]

    return make


def _cell(lines: list[str], k: int, col: int, value: str, sep: str = "\t") -> list[str]:
    cells = lines[k].split(sep)
    cells[col] = value
    return [*lines[:k], sep.join(cells), *lines[k + 1 :]]


def _moves_j1(lines: list[str]) -> list[str]:
    # line 12 of the CSV (sweep of joint 2) with joint 1 at 3 deg instead of 0
    return [*lines[:11], "3" + lines[11][lines[11].index(",") :], *lines[12:]]


CASES = {
    "missing column (sscanss2)": (
        _sscanss2(lambda ls: [*ls[:2], ls[2].rsplit("\t", 1)[0], *ls[3:]]),
        ["f.txt: line 3: 6 columns", "missing column"],
    ),
    "missing column (table)": (
        _table(lambda ls: ls, lambda m: m.replace('x = "x2"', 'x = "x9"')),
        ["f.csv: line 2: missing column 'x9'", "try:"],
    ),
    "unknown unit": (
        _table(lambda ls: ls, lambda m: m.replace('unit = "rad"', 'unit = "grad"')),
        ["map.toml", "unknown revolute joint 'link2' unit 'grad'", "deg | rad"],
    ),
    "joint never moves (sscanss2)": (
        _sscanss2(
            lambda ls: [_cell(ls, k, 4, "0")[k] if k >= 7 else ls[k] for k in range(len(ls))]
        ),
        ["f.txt: joint 2 (link2) never moves", "try:"],
    ),
    "joint never moves (table, infer)": (
        _table(lambda ls: ls[:9]),
        ["f.csv: joint 2 (link2) never moves", "try:"],
    ),
    "two joints move in one sweep (infer)": (
        _table(_moves_j1),
        ["f.csv: line 12 and line 13", "two or more joints change"],
    ),
    "two joints move in one sweep (sweep column)": (
        _table(
            lambda ls: [
                ls[0],
                ls[1] + ",sweep",
                *(x + (",1" if k < 7 else ",2") for k, x in enumerate(_moves_j1(ls)[2:])),
            ],  # fmt: skip
            lambda m: m.replace('column = "infer"', 'column = "sweep"'),
        ),
        ["f.csv: line 12: joint 1 (link1) moves in the sweep of joint 2", "try:"],
    ),
    "NaN row (sscanss2)": (
        _sscanss2(lambda ls: _cell(ls, 4, 2, "nan")),
        ["f.txt: line 5: a value is missing or not a number (NaN)", "try:"],
    ),
    "NaN row (table), --strict": (  # without --strict: dropped and said (issue 42)
        lambda tmp: [
            *_table(lambda ls: [*ls[:4], ls[4].replace(ls[4].split(",")[3], "", 1), *ls[5:]])(tmp),
            "--strict",
        ],  # fmt: skip
        [
            "f.csv: line 5: a measured value is missing or not a finite number (1 such rows; "
            "by column: y1 1)",
            "--strict",
        ],
    ),
    "duplicated row": (
        _sscanss2(lambda ls: [*ls[:4], ls[3], *ls[4:]]),
        ["f.txt: line 4 and line 5 measure joint 1 (link1) at the same reading", "duplicated"],
    ),
    "stops within sweeps.duplicate": (
        _table(lambda ls: ls, lambda m: m + "duplicate = [0.01, 45]\n"),
        [
            "f.csv: line 10 and line 11 measure joint 2 (link2) at the same reading -120",
            "within 45, the map's sweeps.duplicate",
        ],
    ),  # fmt: skip
    "tolerance per joint of another robot": (
        _table(lambda ls: ls, lambda m: m.replace("tolerance = 0.01", "tolerance = [1, 2, 3]")),
        ["map.toml: sweeps.tolerance has 3 values", "one number, or 2 (one per joint"],
    ),
    "type disagrees with the robot": (
        _sscanss2(lambda ls: _cell(ls, 0, 5, "prismatic")),
        ["f.txt: line 1: joint 1 is 'prismatic' in the file but 'revolute'", "try:"],
    ),
}


@pytest.mark.parametrize("case", CASES)
def test_bad_input_one_line_nothing_written(tmp_path: Path, case: str) -> None:
    make, fragments = CASES[case]
    args = make(tmp_path)
    session = tmp_path / "sessions" / "s"
    r = CliRunner().invoke(app, ["import", *args, "--robot", str(TWO_LINK), str(session)])
    assert r.exit_code == EXIT_REFUSED, (r.exit_code, r.output)
    lines = r.stderr.splitlines()
    assert len(lines) == 1 and lines[0].startswith("error: "), r.stderr
    for f in fragments:
        assert f in lines[0], (f, lines[0])
    assert not (session / "recording.mcap").exists()
    assert not session.exists() or not any(session.iterdir())


@pytest.mark.parametrize("command", ["import", "simulate"])
def test_the_temp_files_of_a_killed_run_are_removed_by_the_next(
    tmp_path: Path, command: str
) -> None:
    """Issue 44: ``kill -9`` during ``import --force`` left a temp file beside the recording
    (1 of 16 kills); the next import or simulate of the session, under its lock, removes
    what killed writers left (the names a kill leaves: the staged import and an atomic
    write's temp file beside it), and writes its recording."""
    s = tmp_path / "s"
    src = tmp_path / "two.txt"
    src.write_text(sscanss2_text(TWO_LINK, TWO_LINK_VALUES))
    imp = ["import", str(src), "--format", "sscanss2", "--robot", str(TWO_LINK), str(s)]
    assert CliRunner().invoke(app, imp).exit_code == 0
    debris = [s / ".recording.mcap.import.tmp", s / "..recording.mcap.import.tmp.k9x2.tmp",
              s / ".recording.mcap.q81z.tmp"]  # fmt: skip
    for p in debris:
        p.write_bytes(b"\x89MCAP0\r\n half written")
    argv = imp if command == "import" else ["simulate", str(s), "--points", "5", "--repeats", "1"]
    r = CliRunner().invoke(app, [*argv, "--force"])
    assert r.exit_code == 0, r.output
    assert sorted(p.name for p in s.iterdir() if p.name.endswith(".tmp")) == []
