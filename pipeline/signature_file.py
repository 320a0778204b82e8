"""The arm signature file ``sessions/NAME/signature.json`` (format in schemas/signature.md).

Written from the stage tables at the end of ``identify``; read by controllers.
"""

from __future__ import annotations

import datetime as dt
import json
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from pipeline import __version__
from pipeline.atomic import write_text_atomic
from pipeline.errors import ArmsigError
from pipeline.kinematics.alignment import fit_alignment
from pipeline.kinematics.chain import SerialChain, forward_kinematics
from pipeline.kinematics.signature import pseudo_dh_from_chain
from pipeline.kinematics.transforms import pose_error
from pipeline.robots.description import (
    RobotDescription,
    description_from_dict,
    description_to_dict,
)
from pipeline.stages.frames import chain_from_frames
from pipeline.stages.runner import stage_path, stages
from pipeline.stages.session import session_robot
from pipeline.stages.tables import read_provenance, read_table
from pipeline.units import joints_to_boundary, joints_to_internal

FORMAT = "armsig.signature"
#: 3: the design alignment stays put along symmetries of the design model
#: (:mod:`pipeline.kinematics.alignment`); files of format 2 are rewritten on identify.
FORMAT_VERSION = 3
ALIGNMENT_SAMPLES = 500


def design_alignment(
    signature_chain: SerialChain, robot: RobotDescription, samples: int = ALIGNMENT_SAMPLES
) -> tuple[np.ndarray, np.ndarray, float]:
    """Base ``X`` and tool ``Y`` with ``F_s(q) ≈ X · F_d(q) · Y``, and the RMS misfit (cm).

    Uses only the signature and the design model (random configurations within
    the joint limits, fixed seed): no ground truth.
    """
    rng = np.random.default_rng(0)  # fixed: the same signature gives the same file
    lim = robot.limits
    q = joints_to_internal(
        rng.uniform(lim[:, 0], lim[:, 1], (samples, robot.n_joints)), robot.prismatic
    )
    T_s = forward_kinematics(signature_chain, q)
    T_d = forward_kinematics(robot.design_chain(), q)
    X, Y = fit_alignment(T_s, T_d)
    dp, _ = pose_error(T_s, X @ T_d @ Y)
    return X, Y, float(np.sqrt(np.mean(dp**2)))


def _m(T: np.ndarray) -> list[list[float]]:
    return [[float(v) for v in row] for row in T]


def signature_document(
    session_dir: Path, hashes: dict[str, str | None] | None = None
) -> dict[str, Any]:
    """The signature as a JSON-ready dict, built from the session's stage tables.

    ``hashes`` are the stage content hashes when the caller already has them.
    """
    session = read_table(stage_path(session_dir, "session"))
    robot = session_robot(session)
    pris = robot.prismatic
    chain = chain_from_frames(read_table(stage_path(session_dir, "frames")), pris)
    pdh = pseudo_dh_from_chain(chain)
    X, Y, misfit = design_alignment(chain, robot)
    sm = pdh.smodel
    qs = joints_to_boundary(chain.joint_offsets, pris)
    off = joints_to_boundary(pdh.q_offset, pris)
    features = read_table(stage_path(session_dir, "features")).to_pylist()
    pseudo = []
    for i, j in enumerate(robot.joints):
        if j.prismatic:
            pseudo.append(
                {
                    "type": "prismatic",
                    "q_offset_cm": float(off[i]),
                    "theta_deg": float(np.degrees(pdh.theta[i])),
                    "a_cm": float(pdh.a[i]),
                    "alpha_deg": float(np.degrees(pdh.alpha[i])),
                }
            )
        else:
            pseudo.append(
                {
                    "type": "revolute",
                    "q_offset_deg": float(off[i]),
                    "d_cm": float(pdh.d[i]),
                    "a_cm": float(pdh.a[i]),
                    "alpha_deg": float(np.degrees(pdh.alpha[i])),
                }
            )
    return {
        "format": FORMAT,
        "format_version": FORMAT_VERSION,
        "robot": robot.name,
        "session": session_dir.name,
        "frame": "sensor",
        "length_unit": "cm",
        "angle_unit": "deg",
        "joint_names": [j.name for j in robot.joints],
        "joint_types": [j.type for j in robot.joints],
        "joint_limits": robot.limits.tolist(),
        "encoder_resolution": robot.encoder_resolution.tolist(),
        "signature_configuration": [float(v) for v in qs],
        "smodel": {
            "base": _m(chain.base),
            "links": [_m(B) for B in chain.links],
            "tool": _m(chain.tool),
            "parameters": [
                {
                    "beta_deg": float(np.degrees(sm.beta[i])),
                    "d_bar_cm": float(sm.d_bar[i]),
                    "a_bar_cm": float(sm.a_bar[i]),
                    "alpha_bar_deg": float(np.degrees(sm.alpha_bar[i])),
                    "gamma_deg": float(np.degrees(sm.gamma[i])),
                    "b_cm": float(sm.b[i]),
                }
                for i in range(robot.n_joints)
            ],
        },
        "pseudo_dh": pseudo,
        "design_alignment": {
            "sensor_from_design_base": _m(X),
            "design_flange_to_signature_tool": _m(Y),
            "rms_misfit_cm": misfit,
        },
        "robot_description": description_to_dict(robot),
        "pseudo_dh_base": _m(pdh.base),
        "pseudo_dh_tool": _m(pdh.tool),
        "feature_accuracy": [
            {
                k: f[k]
                for k in (
                    "joint",
                    "n_points",
                    "sweep_deg",
                    "travel_cm",
                    "radius_cm",
                    "sigma_normal_cm",
                    "sigma_radial_cm",
                    "sigma_delta_deg",
                    "sigma_c_cm",
                    "methods_angle_deg",
                )
            }
            for f in features
        ],
        "warnings": [f"joint {f['joint']}: {w}" for f in features for w in f["warnings"]],
        "provenance": {
            "recording_sha256": session.column("recording_sha256")[0].as_py(),
            "stages": hashes if hashes is not None else stage_hashes(session_dir),
            "package_version": __version__,
            "created": dt.datetime.now(dt.UTC).isoformat(timespec="seconds"),
        },
    }


