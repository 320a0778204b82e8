"""Record a simulated session: ``sessions/NAME/recording.mcap`` and ``rig-truth.json``.

The recording holds only what a real rig could record; the ground truth goes
to ``rig-truth.json``, which the pipeline never reads (only the audit and the
tests do).
"""

from __future__ import annotations

import json
from dataclasses import asdict, dataclass, field
from pathlib import Path

import numpy as np

from pipeline.atomic import write_text_atomic
from pipeline.errors import ArmsigError
from pipeline.rig.atmosphere import Atmosphere, random_atmosphere
from pipeline.rig.digitizer import DigitizerModel, digitize
from pipeline.rig.plan import (
    default_sensor_from_base,
    plan_measurements,
    target_positions,
    tool_positions,
)
from pipeline.rig.recorder import Message, refuse_existing_recording, write_recording
from pipeline.rig.true_robot import ErrorSigmas, draw_true_robot
from pipeline.robots import get_robot
from pipeline.robots.description import description_to_dict
from pipeline.sensor.geometry import W_AB_CM, W_AC_CM, W_BC_CM, default_geometry
from pipeline.stages.lock import session_lock
from pipeline.units import joints_to_internal

FAULTS = ("bias", "dropouts", "outliers")
CYCLE_S = 0.25  # Section 6.4 / issue: about four digitize cycles per second
SETTLE_S = 1.0  # servo settling after each move
JOINT_SPEED = 30.0  # deg/s (or cm/s) while indexing between positions
SWAP_TARGET_S = 60.0  # moving the target sparker to the next fixture by hand
FIXTURE_SIGMA_CM = 0.1  # true target / probe placement versus nominal
T0_NS = 1_767_225_600 * 10**9  # 2026-01-01T00:00:00Z: recordings carry no wall-clock time
BIAS_SIGMA_CM = 0.05
DROPOUT_PROB = 0.02
OUTLIER_PROB = 0.005


@dataclass(frozen=True)
class SimulationOptions:
    """Everything ``pipeline simulate`` can set (boundary units)."""

    robot: str = "puma560"
    seed: int = 1
    sigmas: ErrorSigmas = field(default_factory=ErrorSigmas)
    noise_factor: float = 1.0
    points: int = 100  # N_i (Section 6.4)
    repeats: int = 10  # N_avg (Section 6.4)
    faults: tuple[str, ...] = ()
    wac_error_cm: float = 0.0  # W_AC calibration error (Section 7.3)
    noiseless: bool = False
    max_sweep_deg: float = 300.0  # cap of every revolute sweep (B-3 experiments)


def _check(opts: SimulationOptions) -> None:
    bad = [f for f in opts.faults if f not in FAULTS]
    if bad:
        raise ArmsigError(
            f"unknown fault {bad[0]!r}", expected=", ".join(FAULTS), fix="--faults bias,dropouts"
        )
    numbers = {
        **{f"sigmas.{k}": v for k, v in asdict(opts.sigmas).items()},
        "noise_factor": opts.noise_factor,
        "max_sweep_deg": opts.max_sweep_deg,
    }
    for name, value in numbers.items():
        if not (np.isfinite(value) and value >= 0.0):
            raise ArmsigError(
                f"simulation option {name} must be a finite number >= 0", got=repr(value)
            )
    if not (0.0 < opts.max_sweep_deg <= 720.0 and np.isfinite(opts.wac_error_cm)):
        raise ArmsigError(
            "simulation options out of range",
            expected="0 < max_sweep_deg <= 720 and a finite wac_error_cm",
            got=f"max_sweep_deg={opts.max_sweep_deg}, wac_error_cm={opts.wac_error_cm}",
        )
    if opts.points < 3 or opts.repeats < 1:
        raise ArmsigError(
            "too few measurements",
            expected="--points >= 3 and --repeats >= 1",
            got=f"points={opts.points}, repeats={opts.repeats}",
        )


