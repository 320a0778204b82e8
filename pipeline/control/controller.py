"""Signature-based control (Chapter 5): poses in, encoder readings out.

A :class:`Controller` drives a robot with its identified signature. Poses are
given in the *design base frame* (the robot's mounting surface, as the design
model defines it) for the signature's tool; the controller maps them into the
signature's sensor frame with the base alignment stored in the signature file
(Section 5.3: design and signature models must share one physical base frame).

- Newton-Raphson (5.4) starts from the closed-form design inverse on the
  requested branch (Puma) or from a damped least-squares design inverse.
- Jacobi iterative (5.8) needs a closed-form design inverse: Puma only.
- Arms with fewer than six joints control only some pose components
  (:func:`task_axes_for`: position and rotation about the base Z for a
  SCARA-like arm); ``Controller.solve(..., task_axes=...)`` solves those.
- A signature with non-geometric terms (issue 27, :mod:`pipeline.kinematics.
  nongeometric`): the joints sit at ``q + Φ(q)β`` for readings ``q``. Every solver
  finds where the joints must sit, ``q*`` (the rigid chain's inverse), and the readings
  are the fixed point of ``q = q* − Φ(q)β`` (:meth:`NonGeometric.readings_for`);
  :meth:`Controller.pose` predicts the deflected pose of readings.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from functools import cached_property
from typing import Any

import numpy as np

from pipeline.control.limits import (
    honour_limits,
    limit_arrays,
    outside_mask,
    wrist_flip_applies,
)
from pipeline.errors import ArmsigError
from pipeline.kinematics.chain import SerialChain, in_frame
from pipeline.kinematics.ik import (
    ALL_AXES,
    DesignInverse,
    IKResult,
    controllable_axes,
    ik_compilable,
    jacobi_iterative,
    newton_raphson,
)
from pipeline.kinematics.ik.result import STATUS_CONVERGED, STATUS_OUT_OF_LIMITS
from pipeline.kinematics.transforms import invert_transform
from pipeline.robots.description import RobotDescription
from pipeline.robots.fk import ToolPose, ToolPoses, chain_pose, chain_poses
from pipeline.signature.alignment import FRAMES
from pipeline.signature.file import Signature
from pipeline.units import joints_to_internal

METHODS = ("nr", "jacobi")


def parse_branch(text: str | None):  # -> Branch | None
    """``right-up-noflip`` style branch names (see :class:`pipeline.robots.puma560.Branch`)."""
    if text is None:
        return None
    from pipeline.robots.puma560 import BRANCHES

    for b in BRANCHES:
        if b.label == text:
            return b
    raise ArmsigError(f"unknown branch {text!r}", expected=", ".join(b.label for b in BRANCHES))


@dataclass(frozen=True)
class Controller:
    """Inverse kinematics of one identified robot."""

    signature: Signature
    robot: RobotDescription
    sensor_from_base: np.ndarray  # X: design base frame -> sensor frame
    flange_to_tool: np.ndarray  # Y: design flange -> signature tool

    @classmethod
    def from_signature(cls, sig: Signature) -> Controller:
        """The controller of a loaded signature, with the file's design alignment X, Y."""
        return cls(sig, sig.robot, sig.sensor_from_design_base, sig.design_flange_to_tool)

    def with_tool(self, flange_to_user_tool: np.ndarray) -> Controller:
        """The controller of a user tool given in the design flange frame (4, 4), cm.

        The flange is the end frame of the robot description's design chain; the
        offset is what the tool's drawing gives. The signature's tool (the probe
        the session measured) is ``Y`` from the flange, so the user tool is
        ``F_s(q) · Y⁻¹ · flange_to_user_tool``: the signature chain's tool moves
        by ``Y⁻¹ · flange_to_user_tool``, the design model's by the offset itself.
        Poses, residuals and the initial estimate then all refer to the user tool.
        """
        F_u = np.asarray(flange_to_user_tool, float)
        R = F_u[:3, :3]
        # A rigid transform: orthonormal to round-off of a matrix built from angles.
        if F_u.shape != (4, 4) or not np.allclose(R.T @ R, np.eye(3), atol=1e-9):
            raise ArmsigError(
                "bad user tool", expected="a (4, 4) rigid transform", got=repr(F_u.tolist())
            )
        c = self.signature.chain
        tool = c.tool @ invert_transform(self.flange_to_tool) @ F_u
        chain = SerialChain(c.links, c.prismatic, c.base, tool, c.joint_offsets)
        sig = replace(self.signature, chain=chain, design_flange_to_tool=F_u)
        return Controller(sig, self.robot, self.sensor_from_base, F_u)

    def with_payload(self, kg: float) -> Controller:
        """The controller of the arm carrying ``kg`` on its flange: the signature's
        non-geometric terms evaluated at that payload (:meth:`NonGeometric.with_payload`:
        predicted when the session measured two payloads or more, else only the payload
        it measured); a rigid signature predicts no payload (one-line refusal)."""
        ng = self.signature.nongeometric
        if ng is None:
            raise ArmsigError(
                "the signature has no non-geometric terms: it cannot predict a payload",
                expected="a signature identified with refine.nongeometric (docs/nongeometric.md)",
                fix="drop --payload-kg, or identify from a pose set measured with payloads",
            )
        sig = replace(self.signature, nongeometric=ng.with_payload(kg))
        return Controller(sig, self.robot, self.sensor_from_base, self.flange_to_tool)

    @property
    def payload_warning(self) -> str | None:
        """A warning when the payload lies outside those the session measured
        (:meth:`NonGeometric.payload_extrapolated`), else None."""
        ng = self.signature.nongeometric
        return None if ng is None else ng.payload_extrapolated()

    @cached_property
    def resolution(self) -> np.ndarray:
        """Encoder resolution in math units (rad / cm), shape (n,)."""
        return joints_to_internal(self.robot.encoder_resolution, self.robot.prismatic)

    @cached_property
    def _limits(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Lower and upper joint limits (rad / cm) and the 2π turn of each joint (0: prismatic)."""
        return limit_arrays(self.robot)

    @cached_property
    def _wrist_flips(self) -> bool:
        """Whether the wrist flip is an equivalence of the design model
        (:func:`pipeline.control.limits.wrist_flip_applies`)."""
        return wrist_flip_applies(self.robot.design_chain())

    @cached_property
    def _design_inverses(self) -> dict[tuple[Any, bool], DesignInverse]:
        """Puma design inverses by (branch, for Jacobi), made on first use."""
        return {}

    def _design_inverse(self, branch, jacobi: bool = False) -> DesignInverse:  # branch: Branch
        """The Puma design inverse on ``branch`` (the initial estimate's clamp margins, or
        the Jacobi iteration's), in the sensor frame."""
        inv = self._design_inverses.get((branch, jacobi))
        if inv is None:
            from pipeline.control import puma560_inverse as pc

            inv = pc.puma_design_inverse(
                branch,
                tool=self.flange_to_tool,
                base=self.sensor_from_base,
                elbow_margin_rad=pc.JACOBI_ELBOW_MARGIN_RAD if jacobi else pc.PUMA_ELBOW_MARGIN_RAD,
                shoulder_margin_cm=(
                    pc.JACOBI_SHOULDER_MARGIN_CM if jacobi else pc.PUMA_SHOULDER_MARGIN_CM
                ),
            )
            self._design_inverses[branch, jacobi] = inv
        return inv

    def _design_model(self, world_from_base: np.ndarray | None = None) -> SerialChain:
        """The design model with the signature's tool (``Y``), in the design base frame or,
        given ``world_from_base`` (4, 4), in that world (the sensor frame: ``X``)."""
        d = self.robot.design_chain()
        base = d.base if world_from_base is None else world_from_base @ d.base
        tool = d.tool @ self.flange_to_tool
        return SerialChain(d.links, d.prismatic, base, tool, d.joint_offsets)

    def pose(
        self, q: np.ndarray | list[float], design: bool = False, frame: str = "design-base"
    ) -> ToolPose:
        """The signature tool's pose at joint readings ``q`` (n,), deg / cm (the joints
        where the signature's non-geometric terms put them), in ``frame``: the design base
        frame (what :meth:`solve` takes back) or the sensor frame (where the points were
        measured: the model's prediction of a measurement). ``design``: the design model's
        pose of the same tool (its flange times ``Y``), for comparison."""
        ng = None if design else self.signature.nongeometric
        return chain_pose(self.robot, self._pose_chain(design, frame), q, ng)

    def poses(self, q: np.ndarray, design: bool = False, frame: str = "design-base") -> ToolPoses:
        """:meth:`pose` of joint readings ``q`` (m, n), deg / cm, in one batch."""
        ng = None if design else self.signature.nongeometric
        return chain_poses(self.robot, self._pose_chain(design, frame), q, ng)

    def _readings(self, res: IKResult) -> IKResult:
        """``res`` (where the joints must sit) as the readings that put them there under the
        signature's non-geometric terms (module docstring); a reading pushed past a limit
        by them marks its row ``out_of_limits``. ``res`` itself without terms."""
        ng = self.signature.nongeometric
        if ng is None:
            return res
        q = ng.readings_for(res.q)
        status = res.status.copy()
        status[res.converged & outside_mask(q, self._limits).any(axis=1)] = STATUS_OUT_OF_LIMITS
        return replace(res, q=q, status=status, converged=status == STATUS_CONVERGED)

    def _pose_chain(self, design: bool, frame: str = "design-base") -> SerialChain:
        """The chain :meth:`pose` evaluates, in ``frame`` (:data:`FRAMES`)."""
        if frame not in FRAMES:
            raise ArmsigError(f"unknown frame {frame!r}", expected=" | ".join(FRAMES))
        X = self.sensor_from_base
        if frame == "sensor":
            return self._design_model(X) if design else self.signature.chain
        return self._design_model() if design else in_frame(self.signature.chain, X)

    def default_branch(self):  # -> Branch
        """The Puma branch of the signature configuration."""
        from pipeline.robots.puma560 import Branch, branch_of

        return Branch(*(int(v) for v in branch_of(self.signature.chain.joint_offsets)))

    def _starts(self, m: int, q_near: np.ndarray | None) -> np.ndarray:
        """Reference configurations (m, n), rad / cm: ``q_near`` broadcast, or the
        signature configuration q^s."""
        n = self.robot.n_joints
        q = np.asarray(self.signature.chain.joint_offsets if q_near is None else q_near, float)
        if q.shape not in ((n,), (m, n)) or not np.isfinite(q).all():
            raise ArmsigError(
                "bad start configuration (--near)",
                expected=f"{n} finite joint values (or one row per target)",
                got=f"shape {q.shape}",
            )
        return np.broadcast_to(q, (m, n))

    def initial_estimate(
        self,
        T_sensor: np.ndarray,
        branch=None,
        q_near: np.ndarray | None = None,
        *,
        compiled: bool = True,
    ) -> np.ndarray:
        """q⁰: closed-form design inverse on ``branch`` (Puma; None: the branch of each
        ``q_near`` row, else of q^s), or damped least squares from ``q_near`` (else q^s).
        ``q_near`` (n,) or (m, n), rad / cm; the Puma's q⁰ takes its 2π class from it.
        ``compiled``: the damped least squares may run compiled (``newton_raphson``'s)."""
        qs = self._starts(T_sensor.shape[0], q_near)
        if self.robot.name == "puma560":
            if branch is None and q_near is None:
                branch = self.default_branch()
            return self._design_inverse(branch)(T_sensor, qs)
        design = self._design_model(self.sensor_from_base)
        res = newton_raphson(
            design, T_sensor, qs, self.resolution, max_iter=100, damping=1e-2, compiled=compiled
        )
        return res.q

    def solve(
        self,
        T_base: np.ndarray,
        branch=None,
        method: str = "nr",
        record_history: bool = False,
        task_axes: tuple[int, ...] | None = None,
        q_near: np.ndarray | None = None,
    ) -> IKResult:
        """Encoder readings (rad / cm) that put the signature tool at ``T_base`` (m, 4, 4).

        ``task_axes``: controlled components of δ = [dx, dy, dz, rx, ry, rz] in
        the design base frame (e.g. :func:`task_axes_for`); Newton-Raphson only.
        None: the full pose.
        ``q_near`` (n,) or (m, n), rad / cm: where to start (:meth:`initial_estimate`):
        the Puma takes its branch from it when ``branch`` is None, other arms start
        their search there and so return the solution it leads to. None: q^s.
        """
        if method not in METHODS:
            raise ArmsigError(f"unknown method {method!r}", expected=" or ".join(METHODS))
        T = np.asarray(T_base, float).reshape(-1, 4, 4)
        if task_axes is not None:
            if method != "nr":
                raise ArmsigError("task axes need Newton-Raphson", fix="use --method nr")
            return self._solve_task_axes(T, branch, tuple(task_axes), record_history, q_near)
        if branch is None and q_near is None and self._compilable:
            branch = self._default_branch
        if not record_history and branch is not None and self._compilable:
            # The compiled path: one target takes the real-time kernel call, so this is
            # thin (cached solver and checks; q_near checked only when given).
            solver = self.realtime(branch)
            near = None if q_near is None else self._starts(T.shape[0], q_near)
            if method == "nr":  # inside the limits, the readings, by the solver (its kernel)
                return solver.solve(T, near)
            res = solver.solve_jacobi(T, near)
            return self._readings(
                self._into_limits(res, self.signature.chain, self.sensor_from_base @ T, None, near)
            )
        if self.robot.name == "puma560" and branch is None and q_near is None:
            branch = self.default_branch()
        T_sensor = self.sensor_from_base @ T
        # A history (the report's convergence table, ik-convergence: a target or a few)
        # solves in numpy from a numpy start: importing and loading the compiled kernel
        # cost 0.3 s of CPU for a sub-millisecond solve (issue 45).
        q0 = self.initial_estimate(T_sensor, branch, q_near, compiled=not record_history)
        if method == "nr":
            res = newton_raphson(
                self.signature.chain, T_sensor, q0, self.resolution, record_history=record_history
            )
            return self._readings(
                self._into_limits(res, self.signature.chain, T_sensor, None, q_near)
            )
        if self.robot.name != "puma560":
            raise ArmsigError(
                f"{self.robot.name}: Jacobi iteration needs a closed-form design inverse",
                fix="use --method nr",
            )
        inv = self._design_inverse(branch, jacobi=True)
        res = jacobi_iterative(
            self.signature.chain,
            self._design_model(self.sensor_from_base),
            inv,
            T_sensor,
            q0,
            self.resolution,
            record_history=record_history,
        )
        return self._readings(self._into_limits(res, self.signature.chain, T_sensor, None, q_near))

    @cached_property
    def _compilable(self) -> bool:
        """Whether a solve on one branch runs in :mod:`pipeline.control.puma560_solver`
        (start and solve compiled): a Puma signature of six revolute joints."""
        c = self.signature.chain
        return self.robot.name == "puma560" and ik_compilable(c) and not c.prismatic.any()

    @cached_property
    def _default_branch(self):  # -> Branch
        return self.default_branch()

    @cached_property
    def _solvers(self) -> dict[Any, Any]:
        """Pre-bound Puma solvers by branch, made on first use."""
        return {}

    def realtime(self, branch=None):  # -> PumaSolver
        """The pre-bound Newton-Raphson solver of a Puma on ``branch`` (None: the
        signature configuration's), for a real-time loop::

            solver = controller.realtime(branch)
            for T in poses:                       # (4, 4), design base frame, cm
                if solver.solve_one(T, q_near=solver.q):   # previous solution: 2π class
                    send(solver.q)                # rad; the solver's own buffer

        :meth:`~pipeline.control.puma560_solver.PumaSolver.solve_one` starts from the
        closed-form design inverse and iterates, both compiled, in one call that
        allocates nothing (the result is in the solver's buffers); the same
        solver answers :meth:`solve` (Newton-Raphson, full pose), so one target
        and a batch give the same bits. Made once per branch and kept.
        """
        if branch is None:
            branch = self._default_branch
        solver = self._solvers.get(branch)
        if solver is not None:
            return solver
        if not self._compilable:
            raise ArmsigError(
                f"{self.robot.name}: no compiled real-time solver",
                expected="a Puma 560 signature of six revolute joints and a branch",
                fix="use Controller.solve",
            )
        from pipeline.control import puma560_inverse as pc
        from pipeline.control.puma560_solver import PumaSolver

        solver = PumaSolver(
            self.signature.chain, self.sensor_from_base, self.flange_to_tool,
            self.sensor_from_base, branch, self.resolution, self._limits,
            (pc.PUMA_ELBOW_MARGIN_RAD, pc.PUMA_SHOULDER_MARGIN_CM),
            design=self._design_model(self.sensor_from_base),
            jacobi_margins=(pc.JACOBI_ELBOW_MARGIN_RAD, pc.JACOBI_SHOULDER_MARGIN_CM),
            nongeometric=self.signature.nongeometric,
        )  # fmt: skip
        self._solvers[branch] = solver
        return solver

    def _into_limits(
        self,
        res: IKResult,
        chain: SerialChain,
        T: np.ndarray,
        task_axes: tuple[int, ...] | None = None,
        q_near: np.ndarray | None = None,
    ) -> IKResult:
        """``res`` (joints shifted in place) inside the limits, or marked ``out_of_limits``
        (:func:`pipeline.control.limits.honour_limits`); ``chain``, ``T``: what it solved,
        ``q_near``: from where (None: q^s)."""
        arm = _puma_arm if self.robot.name == "puma560" else None
        near = self._starts(len(T), q_near)
        return honour_limits(
            res, chain, T, self._limits, self.resolution, self._wrist_flips, task_axes, arm, near
        )

    def _solve_task_axes(
        self,
        T_base: np.ndarray,
        branch,
        axes: tuple[int, ...],
        record_history: bool,
        q_near: np.ndarray | None,
    ) -> IKResult:
        """Newton-Raphson on the ``axes`` components of δ, in the design base frame
        (the chain re-based there, so the axes are the base's)."""
        sig = self.signature.chain
        chain = in_frame(sig, self.sensor_from_base)  # the signature in the design base frame
        if self.robot.name == "puma560":
            q0 = self.initial_estimate(self.sensor_from_base @ T_base, branch, q_near)
        else:
            qs = self._starts(T_base.shape[0], q_near)
            q0 = newton_raphson(self._design_model(), T_base, qs, self.resolution,
                                max_iter=100, damping=1e-2, task_axes=axes).q  # fmt: skip
        res = newton_raphson(
            chain, T_base, q0, self.resolution, record_history=record_history, task_axes=axes
        )
        return self._readings(self._into_limits(res, chain, T_base, axes, q_near))


def _puma_arm(q: np.ndarray) -> np.ndarray:
    """The Puma's shoulder and elbow flags (m, 2) of joints (m, 6): what a solution moved
    into the limits keeps (:func:`pipeline.control.limits.honour_limits`)."""
    from pipeline.robots.puma560 import branch_of

    flags: np.ndarray = branch_of(q)[:, :2]
    return flags


#: Sample configurations :func:`task_axes_for` tests the design Jacobian at.
AXES_SAMPLES = 16


def task_axes_for(robot: RobotDescription) -> tuple[int, ...]:
    """The pose components a robot can control, indices into δ = [dx, dy, dz, rx, ry, rz]
    in its design base frame: all six for six or more joints, otherwise those the
    design model moves (:func:`pipeline.kinematics.ik.controllable_axes`), e.g.
    ``(0, 1, 2, 5)`` for a SCARA-like arm whose joint axes are parallel to the base Z."""
    if robot.n_joints >= 6:
        return ALL_AXES
    rng = np.random.default_rng(0)  # fixed: the same robot gets the same axes
    lim = joints_to_internal(robot.limits.T, robot.prismatic).T
    q = rng.uniform(lim[:, 0], lim[:, 1], (AXES_SAMPLES, robot.n_joints))
    return controllable_axes(robot.design_chain(), q)


def solve_poses(
    controller: Controller,
    xyz_cm: np.ndarray,
    rpy_deg: np.ndarray,
    branches: list[str | None] | None = None,
    method: str = "nr",
    near: np.ndarray | None = None,
) -> tuple[np.ndarray, IKResult]:
    """Solve poses given as position (m, 3) cm and fixed-axis rx, ry, rz (m, 3) deg.

    ``near``: start configuration (n,) or one per pose (m, n), in boundary units
    (deg / cm), see :meth:`Controller.solve`'s ``q_near``.
    Returns the joint readings in boundary units (m, n) and the raw result (joint
    values, rad / cm): readings and joint values differ for a coupled robot
    (:class:`~pipeline.robots.description.Coupling`), whose readings go in and come out.
    Targets are grouped by branch so every group is one batched solve. An arm with
    fewer than six joints solves the components it controls (:func:`task_axes_for`).
    """
    from pipeline.kinematics.transforms import transform_from_xyz_rpy
    from pipeline.units import joints_to_boundary

    T = transform_from_xyz_rpy(np.atleast_2d(xyz_cm), np.deg2rad(np.atleast_2d(rpy_deg)))
    m = T.shape[0]
    labels = branches if branches is not None else [None] * m
    axes = task_axes_for(controller.robot)  # arms with < 6 joints: the components they control
    task_axes = None if axes == ALL_AXES else axes
    q_near = None if near is None else np.asarray(near, float)
    if q_near is not None and q_near.shape[-1:] == (controller.robot.n_joints,):
        q_near = controller.robot.joints_from_readings(q_near)
        q_near = joints_to_internal(q_near, controller.robot.prismatic)  # else: _starts says why
    results: dict[str | None, tuple[np.ndarray, IKResult]] = {}
    for label in dict.fromkeys(labels):
        sel = np.array([b == label for b in labels])
        near_sel = q_near[sel] if q_near is not None and q_near.ndim == 2 else q_near
        res = controller.solve(
            T[sel], parse_branch(label), method, task_axes=task_axes, q_near=near_sel
        )
        results[label] = (sel, res)
    n = controller.robot.n_joints
    fields = {
        "q": np.zeros((m, n)),
        "converged": np.zeros(m, bool),
        "iterations": np.zeros(m, int),
        "position_error_cm": np.zeros(m),
        "orientation_error_rad": np.zeros(m),
        "status": np.zeros(m, int),
    }
    changed = np.zeros(m, bool)  # False where a solve had no branch to keep
    for sel, res in results.values():
        for key, arr in fields.items():
            arr[sel] = getattr(res, key)
        if res.branch_changed is not None:
            changed[sel] = res.branch_changed
    out = IKResult(
        q=fields["q"],
        converged=fields["converged"],
        iterations=fields["iterations"],
        position_error_cm=fields["position_error_cm"],
        orientation_error_rad=fields["orientation_error_rad"],
        status=fields["status"],
        task_axes=axes,
        branch_changed=changed,
    )
    q_joint = joints_to_boundary(out.q, controller.robot.prismatic)
    return controller.robot.readings_from_joints(q_joint), out
