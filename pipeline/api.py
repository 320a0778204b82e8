"""armsig in Python: a session's signature as one object (issue 43; docs/api.md).

::

    import armsig

    arm = armsig.load("sessions/robot3")      # refused in one line when missing or stale
    T = arm.fk([10, -80, 100, 5, 20, 30])     # (4, 4), cm, the robot's base frame
    q = arm.ik(T)                             # the readings that reach it, deg / cm
    model = arm.pinocchio_model()             # pinocchio.Model, SI: the rigid chain

``fk`` and ``ik`` are the whole signature, what ``pipeline fk`` and ``pipeline ik`` give
(:class:`pipeline.control.controller.Controller`): the signature's non-geometric terms
(the sidecar of an export) applied, the joint limits honoured, the readings of a coupled
robot in and out. ``pinocchio_model`` is what a rigid file can hold: the URDF export's
chain (for a signature with terms the rigid chain nearest it, :mod:`pipeline.export.rigid`,
its loss in :attr:`Arm.rigid_loss`), built by pinocchio from the URDF text; its frames
``tool``, ``tool0`` and ``flange`` are the export's. Units: deg / cm at this boundary as at
every other, SI inside pinocchio.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property
from pathlib import Path
from typing import Any

import numpy as np

from pipeline.control.controller import Controller, solve_poses
from pipeline.control.session import session_controller
from pipeline.errors import ArmsigError
from pipeline.export.rigid import RigidLoss


@dataclass(frozen=True)
class Arm:
    """An identified session's signature (:func:`load`)."""

    session: Path
    controller: Controller

    @property
    def joint_names(self) -> list[str]:
        return [j.name for j in self.controller.robot.joints]

    def fk(self, q: Any, frame: str = "design-base") -> np.ndarray:
        """The tool's pose (4, 4), cm, at readings ``q`` (n,) deg / cm, or poses (m, 4, 4)
        of readings (m, n); ``frame``: ``design-base`` (the robot's base, what :meth:`ik`
        takes) or ``sensor`` (where the session measured)."""
        qq = np.asarray(q, float)
        T = self.controller.poses(np.atleast_2d(qq), frame=frame).matrix
        out: np.ndarray = T[0] if qq.ndim == 1 else T
        return out

    def ik(self, pose: Any, near: Any = None) -> np.ndarray:
        """The readings (n,) deg / cm that put the tool at ``pose`` (4, 4), cm, in the
        robot's base frame, or readings (m, n) of poses (m, 4, 4); ``near``: where to start
        (deg / cm; default the signature configuration). A pose not reached is refused in
        one line naming it and why."""
        from pipeline.kinematics.ik import STATUS_NAMES
        from pipeline.kinematics.transforms import xyz_rpy_from_transform

        T = np.asarray(pose, float)
        if T.shape[-2:] != (4, 4) or T.ndim not in (2, 3) or not np.isfinite(T).all():
            raise ArmsigError("bad pose", expected="a (4, 4) or (m, 4, 4) matrix, cm",
                              got=f"shape {T.shape}")  # fmt: skip
        xyz, rpy = xyz_rpy_from_transform(T.reshape(-1, 4, 4))
        q, res = solve_poses(self.controller, xyz, np.degrees(rpy), near=near)
        missed = np.flatnonzero(~res.converged)
        if len(missed):
            k = int(missed[0])
            raise ArmsigError(
                f"{len(missed)} of {len(q)} poses not reached (pose {k}: "
                f"{STATUS_NAMES[int(res.status[k])]}, {res.position_error_cm[k]:.3g} cm off)",
                fix="a pose within the workspace, or near= a configuration close to it",
            )
        out: np.ndarray = q[0] if T.ndim == 2 else q
        return out

    @cached_property
    def _rigid(self) -> tuple[Any, RigidLoss | None]:
        from pipeline.export.rigid import rigid_signature

        return rigid_signature(self.controller.signature, self.session)

    @property
    def rigid_loss(self) -> RigidLoss | None:
        """What :meth:`pinocchio_model` loses against :meth:`fk` at the tool point (None:
        a rigid signature, which it holds exactly)."""
        return self._rigid[1]

    def urdf(self) -> str:
        """The URDF text ``pipeline export --format urdf`` writes (SI, the robot's base)."""
        from pipeline.export import export_chain, render

        best = self._rigid[0]
        chain = export_chain(best, False, "design-base")
        return render(best, chain, "urdf", "signature", "design-base")[0]

    def pinocchio_model(self) -> Any:
        """The rigid chain as a ``pinocchio.Model`` (module docstring); its configuration is
        the readings in rad / m. Needs the ``pin`` package."""
        try:
            import pinocchio as pin
        except ImportError as exc:
            raise ArmsigError("pinocchio_model needs pinocchio", fix="pip install pin") from exc
        return pin.buildModelFromXML(self.urdf())


def load(session: str | Path) -> Arm:
    """The signature of an identified session, refused in one line when it is missing or
    does not match the session's stages (as ``pipeline fk`` refuses it)."""
    return Arm(Path(session), session_controller(session))
