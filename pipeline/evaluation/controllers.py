"""The three controllers under test, as models of the end-effector frame E.

``E`` is the probe (pin, pen or test cube) frame: origin at the probe tip,
axes those of the flange, whose X axis points at the last joint's target
mount (the target fixture of Table F-1 sits at ``(R, 0, z)`` in the flange
frame). Both controllers work in the design base frame:

- *design*: design model, closed-form inverse (Puma, Appendix B.2) or damped
  Newton-Raphson on the design model (others), nominal probe on the flange;
- *signature*: identified S-Model with the identified probe
  (:class:`pipeline.control.Controller`, Newton-Raphson, Chapter 5). The
  S-Model's last frame has its X axis toward the *first* target position
  (4.50), so E is that frame turned about the joint axis by the mean angle
  ``δ`` of the last target in it over its sweep (:func:`flange_angle`):
  measured, not assumed;
- *compensated*: a controller that keeps its design model, driven to compensated targets
  (``pipeline compensate``, docs/compensate.md): the program is taught and solved on the
  signature offline, each target rewritten as the design model's pose at the signature's
  joints, and the design controller (its closed-form inverse on the branch of those joints,
  or Newton-Raphson from them) solves that rewritten target.

Arms with fewer than six joints control the pose components of
:func:`pipeline.control.task_axes_for` only (a SCARA: position and the
rotation about Z); every controller then solves in the taught workspace frame,
so the controlled rotation is about the workspace's axes, the ones the
instruments read.
"""

from __future__ import annotations

import functools
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from pipeline.control.controller import Controller, task_axes_for
from pipeline.control.limits import into_limits
from pipeline.evaluation.tasks import Task
from pipeline.kinematics.chain import SerialChain, forward_kinematics, in_frame
from pipeline.kinematics.ik import ALL_AXES, newton_raphson
from pipeline.kinematics.transforms import Array, invert_transform, rot_z, wrap_angle
from pipeline.robots.description import RobotDescription
from pipeline.signature.file import Signature
from pipeline.units import joints_to_internal

BoolArray = npt.NDArray[np.bool_]
#: The controllers of an evaluation, in the order of the program, the rig and the indices.
CONTROLLERS = ("design", "signature", "compensated")
#: Joint-limit test margin (rad / cm): round-off only; the limits are the robot's own.
LIMIT_MARGIN = 1e-9


#: Margin kept from the joint limits when planning a task's branch on the nominal
#: placement (5° / 1 cm): the taught frame and the model errors move the real
#: solutions by up to a degree or two, which must not push them past a limit.
PLAN_MARGIN_DEG, PLAN_MARGIN_CM = 5.0, 1.0
#: Planned Puma elbows stay this far from fully stretched or folded (deg).
ELBOW_MARGIN_DEG = 20.0


def within_limits(robot: RobotDescription, q: Array, margin: Array | float = 0.0) -> BoolArray:
    """Whether joint vectors (m, n) in rad / cm are inside the robot's limits shrunk by
    ``margin`` (rad / cm, scalar or (n,)), shape (m,)."""
    lim = joints_to_internal(robot.limits.T, robot.prismatic).T
    lo, hi = lim[:, 0] + margin - LIMIT_MARGIN, lim[:, 1] - margin + LIMIT_MARGIN
    ok: BoolArray = np.all((q >= lo) & (q <= hi), axis=-1)
    return ok


