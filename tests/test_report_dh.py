"""The report's D-H table is the one `pipeline export --format dh` writes (issue 42): on
the UR10's parallel axes Hayati's β, d the size of the arm, where the pseudo D-H of stage
`dh` (a common normal far from the arm) reaches metres."""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
from import_data import UR10
from layout_data import one_file, pose_set

from pipeline.identify import identify
from pipeline.importers import import_file
from pipeline.kinematics.dh_table import dh_table_from_chain
from pipeline.report.identification import _dh_section
from pipeline.robots.description import load_description
from pipeline.signature.session import load_session_signature
from pipeline.stages.tables import read_table


def test_report_dh_table_is_exports(tmp_path: Path) -> None:
    paths, text = one_file(pose_set(), tmp_path)
    (tmp_path / "map.toml").write_text(text)
    import_file(str(paths[0]), "table", UR10, tmp_path / "s", tmp_path / "map.toml")
    identify(tmp_path / "s", report=False)
    robot = load_description(UR10)
    section = _dh_section(tmp_path / "s", robot)
    rows = [ln.split("|")[1:-1] for ln in section.splitlines() if re.match(r"\| \d ", ln)]
    d = np.array([float(r[5]) for r in rows])
    want = dh_table_from_chain(load_session_signature(tmp_path / "s" / "signature.json").chain)
    assert np.allclose(d, want.d, atol=1e-4)  # the printed digits (4 decimals)
    beta = [r[11].strip() for r in rows]
    assert [b != "—" for b in beta] == list(want.hayati) and any(want.hayati)
    pseudo = [
        abs(r["d_cm"]) for r in read_table(tmp_path / "s" / "stages" / "dh.arrow").to_pylist()
    ]
    print("pseudo |d| max", max(pseudo), "export-form |d| max", np.abs(d).max())
    assert np.abs(d).max() < 200.0 < max(pseudo)  # the arm's size, not the pseudo D-H's
