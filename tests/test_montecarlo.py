"""Monte-Carlo machinery (statistics, seeds, tables, workers) and the design-control studies."""

from dataclasses import replace

import numpy as np
import polars as pl
import pytest
from typer.testing import CliRunner

from pipeline.cli import app
from pipeline.evaluation.grid12 import INDEX_NAMES, INDEX_SIGNED, INDEX_UNITS
from pipeline.montecarlo import design
from pipeline.montecarlo.engine import Study, run_study
from pipeline.montecarlo.report import nonzero_means, power_law
from pipeline.montecarlo.stats import indices_table, robot_seeds, summarize, summary_table
from pipeline.rig.true_robot import ErrorSigmas


def toy(value: float, seeds: list[np.random.SeedSequence]) -> np.ndarray:
    """A linear toy: index 0 = value·z, index 1 = value·z + value (z standard normal per robot)."""
    z = np.array([np.random.default_rng(s).standard_normal() for s in seeds])
    return np.stack([value * z, value * z + value], axis=-1)


TOY = Study(
    "toy",
    "toy sigma",
    "sigma_cm",
    "cm",
    (0.5, 2.0),
    toy,
    ("a_cm", "b_cm"),
    ("cm", "cm"),
    (True, True),
    batch=300,
)


def test_summarize_known_values() -> None:
    v = np.array([[[1.0, 10.0], [3.0, 10.0], [5.0, 10.0], [7.0, 10.0]]])  # 1 setting, 4 robots
    s = summarize(v)
    np.testing.assert_allclose(s.mean, [[4.0, 10.0]])
    sd = np.sqrt(20.0 / 3.0)  # sample std of 1, 3, 5, 7
    np.testing.assert_allclose(s.std, [[sd, 0.0]])
    np.testing.assert_allclose(s.se_mean, [[sd / 2.0, 0.0]])
    np.testing.assert_allclose(s.se_std, [[sd / np.sqrt(6.0), 0.0]])
    with pytest.raises(ValueError, match="at least 2"):
        summarize(v[:, :1])


def test_robot_seeds_are_prefix_stable_and_distinct() -> None:
    a = robot_seeds(7, "noise", 2, 10)
    b = robot_seeds(7, "noise", 2, 4)
    draw = [np.random.default_rng(s).random() for s in a]
    assert draw[:4] == [np.random.default_rng(s).random() for s in b]
    assert len(set(draw)) == 10
    other = [np.random.default_rng(s).random() for s in robot_seeds(7, "noise", 3, 4)]
    assert not set(other) & set(draw)


def test_linear_toy_std_matches_theory_and_workers_do_not_matter() -> None:
    res = run_study(TOY, robots=2000, seed=3, workers=1, progress=None)
    sm = res.summary
    sigma = np.array(TOY.values)
    # The std of value·z is value; its estimate is within 4 standard errors (p ≈ 6e-5).
    assert np.all(np.abs(sm.std[:, 0] - sigma) < 4 * sm.se_std[:, 0])
    np.testing.assert_allclose(sm.std[:, 1], sm.std[:, 0], rtol=1e-12)  # a shift keeps the std
    assert np.all(np.abs(sm.mean[:, 0]) < 4 * sm.se_mean[:, 0])
    assert np.all(np.abs(sm.mean[:, 1] - sigma) < 4 * sm.se_mean[:, 1])
    other = run_study(TOY, robots=2000, seed=3, workers=2, progress=None, batch=170)
    np.testing.assert_array_equal(other.values, res.values)
    assert not np.array_equal(run_study(TOY, 2000, seed=4, progress=None).values, res.values)


def toy_all(values: tuple[float, ...], seeds: list[np.random.SeedSequence]) -> np.ndarray:
    """The toy on common robots: the same z at every setting."""
    return np.stack([toy(v, seeds) for v in values])


def test_common_robots_study_is_paired_and_worker_independent() -> None:
    paired = replace(TOY, name="paired", evaluate_all=toy_all)
    res = run_study(paired, robots=50, seed=2, progress=None, batch=7)
    # Same robots at both settings: values scale exactly with the setting.
    np.testing.assert_allclose(res.values[1, :, 0], 4.0 * res.values[0, :, 0], rtol=1e-15)
    other = run_study(paired, robots=50, seed=2, workers=2, progress=None, batch=13)
    np.testing.assert_array_equal(other.values, res.values)


def test_tables_have_units_and_read_in_polars(tmp_path) -> None:
    res = run_study(TOY, robots=5, seed=1, progress=None)
    names, units = list(TOY.index_names), list(TOY.index_units)
    x = np.array(TOY.values)
    long = indices_table("toy", "sigma_cm", "cm", x, res.values, names, units)
    assert long.num_rows == 2 * 5 * 2
    assert long.schema.field("value_cm").metadata[b"unit"] == b"cm"
    assert long.schema.field("sigma_cm").metadata[b"unit"] == b"cm"
    df = pl.from_arrow(long)
    row = df.filter((pl.col("setting") == 1) & (pl.col("robot") == 3) & (pl.col("index") == "b_cm"))
    assert row["value_cm"][0] == res.values[1, 3, 1]
    summ = summary_table("toy", "sigma_cm", "cm", x, res.summary, names, units, [True, True])
    sdf = pl.from_arrow(summ)
    assert sdf["std_cm"].to_list() == pytest.approx(res.summary.std.ravel().tolist())
    assert sdf["mean_deg"].null_count() == len(sdf)  # no angle index in the toy


