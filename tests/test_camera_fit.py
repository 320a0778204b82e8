"""The camera's whole-chain fit (pipeline.refine.camera_block, camera_fit; stage camera_fit):
its Jacobian and normal equations against finite differences and the dense product, and
noiseless simulated sessions identified to the acceptance of issue 39."""

from __future__ import annotations

import json
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from pipeline.errors import StageError
from pipeline.optim.block import dense
from pipeline.refine.camera_fit import fit_camera
from pipeline.refine.solve import Problem, linearize, normal_equations, residuals_and_jacobian
from pipeline.rig.camera_audit import audit_camera_fit
from pipeline.rig.simulate import SimulationOptions, simulate_session
from pipeline.robots import get_robot
from pipeline.sensor.camera import Intrinsics
from pipeline.stages import camera_fit, detections, joints, session
from pipeline.stages.base import RECORDING, NoParams
from pipeline.stages.recording import read_recording

UR10 = str(Path(__file__).resolve().parents[1] / "examples" / "ur10_ipa" / "ur10.toml")
SETUPS = ("eye-to-hand", "eye-in-hand")


def _tables(d: Path) -> dict:
    rec = read_recording(d / "recording.mcap")
    out = {RECORDING: rec}
    for stage in (session, joints, detections):
        out[stage.STAGE.name] = stage.STAGE.compute(out, NoParams())
    return out


def _simulated(tmp: Path, robot: str, setup: str, images: int, **kw) -> tuple[Path, dict]:
    d = tmp / f"{Path(robot).stem}-{setup}"
    opts = SimulationOptions(robot=robot, sensor="camera", setup=setup, poses=images, **kw)
    simulate_session(d, opts)
    return d, json.loads((d / "rig-truth.json").read_text())


@pytest.fixture(scope="module", params=SETUPS)
def small(request, tmp_path_factory) -> tuple:
    """A noiseless Puma session of 12 images and its problem, started in closed form."""
    d, _ = _simulated(tmp_path_factory.mktemp("cam"), "puma560", request.param, 12,
                      noiseless=True)  # fmt: skip
    det, design, lens, setup = camera_fit.detections_for_fit(_tables(d))
    fit = fit_camera(det, design, lens, setup, "fitted")
    return fit, det


def test_jacobian_matches_finite_differences(small) -> None:
    fit, _ = small
    problem = Problem(fit.model, fit.block, "linear")
    rng = np.random.default_rng(2)
    x = fit.solution.x + rng.normal(0, 1e-3, fit.solution.x.size)  # off the solution
    r, J = residuals_and_jacobian(problem, x)
    for j in range(x.size):
        h = 1e-6 * max(1.0, abs(x[j]))  # relative: the focal lengths are ~1e3 px
        e = np.zeros(x.size)
        e[j] = h
        fd = residuals_and_jacobian(problem, x + e)[0] - residuals_and_jacobian(problem, x - e)[0]
        fd /= 2 * h
        scale = 1.0 + np.abs(fd).max()
        assert np.abs(fd - J[:, j]).max() < 1e-5 * scale, fit.names[j]


def test_jacobian_with_the_fixed_pose_matches_finite_differences(small) -> None:
    """The chain held at its design: the fixed body's pose is the block's (its rotation
    vector off zero, where the left Jacobian matters)."""
    fit0, det = small
    fit = fit_camera(det, get_robot("puma560").design_chain(),
                     Intrinsics.from_vector(1280, 960, fit0.intrinsics), fit0.block.setup,
                     chain="design")  # fmt: skip
    assert fit.block.param_names[:6] == ("fixed.rx", "fixed.ry", "fixed.rz", "fixed.x",
                                         "fixed.y", "fixed.z")  # fmt: skip
    problem = Problem(fit.model, fit.block, "linear")
    x = fit.solution.x.copy()
    n = fit.model.n_params
    x[n : n + 3] += [0.3, -0.2, 0.1]  # rad: far from the start rotation
    r, J = residuals_and_jacobian(problem, x)
    for j in range(n, n + 6):
        h = 1e-6
        e = np.zeros(x.size)
        e[j] = h
        fd = residuals_and_jacobian(problem, x + e)[0] - residuals_and_jacobian(problem, x - e)[0]
        fd /= 2 * h
        assert np.abs(fd - J[:, j]).max() < 1e-5 * (1.0 + np.abs(fd).max()), fit.names[j]


