"""Record a simulated session: ``sessions/NAME/recording.mcap`` and ``rig-truth.json``.

The recording holds only what a real rig could record; the ground truth goes
to ``rig-truth.json``, which the pipeline never reads (only the audit and the
tests do).
"""

from __future__ import annotations

import json
from dataclasses import asdict, replace
from functools import cache
from pathlib import Path
from typing import Any

import numpy as np

from pipeline.atomic import remove_debris, write_text_atomic
from pipeline.contract.channels import SENSOR_CHANNELS
from pipeline.kinematics.chain import link_frames
from pipeline.rig import tracker
from pipeline.rig.atmosphere import (
    Atmosphere,
    DriftingLinearAir,
    drifting_linear_air,
    random_atmosphere,
)
from pipeline.rig.digitizer import DigitizerModel, digitize
from pipeline.rig.options import SimulationOptions, check_options, options_for_truth
from pipeline.rig.plan import (
    MeasurementPlan,
    default_sensor_from_base,
    plan_measurements,
    target_positions,
    tool_positions,
)
from pipeline.rig.pose_file import read_pose_plan
from pipeline.rig.recorder import Message, refuse_existing_recording, write_recording
from pipeline.rig.resettle import resettle
from pipeline.rig.true_robot import (
    draw_backlash,
    draw_nongeometric,
    draw_true_robot,
    where_joints_sit,
)
from pipeline.robots import get_robot
from pipeline.robots.description import RobotDescription, description_to_dict
from pipeline.sensor.geometry import W_AB_CM, W_AC_CM, W_BC_CM, DigitizerGeometry, default_geometry
from pipeline.stages.lock import session_lock
from pipeline.units import joints_to_internal

CYCLE_S = 0.25  # Section 6.4 / issue: about four digitize cycles per second
SETTLE_S = 1.0  # servo settling after each move
JOINT_SPEED = 30.0  # deg/s (or cm/s) while indexing between positions
SWAP_TARGET_S = 60.0  # moving the target sparker to the next fixture by hand
FIXTURE_SIGMA_CM = 0.1  # true target / probe placement versus nominal
T0_NS = 1_767_225_600 * 10**9  # 2026-01-01T00:00:00Z: recordings carry no wall-clock time
BIAS_SIGMA_CM = 0.05
DROPOUT_PROB = 0.02
OUTLIER_PROB = 0.005


def joint_state(
    robot: Any, sweep: int | str, step: int, q_cmd: np.ndarray, q_enc: np.ndarray, exact: bool,
    payload_kg: float = float("nan"),
) -> dict[str, Any]:  # fmt: skip
    """A /robot/joint_state payload: the controller's readings of joint values ``q_cmd`` and
    ``q_enc`` (deg / cm; through the inverse of the robot's coupling, if any), printed to
    1e-6 (commanded always, encoder unless ``exact``), and the payload (kg) when given."""
    cmd, enc = robot.readings_from_joints(q_cmd), robot.readings_from_joints(q_enc)
    out: dict[str, Any] = {
        "sweep": sweep,
        "step": step,
        "q_commanded": [round(float(v), 6) for v in cmd],
        "q_encoder": [float(v) if exact else round(float(v), 6) for v in enc],
        "units": [j.unit for j in robot.joints],
    }
    if np.isfinite(payload_kg):
        out["payload_kg"] = float(payload_kg)
    return out


def command_payloads(commands: list[Any], payloads_kg: tuple[float, ...]) -> np.ndarray:
    """The payload (kg) on the flange at each command: the pose set's poses cycle through
    ``payloads_kg`` (pose k: ``payloads_kg[k mod len]``), every other command has the
    first; NaN everywhere without payloads (none recorded)."""
    if not payloads_kg:
        return np.full(len(commands), np.nan)
    kg = np.array(payloads_kg, float)
    return np.array([kg[step % len(kg)] if sweep == "poses" else kg[0]
                     for sweep, step, _ in commands])  # fmt: skip


def _robot_message(robot: Any, signature_q: Any, plan: dict[str, Any]) -> Message:
    """The ``/robot/description`` message: design model, q^s as readings, the plan."""
    readings = robot.readings_from_joints(np.array(signature_q))
    return Message(
        "/robot/description",
        T0_NS,
        {
            "robot": description_to_dict(robot),
            "signature_q": [float(v) for v in readings],
            "plan": plan,
            "mode": "simulated",
        },
    )


