"""The range-level sensor model (pipeline.sensor.range_model) against the simulator."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pyarrow as pa
import pyarrow.compute as pc
import pytest
from hypothesis import given
from hypothesis import strategies as st
from scipy.optimize import least_squares

from pipeline.errors import ArmsigError
from pipeline.optim.block import dense
from pipeline.rig.atmosphere import Atmosphere
from pipeline.rig.digitizer import DigitizerModel, digitize
from pipeline.rig.simulate import SimulationOptions, simulate_session
from pipeline.sensor.geometry import MICROPHONES, DigitizerGeometry, default_geometry
from pipeline.sensor.noise import range_sigma_cm
from pipeline.sensor.range_calibration import sensor_calibration
from pipeline.sensor.range_model import RangeBlock, RangeModelOptions, phi
from pipeline.sensor.range_rows import unique_rows
from pipeline.sensor.speed_spline import TimeSpline
from pipeline.stages import ranges as ranges_stage
from pipeline.stages import session as session_stage
from pipeline.stages.base import RECORDING, NoParams
from pipeline.stages.recording import read_recording
from pipeline.stages.refine_problem import session_range_block
from pipeline.sweeps import TOOL_SWEEP


def _tables(sdir: Path) -> tuple[pa.Table, pa.Table]:
    rec = read_recording(sdir / "recording.mcap")
    inputs = {RECORDING: rec}
    return ranges_stage.compute(inputs, NoParams()), session_stage.compute(inputs, NoParams())


def _true_positions(block: RangeBlock, truth: dict) -> np.ndarray:
    """rig-truth's target positions in the block's key order, joined by (sweep, step)."""
    tp = truth["target_positions_cm"]
    by_key = {
        (TOOL_SWEEP if s == "tool" else int(s), int(k)): p
        for s, k, p in zip(tp["sweep"], tp["step"], tp["p"], strict=True)
    }
    keys = zip(block.keys["sweep"].to_pylist(), block.keys["step"].to_pylist(), strict=True)
    return np.array([by_key[k] for k in keys], float)


def _simulate(tmp: Path, **kw: object) -> tuple[RangeBlock, dict, np.ndarray]:
    simulate_session(tmp, SimulationOptions(**kw))  # type: ignore[arg-type]
    block = session_range_block(*_tables(tmp))
    truth = json.loads((tmp / "rig-truth.json").read_text())
    return block, truth, _true_positions(block, truth)


def _x_true(block: RangeBlock, geometry: DigitizerGeometry, bias: list[float]) -> np.ndarray:
    """Parameters of a still, uniform 70 °F atmosphere (f = 1, g = 0) and ``geometry``'s
    microphones in the block's gauge frame."""
    local = (geometry.microphones - block.microphones(np.zeros(block.n_params))) @ block.gauge_axes
    x = block.x0.copy()
    sl = block.slices
    x[sl["mic"]] = [local[m, k] for m, k in ((0, 0), (0, 1), (1, 1), (3, 0), (3, 1), (3, 2))]
    x[sl["bias"]] = bias
    x[sl["speed"]] = 1.0
    x[sl["gradient"]] = 0.0
    return x


def _measured(block: RangeBlock) -> np.ndarray:
    return np.asarray(block.row_kind != "prior")


def test_noiseless_session_round_trip(tmp_path: Path) -> None:
    """Still air, no noise: the model reproduces every simulated range at the truth."""
    block, truth, p = _simulate(tmp_path / "s", seed=2, noiseless=True, points=12, repeats=2)
    geometry = DigitizerGeometry.from_dict(truth["sensor"]["geometry_true"])
    lin = block.linearize(p, _x_true(block, geometry, [0.0] * 4))
    r = lin.r[_measured(block)]
    assert len(r) == block.rows.t_pos.size + block.rows.r_mic.size > 0
    # every heard target echo is a row, D's too
    assert set(block.rows.t_mic.tolist()) == {0, 1, 2, 3}
    assert np.abs(r).max() <= 1e-9  # whitened: ~1e-11 cm; observed ~6e-12


def _atmosphere_tables(
    atm: Atmosphere, noise_factor: float, seed: int
) -> tuple[pa.Table, pa.Table, np.ndarray, DigitizerGeometry]:
    """Ranges of 60 targets × 4 cycles over 3000 s in front of the default digitizer,
    digitized directly (no quantization), as the ``ranges`` stage lays them out."""
    g = default_geometry()
    rng = np.random.default_rng(seed)
    n, rep = 60, 4
    p = np.column_stack(
        [rng.uniform(40, 120, n), rng.uniform(20, 120, n), rng.uniform(60, 140, n)]
    )  # in every microphone's 30-250 cm window, in front of the wall
    cyc = np.repeat(np.arange(n), rep)
    t = np.linspace(0.0, 3000.0, n * rep)
    model = DigitizerModel(g, noise_factor=noise_factor, quantize=False)
    raw = digitize(model, atm, p[cyc], t, rng)
    m = len(cyc)
    ranges = pa.table(
        {
            "sweep": np.repeat(cyc + 1, 20).astype(np.int32),
            "step": np.zeros(20 * m, np.int32),
            "repeat": np.repeat(np.tile(np.arange(rep), n), 20).astype(np.int32),
            "sparker": np.tile(np.repeat(np.arange(1, 6), 4), m).astype(np.int32),
            "microphone": np.tile(np.array(MICROPHONES * 5), m),
            "range_cm": pa.array(raw.ravel(), mask=np.isnan(raw.ravel())),
            "t_s": np.repeat(t, 20),
        }
    )
    plan = {"order": list(range(1, n + 1))}  # the sweeps in the order of their times
    session = pa.table(
        {
            "rig_json": [json.dumps(g.to_dict())],
            "robot_json": [json.dumps({"plan": plan, "signature_q": []})],
        }
    )
    return ranges, session, p, g


