"""Batched numerical inverse kinematics (Chapter 5): Newton-Raphson (5.4), Jacobi (5.8).

The "signature" is the Puma 560 simulator model (7.1)-(7.8) with manufacturing
errors ε drawn per category (σ_p = 0.03 cm, σ_o = 0.03°, σ_e = 0.3°); targets
are ``T* = F_s(q_true)`` with ``q_true`` uniform inside the joint limits.
"""

import time

import numpy as np
import pytest

from pipeline.control import puma560_inverse as pc
from pipeline.control.puma560_inverse import puma_design_inverse
from pipeline.errors import KinematicsError
from pipeline.kinematics import ik
from pipeline.kinematics.chain import forward_kinematics
from pipeline.kinematics.ik.jacobi import _anderson
from pipeline.robots import get_robot
from pipeline.robots import puma560 as P

PUMA = get_robot("puma560")
DESIGN = PUMA.design_chain()
RES = np.deg2rad(PUMA.encoder_resolution)  # 0.005° = 8.7e-5 rad per count
LIM = np.deg2rad(PUMA.limits)
# Accuracy demanded of a converged solve (the brief): 1e-6 cm and 1e-7°.
POS_TOL_CM = 1e-6
ROT_TOL_RAD = np.deg2rad(1e-7)
N_TARGETS = 10_000
SEED = 20261122  # the conftest `rng` seed, for the module-scoped fixture
A2, A3, D4 = P.DESIGN_A_CM[1], P.DESIGN_A_CM[2], P.DESIGN_D_CM[3]
FLAGS_TABLE = np.array([[b.shoulder, b.elbow, b.wrist] for b in P.BRANCHES])


def _eps(rng, sigma_p=0.03, sigma_o_deg=0.03, sigma_e_deg=0.3):
    """ε (39,) in cm / rad: N(0, σ) per category of ERRATA.md (1-based indices)."""
    eps = np.zeros(P.N_EPS)
    for idx, sigma in (
        (P.EPS_POSITIONAL, sigma_p),
        (P.EPS_ORIENTATIONAL, np.deg2rad(sigma_o_deg)),
        (P.EPS_ENCODER, np.deg2rad(sigma_e_deg)),
    ):
        i = np.array(idx) - 1
        eps[i] = rng.normal(0.0, sigma, i.size)
    return eps


def _design_start(T, flags):
    """Section 5.2: q0 = closed-form design inverse on each target's branch (m, 6)."""
    q0 = np.zeros((len(T), 6))
    for b in P.BRANCHES:
        sel = np.all(flags == [b.shoulder, b.elbow, b.wrist], axis=-1)
        if sel.any():
            q0[sel] = puma_design_inverse(b)(T[sel], np.zeros((sel.sum(), 6)))
    return q0


def _margins(q):
    """Distance of configurations (m, 6) from the Puma's three singularities.

    Returns wrist |θ5| folded to [0°, 90°], elbow angle from stretched/folded in
    degrees, and the wrist centre's reach from the shoulder axis in cm (design
    geometry, as :func:`pipeline.robots.puma560.branch_of`).
    """
    wrist = np.rad2deg(np.arcsin(np.abs(np.sin(q[:, 4]))))
    elbow = np.rad2deg(np.arcsin(np.abs(np.cos(q[:, 2] + np.arctan2(A3, D4)))))
    s23, c23 = np.sin(q[:, 1] + q[:, 2]), np.cos(q[:, 1] + q[:, 2])
    shoulder = np.abs(D4 * s23 + A3 * c23 + A2 * np.cos(q[:, 1]))
    return wrist, elbow, shoulder


def _good(result, flags):
    """Converged, within the accuracy demanded, and on the branch of q_true."""
    return (
        result.converged
        & (result.position_error_cm <= POS_TOL_CM)
        & (result.orientation_error_rad <= ROT_TOL_RAD)
        & np.all(P.branch_of(result.q) == flags, axis=-1)
    )