@dataclass(frozen=True, eq=False)
class DesignModel:
    """Design model with the nominal probe ``tool`` (flange -> E, (4, 4))."""

    robot: RobotDescription
    tool: Array

    name = "design"

    @property
    def chain(self) -> SerialChain:
        """Design links with the probe on the flange (the last link frame: where the
        rig mounts it, ``true_tool_in_last_link_cm``), not on the description's tool."""
        d = self.robot.design_chain()
        return SerialChain(d.links, d.prismatic, d.base, self.tool, d.joint_offsets)

    def fk(self, q: Array) -> Array:
        """E in the design base frame, q (..., n) rad / cm -> (..., 4, 4)."""
        return forward_kinematics(self.chain, q)

    def solve(
        self, T: Array, branches: list, q_near: Array, workspace: Array | None = None
    ) -> tuple[Array, BoolArray]:
        """Joint vectors (m, n) reaching E poses T (m, 4, 4); and which are valid (m,).

        ``workspace`` (4, 4): the frame whose axes the task axes of an arm with
        fewer than six joints refer to (default: the base frame)."""

        one = functools.partial(self._solve, workspace=workspace)
        return solve_with_wrist_flip(one, self.robot, T, branches, q_near)

    def _solve(
        self, T: Array, branches: list, q_near: Array, workspace: Array | None
    ) -> tuple[Array, BoolArray]:
        m = len(T)
        q = np.full((m, self.robot.n_joints), np.nan)
        if self.robot.name == "puma560":
            from pipeline.control.puma560_inverse import puma_design_inverse

            d = self.robot.design_chain()
            for br in dict.fromkeys(branches):
                sel = np.array([b == br for b in branches])
                inv = puma_design_inverse(br, tool=d.tool @ self.tool, base=d.base, clamp=False)
                q[sel] = inv(T[sel], np.broadcast_to(q_near, (int(sel.sum()), len(q_near))))
            ok = np.isfinite(q).all(axis=1)
        else:
            q, ok = nr_multistart(self.chain, self.robot, T, q_near, workspace)
        q = into_limits(self.robot, np.where(np.isfinite(q), q, 0.0))
        return q, ok & within_limits(self.robot, q)


@dataclass(frozen=True, eq=False)
class SignatureModel:
    """Identified signature; ``delta`` (rad) turns its tool frame into E."""

    signature: Signature
    delta: float

    name = "signature"

    @property
    def robot(self) -> RobotDescription:
        return self.signature.robot

    @property
    def chain(self) -> SerialChain:
        c = self.signature.chain
        base = invert_transform(self.signature.sensor_from_design_base) @ c.base
        return SerialChain(c.links, c.prismatic, base, c.tool @ rot_z(self.delta), c.joint_offsets)

    def fk(self, q: Array) -> Array:
        """E in the design base frame, q (..., n) rad / cm -> (..., 4, 4)."""
        return forward_kinematics(self.chain, q)

    def solve(
        self, T: Array, branches: list, q_near: Array, workspace: Array | None = None
    ) -> tuple[Array, BoolArray]:
        """Joint vectors (m, n) reaching E poses T (m, 4, 4) by Newton-Raphson; valid mask (m,).

        ``workspace`` as for :meth:`DesignModel.solve`."""

        one = functools.partial(self._solve, workspace=workspace)
        return solve_with_wrist_flip(one, self.robot, T, branches, q_near)

    def _solve(
        self, T: Array, branches: list, q_near: Array, workspace: Array | None
    ) -> tuple[Array, BoolArray]:
        s = self.signature
        if s.robot.name != "puma560":  # Controller.solve cannot start near the task
            q, ok = nr_multistart(self.chain, s.robot, T, q_near, workspace)
            return q, ok & within_limits(s.robot, q)
        ctrl = Controller(s, s.robot, s.sensor_from_design_base, s.design_flange_to_tool)
        T_tool = T @ rot_z(-self.delta)  # the controller's tool is the S-Model tool
        m = len(T)
        q = np.zeros((m, s.robot.n_joints))
        ok = np.zeros(m, bool)
        for br in dict.fromkeys(branches):
            sel = np.array([b == br for b in branches])
            res = ctrl.solve(T_tool[sel], br, "nr")
            q[sel], ok[sel] = res.q, res.converged
        return q, ok & within_limits(s.robot, q)


