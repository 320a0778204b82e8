"""What an export of a signature with non-geometric terms holds: the best rigid chain.

URDF, the D-H tables, the chain JSON and ``--onto`` state a rigid chain. For a signature
with non-geometric terms they hold the rigid chain that best reproduces the whole
signature at the tool point over :data:`FIT_CONFIGURATIONS` uniform readings within the
joint limits (:func:`pipeline.refine.rigid.best_rigid_chain`, gravity and payload as
identified), or over the configurations a user gives (``export --over FILE``: where the
robot works, e.g. its program's), and state what the file still loses against it
(:class:`RigidLoss`). The parameters the session's own fit held (its ``refine`` table)
stay held. A rigid signature is exported as it is.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np

from pipeline.errors import ArmsigError
from pipeline.signature.file import Signature
from pipeline.units import joints_to_internal

#: Uniform readings the rigid chain is fitted over (seed :data:`FIT_SEED`): the loss over
#: the whole joint range; 27 parameters of a 6-joint arm against 15,000 coordinates, so
#: the loss on another sample of this size differs by ~1e-3 of itself (measured: UR10).
FIT_CONFIGURATIONS = 5000
FIT_SEED = 43
MM_PER_CM = 10.0


@dataclass(frozen=True)
class RigidLoss:
    """What the exported rigid chain loses against the whole signature at the tool point
    (mm) over ``configurations`` readings within the joint limits; ``signature_rigid_*``:
    what the signature's own rigid part alone (the terms left out) would lose there."""

    configurations: int
    over: str  # "the joint limits", or the --over file
    rms_mm: float
    max_mm: float
    signature_rigid_rms_mm: float
    signature_rigid_max_mm: float
    held: tuple[str, ...]  # parameters kept at the signature's values

    def to_dict(self) -> dict[str, Any]:
        return asdict(self)

    def text(self, what: str) -> str:
        """The warning's clause: ``what`` (``the URDF``) and the loss."""
        return (
            f"{what} holds the rigid chain nearest the whole signature: it loses "
            f"{self.rms_mm:.3f} mm RMS, {self.max_mm:.3f} mm max at the tool point over "
            f"{self.configurations:,} configurations {self.over} (the "
            f"signature's rigid part alone: {self.signature_rigid_rms_mm:.3f} mm RMS, "
            f"{self.signature_rigid_max_mm:.3f} mm max)"
        )


def fit_readings(sig: Signature) -> np.ndarray:
    """The :data:`FIT_CONFIGURATIONS` readings (rad / cm) the rigid chain is fitted over."""
    lim = sig.robot.limits
    rng = np.random.default_rng(FIT_SEED)
    q = rng.uniform(lim[:, 0], lim[:, 1], (FIT_CONFIGURATIONS, len(lim)))
    return joints_to_internal(q, sig.prismatic)


def session_held(session_dir: Path) -> tuple[str, ...]:
    """The parameters the session's fit held (its ``refine`` table's summary), () without
    one."""
    from pipeline.stages.refine import refine_summary
    from pipeline.stages.runner import stage_path
    from pipeline.stages.tables import read_table

    path = stage_path(session_dir, "refine")
    if not path.is_file():
        return ()
    ident = refine_summary(read_table(path)).get("identifiability", {})
    return tuple(str(h["name"]) for h in ident.get("held", []))


def over_readings(sig: Signature, over: str | Path) -> np.ndarray:
    """The readings (rad / cm) of an ``--over`` file (``fk --q-file``'s format: q1_deg,
    ...); one line when it has too few to fix the chain (the refinement's own rule)."""
    from pipeline.control.targets import read_joints
    from pipeline.refine.identifiability import poses_needed

    _, q = read_joints(over, sig.robot, "--over")
    need = poses_needed(int(np.where(sig.prismatic, 2, 4).sum()) + 3)
    if len(q) < need:
        raise ArmsigError(
            f"--over {over}: {len(q)} configurations cannot fix the rigid chain",
            expected=f"at least {need} configurations spread over the joint ranges",
            got=str(len(q)),
            fix="give more configurations, or leave --over out (the joint limits)",
        )
    return joints_to_internal(q, sig.prismatic)


def rigid_signature(
    sig: Signature, session_dir: Path, over: str | Path | None = None
) -> tuple[Signature, RigidLoss | None]:
    """``sig`` as a rigid file holds it: itself when it has no non-geometric terms (and no
    loss), else the best rigid chain (module docstring) over the joint limits or the
    ``over`` file's configurations, without terms, and its loss."""
    if sig.nongeometric is None:
        return sig, None
    from pipeline.refine.rigid import best_rigid_chain

    q = fit_readings(sig) if over is None else over_readings(sig, over)
    fit = best_rigid_chain(sig.chain, sig.nongeometric, q, session_held(session_dir))
    if fit.status != "converged":
        raise RuntimeError(f"the best rigid chain did not converge: {fit.status}")  # a bug
    loss = RigidLoss(
        len(q),
        "within the joint limits" if over is None else f"of {Path(over).name}",
        fit.rms_cm * MM_PER_CM,
        fit.max_cm * MM_PER_CM,
        float(np.sqrt(np.mean(fit.rigid_errors_cm**2))) * MM_PER_CM,
        float(fit.rigid_errors_cm.max()) * MM_PER_CM,
        fit.held,
    )
    return replace(sig, chain=fit.chain, nongeometric=None), loss
