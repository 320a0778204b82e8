"""Issue 43, item 4: the Python API, ``armsig.load(session).fk(q) / .ik(pose) /
.pinocchio_model()``, against the command line's own functions and pinocchio."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from test_export import compliant  # noqa: F401  (the fixture, shared)

import armsig
from pipeline.control.session import session_controller
from pipeline.export import export_chain
from pipeline.export.rigid import rigid_signature
from pipeline.kinematics.chain import forward_kinematics
from pipeline.signature.session import load_session_signature


def _readings(arm: armsig.Arm, m: int, seed: int) -> np.ndarray:
    lim = arm.controller.robot.limits
    return np.random.default_rng(seed).uniform(lim[:, 0] * 0.8, lim[:, 1] * 0.8, (m, len(lim)))


def test_fk_is_the_whole_signature_and_ik_inverts_it(compliant) -> None:  # noqa: F811
    d = compliant["terms"]
    arm = armsig.load(d)
    q = _readings(arm, 50, 1)
    T = arm.fk(q)
    ctl = session_controller(d)
    assert np.array_equal(T, ctl.poses(q).matrix)  # pipeline fk's, bit for bit
    assert np.array_equal(arm.fk(q[0]), T[0])
    rigid = session_controller(compliant["rigid"]).poses(q).matrix  # no terms
    assert np.abs(T[:, :3, 3] - rigid[:, :3, 3]).max() > 1e-3  # cm: the terms are applied
    back = arm.fk(arm.ik(T[:10], near=q[:10]))
    np.testing.assert_allclose(back[:, :3, 3], T[:10, :3, 3], rtol=0, atol=1e-6)  # cm
    np.testing.assert_allclose(back[:, :3, :3], T[:10, :3, :3], rtol=0, atol=1e-8)


def test_pinocchio_model_is_the_rigid_export(compliant) -> None:  # noqa: F811
    """A rigid signature: pinocchio's tool = arm.fk to 1e-9 m. With terms: the rigid
    chain nearest the signature (the URDF export's), to 1e-9 m."""
    import pinocchio as pin

    for name in ("rigid", "terms"):
        arm = armsig.load(compliant[name])
        model = arm.pinocchio_model()
        data = model.createData()
        frame = model.getFrameId("tool")
        q = _readings(arm, 200, 2)
        P = np.empty((len(q), 3))
        for k, qk in enumerate(np.radians(q)):
            pin.framesForwardKinematics(model, data, qk)
            P[k] = data.oMf[frame].translation * 100
        err = np.linalg.norm(P - arm.fk(q)[:, :3, 3], axis=1)
        if name == "rigid":
            assert arm.rigid_loss is None and err.max() < 1e-7, err.max()  # cm
        else:
            loss = arm.rigid_loss
            assert loss is not None and loss.rms_mm > 0.05
            sig = load_session_signature(compliant[name] / "signature.json")
            assert sig.nongeometric is not None  # the URDF's chain is not the signature's
            own = forward_kinematics(sig.chain, np.radians(q))[:, :3, 3]
            assert np.abs(own - P).max() > 1e-4  # cm: not the signature's rigid part
            best = export_chain(rigid_signature(sig, compliant[name])[0], False, "design-base")
            near = forward_kinematics(best, np.radians(q))[:, :3, 3]
            assert np.abs(near - P).max() < 1e-7  # cm: the nearest rigid chain, to 1e-9 m


def test_bad_input_is_one_line(compliant, tmp_path: Path) -> None:  # noqa: F811
    with pytest.raises(armsig.ArmsigError) as e:
        armsig.load(tmp_path)
    assert "\n" not in str(e.value)
    arm = armsig.load(compliant["rigid"])
    with pytest.raises(armsig.ArmsigError, match="bad pose"):
        arm.ik(np.eye(3))
    far = np.eye(4)
    far[:3, 3] = [1000.0, 0.0, 0.0]  # 10 m away
    with pytest.raises(armsig.ArmsigError, match="1 of 1 poses not reached"):
        arm.ik(far)