@pytest.fixture(scope="module")
def batch():
    """10,000 targets of one realistic signature, solved by both methods (timed)."""
    rng = np.random.default_rng(SEED)
    sig = P.simulator_chain(_eps(rng))
    q_true = rng.uniform(LIM[:, 0], LIM[:, 1], (N_TARGETS, 6))
    T = forward_kinematics(sig, q_true)
    flags = P.branch_of(q_true)
    t0 = time.perf_counter()
    q0 = _design_start(T, flags)
    nr = ik.newton_raphson(sig, T, q0, RES)
    t1 = time.perf_counter()
    inverse = puma_design_inverse(
        elbow_margin_rad=pc.JACOBI_ELBOW_MARGIN_RAD, shoulder_margin_cm=pc.JACOBI_SHOULDER_MARGIN_CM
    )
    ji = ik.jacobi_iterative(sig, DESIGN, inverse, T, q0, RES)
    t2 = time.perf_counter()
    ji_plain = ik.jacobi_iterative(sig, DESIGN, inverse, T, q0, RES, accelerate=False)
    wrist, elbow, shoulder = _margins(q_true)
    # Away from singularities: 2° from the wrist and 2 cm from the shoulder
    # singularity, 10° from the stretched/folded elbow (89 % of uniform targets).
    # Closer, 0.5 cm of model error moves the solution by up to tens of degrees
    # (the elbow's reach is quadratic in its angle), so the design start is far
    # and Newton needs more than four iterations (Section 5.2: planners avoid
    # such near-degenerate configurations).
    regular = (wrist >= 2.0) & (elbow >= 10.0) & (shoulder >= 2.0)
    return dict(
        sig=sig, q_true=q_true, T=T, flags=flags, q0=q0, nr=nr, ji=ji, ji_plain=ji_plain,
        t_nr=t1 - t0, t_ji=t2 - t1, regular=regular,
        wrist=wrist, elbow=elbow, shoulder=shoulder,
    )  # fmt: skip


def test_10k_outputs_finite_and_statuses_consistent(batch) -> None:
    for r in (batch["nr"], batch["ji"]):
        for a in (r.q, r.position_error_cm, r.orientation_error_rad):
            assert np.isfinite(a).all()
        assert set(np.unique(r.status)) <= set(ik.STATUS_NAMES)
        np.testing.assert_array_equal(r.converged, r.status == ik.STATUS_CONVERGED)
        # Every converged target meets the accuracy demanded, not just most.
        assert r.position_error_cm[r.converged].max() <= POS_TOL_CM
        assert r.orientation_error_rad[r.converged].max() <= ROT_TOL_RAD
    assert batch["t_nr"] + batch["t_ji"] < 20.0  # s, the budget for both 10k solves


def test_10k_newton_raphson(batch) -> None:
    nr, regular = batch["nr"], batch["regular"]
    good = _good(nr, batch["flags"])
    assert good[regular].mean() >= 0.999
    assert good.mean() >= 0.998  # all targets, singular neighbourhoods included
    fast = good & (nr.iterations <= 4)  # Section 5.2/5.4: "3-4 iterations"
    assert fast[regular].mean() >= 0.99
    assert fast.mean() >= 0.95
    # The failures are all next to a singularity.
    bad = ~good
    near = (batch["wrist"] < 5.0) | (batch["elbow"] < 10.0) | (batch["shoulder"] < 5.0)
    assert near[bad].all()


def test_10k_jacobi(batch) -> None:
    ji, regular = batch["ji"], batch["regular"]
    good = _good(ji, batch["flags"])
    assert good[regular].mean() >= 0.999
    assert (good & (ji.iterations <= 12))[regular].mean() >= 0.999
    # Issue 5's acceptance on all targets. Near singularities the plain map
    # (5.8) stops contracting (the design inverse amplifies the model mismatch
    # by ~1/σ_min): measured 0.55 % failures without acceleration, all next to a
    # singularity; Anderson acceleration of the same map rescues most of them.
    assert good.mean() >= 0.999
    plain = _good(batch["ji_plain"], batch["flags"])
    assert 0.985 <= plain.mean() < good.mean()
    bad = ~plain
    near = (batch["wrist"] < 5.0) | (batch["elbow"] < 10.0) | (batch["shoulder"] < 5.0)
    assert near[bad].all()
    # Where (5.8) contracts, the accelerated solver is the plain iteration.
    same = batch["ji_plain"].iterations == ji.iterations
    assert same[regular].mean() >= 0.99
    # Linear (Jacobi) against quadratic (Newton) convergence, Tables 5-1/5-2.
    both = good & _good(batch["nr"], batch["flags"])
    assert np.median(ji.iterations[both]) > np.median(batch["nr"].iterations[both])