@dataclass(frozen=True, eq=False)
class CompensatedModel:
    """The design controller driven to compensated targets (:mod:`pipeline.control.compensate`):
    taught with the signature (the offline tool's model, ``fk``), each target solved on the
    signature, rewritten as ``design.fk(q_s)`` and solved by the design controller from
    ``q_s``'s configuration: its closed-form inverse on ``q_s``'s branch (Puma), else
    Newton-Raphson started at ``q_s`` (the condition docs/compensate.md states)."""

    design: DesignModel
    signature: SignatureModel

    name = "compensated"

    @property
    def robot(self) -> RobotDescription:
        return self.design.robot

    def fk(self, q: Array) -> Array:
        """E in the design base frame as the offline tool models it (the signature)."""
        return self.signature.fk(q)

    def compensated_targets(
        self, T: Array, branches: list, q_near: Array, workspace: Array | None = None
    ) -> tuple[Array, Array, BoolArray]:
        """The signature's joints ``q_s`` (m, n) for E poses T, the rewritten targets
        ``design.fk(q_s)`` (m, 4, 4) the nominal controller is given, and which are valid."""
        q_s, ok = self.signature.solve(T, branches, q_near, workspace)
        return q_s, self.design.fk(q_s), ok

    def solve(
        self, T: Array, branches: list, q_near: Array, workspace: Array | None = None
    ) -> tuple[Array, BoolArray]:
        """Joint vectors (m, n) the design controller commands for the compensated targets
        of E poses T; valid mask (m,)."""
        q_s, T_c, ok = self.compensated_targets(T, branches, q_near, workspace)
        if self.robot.name == "puma560":
            from pipeline.robots.puma560 import Branch, branch_of

            flags = branch_of(np.where(ok[:, None], q_s, 0.0))
            own = [Branch(*(int(v) for v in f)) if good else b
                   for f, good, b in zip(flags, ok, branches, strict=True)]  # fmt: skip
            q, ok_d = self.design.solve(T_c, own, q_s[0], workspace)
        else:
            q, ok_d = nr_multistart(self.design.chain, self.robot, T_c, q_s, workspace)
            ok_d &= within_limits(self.robot, q)
        # The turn of each revolute joint nearest the written readings (a controller told the
        # configuration takes it): not a 360° turn away where both are inside the limits.
        near = np.where(self.robot.prismatic, q, q_s + wrap_angle(q - q_s))
        q = np.where(within_limits(self.robot, near)[:, None], near, q)
        return q, ok & ok_d


#: Seeded restarts of the damped Newton-Raphson for robots without a closed-form inverse.
RESTARTS = 10


def nr_multistart(
    chain: SerialChain,
    robot: RobotDescription,
    T: Array,
    q_near: Array,
    workspace: Array | None = None,
) -> tuple[Array, BoolArray]:
    """Damped Newton-Raphson (5.4) from ``q_near`` (the taught configuration, (n,), or one
    start per target, (m, n)), then
    from the middle of the joint limits and seeded draws for the targets that did
    not converge inside the limits (robots without a closed-form inverse).

    An arm with fewer than six joints solves its task axes
    (:func:`pipeline.control.task_axes_for`) in ``workspace`` coordinates
    (chain and targets mapped by its inverse; default: the chain's base frame)."""
    axes = task_axes_for(robot)
    if axes != ALL_AXES and workspace is not None:
        chain, T = in_frame(chain, workspace), invert_transform(workspace) @ T
    task_axes = None if axes == ALL_AXES else axes
    res_q = joints_to_internal(robot.encoder_resolution, robot.prismatic)
    lim = joints_to_internal(robot.limits.T, robot.prismatic).T
    rng = np.random.default_rng(0)  # fixed: the same targets get the same program
    starts = [np.asarray(q_near, float), lim.mean(axis=1)]
    starts += list(rng.uniform(lim[:, 0], lim[:, 1], (RESTARTS, len(lim))))
    m = len(T)
    q = np.zeros((m, robot.n_joints))
    ok = np.zeros(m, bool)
    for q0 in starts:
        todo = np.flatnonzero(~ok)
        if not len(todo):
            break
        start = q0[todo] if q0.ndim == 2 else np.broadcast_to(q0, (len(todo), len(q0)))
        r = newton_raphson(chain, T[todo], start, res_q, max_iter=100, damping=1e-2,
                           task_axes=task_axes)  # fmt: skip
        qq = into_limits(robot, r.q)
        good = r.converged & within_limits(robot, qq)
        q[todo[good]], ok[todo[good]] = qq[good], True
    return q, ok


def solve_with_wrist_flip(
    solve: Callable[[Array, list, Array], tuple[Array, BoolArray]],
    robot: RobotDescription,
    T: Array,
    branches: list,
    q_near: Array,
) -> tuple[Array, BoolArray]:
    """``solve`` on the planned branches, then once more with the wrist flipped where
    that failed (Puma). Next to the wrist singularity (θ5 ≈ 0) the closed form's θ4
    is ill-defined and may land ~180° off, outside θ4's limits; the flipped wrist
    ``(θ4 + π, −θ5, θ6 + π)`` reaches the same pose (the signature's nearly).
    """
    q, ok = solve(T, branches, q_near)
    if robot.name != "puma560" or ok.all():
        return q, ok
    from pipeline.robots.puma560 import Branch

    bad = np.flatnonzero(~ok)
    flipped = [Branch(b.shoulder, b.elbow, -b.wrist) for b in (branches[k] for k in bad)]
    q2, ok2 = solve(T[bad], flipped, q_near)
    q[bad[ok2]], ok[bad[ok2]] = q2[ok2], True
    return q, ok


