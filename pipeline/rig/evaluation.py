"""The evaluation rig: teach the workspace frames, run joint programs on the true robot,
read the instruments, and record ``sessions/NAME/evaluation.mcap`` (docs/evaluation.md).

This is hardware: it alone reads ``rig-truth.json``. The fixtures sit at their
nominal places in the base frame plus a placement error (the lab cannot put
them exactly), the probe is the true probe of the session, the servo settles
within ±1 encoder count (Section 6.5), and each instrument reads with its
resolution (Sections 6.5.1-6.5.3).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from pipeline.control.controller import task_axes_for
from pipeline.errors import ArmsigError
from pipeline.evaluation.controllers import (
    CONTROLLERS,
    DesignModel,
    task_branches,
    task_poses,
    within_limits,
)
from pipeline.evaluation.geometry import rotation_vector
from pipeline.evaluation.tasks import (
    CATHETOMETER_CM,
    RANKY_CM,
    RANKY_DEG,
    RULE_CM,
    Task,
    tasks_for,
)
from pipeline.kinematics.chain import SerialChain, forward_kinematics, in_frame
from pipeline.kinematics.ik import ALL_AXES, newton_raphson
from pipeline.kinematics.transforms import invert_transform, rot_x, rot_y, rot_z, trans
from pipeline.rig.audit import read_truth, true_chain, true_nongeometric
from pipeline.rig.plan import PROBE_LENGTH_CM
from pipeline.rig.recorder import EVAL_CHANNELS, Message, write_recording
from pipeline.rig.session_files import T0_NS
from pipeline.robots import get_robot
from pipeline.units import joints_to_boundary, joints_to_internal

#: Fixture placement error (1 σ) about the nominal place: a lab sets a table or
#: jig to a few mm and a few tenths of a degree. Teaching absorbs it (Section 6.5).
FIXTURE_SIGMA_CM = 0.5
FIXTURE_SIGMA_DEG = 0.2
STEP_NS = 10**9  # one message per second of rig time
TEACH_STARTS = 10  # random starts of the teach search for robots without a closed form


@dataclass(frozen=True)
class EvaluationRigOptions:
    """Switches of the evaluation rig (recorded in ``/eval/description``).

    ``perfect_servo``: joints reach their commands exactly and teach readings
    are not rounded to encoder counts; ``exact_instruments``: readings are not
    quantized to the instruments' resolutions.
    """

    perfect_servo: bool = False
    exact_instruments: bool = False

    def description(self, robot: str) -> dict[str, Any]:
        return {
            "mode": "simulated",
            "servo": "perfect" if self.perfect_servo else "pm1count",
            "instruments": "exact" if self.exact_instruments else "resolution",
            "robot": robot,
        }


def _quantize(x: np.ndarray, step: float, exact: bool) -> np.ndarray:
    """Instrument reading: ``x`` rounded to multiples of ``step`` (unless ``exact``).

    The product is rounded to 1e-9 so that equal readings are equal floats
    (0.025 multiples are not exact in binary); far below every resolution.
    """
    x = np.asarray(x, float)
    return x if exact else np.round(np.round(x / step) * step, 9)


class SimulatedRig:
    """The true robot, its probe and the placed fixtures of one simulated session."""

    def __init__(self, session_dir: str | Path, opts: EvaluationRigOptions) -> None:
        sdir = Path(session_dir)
        path = sdir / "rig-truth.json"
        if not path.is_file():
            raise ArmsigError(
                f"{sdir}: no evaluation.mcap and no rig-truth.json",
                expected="a recorded evaluation (hardware) or a simulated session",
                fix="record /eval/teach, /eval/program and /eval/measurement on the robot "
                "(docs/evaluation.md), or simulate the session with `pipeline simulate`",
            )
        truth = read_truth(path)
        c = true_chain(truth)
        try:
            robot_name = str(truth["options"]["robot"])
            sensor_from_base = np.array(truth["sensor_from_base"], float).reshape(4, 4)
            tip = np.array(truth["true_tool_in_last_link_cm"], float).reshape(3)
            seed = int(truth["seed"])
        except (KeyError, TypeError, ValueError, OverflowError) as exc:
            raise ArmsigError(
                f"{path}: the ground truth is incomplete",
                expected="options.robot, sensor_from_base (4x4), true_tool_in_last_link_cm "
                "(3) and seed, as `pipeline simulate` writes them",
                got=f"{type(exc).__name__}: {exc}",
                fix="simulate the session again (`pipeline simulate NAME --force`)",
            ) from exc
        self.opts = opts
        self.robot = get_robot(robot_name)
        self.nominal_tool = trans(0.0, 0.0, PROBE_LENGTH_CM)
        base = invert_transform(sensor_from_base) @ c.base
        # E: origin at the probe tip, axes of the frame the last joint's targets are
        # mounted in (F_{n-1}·M_n, pipeline.rig.plan.target_positions), whose X axis
        # points at the nominal mount (R, 0, z). The last link frame is that frame
        # times the constant K̄_n, whose rotation the generic true-robot model perturbs
        # (the Puma's is the identity), so the probe's rotation undoes it.
        probe = np.eye(4)
        probe[:3, :3] = c.links[-1][:3, :3].T
        probe[:3, 3] = tip
        self.chain = SerialChain(c.links, c.prismatic, base, c.tool @ probe)
        #: Where the true joints sit for given readings (compliance, angle errors).
        self.nongeometric = true_nongeometric(truth, self.robot)
        self.res = joints_to_internal(self.robot.encoder_resolution, self.robot.prismatic)
        rng = np.random.default_rng([seed, 6])  # issue 6's own stream
        self.rng_fixture, self.rng_servo = rng.spawn(2)
        #: The servo stream's state before the signature's run of the last task: the
        #: compensated run of that task replays it (common random numbers, issue 30), so
        #: the two differ only by what their controllers command, and the design and
        #: signature draws are those of an evaluation without the compensated run.
        self._signature_servo_state: Mapping[str, Any] | None = None
        self.tasks = tasks_for(self.robot, self.nominal_tool)
        self.fixture = {}
        for t in self.tasks:
            p = self.rng_fixture.normal(0.0, FIXTURE_SIGMA_CM, 3)
            r = np.deg2rad(self.rng_fixture.normal(0.0, FIXTURE_SIGMA_DEG, 3))
            self.fixture[t.name] = (
                t.fixture_in_base @ trans(*p) @ rot_x(r[0]) @ rot_y(r[1]) @ rot_z(r[2])
            )

    def _units(self) -> list[str]:
        return [j.unit for j in self.robot.joints]

    def teach(self, task: Task) -> np.ndarray | None:
        """Encoder readings (3, n) in rad / cm with the true probe on the teach points.

        An arm with fewer than six joints puts the probe tip on the point with the
        yaw (its task axes) about the fixture's axes; it cannot follow the fixture's tilt."""
        poses, _ = task_poses(task)
        nominal = task.fixture_in_base @ poses
        branches, _ = task_branches(self.robot, self.nominal_tool, task)
        design = DesignModel(self.robot, self.nominal_tool)
        axes = task_axes_for(self.robot)
        chain, targets = self.chain, self.fixture[task.name] @ poses
        if axes != ALL_AXES:
            chain, targets = in_frame(self.chain, self.fixture[task.name]), poses
        q = np.full((3, self.robot.n_joints), np.nan)
        for q_near in self._starts():  # the operator jogs from a few configurations
            q0, ok0 = design.solve(nominal, branches, q_near, task.fixture_in_base)
            res = newton_raphson(chain, targets, q0, self.res,
                                 task_axes=None if axes == ALL_AXES else axes)  # fmt: skip
            readings = res.q if self.nongeometric is None else self.nongeometric.readings_for(res.q)
            good = ok0 & res.converged & within_limits(self.robot, readings) & np.isnan(q[:, 0])
            q[good] = readings[good]
            if not np.isnan(q).any():
                break
        if np.isnan(q).any():
            return None
        return q if self.opts.perfect_servo else np.round(q / self.res) * self.res

    def _starts(self) -> list[np.ndarray]:
        """Start configurations of the teach search (rad / cm): the Puma's closed form
        needs one; other robots try the middle of the joint limits, then seeded draws."""
        lim = joints_to_internal(self.robot.limits.T, self.robot.prismatic).T
        starts = [lim.mean(axis=1)]
        if self.robot.name != "puma560":
            rng = np.random.default_rng(0)  # fixed: the same robot is taught the same way
            starts += list(rng.uniform(lim[:, 0], lim[:, 1], (TEACH_STARTS, len(lim))))
        return starts

    def reach(self, q_cmd: np.ndarray, controller: str = "design") -> np.ndarray:
        """Joint positions (m, n) reached for commands (m, n) rad / cm: ±1 count servo."""
        if self.opts.perfect_servo:
            return q_cmd
        counts = np.round(q_cmd / self.res) * self.res  # the controller commands whole counts
        rng = self.rng_servo
        if controller == "signature":
            self._signature_servo_state = rng.bit_generator.state
        elif controller == "compensated" and self._signature_servo_state is not None:
            rng = np.random.Generator(type(rng.bit_generator)())
            rng.bit_generator.state = self._signature_servo_state
        return counts + rng.uniform(-1.0, 1.0, q_cmd.shape) * self.res

    def measure(self, task: Task, controller: str, q_cmd: np.ndarray) -> list[dict[str, Any]]:
        """Instrument readings for one task's program (m, n) of one controller."""
        q = self.reach(q_cmd, controller)
        if self.nongeometric is not None:
            q = self.nongeometric.effective(q)
        E = invert_transform(self.fixture[task.name]) @ forward_kinematics(self.chain, q)
        p = E[:, :3, 3]
        exact = self.opts.exact_instruments
        head = {"task": task.name, "controller": controller, "instrument": task.instrument}
        out = []
        if task.name == "lines1d":
            length = np.linalg.norm(p[1::2] - p[0::2], axis=-1)
            for k, v in enumerate(_quantize(length, CATHETOMETER_CM, exact)):
                out.append({**head, "point": k + 1, "length_cm": float(v)})
            return out
        if task.name == "grid2d":
            for k, v in enumerate(_quantize(p[:, :2], RULE_CM, exact)):
                out.append({**head, "point": k + 1, "xy_cm": [float(x) for x in v]})
            return out
        exact = exact or task.instrument == "exact"
        w = np.degrees(rotation_vector(task.tool_rotation, E[:, :3, :3]))
        xyz = _quantize(p, RANKY_CM, exact)
        rot = _quantize(w, RANKY_DEG, exact)
        for k in range(len(p)):
            out.append(
                {
                    **head,
                    "point": k + 1,
                    "xyz_cm": [float(x) for x in xyz[k]],
                    "rotation_deg": [float(x) for x in rot[k]],
                }
            )
        return out