def test_normal_equations_are_the_dense_products(small) -> None:
    """The structured JᵀWJ, with the cross terms of rows that depend on a position and on
    the kinematics directly (pixels), equals the dense product."""
    fit, _ = small
    problem = Problem(fit.model, fit.block, "linear")
    x = fit.solution.x + 1e-3
    r, J = residuals_and_jacobian(problem, x)
    w = np.random.default_rng(3).uniform(0.5, 1.5, r.size)
    A, g = normal_equations(problem, x, linearize(problem, x))(w)
    A_ref, g_ref = J.T @ (w[:, None] * J), J.T @ (w * r)
    assert np.abs(A - A_ref).max() <= 1e-9 * np.abs(A_ref).max()
    assert np.abs(g - g_ref).max() <= 1e-9 * np.abs(g_ref).max()


def test_prior_rows_pull_towards_the_prior(small) -> None:
    fit, _ = small
    prior = fit.block.x0 + 1.0
    block = replace(fit.block, prior=prior, prior_sigma=np.full(9, 2.0))
    lin = block.linearize_pose(fit.model, fit.solution.x[: fit.model.n_params], fit.block.x0)
    assert np.allclose(lin.r[-9:], -0.5) and (lin.pos[-9:] == -1).all()
    assert np.allclose(dense(lin.d_x)[-9:], np.eye(9) / 2.0)


def test_closed_form_start_is_near_and_the_fit_moves_from_it(small) -> None:
    """The start (OpenCV's hand-eye on the design chain) is near the fit, and the fit
    moves from it: the hand-eye of the design chain is off by ~0.1-0.5 cm and 0.2-1°
    (the Puma's errors, 0.03 cm and 0.3° of encoder offset, on its levers), so joint 1's
    axis line moves by up to ~0.6 cm (measured: 0.57 cm eye-to-hand)."""
    fit, _ = small
    n = fit.model.n_axis_params
    moved = np.abs(fit.solution.x[:n] - fit.x_start[:n])
    assert 1e-5 < moved.max() < 2.0  # rad / cm


def test_too_few_images_are_refused_in_one_line(small) -> None:
    fit, det = small
    few = replace(det, q=det.q[:4], image=det.image[det.image < 4],
                  local=det.local[det.image < 4], uv=det.uv[det.image < 4],
                  sigma_px=det.sigma_px[det.image < 4])  # fmt: skip
    lens = Intrinsics.from_vector(1280, 960, fit.intrinsics)
    with pytest.raises(StageError) as err:
        fit_camera(few, get_robot("puma560").design_chain(), lens, fit.block.setup)
    assert "4 images" in str(err.value) and "\n" not in str(err.value)


@pytest.mark.parametrize("intrinsics", ["fitted", "fixed"])
@pytest.mark.parametrize("setup", SETUPS)
@pytest.mark.parametrize("robot", ["puma560", UR10])
def test_noiseless_sessions_identify_exactly(
    tmp_path: Path, robot: str, setup: str, intrinsics: str
) -> None:
    """Issue 39's acceptance: 40 noiseless images; tool pose ≤ 1e-6 cm and 1e-6°, both
    hand-eye transforms ≤ 1e-6 cm and 1e-6°, intrinsics ≤ 1e-6 relative; the intrinsics
    fitted from the nominal lens, or held at the true one."""
    d, truth = _simulated(tmp_path, robot, setup, 40, noiseless=True)
    tables = _tables(d)
    det, design, lens, _ = camera_fit.detections_for_fit(tables)
    if intrinsics == "fixed":
        lens = Intrinsics.from_dict(truth["camera"]["intrinsics_true"])
    fit = fit_camera(det, design, lens, setup, intrinsics)
    assert fit.solution.status == "converged" and fit.rms_px < 1e-6
    from pipeline.robots.description import description_from_dict

    robot_desc = description_from_dict(tables[RECORDING].robot["robot"])
    audit = audit_camera_fit(fit, truth, robot_desc, det.q_signature)
    assert audit.tool_position_cm <= 1e-6 and audit.tool_orientation_deg <= 1e-6
    assert audit.fixed_position_cm <= 1e-6 and audit.fixed_orientation_deg <= 1e-6
    assert audit.flange_position_cm <= 1e-6 and audit.flange_orientation_deg <= 1e-6
    assert audit.intrinsics_relative <= 1e-6