def session_plan(
    robot: RobotDescription,
    geometry: DigitizerGeometry,
    sensor_from_base: np.ndarray,
    points: int,
    repeats: int,
    max_sweep_deg: float,
) -> MeasurementPlan:
    """:func:`plan_measurements` of a simulated session, cached per process: planning is
    ~2 s of a ~2.7 s simulate and depends only on these arguments, never on the seed.
    Keyed by content (the geometry as its JSON, the placement's 16 numbers), so a changed
    geometry or placement is planned anew. Safe to share: the plan is frozen, all tuples."""
    placement = tuple(float(v) for v in np.asarray(sensor_from_base, float).ravel())
    key = json.dumps(geometry.to_dict(), sort_keys=True)
    return _plan_by_content(robot, key, placement, points, repeats, max_sweep_deg)


@cache
def _plan_by_content(
    robot: RobotDescription,
    geometry_json: str,
    placement: tuple[float, ...],
    points: int,
    repeats: int,
    max_sweep_deg: float,
) -> MeasurementPlan:
    return plan_measurements(
        robot,
        DigitizerGeometry.from_dict(json.loads(geometry_json)),
        np.array(placement).reshape(4, 4),
        points,
        repeats,
        max_sweep_deg=max_sweep_deg,
    )


def simulate_session(session_dir: str | Path, opts: SimulationOptions, force: bool = False) -> Path:
    """Simulate a rig session and write it to ``session_dir``; returns the recording path.

    A folder that already holds ``recording.mcap`` is refused unless ``force``.
    """
    check_options(opts)
    out = Path(session_dir)
    refuse_existing_recording(out, force, "a simulated one")
    robot = get_robot(opts.robot)
    rng = np.random.default_rng(opts.seed)
    rng_robot, rng_world, rng_servo, rng_sensor = rng.spawn(4)
    true = draw_true_robot(robot, rng_robot, opts.sigmas)
    true = replace(
        true,
        nongeometric=draw_nongeometric(
            robot, opts.compliance_mm, opts.harmonic_deg, opts.seed, opts.payloads_kg
        ),
        backlash=draw_backlash(robot, opts.backlash_mm, opts.seed),
    )
    geometry_true = default_geometry()
    geometry_recorded = default_geometry(W_AB_CM, W_BC_CM, W_AC_CM + opts.wac_error_cm)
    sensor_from_base = default_sensor_from_base(robot)
    plan = session_plan(
        robot, geometry_recorded, sensor_from_base, opts.points, opts.repeats, opts.max_sweep_deg
    )
    q_plan = read_pose_plan(Path(opts.plan_file), robot) if opts.plan_file else None
    if opts.poses or q_plan is not None:  # the tool reflector off the flange axis
        tool = tracker.pose_tool_local(plan.tool_local_cm)
        plan = replace(plan, tool_local_cm=(float(tool[0]), float(tool[1]), float(tool[2])))
    pris = robot.prismatic
    res = robot.encoder_resolution

    # Fixture errors: the real sparker mounts and probe are not where the plan says.
    fixture = 0.0 if opts.noiseless else FIXTURE_SIGMA_CM
    target_true = {
        s.joint: np.array(s.target_local_cm) + rng_world.normal(0, fixture, 3) for s in plan.sweeps
    }
    tool_true = np.array(plan.tool_local_cm) + rng_world.normal(0, fixture, 3)
    h_air = float(geometry_true.height(np.zeros(3)) + 50.0)
    if opts.air == "drifting":  # its own stream: the lab's draws stay those of the seed
        atmosphere: Atmosphere | DriftingLinearAir = drifting_linear_air(
            rng_world.spawn(1)[0], h_air
        )
    else:
        atmosphere = Atmosphere() if opts.noiseless else random_atmosphere(rng_world, h_air)

    # Command list, in recording order: targets n..1, then the tool probe at q^s.
    qs = np.array(plan.signature_q)
    commands: list[tuple[int | str, int, np.ndarray]] = []
    for sweep in plan.sweeps if opts.sweeps else ():
        for step, value in enumerate(sweep.q_values):
            q = qs.copy()
            q[sweep.joint - 1] = value
            commands.append((sweep.joint, step, q))
    if opts.sweeps:
        commands.append(("tool", 0, qs.copy()))
    points = opts.sensor == "tracker"
    nests: dict[int | str, np.ndarray] = {}
    if points:
        rng_check = rng.spawn(1)[0]  # a fifth stream: the four above stay the sonic rig's
        nests = {
            s.joint: tracker.nest_locals(
                target_true[s.joint], opts.targets, s.joint == opts.nest_on_axis, rng_world, fixture
            )
            for s in plan.sweeps
        }
        q_check = tracker.check_configurations(
            opts.check, robot.limits, true.chain, sensor_from_base, tool_true, geometry_true,
            rng_check,
        )  # fmt: skip
        commands += [("check", k, q) for k, q in enumerate(q_check)]
        if opts.poses or q_plan is not None:  # a sixth and seventh stream: others keep their bytes
            rng_poses, rng_nest = rng.spawn(2)
            nests["poses"] = tracker.nest_locals(tool_true, opts.targets, False, rng_nest, fixture)
            q_poses = q_plan if q_plan is not None else tracker.check_configurations(
                opts.poses, robot.limits, true.chain, sensor_from_base, tool_true, geometry_true,
                rng_poses,
            )  # fmt: skip
            commands += [("poses", k, q) for k, q in enumerate(q_poses)]
    n_avg = 1 if points else opts.repeats
    q_cmd = np.array([c[2] for c in commands])
    if opts.noiseless:
        q_reached = q_cmd.copy()
        q_enc = q_cmd.copy()
    else:
        # Joint servo: each joint that is commanded to move settles within ±1 encoder
        # count of its command; a joint that is not commanded to move stays put.
        q_reached = q_cmd + rng_servo.uniform(-1.0, 1.0, q_cmd.shape) * res
        for k in range(1, len(q_cmd)):
            held = q_cmd[k] == q_cmd[k - 1]
            q_reached[k, held] = q_reached[k - 1, held]
        q_enc = np.round(q_reached / res) * res
    if opts.resettle_counts > 0:  # the arm parked between sweeps, the brakes engaging
        sweep_of = [c[0] for c in commands]
        q_reached = resettle(q_reached, sweep_of, res, opts.resettle_counts, rng_servo.spawn(1)[0])
        q_enc = q_reached.copy() if opts.noiseless else np.round(q_reached / res) * res

    # Timing: move, settle, N_avg cycles; a pause to swap fixtures between sweeps.
    t = 0.0
    t_config = np.zeros(len(commands))
    for k, (sweep_id, _, q) in enumerate(commands):
        if k == 0 or commands[k - 1][0] != sweep_id:
            t += SWAP_TARGET_S
            move = 0.0
        else:
            move = float(np.max(np.abs(q - commands[k - 1][2]))) / JOINT_SPEED
        t += move + SETTLE_S
        t_config[k] = t
        t += n_avg * CYCLE_S

    # Where the target sparker physically is at each configuration.
    qi = joints_to_internal(q_reached, pris)
    payload = command_payloads(commands, opts.payloads_kg)
    # Where the joints sit: deflected, angle errors, backlash.
    qi = where_joints_sit(qi, true.nongeometric, true.backlash, np.nan_to_num(payload, nan=0.0))
    p_target = np.zeros((len(commands), 3))
    for k, (sweep_id, _, _) in enumerate(commands):
        if sweep_id in ("tool", "check", "poses"):
            p_target[k] = tool_positions(true.chain, sensor_from_base, qi[k], tool_true)
        else:
            p_target[k] = target_positions(
                true.chain, sensor_from_base, qi[k], int(sweep_id), target_true[int(sweep_id)]
            )
    if points:
        return _record_points(
            out, force, opts, robot, true, plan, sensor_from_base, commands, q_cmd, q_enc, qi,
            t_config, nests, tool_true, target_true, rng_sensor, payload,
        )  # fmt: skip
    cyc_cfg = np.repeat(np.arange(len(commands)), opts.repeats)
    cyc_t = t_config[cyc_cfg] + np.tile(np.arange(opts.repeats) * CYCLE_S, len(commands))
    model = DigitizerModel(
        geometry=geometry_true,
        noise_factor=0.0 if opts.noiseless else opts.noise_factor,
        quantize=not opts.noiseless,
        # Drawn from a child stream: switching the fault on leaves the range noise of the
        # seed unchanged, so a session with and without it differ by the biases alone.
        mic_bias_cm=(
            tuple(rng_sensor.spawn(1)[0].normal(0, BIAS_SIGMA_CM, 4))
            if "bias" in opts.faults
            else (0.0,) * 4
        ),  # type: ignore[arg-type]
        dropout_prob=DROPOUT_PROB if "dropouts" in opts.faults else 0.0,
        outlier_prob=OUTLIER_PROB if "outliers" in opts.faults else 0.0,
    )
    raw = digitize(model, atmosphere, p_target[cyc_cfg], cyc_t, rng_sensor)

    messages = [
        Message("/rig/description", T0_NS, geometry_recorded.to_dict()),
        _robot_message(robot, plan.signature_q, plan.to_dict()),
    ]
    digits = None if opts.noiseless else 2  # quantized ranges print as 0.01 cm
    for k, (sweep_id, step, _) in enumerate(commands):
        t_ns = T0_NS + int(round(t_config[k] * 1e9))
        messages.append(
            Message(
                "/robot/joint_state",
                t_ns,
                joint_state(robot, sweep_id, step, q_cmd[k], q_enc[k], opts.noiseless, payload[k]),
            )
        )
        for r in range(opts.repeats):
            c = k * opts.repeats + r
            rows = [
                [
                    None if np.isnan(v) else (float(v) if digits is None else round(float(v), 2))
                    for v in row
                ]
                for row in raw[c]
            ]
            messages.append(
                Message(
                    "/sonic/ranges",
                    T0_NS + int(round(cyc_t[c] * 1e9)),
                    {"sweep": sweep_id, "step": step, "repeat": r, "ranges_cm": rows},
                )
            )
    truth = _truth(opts, robot, true, sensor_from_base, tool_true, target_true)
    truth.update(
        {
            "sensor": {
                "geometry_true": geometry_true.to_dict(),
                "geometry_recorded": geometry_recorded.to_dict(),
                "atmosphere": asdict(atmosphere),
                "mic_bias_cm": list(model.mic_bias_cm),
                "dropout_prob": model.dropout_prob,
                "outlier_prob": model.outlier_prob,
            },
            "target_positions_cm": {
                "sweep": [c[0] for c in commands],
                "step": [c[1] for c in commands],
                "p": p_target.tolist(),
            },
        }
    )
    return _write(out, force, _logged(messages, opts), truth, "sonic")