def test_encoder_rule_alone_is_not_accurate_enough(batch) -> None:
    # Appendix C.1 step 8 without the pose tolerance: steps below one encoder
    # count still leave errors above 1e-7° (Newton) and far above (Jacobi).
    sel = batch["regular"]
    args = (batch["T"][sel], batch["q0"][sel], RES)
    kw = dict(position_tol_cm=None, orientation_tol_rad=None)
    nr = ik.newton_raphson(batch["sig"], *args, **kw)
    ji = ik.jacobi_iterative(batch["sig"], DESIGN, puma_design_inverse(), *args, **kw)
    assert nr.converged.mean() >= 0.999 and ji.converged.mean() >= 0.999
    assert nr.orientation_error_rad[nr.converged].max() > ROT_TOL_RAD
    # The rule tests the Newton increment J⁻¹δ, not a shortened safeguard step:
    # a Newton step below one count leaves ~|J|·res² ≈ 1e-6 cm at most.
    assert nr.position_error_cm[nr.converged].max() < 1e-5
    assert ji.position_error_cm[ji.converged].max() > 10 * POS_TOL_CM
    # ... and the defaults cost Newton at most one polishing iteration.
    both = nr.converged & batch["nr"].converged[sel]
    assert (batch["nr"].iterations[sel][both] - nr.iterations[both] <= 1).all()


def test_noiseless_round_trip(rng) -> None:
    # Signature == design: IK of FK(q) returns q.
    q = rng.uniform(LIM[:, 0], LIM[:, 1], (1000, 6))
    T = forward_kinematics(DESIGN, q)
    q0 = _design_start(T, P.branch_of(q))
    nr = ik.newton_raphson(DESIGN, T, q0, RES)
    ji = ik.jacobi_iterative(DESIGN, DESIGN, puma_design_inverse(), T, q0, RES)
    for r in (nr, ji):
        assert r.converged.all()
        np.testing.assert_allclose(P.wrap_angle(r.q - q), 0.0, atol=1e-9)
    # The design start is already exact: one step, below one count, ends it.
    assert (nr.iterations == 1).all() and (ji.iterations == 1).all()


def test_noiseless_from_perturbed_start(rng) -> None:
    # Starting 0.02 rad (~230 counts) off, both methods must actually iterate.
    q = rng.uniform(LIM[:, 0], LIM[:, 1], (2000, 6))
    q0 = q + rng.normal(0.0, 0.02, q.shape)
    # Keep starts on the branch of q and away from singularities, where a 1°
    # perturbation may legitimately lead to another solution.
    wrist, elbow, shoulder = _margins(q)
    keep = np.all(P.branch_of(q0) == P.branch_of(q), axis=-1)
    keep &= (wrist >= 2.0) & (elbow >= 10.0) & (shoulder >= 2.0)
    q, q0 = q[keep], q0[keep]
    T = forward_kinematics(DESIGN, q)
    # Joint accuracy ≈ pose tolerance / (arm length · conditioning): the default
    # 1e-7 cm gives ~1e-8 rad here, so ask for 1e-9 cm / 1e-11 rad to get 1e-9 rad.
    tight = dict(position_tol_cm=1e-9, orientation_tol_rad=1e-11)
    nr = ik.newton_raphson(DESIGN, T, q0, RES, **tight)
    ji = ik.jacobi_iterative(DESIGN, DESIGN, puma_design_inverse(), T, q0, RES, **tight)
    for r in (nr, ji):
        assert r.converged.all()
        np.testing.assert_allclose(P.wrap_angle(r.q - q), 0.0, atol=1e-9)
    assert (nr.iterations >= 3).all()  # quadratic from 1e-2 rad: 1e-4, 1e-8, done
    # Jacobi with F_s = F_d is exact after one step (T^0 = T*), plus the check.
    assert (ji.iterations == 2).all()


@pytest.mark.parametrize("method", ["nr", "ji"])
def test_batch_equals_loop(rng, monkeypatch, method) -> None:
    import pipeline.kinematics.chain as chain_module

    monkeypatch.setattr(chain_module, "SOA_BLOCK", 8)  # the batch in blocks, as 100,000 are
    sig = P.simulator_chain(_eps(rng))
    q = rng.uniform(LIM[:, 0], LIM[:, 1], (25, 6))
    T = forward_kinematics(sig, q)
    q0 = _design_start(T, P.branch_of(q))

    def solve(Tk, q0k):
        if method == "nr":
            return ik.newton_raphson(sig, Tk, q0k, RES)
        return ik.jacobi_iterative(sig, DESIGN, puma_design_inverse(), Tk, q0k, RES)

    whole = solve(T, q0)
    singles = [solve(T[k], q0[k]) for k in range(len(q))]  # (4, 4) and (6,): batch of one
    for k, s in enumerate(singles):
        assert s.q.shape == (1, 6) and s.status.shape == (1,)
        np.testing.assert_allclose(s.q[0], whole.q[k], rtol=0, atol=1e-12)
        assert s.iterations[0] == whole.iterations[k]
        assert s.status[0] == whole.status[k]