@pytest.mark.parametrize("setup", SETUPS)
def test_hand_eye_alone_is_exact_when_the_design_is_the_robot(tmp_path: Path, setup: str) -> None:
    """The peers' problem (``chain="design"``) on a robot built to its design (no
    manufacturing error), noiseless: both hand-eye transforms to 1e-6 cm and 1e-6° in
    the truth's frames, and the lens to 1e-6 relative. The hand-eye-alone bench
    (``bench.camera_hand_eye``) compares the same two transforms."""
    from pipeline.kinematics.chain import link_frames
    from pipeline.kinematics.transforms import invert_transform
    from pipeline.rig.camera_audit import pose_errors, true_hand_eye
    from pipeline.rig.true_robot import ErrorSigmas

    d, truth = _simulated(tmp_path, "puma560", setup, 20, noiseless=True,
                          sigmas=ErrorSigmas(0.0, 0.0, 0.0))  # fmt: skip
    det, design, lens, _ = camera_fit.detections_for_fit(_tables(d))
    fit = fit_camera(det, design, lens, setup, chain="design")
    assert fit.solution.status == "converged" and fit.rms_px < 1e-6
    F_s = link_frames(design, det.q_signature[None])[0, design.n_joints]
    on_flange = invert_transform(F_s) @ fit.tool_poses(det.q_signature[None], det.q_signature)[0]
    for got, want in zip((fit.fixed_in_base, on_flange), true_hand_eye(truth), strict=True):
        cm, deg = pose_errors(np.asarray(got), want)
        assert cm <= 1e-6 and deg <= 1e-6
    true_k = Intrinsics.from_dict(truth["camera"]["intrinsics_true"]).vector()
    assert (np.abs(fit.intrinsics - true_k) / np.maximum(np.abs(true_k), 1.0)).max() <= 1e-6


def test_stage_holds_the_recorded_lens_when_fixed(tmp_path: Path) -> None:
    d, _ = _simulated(tmp_path, "puma560", "eye-in-hand", 15, noiseless=True)
    tables = _tables(d)
    table = camera_fit.compute(tables, camera_fit.Params(intrinsics="fixed"))
    rows = table.to_pylist()
    lens = json.loads(tables["session"].column("rig_json")[0].as_py())["camera"]
    got = {r["name"]: r for r in rows if r["group"] == "intrinsics"}
    assert all(got[f"camera.{k}"]["value"] == lens.get(k, 0.0) for k in ("fx", "cy", "k1"))
    assert all(r["sigma"] == 0.0 for r in got.values())
    meta = json.loads(table.schema.metadata[b"armsig.camera_fit"])
    assert meta["n_images"] == 15 and meta["intrinsics"] == "fixed"
    # the nominal lens is wrong (focal 1 % off, no distortion): the pixels say so
    assert meta["rms_px"] > 0.5


def test_bad_stage_parameter_is_one_line() -> None:
    from pipeline.errors import ArmsigError

    with pytest.raises(ArmsigError) as err:
        camera_fit.Params(intrinsics="guessed")
    assert "camera_fit.intrinsics" in str(err.value)
    assert "\n" not in str(err.value)


