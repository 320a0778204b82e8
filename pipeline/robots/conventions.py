"""Robot descriptions as makers give them, brought to armsig's standard D-H form.

Modified D-H (Craig): a joint table with ``mdh = { alpha_deg, a_cm, theta_deg, d_cm }``,
the link ``Rot(x, α_{i-1}) Trans(a_{i-1}, 0, 0) Rot(z, θ_i) Trans(0, 0, d_i)``. The product
of such links regroups exactly into standard ones (``Rot(x, α)`` and ``Trans(a)`` along x
commute): the first row's ``Trans(a_0) Rot(x, α_0)`` joins the base, standard row i takes
θ_i, d_i and the next row's a and α, and the last standard row has a = α = 0.

Fixed rows (``type = "fixed"``, a torso held still): a constant link before the first
moving joint joins the base, one after the last joins the tool; a fixed row between moving
joints is refused in one line (the standard form has no place for it).

Applied to the parsed document before it is checked (:func:`standard_form`), so that the
rest of armsig sees one convention.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from pipeline.errors import RobotDescriptionError

MDH_KEYS = ("alpha_deg", "a_cm", "theta_deg", "d_cm")
FIXED = "fixed"


def _pose_matrix(pose: Any, where: str) -> np.ndarray:
    """A ``[base]`` or ``[tool]`` table's matrix; a malformed one refused in one line."""
    from pipeline.kinematics.transforms import transform_from_xyz_rpy

    pose = {} if pose is None else pose
    try:
        xyz = np.array(pose.get("xyz_cm", [0.0] * 3), float).reshape(3)
        rpy = np.array(pose.get("rpy_deg", [0.0] * 3), float).reshape(3)
    except (AttributeError, TypeError, ValueError):
        raise RobotDescriptionError(
            f"{where}: xyz_cm and rpy_deg must be lists of three numbers", got=repr(pose)[:80]
        ) from None
    if not np.isfinite([*xyz, *rpy]).all():
        raise RobotDescriptionError(f"{where}: a number is not finite", got=repr(pose)[:80])
    return transform_from_xyz_rpy(xyz, np.deg2rad(rpy))


def _pose_dict(T: np.ndarray) -> dict[str, list[float]]:
    from pipeline.kinematics.transforms import xyz_rpy_from_transform

    xyz, rpy = xyz_rpy_from_transform(T)
    return {"xyz_cm": [float(v) for v in xyz], "rpy_deg": [float(v) for v in np.rad2deg(rpy)]}


def _number(row: dict[str, Any], key: str, where: str) -> float:
    v = row.get(key)
    if isinstance(v, bool) or not isinstance(v, int | float) or not np.isfinite(v):
        raise RobotDescriptionError(f"{where}: field {key!r} must be a finite number", got=repr(v))
    return float(v)


def _link(row: dict[str, Any], where: str) -> np.ndarray:
    """A standard D-H row's constant link (cm, the angles in deg)."""
    from pipeline.kinematics.dh import dh_link

    th, d, a, al = (_number(row, k, where) for k in ("theta_deg", "d_cm", "a_cm", "alpha_deg"))
    return dh_link(np.deg2rad(th), d, a, np.deg2rad(al))


def standard_form(data: Any, source: str) -> Any:
    """``data`` (a parsed description) with modified D-H rows turned standard and fixed rows
    folded into the base or the tool; unchanged when it has neither."""
    if not isinstance(data, dict) or not isinstance(data.get("joints"), list):
        return data  # the checks of description_from_dict name what is wrong
    joints = [j for j in data["joints"]]
    tables = [j for j in joints if isinstance(j, dict)]
    mdh = [j for j in tables if "mdh" in j]
    fixed = [j for j in tables if j.get("type") == FIXED]
    if not mdh and not fixed:
        return data
    out = dict(data)
    if mdh:
        if len(mdh) != len(joints) or any("dh" in j for j in mdh):
            raise RobotDescriptionError(
                f"{source}: some joints give mdh (modified D-H) and some dh",
                expected="one convention for every joint: all dh, or all mdh",
                fix="write every row in the same convention",
            )
        joints, base = _from_modified(joints, source)
        out["base"] = _pose_dict(_pose_matrix(data.get("base"), f"{source}: base") @ base)
    moving = [k for k, j in enumerate(joints) if j.get("type") != FIXED]
    if not moving:
        raise RobotDescriptionError(f"{source}: every joint is fixed", expected="a moving joint")
    inner = [
        k for k, j in enumerate(joints) if j.get("type") == FIXED and moving[0] < k < moving[-1]
    ]
    if inner:
        raise RobotDescriptionError(
            f"{source}: joints[{inner[0]}] is fixed between moving joints",
            expected="fixed rows before the first moving joint (base) or after the last (tool)",
            fix="multiply it into the neighbouring rows by hand, or describe the arm without it",
        )
    B = _pose_matrix(out.get("base"), f"{source}: base")
    T = _pose_matrix(out.get("tool"), f"{source}: tool")
    for k in range(moving[0]):
        B = B @ _link(joints[k].get("dh", {}), f"{source}: joints[{k}].dh")
    for k in reversed(range(moving[-1] + 1, len(joints))):
        T = _link(joints[k].get("dh", {}), f"{source}: joints[{k}].dh") @ T
    if fixed:
        out["base"], out["tool"] = _pose_dict(B), _pose_dict(T)
    out["joints"] = [joints[k] for k in moving]
    return out


def _from_modified(
    joints: list[dict[str, Any]], source: str
) -> tuple[list[dict[str, Any]], np.ndarray]:
    """Standard rows of modified ones (module docstring) and the base's extra factor."""
    from pipeline.kinematics.transforms import rot_x, trans_x

    rows = []
    for k, j in enumerate(joints):
        m = j["mdh"]
        if not isinstance(m, dict) or sorted(m) != sorted(MDH_KEYS):
            raise RobotDescriptionError(
                f"{source}: joints[{k}].mdh", expected="the keys " + ", ".join(MDH_KEYS),
                got=repr(m)[:80],
            )  # fmt: skip
        rows.append({key: _number(m, key, f"{source}: joints[{k}].mdh") for key in MDH_KEYS})
    out = []
    for k, j in enumerate(joints):
        nxt = rows[k + 1] if k + 1 < len(rows) else {"a_cm": 0.0, "alpha_deg": 0.0}
        std = {"theta_deg": rows[k]["theta_deg"], "d_cm": rows[k]["d_cm"],
               "a_cm": nxt["a_cm"], "alpha_deg": nxt["alpha_deg"]}  # fmt: skip
        out.append({**{key: v for key, v in j.items() if key != "mdh"}, "dh": std})
    base = trans_x(rows[0]["a_cm"]) @ rot_x(np.deg2rad(rows[0]["alpha_deg"]))
    return out, base
