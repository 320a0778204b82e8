"""True D-H parameters of prismatic joints (4.61)-(4.73): exact, a_i = 0, batched."""

import numpy as np
import pytest

from pipeline.kinematics.chain import SerialChain, forward_kinematics, link_frames
from pipeline.kinematics.signature import (
    chain_from_pseudo_dh,
    pseudo_dh_from_chain,
    signature_chain,
)
from pipeline.kinematics.transforms import pose_error, rot_z, trans
from pipeline.kinematics.true_dh import true_dh_from_chain
from pipeline.robots import get_robot
from tests.conftest import random_rigid

PATTERNS = ["RRPRRR", "PRRR", "RPPR", "PPP", "RRRP", "PRP", "P", "RPR"]


def _random_chain(
    rng: np.random.Generator, pattern: str, batch: tuple[int, ...] = ()
) -> SerialChain:
    n = len(pattern)
    m = int(np.prod(batch, dtype=int))
    return SerialChain(
        links=random_rigid(rng, m * n, 30.0).reshape(*batch, n, 4, 4),
        prismatic=np.array([c == "P" for c in pattern]),
        base=random_rigid(rng, m).reshape(*batch, 4, 4),
        tool=random_rigid(rng, m, 10.0).reshape(*batch, 4, 4),
        joint_offsets=rng.normal(0, 1, n),
    )


@pytest.mark.parametrize("pattern", PATTERNS)
def test_true_dh_reproduces_chain_with_a_zero(rng: np.random.Generator, pattern: str) -> None:
    chain = _random_chain(rng, pattern)
    pris = chain.prismatic
    t = true_dh_from_chain(chain)
    q = rng.normal(0, 1, (300, len(pattern))) * np.where(pris, 40.0, 2.0)
    dp, dth = pose_error(
        forward_kinematics(chain, q), forward_kinematics(chain_from_pseudo_dh(t, pris), q)
    )
    # Products of ~10 transforms with 30-100 cm offsets: rounding ~1e-13 cm.
    assert dp.max() < 1e-9 and dth.max() < 1e-12
    assert np.all(t.a[pris] == 0.0)  # by construction, not by rounding
    assert np.all(pseudo_dh_from_chain(chain).a[pris] != 0.0)  # the modified model has a_i ≠ 0
    for k in np.flatnonzero(pris):
        if k > 0:  # S_{i-1} relocated onto the D-H frame T_{i-1}: γ_{i-1} = b_{i-1} = 0
            # (exactly, or to rounding when joint i-1 is prismatic too and γ_{i-1} is recomputed)
            assert abs(t.smodel.gamma[k - 1]) < 1e-12 and t.smodel.b[k - 1] == 0.0
        if k + 1 < len(pattern) and not pris[k + 1]:  # b_i = −d̄_{i+1}, so d_{i+1} = 0
            assert abs(t.d[k + 1]) < 1e-12


def test_revolute_chain_true_equals_modified(rng: np.random.Generator) -> None:
    chain = _random_chain(rng, "RRRRRR")
    t, m = true_dh_from_chain(chain), pseudo_dh_from_chain(chain)
    for name in ("q_offset", "d", "a", "alpha", "base", "tool"):
        np.testing.assert_array_equal(getattr(t, name), getattr(m, name))


@pytest.mark.parametrize("pattern", ["RRPRRR", "PPR"])
def test_batch_equals_loop_of_singles(rng: np.random.Generator, pattern: str) -> None:
    chain = _random_chain(rng, pattern, batch=(2, 3))
    t = true_dh_from_chain(chain)
    for idx in np.ndindex(2, 3):
        single = SerialChain(
            links=chain.links[idx],
            prismatic=chain.prismatic,
            base=chain.base[idx],
            tool=chain.tool[idx],
            joint_offsets=chain.joint_offsets,
        )
        s = true_dh_from_chain(single)
        for name in ("q_offset", "a", "alpha", "base", "tool"):
            np.testing.assert_allclose(getattr(t, name)[idx], getattr(s, name), atol=1e-12)


# Revolute joints whose design d the true D-H model must return: the others sit
# next to parallel axes, where (4.69)/(3.32) move the distance into another d, or
# are the last joint, whose d moves into the tool (S̄_n = S̄_{n-1}).
D_CHECKED = {"stanford": [0, 1, 3, 4], "scara": [0]}


@pytest.mark.parametrize("name", sorted(D_CHECKED))
def test_design_recovered_from_any_line_position(rng: np.random.Generator, name: str) -> None:
    """Ground truth: frames of a design model with each prismatic frame put on an
    arbitrary parallel line (Figure 4-6); the true D-H model is the design's."""
    rob = get_robot(name)
    design, pris, n = rob.design_chain(), rob.prismatic, rob.n_joints
    lim = rob.limits
    for _ in range(5):
        qs = np.where(pris, 1.0, np.pi / 180) * rng.uniform(lim[:, 0], lim[:, 1])
        F = link_frames(design, qs)[:n]
        F = np.concatenate([F, F[-1:]])
        for k in np.flatnonzero(pris):
            F[k] = F[k] @ trans(*rng.normal(0, 20, 3)) @ rot_z(rng.uniform(-3, 3))
        sig = signature_chain(F, qs, pris)
        t, m = true_dh_from_chain(sig), pseudo_dh_from_chain(sig)
        dh = [j.dh for j in rob.joints]
        assert np.all(t.a[pris] == 0.0) and np.all(np.abs(m.a[pris]) > 1e-3)
        # |a| and |α|: the sense of X is a convention (ERRATA: β or its twin 180° away;
        # parallel axes fold β into (-90°, 90°], docs/errata-found.md).
        np.testing.assert_allclose(np.abs(t.a), [abs(r.a_cm) for r in dh], atol=1e-9)
        ks = D_CHECKED[name]
        np.testing.assert_allclose(t.d[ks], [dh[k].d_cm for k in ks], atol=1e-9)
        np.testing.assert_allclose(
            np.abs(np.degrees(t.alpha)), [abs(r.alpha_deg) for r in dh], atol=1e-9
        )
        q = np.where(pris, 30.0, 3.0) * rng.uniform(-1, 1, (50, n))
        dp, dth = pose_error(
            forward_kinematics(chain_from_pseudo_dh(m, pris), q),
            forward_kinematics(chain_from_pseudo_dh(t, pris), q),
        )
        assert dp.max() < 1e-9 and dth.max() < 1e-9


def test_stanford_boom_offset_is_the_design_one(rng: np.random.Generator) -> None:
    """(4.73): the Stanford design's d_3 equals the boom reading, so its offset is 0."""
    rob = get_robot("stanford")
    pris = rob.prismatic
    qs = np.where(pris, 75.0, np.deg2rad(rng.uniform(-60, 60, 6)))
    F = link_frames(rob.design_chain(), qs)[:6]
    F = np.concatenate([F, F[-1:]])
    F[2] = F[2] @ trans(4.0, -3.0, 12.0)
    t = true_dh_from_chain(signature_chain(F, qs, pris))
    assert abs(t.q_offset[2]) < 1e-9