def test_batched_robots(rng) -> None:
    # One signature per target (a Monte-Carlo batch of robots) equals a loop.
    eps = np.stack([_eps(rng) for _ in range(12)])
    sigs = P.simulator_chain(eps)
    q = rng.uniform(LIM[:, 0], LIM[:, 1], (12, 6))
    T = forward_kinematics(sigs, q)
    q0 = _design_start(T, P.branch_of(q))
    whole = ik.newton_raphson(sigs, T, q0, RES)
    assert whole.converged.all()
    for k in range(12):
        one = ik.newton_raphson(P.simulator_chain(eps[k]), T[k], q0[k], RES)
        np.testing.assert_allclose(one.q[0], whole.q[k], rtol=0, atol=1e-12)


def _poor_signature(rng):
    """A grossly inaccurate signature and one target with 6.806 cm initial error.

    Section 5.4: Tables 5-1/5-2 start from a radial error of 6.8063937 cm. ε is
    a fixed random direction scaled (bisection) until the design start misses
    the target by exactly that much.
    """
    direction = _eps(rng, sigma_p=1.0, sigma_o_deg=1.0, sigma_e_deg=1.0)
    q_true = np.deg2rad([[30.0, -60.0, 120.0, 40.0, 50.0, 20.0]])
    flags = P.branch_of(q_true)

    def initial_error(scale):
        sig = P.simulator_chain(scale * direction)
        T = forward_kinematics(sig, q_true)
        q0 = _design_start(T, flags)
        return np.linalg.norm(forward_kinematics(sig, q0)[0, :3, 3] - T[0, :3, 3])

    lo, hi = 0.0, 1.0
    while initial_error(hi) < 6.8063937:
        hi *= 2.0
    for _ in range(60):
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if initial_error(mid) < 6.8063937 else (lo, mid)
    sig = P.simulator_chain(hi * direction)
    T = forward_kinematics(sig, q_true)
    return sig, T, _design_start(T, flags), flags


def test_poor_signature_converges_tables_5_1_5_2(rng) -> None:
    sig, T, q0, flags = _poor_signature(rng)
    nr = ik.newton_raphson(sig, T, q0, RES, record_history=True)
    ji = ik.jacobi_iterative(sig, DESIGN, puma_design_inverse(), T, q0, RES, record_history=True)
    for r in (nr, ji):
        h = r.history
        assert h is not None
        k = r.iterations[0]
        assert h.q.shape == (k + 1, 1, 6) and h.delta.shape == (k + 1, 1, 6)
        np.testing.assert_allclose(h.position_error_cm[0, 0], 6.8063937, atol=1e-6)
        # X, Y, Z axis errors and the radial error of Tables 5-1/5-2.
        np.testing.assert_allclose(
            np.linalg.norm(h.delta[:, 0, :3], axis=-1), h.position_error_cm[:, 0]
        )
        radial = h.position_error_cm[:, 0]
        assert (np.diff(radial[: k + 1]) < 0).all()  # decreasing at every iteration
        assert r.converged[0] and np.all(P.branch_of(r.q) == flags)
        assert radial[-1] <= POS_TOL_CM
    # Quadratic against linear convergence (Table 5-1 against Table 5-2): once
    # below 0.1 cm, each Newton error is below the square of the previous one
    # (in cm); Jacobi gains a roughly constant factor per iteration instead.
    assert nr.iterations[0] <= 6 < ji.iterations[0]

    def quadratic(radial):
        pairs = [(a, b) for a, b in zip(radial[:-1], radial[1:], strict=True) if a < 0.1]
        return len(pairs) >= 2 and all(b <= a**2 for a, b in pairs)

    assert quadratic(nr.history.position_error_cm[:, 0])
    assert not quadratic(ji.history.position_error_cm[:, 0])