def stage_hashes(session_dir: Path) -> dict[str, str | None]:
    """Content hash of every committed stage output."""
    return {
        s.name: read_provenance(stage_path(session_dir, s.name)).get("content_hash")
        for s in stages()
    }


def write_signature(session_dir: str | Path) -> tuple[Path, dict[str, Any]]:
    """Write ``signature.json`` beside the recording (atomically); return it and its document.

    An existing file built from the same stage outputs is kept as it is, so a
    warm run changes nothing on disk.
    """
    sdir = Path(session_dir)
    path = sdir / "signature.json"
    current = stage_hashes(sdir)
    try:
        old = json.loads(path.read_text())
        if old.get("format_version") == FORMAT_VERSION and old["provenance"]["stages"] == current:
            return path, old
    except (OSError, ValueError, KeyError, TypeError):
        pass
    doc = signature_document(sdir, current)
    write_text_atomic(path, json.dumps(doc, indent=1) + "\n")
    return path, doc


@dataclass(frozen=True)
class Signature:
    """A loaded signature.

    ``chain``: the S-Model chain (sensor frame, encoder readings in rad / cm);
    ``robot``: the design robot description; ``sensor_from_design_base`` and
    ``design_flange_to_tool``: the design alignment X, Y (4, 4) of the file.
    """

    robot: RobotDescription
    chain: SerialChain
    sensor_from_design_base: np.ndarray
    design_flange_to_tool: np.ndarray

    @property
    def prismatic(self) -> np.ndarray:
        return self.robot.prismatic


def load_signature(path: str | Path) -> Signature:
    """Read a signature file; a clear error for a missing, foreign or broken file."""
    p = Path(path)
    try:
        doc = json.loads(p.read_text(encoding="utf-8"))
    except (OSError, json.JSONDecodeError) as exc:
        raise ArmsigError(
            f"cannot read signature {p}",
            got=str(exc),
            fix="run `pipeline identify SESSION` to write it",
        ) from exc
    if doc.get("format") != FORMAT:
        raise ArmsigError(
            f"{p}: not an armsig signature", expected=FORMAT, got=repr(doc.get("format"))
        )
    try:
        robot = description_from_dict(doc["robot_description"], source=str(p))
        sm = doc["smodel"]
        al = doc["design_alignment"]
        chain = SerialChain(
            links=np.array(sm["links"], float),
            prismatic=robot.prismatic,
            base=np.array(sm["base"], float),
            tool=np.array(sm["tool"], float),
            joint_offsets=joints_to_internal(
                np.array(doc["signature_configuration"], float), robot.prismatic
            ),
        )
        return Signature(
            robot,
            chain,
            np.array(al["sensor_from_design_base"], float),
            np.array(al["design_flange_to_signature_tool"], float),
        )
    except (KeyError, ValueError, TypeError) as exc:
        raise ArmsigError(
            f"{p}: signature is incomplete",
            got=f"{type(exc).__name__}: {exc}",
            fix="re-run `pipeline identify` on its session",
        ) from exc
