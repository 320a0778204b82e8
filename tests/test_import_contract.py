"""Issue 32 item 6: ``import`` writes only what ``identify`` accepts. The recording is
checked with identify's own reader (the channel schemas and the session contract) before
it takes the place of ``recording.mcap``; what fails is refused in one line."""

from __future__ import annotations

from pathlib import Path

import pytest
from import_data import TWO_LINK, TWO_LINK_MAP, UR10, pose_set_map, pose_set_table, two_link_table

from pipeline.errors import ImportFileError
from pipeline.importers import import_file
from pipeline.stages.recording import read_recording


def test_coordinates_beyond_the_contract_refused(tmp_path: Path) -> None:
    """A UR10 measured in mm, declared as m: points 1,300 m out, beyond the contract's
    ±1,000 m; identify refused the recording, import wrote it."""
    src, _ = pose_set_table(tmp_path / "p.csv")
    mp = tmp_path / "map.toml"
    mp.write_text(pose_set_map().replace('length_unit = "mm"', 'length_unit = "m"'))
    with pytest.raises(ImportFileError) as e:
        import_file(src, "table", UR10, tmp_path / "s", mp)
    msg = str(e.value)
    assert "p.csv: identify would refuse this recording" in msg and "_cm must be" in msg, msg
    assert "length_unit" in msg and "\n" not in msg
    left = sorted(p.name for p in (tmp_path / "s").iterdir())
    assert left == [".pipeline.lock"], left  # no recording, no temp file


def test_two_targets_recording_is_one_identify_reads(tmp_path: Path) -> None:
    """Two reflectors: the tool measurement carries the tool target only (the contract's
    plan.tool_target); it carried both, which identify refused."""
    src = two_link_table(tmp_path / "two.csv")
    mp = tmp_path / "map.toml"
    mp.write_text(TWO_LINK_MAP)
    import_file(src, "table", TWO_LINK, tmp_path / "s", mp)
    rec = read_recording(tmp_path / "s" / "recording.mcap")
    assert rec is not None