def test_wrist_singular_targets(rng) -> None:
    q = rng.uniform(LIM[:, 0], LIM[:, 1], (200, 6))
    q[:, 4] = 0.0  # θ5 = 0: joints 4 and 6 aligned
    # Design == signature: exactly singular solutions, start perturbed away.
    T = forward_kinematics(DESIGN, q)
    q0 = q + rng.normal(0.0, 0.02, q.shape)
    nr = ik.newton_raphson(DESIGN, T, q0, RES)
    ji = ik.jacobi_iterative(DESIGN, DESIGN, puma_design_inverse(), T, q0, RES)
    for r in (nr, ji):
        assert np.isfinite(r.q).all()
        assert r.converged.all()  # a reachable singular target still converges
        assert r.position_error_cm.max() <= POS_TOL_CM
        assert r.orientation_error_rad.max() <= ROT_TOL_RAD
    # A realistic signature: the targets are within model error of its singularity.
    sig = P.simulator_chain(_eps(rng))
    T = forward_kinematics(sig, q)
    q0 = _design_start(T, P.branch_of(q))
    nr = ik.newton_raphson(sig, T, q0, RES)
    ji = ik.jacobi_iterative(sig, DESIGN, puma_design_inverse(), T, q0, RES)
    for r in (nr, ji):
        assert np.isfinite(r.q).all() and np.isfinite(r.position_error_cm).all()
        assert r.position_error_cm[r.converged].max() <= POS_TOL_CM
        # Whatever does not converge says so, with a failure code.
        failed = {ik.STATUS_MAX_ITER, ik.STATUS_SINGULAR, ik.STATUS_UNREACHABLE}
        assert set(r.status[~r.converged]) <= failed
        # Measured 97 % (Newton) and 98.5 % (Jacobi) converge here; for a
        # signature whose own wrist singularity lies right at θ5 = 0 Jacobi
        # converged on 0.5 % only (the fixed point does not contract there).
    assert nr.converged.mean() >= 0.9


def test_start_at_singular_home(rng) -> None:
    # q0 = 0 has θ5 = 0 exactly (rank-5 Jacobian) and is far from every target.
    sig = P.simulator_chain(_eps(rng))
    q = rng.uniform(LIM[:, 0], LIM[:, 1], (200, 6))
    T = forward_kinematics(sig, q)
    nr = ik.newton_raphson(sig, T, np.zeros(6), RES)
    assert np.isfinite(nr.q).all() and np.isfinite(nr.position_error_cm).all()
    assert nr.converged.mean() >= 0.9  # to some solution, not necessarily q's branch
    assert nr.position_error_cm[nr.converged].max() <= POS_TOL_CM


def test_workspace_boundary_targets(rng) -> None:
    # Elbow exactly stretched (design == signature): the reach limit itself.
    q = rng.uniform(LIM[:, 0], LIM[:, 1], (200, 6))
    q[:, 2] = np.pi / 2 - np.arctan2(A3, D4)
    T = forward_kinematics(DESIGN, q)
    q0 = _design_start(T, P.branch_of(q))
    assert np.isfinite(q0).all()  # clamped onto the workspace where needed
    nr = ik.newton_raphson(DESIGN, T, q0, RES)
    assert np.isfinite(nr.q).all()
    assert nr.converged.mean() >= 0.95
    assert nr.position_error_cm[nr.converged].max() <= POS_TOL_CM


def test_out_of_workspace_targets(rng) -> None:
    sig = P.simulator_chain(_eps(rng))
    q = rng.uniform(LIM[:, 0], LIM[:, 1], (100, 6))
    T = forward_kinematics(sig, q)
    # Move each target to 130 cm from the shoulder along its own direction. The
    # design flange reaches at most √(d2² + (a2 + √(d4² + a3²))²) + d6 = 93.59 cm
    # (this signature 93.62 cm), so at least 36 cm remain.
    shoulder = np.array([0.0, 0.0, P.DESIGN_D_CM[0]])
    out = T[:, :3, 3] - shoulder
    T[:, :3, 3] = shoulder + 130.0 * out / np.linalg.norm(out, axis=-1, keepdims=True)
    q0 = _design_start(T, P.branch_of(q))  # clamped: the design cannot reach either
    nr = ik.newton_raphson(sig, T, q0, RES)
    ji = ik.jacobi_iterative(sig, DESIGN, puma_design_inverse(), T, q0, RES)
    for r in (nr, ji):
        assert np.isfinite(r.q).all() and np.isfinite(r.position_error_cm).all()
        assert not r.converged.any()
        assert (r.position_error_cm > 36.0).all()  # the residual is reported
    # A stall at the reach limit: no step descends (unreachable). The rest creep
    # along the workspace boundary by more than an encoder count per iteration.
    assert (nr.status == ik.STATUS_UNREACHABLE).mean() >= 0.9
    assert (ji.status == ik.STATUS_UNREACHABLE).mean() >= 0.9
    # Without clamping the design inverse has no solution: Jacobi stops at once.
    ji = ik.jacobi_iterative(sig, DESIGN, puma_design_inverse(clamp=False), T, q0, RES)
    assert (ji.status == ik.STATUS_UNREACHABLE).all() and (ji.iterations == 0).all()
    np.testing.assert_array_equal(ji.q, q0)