def record_evaluation(
    session_dir: str | Path,
    program: list[dict[str, Any]] | None = None,
    opts: EvaluationRigOptions | None = None,
) -> Path:
    """Teach every task and, given a ``program``, run it; write ``evaluation.mcap``.

    ``program``: ``/eval/program`` payloads (task, controller, point,
    q_commanded in deg / cm, units) in execution order. Tasks the true robot
    cannot be taught are left out of ``/eval/teach``.
    """
    sdir = Path(session_dir)
    rig = SimulatedRig(sdir, opts or EvaluationRigOptions())
    units = rig._units()
    t = T0_NS
    messages = [Message("/eval/description", t, rig.opts.description(rig.robot.name))]
    for task in rig.tasks:
        q = rig.teach(task)
        if q is None:
            continue
        qb = joints_to_boundary(q, rig.robot.prismatic)
        for k in range(3):
            t += STEP_NS
            payload = {"task": task.name, "point": k + 1, "q_encoder": [float(v) for v in qb[k]]}
            messages.append(Message("/eval/teach", t, {**payload, "units": units}))
    for task in rig.tasks:
        for controller in CONTROLLERS:
            rows = [
                r for r in program or [] if r["task"] == task.name and r["controller"] == controller
            ]
            if not rows:
                continue
            q_cmd = joints_to_internal(
                np.array([r["q_commanded"] for r in rows]), rig.robot.prismatic
            )
            for r in rows:
                t += STEP_NS
                messages.append(Message("/eval/program", t, r))
            for m in rig.measure(task, controller, q_cmd):
                t += STEP_NS
                messages.append(Message("/eval/measurement", t, m))
    if not any(m.topic == "/eval/teach" for m in messages):
        raise ArmsigError(
            f"{sdir}: no task fits {rig.robot.name}",
            expected="a robot that can put its probe on the teach points of at least one task",
            got="every task's teach points out of reach or outside the joint limits",
            fix="see docs/evaluation.md (task placement and scaling)",
        )
    path = sdir / "evaluation.mcap"
    write_recording(path, messages, EVAL_CHANNELS)
    return path