def _synthetic(setup: str, move: str, focal_px: float = 1000.0, noise_px: float = 0.2) -> tuple:
    """40 images of a Puma whose poses are random (``random``), or where only joints 1 and
    2 move a few degrees about one pose (``translate``: one target orientation), noise
    ``noise_px`` (0.2 px stated); detections, design, nominal lens (and the true lens,
    ``_synthetic.truth``)."""
    from pipeline.kinematics.chain import link_frames
    from pipeline.refine.camera_fit import Detections
    from pipeline.rig import camera
    from pipeline.rig.true_robot import draw_true_robot
    from pipeline.sensor.camera import project
    from pipeline.units import joints_to_internal

    robot = get_robot("puma560")
    rng = np.random.default_rng(3)
    true = draw_true_robot(robot, rng)
    target = camera.DEFAULT_TARGET
    fixed, onf = camera.placement(setup, true.chain, robot.limits, target, rng)
    nominal = camera.nominal_intrinsics(1280, 960, focal_px)
    lens = camera.true_intrinsics(nominal, (-0.12, 0.05, 5e-4, -3e-4, 0.0), rng)
    _synthetic.truth = lens  # type: ignore[attr-defined]
    q, _ = camera.draw_images(40, setup, true.chain, robot.limits, target, fixed, onf, lens, rng)
    if move == "translate":
        q = q[0] + np.zeros_like(q)
        q[:, 0] += np.linspace(-5, 5, 40)
        q[:, 1] += np.tile(np.linspace(-3, 3, 8), 5)
    _, local = target.points()
    F = link_frames(true.chain, joints_to_internal(q, robot.prismatic))[:, robot.n_joints]
    T = camera.camera_from_target(setup, fixed, onf, F)
    kept, found, _ = camera.detect(target, T, lens, local)
    T, found, q = T[kept], found[kept], q[kept]
    uv = project(camera.camera_points(T, local), lens.vector())[found]
    det = Detections(
        np.repeat(np.arange(len(q)), found.sum(1)), np.tile(local, (len(q), 1, 1))[found],
        uv + rng.normal(0, noise_px, uv.shape), np.full(len(uv), 0.2),
        joints_to_internal(q, robot.prismatic), np.zeros(robot.n_joints),
    )  # fmt: skip
    return det, robot.design_chain(), nominal


def test_random_poses_identify_every_parameter() -> None:
    from pipeline.refine.camera_fit import held_line

    det, design, lens = _synthetic("eye-to-hand", "random")
    fit = fit_camera(det, design, lens, "eye-to-hand")
    assert not fit.identifiability.held.any() and held_line(fit, 0.2) is None


@pytest.mark.parametrize("setup", ["eye-to-hand", "eye-in-hand"])
def test_a_narrow_view_fits_the_principal_point_its_start_knows_worse(setup: str) -> None:
    """f 3,000 px, detections four times better than their stated 0.2 px (as rendered
    noiseless images give): by the design's 1 px tolerance the principal point and k3
    cannot be told from the noise, and held at OpenCV's start they left p2 22σ off the
    truth. The images determine them better than that start does, so they are fitted:
    nothing held, every lens term within 4σ of the truth."""
    from pipeline.refine.camera_fit import tolerances
    from pipeline.refine.identifiability import tolerance_scale

    det, design, lens = _synthetic(setup, "random", 3000.0, 0.05)
    truth = _synthetic.truth.vector()  # type: ignore[attr-defined]
    fit = fit_camera(det, design, lens, setup)
    assert not fit.identifiability.held.any()
    sigma = fit.solution.sigma[-9:]
    assert np.all(np.abs(fit.intrinsics - truth) < 4 * sigma)
    units = (*fit.model.param_units, *fit.block.param_units)
    tol, design_tol = tolerances(units, fit.start, fit.block), tolerance_scale(units)
    assert np.array_equal(tol[:-9], design_tol[:-9])  # the chain's and hand-eye's: the design's
    assert np.all(tol[-9:] >= design_tol[-9:]) and tol[-7] > design_tol[-7]  # cx: OpenCV's σ


def test_one_target_orientation_holds_the_focal_length_and_says_what_to_measure() -> None:
    """Only joints 1 and 2 move, a few degrees: the wrist's axes and the tool cannot be
    seen (structural), nor the focal lengths apart from the distance (below the noise):
    held at their start, named in one line that says what to measure."""
    from pipeline.refine.camera_fit import held_line

    det, design, lens = _synthetic("eye-to-hand", "translate")
    fit = fit_camera(det, design, lens, "eye-to-hand")
    held = {fit.names[k] for k in np.flatnonzero(fit.identifiability.held)}
    assert {"camera.fx", "camera.fy", "joint4.rx", "tool_rot.rz"} <= held
    line = held_line(fit, 0.2)
    assert line is not None and "\n" not in line
    assert "camera.fx" in line and "tilt the target" in line and "move joint3" in line
    assert np.all(fit.solution.sigma[fit.identifiability.held] == 0)  # not fitted to noise


def test_a_row_of_corners_is_no_detection() -> None:
    from pipeline.rig import camera

    board = camera.DEFAULT_TARGET
    _, local = board.points()
    one_row = np.zeros((1, len(local)), bool)
    one_row[0, :7] = True  # the first row of the 7 × 5 corners
    two_rows = one_row.copy()
    two_rows[0, 7:14] = True
    assert not camera._spread(one_row, local, board.spacing_cm)[0]
    assert camera._spread(two_rows, local, board.spacing_cm)[0]