def _truth(
    opts: SimulationOptions,
    robot: Any,
    true: Any,
    sensor_from_base: np.ndarray,
    tool_true: np.ndarray,
    target_true: dict[int, np.ndarray],
) -> dict[str, Any]:
    """The part of ``rig-truth.json`` both sensors share (the audit reads the kinematics)."""
    return {
        "robot": robot.name,
        "seed": opts.seed,
        "options": options_for_truth(opts),
        "true_kinematics": {
            "frame": "sensor",
            "length_unit": "cm",
            "angle_unit": "deg",
            "joint_types": [j.type for j in robot.joints],
            "base": (sensor_from_base @ true.chain.base).tolist(),
            "links": true.chain.links.tolist(),
        },
        **_nongeometric_truth(true),
        "true_tool_in_last_link_cm": tool_true.tolist(),
        "true_targets_local_cm": {str(k): v.tolist() for k, v in target_true.items()},
        "sensor_from_base": sensor_from_base.tolist(),
        "errors": true.errors,
    }


def _nongeometric_truth(true: Any) -> dict[str, Any]:
    """``true_nongeometric`` of rig-truth.json (absent for a rigid robot): the terms and
    their coefficients in internal units (rad/cm, rad); ``true_backlash`` (absent without
    it): the error the model does not have (:meth:`pipeline.rig.backlash.Backlash.to_truth`)."""
    ng = true.nongeometric
    out: dict[str, Any] = {}
    if ng is not None:
        out["true_nongeometric"] = {
            "terms": list(ng.terms.names),
            "units": list(ng.terms.units),
            "coefficients": ng.coefficients.tolist(),
        }
    if true.backlash is not None:
        out["true_backlash"] = true.backlash.to_truth()
    return out


