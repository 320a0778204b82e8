"""Issue 29, item 3: a stated point noise for every import format (a map's ``sigma``, or σ
columns) reaches the fit's weights and the verdict's χ²; without one the verdict applies no
χ² rule and says so."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from import_data import TABLE, sscanss2_text

from pipeline.errors import ImportFileError
from pipeline.identify import identify
from pipeline.importers import import_file
from pipeline.stages.recording import read_recording
from pipeline.stages.refine import refine_summary
from pipeline.stages.runner import stage_path
from pipeline.stages.tables import read_table

#: 11 stops per joint of SScanSS-2's P R P P table (mm / deg).
VALUES = [list(range(0, 501, 50)), list(range(-180, 181, 36)),
          list(range(-200, 201, 40)), list(range(-200, 201, 40))]  # fmt: skip
SIGMA_MM = 0.01


def _noisy_table(path: Path) -> Path:
    """The table's design geometry, every coordinate with N(0, 0.01 mm) noise (seeded)."""
    rng = np.random.default_rng(29)
    rows = []
    for line in sscanss2_text(TABLE, VALUES, digits=15).splitlines():
        c = line.split("\t")
        c[1:4] = [f"{float(v) + rng.normal(0.0, SIGMA_MM):.6f}" for v in c[1:4]]
        rows.append("\t".join(c))
    path.write_text("\n".join(rows) + "\n")
    return path


def _identified(
    tmp: Path, name: str, map_text: str | None, loss: str = "soft_l1"
) -> tuple[dict, dict]:
    mp = None
    if map_text is not None:
        mp = tmp / f"{name}.toml"
        mp.write_text(map_text)
    d = tmp / name
    import_file(_noisy_table(tmp / "table.txt"), "sscanss2", TABLE, d, mp)
    identify(d, report=False, overrides={"refine": {"loss": loss}})
    verdict = read_table(stage_path(d, "verdict")).to_pylist()[0]
    return verdict, refine_summary(read_table(stage_path(d, "refine")))


def test_a_stated_sigma_weighs_the_fit_and_the_verdict_says_so(tmp_path: Path) -> None:
    stated, fit = _identified(tmp_path, "stated", f'format = "sscanss2"\nsigma = {SIGMA_MM}\n')
    rec = read_recording(tmp_path / "stated" / "recording.mcap")
    assert np.allclose(rec.point_sigma_cm, SIGMA_MM / 10.0)
    assert stated["noise_stated"] and stated["stated_sigma_cm"] == pytest.approx(0.001)
    assert 0.7 < stated["chi2_per_dof"] < 1.4, stated  # the noise drawn is the noise stated
    assert "χ²/dof" in stated["line"] and "(stated σ 0.001 cm)" in stated["line"]
    bare, bare_fit = _identified(tmp_path, "bare", None)
    assert not bare["noise_stated"] and bare["stated_sigma_cm"] is None
    assert "χ²/dof" not in bare["line"] and "χ² not judged" in bare["line"], bare["line"]
    assert bare["verdict"] == "PASS" and bare["reasons"] == []
    # the σ is the weight: least squares, the same residuals at 1 cm (unstated) and 0.001 cm
    stated_ls = _identified(tmp_path, "ls", f"sigma = {SIGMA_MM}\n", "linear")[1]
    bare_ls = _identified(tmp_path, "bare_ls", None, "linear")[1]
    # (to the readings' rounding, resolution²/12, added to each point's variance: 0.16 %)
    assert stated_ls["chi2"] / bare_ls["chi2"] == pytest.approx(1e6, rel=0.005)


def test_a_sscanss2_map_holds_only_a_sigma(tmp_path: Path) -> None:
    mp = tmp_path / "map.toml"
    mp.write_text("sigma = 0.01\n[sweeps]\ntolerance = 0.5\n")
    with pytest.raises(ImportFileError, match="--format sscanss2 reads only sigma and length_unit"):
        import_file(_noisy_table(tmp_path / "t.txt"), "sscanss2", TABLE, tmp_path / "s", mp)


def test_the_map_sigma_has_the_maps_length_unit(tmp_path: Path) -> None:
    mp = tmp_path / "map.toml"
    mp.write_text('length_unit = "cm"\nsigma = 0.001\n')
    import_file(_noisy_table(tmp_path / "t.txt"), "sscanss2", TABLE, tmp_path / "s", mp)
    assert np.allclose(read_recording(tmp_path / "s" / "recording.mcap").point_sigma_cm, 0.001)