def test_history_rows_repeat_after_stop(rng) -> None:
    sig = P.simulator_chain(_eps(rng))
    q = rng.uniform(LIM[:, 0], LIM[:, 1], (30, 6))
    T = forward_kinematics(sig, q)
    q0 = _design_start(T, P.branch_of(q))
    r = ik.newton_raphson(sig, T, q0, RES, record_history=True)
    h = r.history
    assert h.q.shape[0] == r.iterations.max() + 1
    np.testing.assert_array_equal(h.q[0], q0)
    np.testing.assert_array_equal(h.q[-1], r.q)
    for k in range(30):
        np.testing.assert_array_equal(
            h.q[r.iterations[k] :, k], np.broadcast_to(r.q[k], h.q[r.iterations[k] :, k].shape)
        )
    assert ik.newton_raphson(sig, T, q0, RES).history is None


def test_puma_design_inverse_tracks_previous_iterate(rng) -> None:
    q = rng.uniform(LIM[:, 0], LIM[:, 1], (500, 6))
    T = forward_kinematics(DESIGN, q)
    # Near q (any 2π class, e.g. θ6 = 250°): the branch of q, unwrapped to q.
    out = puma_design_inverse()(T, q + rng.normal(0.0, 1e-4, q.shape))
    np.testing.assert_allclose(out, q, atol=1e-9)
    # A fixed branch returns that branch for every target.
    for b in P.BRANCHES:
        got = P.branch_of(puma_design_inverse(b)(T, q))
        assert (got == [b.shoulder, b.elbow, b.wrist]).all()
    # Wrist singular: θ4 is kept from q_near, θ6 takes the rest of the rotation.
    q[:, 4] = 0.0
    T = forward_kinematics(DESIGN, q)
    near = q.copy()
    near[:, 3] += 0.3
    out = puma_design_inverse()(T, near)
    np.testing.assert_allclose(out[:, 3], near[:, 3], atol=1e-12)
    np.testing.assert_allclose(forward_kinematics(DESIGN, out), T, atol=1e-9)
    with pytest.raises(KinematicsError):
        puma_design_inverse("right")  # type: ignore[arg-type]


def test_bad_inputs_raise(rng) -> None:
    T = forward_kinematics(DESIGN, np.zeros((3, 6)))
    with pytest.raises(KinematicsError, match="non-finite"):
        ik.newton_raphson(DESIGN, T, np.full((3, 6), np.nan), RES)
    with pytest.raises(KinematicsError, match="start configurations"):
        ik.newton_raphson(DESIGN, T, np.zeros((2, 6)), RES)
    with pytest.raises(KinematicsError, match="target poses"):
        ik.newton_raphson(DESIGN, T[:, :3], np.zeros((3, 6)), RES)
    with pytest.raises(KinematicsError, match="resolution"):
        ik.newton_raphson(DESIGN, T, np.zeros((3, 6)), 0.0)

    def wrong(Tk, qk):
        return qk[:, :5]

    with pytest.raises(KinematicsError, match="shape"):
        ik.jacobi_iterative(DESIGN, DESIGN, wrong, T, np.zeros((3, 6)), RES)


def test_anderson_step_solves_an_affine_map(rng) -> None:
    """For G(q) = A q + b, n + 1 plain iterates give the fixed point exactly,
    even where the plain iteration diverges (spectral radius > 1)."""
    n, k = 6, 4
    A = rng.normal(0.0, 0.8, (k, n, n))  # several eigenvalues outside the unit circle
    b = rng.normal(size=(k, n))
    Q = np.zeros((k, n + 1, n))
    G = np.zeros((k, n + 1, n))
    q = rng.normal(size=(k, n))
    for j in range(n + 1):
        Q[:, j] = q
        G[:, j] = q = np.einsum("kij,kj->ki", A, q) + b
    fixed = np.linalg.solve(np.eye(n) - A, b[..., None])[..., 0]
    np.testing.assert_allclose(_anderson(Q, G, np.full(k, n + 1)), fixed, atol=1e-8)
    # With a single stored iterate it is the plain step G(q_k).
    np.testing.assert_allclose(_anderson(Q, G, np.ones(k, np.int64)), G[:, -1], atol=0)