def _logged(messages: list[Message], opts: SimulationOptions) -> list[Message]:
    """The messages as a logger writes them: each measurement logged ``U(0,
    log_jitter_s)`` after it was measured (its own stream of the seed), so that with a
    jitter of more than a cycle's 0.25 s cycles are logged out of measurement order. The
    measurement time (``publish_time``) stays; descriptions are logged when written."""
    if opts.log_jitter_s == 0.0:
        return messages
    rng = np.random.default_rng([opts.seed, 33])  # issue 33: apart from the rig's streams
    delay = rng.uniform(0.0, opts.log_jitter_s, len(messages))
    return [
        m if m.topic.endswith("/description") else replace(m, log_time_ns=m.time_ns + int(d * 1e9))
        for m, d in zip(messages, delay, strict=True)
    ]


def _write(
    out: Path, force: bool, messages: list[Message], truth: dict[str, Any], sensor: str
) -> Path:
    """Write the recording (messages in log-time order) and ``rig-truth.json``."""
    # stable: descriptions stay first
    messages.sort(key=lambda m: m.time_ns if m.log_time_ns is None else m.log_time_ns)
    recording = out / "recording.mcap"
    out.mkdir(parents=True, exist_ok=True)
    # Under the session lock, like every pipeline run on the folder: no run reads a
    # recording half replaced, and a recording that appeared meanwhile is still refused.
    with session_lock(out):
        refuse_existing_recording(out, force, "a simulated one")
        remove_debris(out)  # the temp files of a killed simulate or import (issue 44)
        write_recording(recording, messages, SENSOR_CHANNELS[sensor])
        write_text_atomic(out / "rig-truth.json", json.dumps(truth, indent=1) + "\n")
    return recording