#: The strongest lab (B-2)-(B-5) allows: 1.8 °F over 150 cm, ±0.3 °F drifting with a
#: 15-minute period.
_LAB = Atmosphere(72.0, 1.8 / 150.0, 0.3, 900.0, 0.3, 50.0)


def test_linear_speed_model_against_the_exact_integral() -> None:
    """Gradient and drift, no noise: fitting the sensor parameters with the positions at
    the truth leaves the model-versus-integral error of the linear-speed law (B-3)."""
    ranges, session, p, _ = _atmosphere_tables(_LAB, 0.0, 5)
    block = session_range_block(ranges, session)
    pk = p[block.keys["sweep"].to_numpy() - 1]
    sol = least_squares(
        lambda x: block.linearize(pk, x).r,
        block.x0,
        jac=lambda x: dense(block.linearize(pk, x).d_x),
        x_scale="jac",
        xtol=1e-15,
        ftol=1e-15,
    )
    meas = _measured(block)
    sigma = range_sigma_cm(np.concatenate([block.rows.t_s_cm, block.rows.r_s_cm]), 0.01)
    err_cm = block.linearize(pk, sol.x).r[meas] * sigma
    # Measured 8e-5 cm max, 2e-5 cm RMS: the knots' fit to the drift and c ∝ sqrt(T)
    # not quite linear. 1e-4 cm is a tenth of the 0.001 cm the refinement may ignore.
    assert np.abs(err_cm).max() < 1e-4
    assert np.sqrt(np.mean(err_cm**2)) < 5e-5


def test_phi_and_its_derivative() -> None:
    """φ(d) = log1p(d)/d and φ' across the series/closed-form switch."""
    d = np.array(
        [-0.3, -0.0100001, -0.0099999, -1e-3, -1e-9, 0.0, 1e-9, 1e-3, 0.0099999, 0.02, 0.5]
    )
    f, df = phi(d)
    exact = np.where(d == 0, 1.0, np.log1p(d) / np.where(d == 0, 1.0, d))
    np.testing.assert_allclose(f, exact, rtol=1e-15)
    h = 1e-6
    fd = (np.log1p(d + h) / (d + h) - np.log1p(d - h) / (d - h)) / (2 * h)
    np.testing.assert_allclose(df, fd, rtol=1e-7)  # central difference: ~1e-9 relative
    assert df[5] == -0.5


def test_jacobians_against_central_differences() -> None:
    ranges, session, p, _ = _atmosphere_tables(_LAB, 1.0, 7)
    block = session_range_block(ranges, session)
    pk = p[block.keys["sweep"].to_numpy() - 1]
    rng = np.random.default_rng(3)
    x = block.x0.copy()
    sl = block.slices
    x[sl["mic"]] += rng.normal(0, 0.5, 6)
    x[sl["bias"]] += rng.normal(0, 0.05, 4)
    x[sl["gradient"]] *= 1.5  # |d| ~ 3e-3: the series branch of φ'
    lin = block.linearize(pk, x)
    d_x = dense(lin.d_x)
    scale = {"mic": 1e-3, "bias": 1e-3, "speed": 1e-7, "gradient": 1e-9}
    steps = np.concatenate([np.full(s.stop - s.start, scale[k]) for k, s in sl.items()])
    fd = np.empty_like(d_x)
    for j, h in enumerate(steps):
        e = np.zeros_like(x)
        e[j] = h
        fd[:, j] = (block.linearize(pk, x + e).r - block.linearize(pk, x - e).r) / (2 * h)
    col = np.abs(d_x).max(axis=0)  # relative to each column's largest entry
    np.testing.assert_allclose(fd / col, d_x / col, rtol=1e-6, atol=1e-6)
    fdp = np.empty_like(lin.d_p)
    for i in range(3):
        e = np.zeros_like(pk)
        e[:, i] = 1e-4
        r_plus, r_minus = block.linearize(pk + e, x).r, block.linearize(pk - e, x).r
        fdp[:, i] = (r_plus - r_minus) / 2e-4
    col_p = np.abs(lin.d_p).max(axis=0)
    np.testing.assert_allclose(fdp / col_p, lin.d_p / col_p, rtol=1e-6, atol=1e-6)
    assert np.all(lin.d_p[lin.pos == -1] == 0.0)