def simulate_session(session_dir: str | Path, opts: SimulationOptions, force: bool = False) -> Path:
    """Simulate a rig session and write it to ``session_dir``; returns the recording path.

    A folder that already holds ``recording.mcap`` is refused unless ``force``.
    """
    _check(opts)
    out = Path(session_dir)
    refuse_existing_recording(out, force, "a simulated one")
    robot = get_robot(opts.robot)
    rng = np.random.default_rng(opts.seed)
    rng_robot, rng_world, rng_servo, rng_sensor = rng.spawn(4)
    true = draw_true_robot(robot, rng_robot, opts.sigmas)
    geometry_true = default_geometry()
    geometry_recorded = default_geometry(W_AB_CM, W_BC_CM, W_AC_CM + opts.wac_error_cm)
    sensor_from_base = default_sensor_from_base(robot)
    plan = plan_measurements(
        robot,
        geometry_recorded,
        sensor_from_base,
        opts.points,
        opts.repeats,
        max_sweep_deg=opts.max_sweep_deg,
    )
    pris = robot.prismatic
    res = robot.encoder_resolution

    # Fixture errors: the real sparker mounts and probe are not where the plan says.
    fixture = 0.0 if opts.noiseless else FIXTURE_SIGMA_CM
    target_true = {
        s.joint: np.array(s.target_local_cm) + rng_world.normal(0, fixture, 3) for s in plan.sweeps
    }
    tool_true = np.array(plan.tool_local_cm) + rng_world.normal(0, fixture, 3)
    atmosphere = (
        Atmosphere()
        if opts.noiseless
        else random_atmosphere(rng_world, h_ref_cm=float(geometry_true.height(np.zeros(3)) + 50.0))
    )

    # Command list, in recording order: targets n..1, then the tool probe at q^s.
    qs = np.array(plan.signature_q)
    commands: list[tuple[int | str, int, np.ndarray]] = []
    for sweep in plan.sweeps:
        for step, value in enumerate(sweep.q_values):
            q = qs.copy()
            q[sweep.joint - 1] = value
            commands.append((sweep.joint, step, q))
    commands.append(("tool", 0, qs.copy()))
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
        t += opts.repeats * CYCLE_S

    # Where the target sparker physically is at each configuration.
    qi = joints_to_internal(q_reached, pris)
    p_target = np.zeros((len(commands), 3))
    for k, (sweep_id, _, _) in enumerate(commands):
        if sweep_id == "tool":
            p_target[k] = tool_positions(true.chain, sensor_from_base, qi[k], tool_true)
        else:
            p_target[k] = target_positions(
                true.chain, sensor_from_base, qi[k], int(sweep_id), target_true[int(sweep_id)]
            )
    cyc_cfg = np.repeat(np.arange(len(commands)), opts.repeats)
    cyc_t = t_config[cyc_cfg] + np.tile(np.arange(opts.repeats) * CYCLE_S, len(commands))
    model = DigitizerModel(
        geometry=geometry_true,
        noise_factor=0.0 if opts.noiseless else opts.noise_factor,
        quantize=not opts.noiseless,
        mic_bias_cm=(
            tuple(rng_sensor.normal(0, BIAS_SIGMA_CM, 4)) if "bias" in opts.faults else (0.0,) * 4
        ),  # type: ignore[arg-type]
        dropout_prob=DROPOUT_PROB if "dropouts" in opts.faults else 0.0,
        outlier_prob=OUTLIER_PROB if "outliers" in opts.faults else 0.0,
    )
    raw = digitize(model, atmosphere, p_target[cyc_cfg], cyc_t, rng_sensor)

    units = ["cm" if p else "deg" for p in pris]
    # The controller reports readings: through the inverse of the robot's coupling, if any.
    read_cmd, read_enc = robot.readings_from_joints(q_cmd), robot.readings_from_joints(q_enc)
    messages = [
        Message("/rig/description", T0_NS, geometry_recorded.to_dict()),
        Message(
            "/robot/description",
            T0_NS,
            {
                "robot": description_to_dict(robot),
                "signature_q": [float(v) for v in robot.readings_from_joints(qs)],
                "plan": plan.to_dict(),
                "mode": "simulated",
            },
        ),
    ]
    digits = None if opts.noiseless else 2  # quantized ranges print as 0.01 cm
    for k, (sweep_id, step, _) in enumerate(commands):
        t_ns = T0_NS + int(round(t_config[k] * 1e9))
        messages.append(
            Message(
                "/robot/joint_state",
                t_ns,
                {
                    "sweep": sweep_id,
                    "step": step,
                    "q_commanded": [round(float(v), 6) for v in read_cmd[k]],
                    "q_encoder": [
                        float(v) if opts.noiseless else round(float(v), 6) for v in read_enc[k]
                    ],
                    "units": units,
                },
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
    messages.sort(key=lambda m: m.time_ns)  # stable: descriptions stay first
    recording = out / "recording.mcap"
    truth = {
        "robot": robot.name,
        "seed": opts.seed,
        "options": {**asdict(opts), "faults": list(opts.faults)},
        "true_kinematics": {
            "frame": "sensor",
            "length_unit": "cm",
            "angle_unit": "deg",
            "joint_types": [j.type for j in robot.joints],
            "base": (sensor_from_base @ true.chain.base).tolist(),
            "links": true.chain.links.tolist(),
        },
        "true_tool_in_last_link_cm": tool_true.tolist(),
        "true_targets_local_cm": {str(k): v.tolist() for k, v in target_true.items()},
        "sensor_from_base": sensor_from_base.tolist(),
        "errors": true.errors,
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
    out.mkdir(parents=True, exist_ok=True)
    # Under the session lock, like every pipeline run on the folder: no run reads a
    # recording half replaced, and a recording that appeared meanwhile is still refused.
    with session_lock(out):
        refuse_existing_recording(out, force, "a simulated one")
        write_recording(recording, messages)
        write_text_atomic(out / "rig-truth.json", json.dumps(truth, indent=1) + "\n")
    return recording