def _record_points(
    out: Path,
    force: bool,
    opts: SimulationOptions,
    robot: Any,
    true: Any,
    plan: Any,
    sensor_from_base: np.ndarray,
    commands: list[tuple[int | str, int, np.ndarray]],
    q_cmd: np.ndarray,
    q_enc: np.ndarray,
    qi: np.ndarray,
    t_config: np.ndarray,
    nests: dict[int | str, np.ndarray],
    tool_true: np.ndarray,
    target_true: dict[int, np.ndarray],
    rng: np.random.Generator,
    payload: np.ndarray,
) -> Path:
    """The tracker's session: every nest reflector (sweeps; the tool's nest at the poses)
    or the tool target (tool, check) measured once per configuration
    (:mod:`pipeline.rig.tracker`)."""
    ids = tracker.target_ids(opts.targets)
    rows: list[tuple[int, str, np.ndarray]] = []  # (command, target, true position)
    for k, (sweep_id, _, _) in enumerate(commands):
        if sweep_id in ("tool", "check"):
            p = tool_positions(true.chain, sensor_from_base, qi[k], tool_true)
            rows.append((k, tracker.TOOL_TARGET, p))
            continue
        if sweep_id == "poses":
            for tid, local in zip(ids, nests["poses"], strict=True):
                rows.append((k, tid, tool_positions(true.chain, sensor_from_base, qi[k], local)))
            continue
        j = int(sweep_id)
        for tid, local in zip(ids, nests[j], strict=True):
            rows.append((k, tid, target_positions(true.chain, sensor_from_base, qi[k], j, local)))
    p_true = np.array([r[2] for r in rows]).reshape(-1, 3)
    p_meas, sigma = tracker.measure(p_true, rng, opts.noiseless)
    n_poses = sum(c[0] == "poses" for c in commands)
    messages = [
        Message("/rig/description", T0_NS, tracker.rig_description()),
        _robot_message(
            robot,
            plan.signature_q,
            tracker.plan_dict(plan, opts.targets, opts.check, n_poses, opts.sweeps),
        ),
    ]
    for k, (sweep_id, step, _) in enumerate(commands):
        messages.append(
            Message(
                "/robot/joint_state",
                T0_NS + int(round(t_config[k] * 1e9)),
                joint_state(robot, sweep_id, step, q_cmd[k], q_enc[k], opts.noiseless, payload[k]),
            )
        )
    tool = tracker.TOOL_TARGET
    six_d = [m for m, (k, t, _) in enumerate(rows)
             if opts.six_d and commands[k][0] == "poses" and t == tool]  # fmt: skip
    R_probe = tracker.probe_rotation(rng.spawn(1)[0], opts.noiseless)
    R_true = (
        sensor_from_base[:3, :3]
        @ link_frames(true.chain, qi[[rows[m][0] for m in six_d]])[:, -2, :3, :3]
        @ R_probe
    )
    oriented = dict(
        zip(
            six_d, tracker.measure_orientation(R_true, rng.spawn(1)[0], opts.noiseless), strict=True
        )
    )
    for m, (k, tid, _) in enumerate(rows):
        sweep_id, step, _ = commands[k]
        t_ns = T0_NS + int(round((t_config[k] + CYCLE_S * (1 + ids.index(tid))) * 1e9))
        message = tracker.point_message(sweep_id, step, tid, p_meas[m], sigma[m], opts.noiseless)
        message.update(oriented.get(m, {}))
        messages.append(Message("/points", t_ns, message))
    truth = _truth(opts, robot, true, sensor_from_base, tool_true, target_true)
    if opts.six_d:
        truth["true_tool_rotation_in_last_link"] = R_probe.tolist()
    truth.update(
        {
            "true_nest_local_cm": {str(j): v.tolist() for j, v in nests.items()},
            "sensor": {"kind": "tracker", **tracker.rig_description()},
            "target_positions_cm": {
                "sweep": [commands[k][0] for k, _, _ in rows],
                "step": [commands[k][1] for k, _, _ in rows],
                "target": [t for _, t, _ in rows],
                "p": p_true.tolist(),
            },
        }
    )
    return _write(out, force, _logged(messages, opts), truth, "points")