def test_mixed_units_split_into_columns() -> None:
    v = np.arange(2 * 3 * 34, dtype=float).reshape(2, 3, 34)
    t = pl.from_arrow(
        indices_table("d", "sigma_e_deg", "deg", np.array([0.1, 0.2]), v, INDEX_NAMES, INDEX_UNITS)
    )
    deg = t.filter(pl.col("index") == "vertex1_orientation_error_deg")
    assert deg["value_cm"].null_count() == len(deg) and deg["value_deg"].null_count() == 0


def test_power_law_and_zero_mean_checks() -> None:
    x = np.array([20.0, 40.0, 60.0, 80.0, 100.0])
    p, se = power_law(x, 3.0 * x**-0.5, 0.01 * x**-0.5)
    assert p == pytest.approx(-0.5, abs=1e-12) and se > 0


def test_zero_manufacturing_error_gives_zero_design_error() -> None:
    seeds = robot_seeds(0, "encoder", 0, 4)
    v = design.design_indices(ErrorSigmas(0.0, 0.0, 0.0), seeds)
    # Design inverse and forward kinematics of the same model agree to round-off (~1e-13).
    assert np.abs(v).max() < 1e-9


def test_design_error_is_linear_for_small_encoder_errors() -> None:
    seeds = robot_seeds(0, "encoder", 0, 6)
    small = design.design_indices(ErrorSigmas(0.0, 0.0, 1e-4), seeds)
    double = design.design_indices(ErrorSigmas(0.0, 0.0, 2e-4), seeds)
    signed = np.array(INDEX_SIGNED)
    # Same draws scaled by 2: first-order errors double (second order: ~1e-6 relative).
    np.testing.assert_allclose(double[:, signed], 2.0 * small[:, signed], rtol=1e-3, atol=1e-12)
    np.testing.assert_allclose(double[:, ~signed], 2.0 * small[:, ~signed], rtol=1e-3)


def test_design_batch_equals_loop() -> None:
    seeds = robot_seeds(5, "machining", 1, 5)
    batch = design.machining_setting(0.03, seeds)
    loop = np.concatenate([design.machining_setting(0.03, [s]) for s in seeds])
    np.testing.assert_allclose(batch, loop, rtol=0, atol=1e-12)
    assert batch.shape == (5, 34)


def test_encoder_study_statistics() -> None:
    res = run_study(
        Study(
            "encoder",
            "",
            "sigma_e_deg",
            "deg",
            (0.1, 0.5),
            design.encoder_setting,
            INDEX_NAMES,
            INDEX_UNITS,
            INDEX_SIGNED,
        ),  # fmt: skip
        robots=200,
        seed=1,
        progress=None,
    )
    k = INDEX_NAMES.index("vertex4_radial_error_cm")
    # Encoder errors dominate: 5× σ_e gives nearly 5× the radial std (σ_p, σ_o add a little).
    ratio = res.summary.std[1, k] / res.summary.std[0, k]
    assert 4.0 < ratio < 5.5
    hits, total = nonzero_means(_as_arrays(res))
    assert total == 2 * 19 and hits <= total


def _as_arrays(res):  # the report's view of an in-memory result
    from pipeline.montecarlo.report import SummaryArrays

    s = res.summary
    return SummaryArrays("encoder", "sigma_e_deg", np.array(res.study.values),
                         list(INDEX_NAMES), np.array(INDEX_SIGNED), s.mean, s.std,
                         s.se_mean, s.se_std, s.robots, 0.0)  # fmt: skip


def test_cli_writes_tables_figures_and_report(tmp_path) -> None:
    runner = CliRunner()
    out = tmp_path / "mc"
    r = runner.invoke(
        app, ["montecarlo", "--study", "machining", "--robots", "6", "--out", str(out)]
    )
    assert r.exit_code == 0, r.output
    for f in ("indices.arrow", "summary.arrow", "radial_std.png", "std_grid.png", "mean_grid.png"):
        assert (out / "machining" / f).is_file()
    df = pl.read_ipc(out / "machining" / "indices.arrow")
    assert df.height == 5 * 6 * 34
    assert "machining" in (out / "montecarlo.md").read_text()
    bad = runner.invoke(app, ["montecarlo", "--study", "nope", "--out", str(out)])
    # a usage error since --study is a choice (issue 30): exit 2, the choices listed
    assert bad.exit_code == 2 and "'nope' is not one of" in bad.output and "'refine'" in bad.output


def test_progress_redraws_on_a_terminal_and_logs_one_line_elsewhere() -> None:
    import io

    from pipeline.progress import Progress

    class Terminal(io.StringIO):
        def isatty(self) -> bool:
            return True

    for stream, lines in ((io.StringIO(), 0), (Terminal(), 4)):  # a log: no \r
        bar = Progress("noise", 4, stream)
        for _ in range(4):
            bar.step()
        text = stream.getvalue()
        assert text.count("\r") == lines and text.endswith("\n") and "4/4 batches" in text
        assert text.count("\n") == 1