def _fit_sensor(block: RangeBlock, p: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Sensor parameters with the positions held at ``p``; covariance (JᵀJ)⁻¹·χ²/dof."""
    sol = least_squares(
        lambda x: block.linearize(p, x).r,
        block.x0,
        jac=lambda x: dense(block.linearize(p, x).d_x),
        x_scale="jac",
    )
    j = sol.jac
    dof = len(sol.fun) - len(sol.x)
    cov = np.linalg.inv(j.T @ j) * float(sol.fun @ sol.fun) / dof
    return sol.x, cov


def test_self_calibration_of_the_range_biases(tmp_path: Path) -> None:
    block, truth, p = _simulate(tmp_path / "s", seed=11, faults=("bias",), points=30, repeats=4)
    x, cov = _fit_sensor(block, p)
    cal = sensor_calibration(block, x, cov)
    true_bias = np.array(truth["sensor"]["mic_bias_cm"])
    assert np.abs(true_bias).max() > 0.05  # the fault is there to find
    z = (cal.bias_cm - true_bias) / cal.bias_sigma_cm
    assert np.all(np.abs(z) <= 3.0), (cal.bias_cm, cal.bias_sigma_cm, true_bias)
    assert np.all(cal.bias_sigma_cm < 0.01)  # a real estimate, not the 1 cm prior


def test_self_calibration_of_microphone_a(tmp_path: Path) -> None:
    """W_AC recorded 0.5 cm long: the fit puts A back where it is."""
    block, truth, p = _simulate(tmp_path / "s", seed=12, wac_error_cm=0.5, points=30, repeats=4)
    x, cov = _fit_sensor(block, p)
    true_a = DigitizerGeometry.from_dict(truth["sensor"]["geometry_true"]).microphones[0]
    recorded_a = block.geometry.microphones[0]
    a_gauge = (true_a - block.microphones(np.zeros(block.n_params))[0]) @ block.gauge_axes
    sl = block.slices["mic"]
    fitted, sigma = x[sl][:2], np.sqrt(np.diag(cov)[sl][:2])
    assert np.linalg.norm(true_a - recorded_a) > 0.4
    assert np.all(np.abs(fitted - a_gauge[:2]) <= 3.0 * sigma), (fitted, sigma, a_gauge)
    assert np.all(sigma < 0.1)


@pytest.fixture(scope="module")
def noiseless_tables(tmp_path_factory: pytest.TempPathFactory) -> tuple[pa.Table, pa.Table]:
    d = tmp_path_factory.mktemp("rangemodel") / "s"
    simulate_session(d, SimulationOptions(seed=3, noiseless=True, points=8, repeats=2))
    return _tables(d)


def _drop(ranges: pa.Table, mask: pa.ChunkedArray) -> pa.Table:
    values = pc.if_else(mask, pa.scalar(None, pa.float64()), ranges.column("range_cm"))
    return ranges.set_column(ranges.column_names.index("range_cm"), "range_cm", values)


def _one_line_error(ranges: pa.Table, session: pa.Table, match: str) -> None:
    with pytest.raises(ArmsigError, match=match) as info:
        session_range_block(ranges, session)
    assert "\n" not in str(info.value) and "expected" in str(info.value)


def test_no_rod_ranges(noiseless_tables: tuple[pa.Table, pa.Table]) -> None:
    ranges, session = noiseless_tables
    rods = pc.less_equal(ranges.column("sparker"), 4)
    _one_line_error(_drop(ranges, rods), session, "calibration-rod ranges at microphone B")


def test_microphone_never_heard(noiseless_tables: tuple[pa.Table, pa.Table]) -> None:
    ranges, session = noiseless_tables
    mic_c = pc.and_(
        pc.equal(ranges.column("microphone"), "C"), pc.equal(ranges.column("sparker"), 5)
    )
    _one_line_error(_drop(ranges, mic_c), session, "microphone C never heard")


def test_bad_options() -> None:
    with pytest.raises(ArmsigError, match="positive"):
        RangeModelOptions(knot_spacing_s=0.0)


@given(
    st.lists(
        st.tuples(st.integers(-1, 7), st.integers(0, 300), st.integers(0, 12)),
        min_size=1,
        max_size=200,
    )
)
def testunique_rows_is_numpy_unique(rows: list[tuple[int, int, int]]) -> None:
    a = np.array(rows, np.int64)
    keys, inverse = unique_rows(a)
    ref_keys, ref_inverse = np.unique(a, axis=0, return_inverse=True)
    np.testing.assert_array_equal(keys, ref_keys)
    np.testing.assert_array_equal(inverse, ref_inverse.reshape(-1))


def test_spline_basis_is_the_design_matrix() -> None:
    spline = TimeSpline.over(10.0, 2345.0, 120.0)
    t = np.concatenate([[10.0, 2345.0], np.random.default_rng(1).uniform(10.0, 2345.0, 500)])
    idx, val = spline.basis(t)
    dense = np.zeros((len(t), spline.n_coef))
    np.put_along_axis(dense, idx, val, axis=1)
    np.testing.assert_array_equal(dense, spline.design(t))
    np.testing.assert_allclose(dense.sum(axis=1), 1.0, rtol=1e-14)  # partition of unity