def test_pipeline_audit_of_an_identified_camera_session(tmp_path: Path) -> None:
    """The camera_fit table alone rebuilds the fitted chain (its start frames, q̄^s and
    parameters): `pipeline audit` of a noiseless session meets the acceptance."""
    from typer.testing import CliRunner

    from pipeline.cli import app
    from pipeline.identify import identify
    from pipeline.rig.camera_audit import audit_camera_session

    d, _ = _simulated(tmp_path, "puma560", "eye-in-hand", 40, noiseless=True)
    identify(d, report=False)
    audit = audit_camera_session(d)
    assert audit.tool_position_cm <= 1e-6 and audit.tool_orientation_deg <= 1e-6
    assert audit.fixed_position_cm <= 1e-6 and audit.flange_orientation_deg <= 1e-6
    assert audit.intrinsics_relative <= 1e-6
    out = CliRunner().invoke(app, ["audit", str(d), "--json"])
    assert out.exit_code == 0 and json.loads(out.stdout)["tool_position_cm"] <= 1e-6


def test_a_prior_on_the_lens_pulls_the_fit_to_it(tmp_path: Path) -> None:
    """camera_fit.intrinsics=prior: a tight prior keeps the recorded lens, a loose one
    lets the pixels move it to the fitted values."""
    d, _ = _simulated(tmp_path, "puma560", "eye-to-hand", 15)
    tables = _tables(d)
    recorded = json.loads(tables["session"].column("rig_json")[0].as_py())["camera"]

    def lens(params) -> dict:
        rows = camera_fit.compute(tables, params).to_pylist()
        return {r["name"]: r["value"] for r in rows if r["group"] == "intrinsics"}

    tight = lens(camera_fit.Params(intrinsics="prior", prior_focal_px=1e-6,
                                   prior_center_px=1e-6, prior_distortion=1e-9))  # fmt: skip
    loose = lens(camera_fit.Params(intrinsics="prior", prior_focal_px=1e6,
                                   prior_center_px=1e6, prior_distortion=1e6))  # fmt: skip
    fitted = lens(camera_fit.Params())
    assert abs(tight["camera.fx"] - recorded["fx"]) < 1e-3
    assert abs(loose["camera.fx"] - fitted["camera.fx"]) < 1e-3 * abs(fitted["camera.fx"])
    assert abs(fitted["camera.fx"] - recorded["fx"]) > 1.0  # the nominal lens is 1 % off


TARGET_FILES = {
    "checkerboard": 'kind = "checkerboard"\nrows = 7\ncolumns = 9\nspacing_cm = 3.0\n',
    "circles": 'kind = "circles"\nrows = 6\ncolumns = 8\nspacing_cm = 3.5\n',
    "aruco": 'kind = "aruco"\nrows = 4\ncolumns = 5\nspacing_cm = 5.0\nmarker_cm = 4.0\n'
    'dictionary = "DICT_4X4_50"\nfirst_id = 3\n',
}


@pytest.mark.parametrize("kind", list(TARGET_FILES))
def test_every_target_kind_identifies_exactly(tmp_path: Path, kind: str) -> None:
    """A whole checkerboard, a circle grid and a marker set (ids 4m + k, from marker 3):
    20 noiseless images, eye-to-hand, identify to the acceptance."""
    from pipeline.robots.description import description_from_dict

    board = tmp_path / "board.toml"
    board.write_text(TARGET_FILES[kind], encoding="utf-8")
    d, truth = _simulated(tmp_path, "puma560", "eye-to-hand", 20, noiseless=True,
                          target_file=str(board))  # fmt: skip
    tables = _tables(d)
    det, design, lens, setup = camera_fit.detections_for_fit(tables)
    fit = fit_camera(det, design, lens, setup)
    desc = description_from_dict(tables[RECORDING].robot["robot"])
    audit = audit_camera_fit(fit, truth, desc, det.q_signature)
    assert audit.tool_position_cm <= 1e-6 and audit.tool_orientation_deg <= 1e-6
    assert audit.fixed_position_cm <= 1e-6 and audit.flange_position_cm <= 1e-6
    assert audit.intrinsics_relative <= 1e-6
