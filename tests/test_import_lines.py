"""Issue 32 item 3: lines are what an editor shows, and duplicates are refused.

``skip_lines`` counts only \\n, \\r\\n and \\r as line ends: a form feed, U+2028, NEL or
a vertical tab inside a line leaves the numbering alone. A repeated YAML key (rct) and a
repeated header name the map uses are refused with one line naming them."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from import_data import TWO_LINK, TWO_LINK_MAP, two_link_table
from typer.testing import CliRunner

from pipeline.cli import EXIT_REFUSED, app
from pipeline.errors import ImportFileError
from pipeline.importers.mapping import load_map
from pipeline.importers.rct import read_rct
from pipeline.importers.table import read_table
from pipeline.robots.description import load_description

OUTLIER_MM = 50.0


def _with_outlier(tmp: Path, odd: str, line_end: str = "\n") -> tuple[Path, int]:
    """The two-link table with ``odd`` inside its 3rd data row and a row 50 mm off after
    it; the outlier's line number as an editor shows it."""
    src = two_link_table(tmp / "t.csv")
    lines = src.read_text().splitlines()  # 1 comment, 1 header, rows
    cells = lines[4].split(",")
    out = ",".join([*cells[:4], str(float(cells[4]) + OUTLIER_MM), *cells[5:]])
    lines[4] = lines[4] + odd  # an odd character at the end of the row before
    lines.insert(5, out)
    src.write_bytes(line_end.join(lines).encode() + b"\n")
    return src, 6


@pytest.mark.parametrize(
    ("odd", "line_end"),
    [("\f", "\n"), ("\u2028", "\n"), ("\x85", "\n"), ("\v", "\n"), ("\x1c", "\n"),
     ("\u2029", "\r\n"), ("\f", "\r")],
)  # fmt: skip
def test_skip_lines_counts_lines_as_an_editor(tmp_path: Path, odd: str, line_end: str) -> None:
    src, outlier = _with_outlier(tmp_path, odd, line_end)
    mp = tmp_path / "map.toml"
    mp.write_text(f"skip_lines = [{outlier}]\n" + TWO_LINK_MAP)
    rows = read_table(src, load_map(mp), load_description(TWO_LINK))
    assert f"line {outlier}" not in rows.where and "line 5" in rows.where, rows.where
    assert len(rows.where) == 7 + 7 - 1 + 1  # the sweeps' rows (home in both) and line 5
    z = rows.targets["a"][:, 2]
    assert np.ptp(z) < OUTLIER_MM / 10 / 2  # the 5 cm outlier is not among them


def test_cr_cr_lf_is_two_line_ends(tmp_path: Path) -> None:
    """An editor shows \\r\\r\\n as a line end and an empty line: the numbers after it
    count both (as every line end of the file: \\n, \\r\\n or \\r)."""
    src, outlier = _with_outlier(tmp_path, "\r\r")
    mp = tmp_path / "map.toml"
    mp.write_text(f"skip_lines = [{outlier + 1}]\n" + TWO_LINK_MAP)
    rows = read_table(src, load_map(mp), load_description(TWO_LINK))
    assert np.ptp(rows.targets["a"][:, 2]) < OUTLIER_MM / 10 / 2


def _refused(args: list[str]) -> str:
    r = CliRunner().invoke(app, ["import", *args])
    assert r.exit_code == EXIT_REFUSED, r.output
    assert len(r.stderr.splitlines()) == 1, r.stderr
    return r.stderr


def test_duplicated_header_name_refused_unless_numbered(tmp_path: Path) -> None:
    src = two_link_table(tmp_path / "t.csv")
    text = src.read_text().replace("x2,y2,z2", "x1,y1,z1")  # two reflectors, same names
    src.write_text(text)
    mp = tmp_path / "map.toml"
    mp.write_text(TWO_LINK_MAP)
    err = _refused([str(src), "--format", "table", "--robot", str(TWO_LINK),
                    "--map", str(mp), str(tmp_path / "s")])  # fmt: skip
    assert "'x1'" in err and "columns 3 and 6" in err and "by its number" in err, err
    assert not (tmp_path / "s" / "recording.mcap").exists()
    # disambiguated in the map: the reflectors' columns by number
    numbered = TWO_LINK_MAP.replace('x = "x1"\ny = "y1"\nz = "z1"', "x = 3\ny = 4\nz = 5")
    mp.write_text(numbered.replace('x = "x2"\ny = "y2"\nz = "z2"', "x = 6\ny = 7\nz = 8"))
    rows = read_table(src, load_map(mp), load_description(TWO_LINK))
    np.testing.assert_allclose(rows.targets["b"][:, 2] - rows.targets["a"][:, 2], 0.05)


RCT_ENTRY = """{k}:
  pose: {{x: {x}, y: 0.1, z: 0.2, qw: 1.0, qx: 0.0, qy: 0.0, qz: 0.0}}
  target_joints: [0.0, 0.0]
  camera_joints: []
"""


def test_duplicated_yaml_key_refused(tmp_path: Path) -> None:
    robot = load_description(Path(__file__).resolve().parent.parent / "examples" /
                             "rct_positioner" / "positioner.toml")  # fmt: skip
    src = tmp_path / "m.yaml"
    src.write_text("".join(RCT_ENTRY.format(k=k, x=x) for k, x in ((1, 0.1), (2, 0.2), (1, 0.3))))
    with pytest.raises(ImportFileError, match=r"m.yaml: line 9: key 1 appears twice") as e:
        read_rct(src, robot)
    assert "\n" not in str(e.value)