def flange_angle(chain: SerialChain, q: Array, p: Array) -> float:
    """Angle δ (rad) of the last joint's target about the last S-Model frame's Z axis.

    The circular mean over the last sweep of ``atan2(y, x)`` of the target in the
    chain's last link frame (tool excluded); ``q`` (m, n): the joint values of the sweep's
    steps (deg / cm), ``p`` (m, 3): the target's measured positions (cm), NaN where none.
    """
    ok = np.isfinite(p).all(axis=1)
    bare = SerialChain(chain.links, chain.prismatic, chain.base, np.eye(4), chain.joint_offsets)
    L = forward_kinematics(bare, joints_to_internal(q[ok], chain.prismatic))
    local = np.einsum("kji,kj->ki", L[:, :3, :3], p[ok] - L[:, :3, 3])
    phi = np.arctan2(local[:, 1], local[:, 0])
    return float(np.arctan2(np.mean(np.sin(phi)), np.mean(np.cos(phi))))


def plan_branches(robot: RobotDescription, tool: Array, T_base: Array) -> list:
    """Puma configuration branch per pose (design model, nominal fixture placement).

    One branch for the whole pose set, as an operator would program a task: the
    branch whose design solutions are within the joint limits (less
    :data:`PLAN_MARGIN_DEG`) for the most poses (and the elbow
    :data:`ELBOW_MARGIN_DEG` from stretched), ties broken by the distance from the
    wrist singularity (smallest |sin θ5| largest). Poses it cannot serve get their
    own best branch, or the main one if none serves them.
    ``None`` for other robots (their solvers start from the taught configuration).
    """
    if robot.name != "puma560":
        return [None] * len(T_base)
    from pipeline.robots import puma560

    d = robot.design_chain()
    q, ok = puma560.inverse_kinematics(T_base, tool=d.tool @ tool, base=d.base)
    margin = np.where(robot.prismatic, PLAN_MARGIN_CM, np.deg2rad(PLAN_MARGIN_DEG))
    sin5 = np.full(ok.shape, -1.0)  # -1: branch unusable for that pose
    for b in range(len(puma560.BRANCHES)):
        qq = into_limits(robot, np.where(ok[:, b, None], q[:, b], 0.0))
        # Elbow at least ELBOW_MARGIN_DEG from stretched / folded (|sin(θ3 + φ)| = 1 there,
        # φ = atan2(a3, d4)): next to it the design model and the robot disagree on reach.
        elbow = np.abs(
            np.cos(qq[:, 2] + np.arctan2(puma560.DESIGN_A_CM[2], puma560.DESIGN_D_CM[3]))
        )
        good = (
            ok[:, b].astype(bool)
            & within_limits(robot, qq, margin)
            & (elbow > np.sin(np.deg2rad(ELBOW_MARGIN_DEG)))
        )
        sin5[:, b] = np.where(good, np.abs(np.sin(qq[:, 4])), -1.0)
    usable = sin5 >= 0.0
    score = [(usable[:, b].sum(), sin5[usable[:, b], b].min(initial=1.0)) for b in range(8)]
    main = max(range(8), key=lambda b: score[b])
    own = np.argmax(sin5, axis=1)
    pick = np.where(usable[:, main] | ~usable.any(axis=1), main, own)
    return [puma560.BRANCHES[int(b)] for b in pick]


def task_poses(task: Task) -> tuple[Array, Array]:
    """Teach poses (3, 4, 4) and target poses (m, 4, 4) in fixture coordinates."""
    teach = np.tile(np.eye(4), (3, 1, 1))
    teach[:, :3, :3] = task.tool_rotation
    teach[:, :3, 3] = task.teach_cm
    return teach, task.targets()


def task_branches(robot: RobotDescription, tool: Array, task: Task) -> tuple[list, list]:
    """:func:`plan_branches` of a task's teach and target poses together (one plan)."""
    teach, targets = task_poses(task)
    br = plan_branches(robot, tool, task.fixture_in_base @ np.concatenate([teach, targets]))
    return br[:3], br[3:]
