"""The real-time Puma 560 solver: :class:`PumaSolver`, bound to one signature and
branch, runs the compiled design start and Newton-Raphson solve
(:mod:`pipeline.control.puma560_newton`) or Jacobi iteration
(:mod:`pipeline.control.puma560_jacobi`) of each target in one kernel call, and
finishes the targets those defer with the numpy iterations of
:mod:`pipeline.kinematics.ik`."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import replace
from typing import cast

import numpy as np

from pipeline.control.limits import honour_limits
from pipeline.control.puma560_jacobi import J_MAX_ITER, J_NO_INVERSE, J_STALLED, _jacobi_targets
from pipeline.control.puma560_newton import (
    _PACK_SIZES,
    _S_DELTA,
    _S_END,
    _S_ERRORS,
    _S_Q,
    _S_Q0,
    _S_TARGET,
    _S_TW,
    OFF_BRANCH,
    OUT_OF_LIMITS,
    OUT_OF_LIMITS_OFF_BRANCH,
    _solve_packed,
    _solve_targets,
)
from pipeline.control.puma560_start import NO_START
from pipeline.kinematics.chain import SerialChain, forward_kinematics
from pipeline.kinematics.ik.batch import IntArray, _errors
from pipeline.kinematics.ik.jacobi import DesignInverse, jacobi_iterative
from pipeline.kinematics.ik.newton import finish_deferred, ik_compilable
from pipeline.kinematics.ik.result import (
    STATUS_CONVERGED,
    STATUS_MAX_ITER,
    STATUS_OUT_OF_LIMITS,
    STATUS_UNREACHABLE,
    IKResult,
    _result,
    mark_singular,
)
from pipeline.kinematics.ik_compiled import (
    FAST_CONVERGED,
    FAST_DEFERRED,
    homogeneous,
    run_in_shares,
)
from pipeline.kinematics.kernels import Kernel
from pipeline.kinematics.nongeometric import NonGeometric
from pipeline.kinematics.nongeometric_compiled import CompiledDeflection
from pipeline.kinematics.transforms import Array, differential_motion, invert_transform
from pipeline.robots import puma560
from pipeline.robots.puma560 import Branch

#: The one-target kernel as a :class:`~pipeline.kinematics.kernels.Kernel`: its ``run``
#: called directly (the compiled dispatcher, or Python inside ``interpreted``).
_PACKED = cast(Kernel, _solve_packed)
#: Templates of a one-target result's flags and status (:meth:`PumaSolver.solve`).
_ONE_TRUE, _ONE_FALSE = np.ones(1, bool), np.zeros(1, bool)
_ONE_ZERO = np.zeros(1, np.int64)


class PumaSolver:
    """Newton-Raphson from the Puma design start, bound to one signature and branch.

    Made by :meth:`pipeline.control.Controller.realtime` (or from the parts
    here). Every array the kernel reads is made once, contiguous, at
    construction; :meth:`solve_one` writes into buffers owned by the solver.

    Fallback order, per target, each step only where the previous one left the
    target unsolved or off the requested branch:

    1. Newton-Raphson (5.4) from the design start, Levenberg-Marquardt steps
       where a Newton step does not descend (:mod:`pipeline.kinematics.ik_compiled`);
    2. (branch-preserving) the same from the start with θ4 and θ6 turned
       against each other (:data:`pipeline.robots.puma560.WRIST_TURNS`), the first
       solution on the branch;
    3. (any branch, flagged) the first solution of 1-2 on another branch,
       with :attr:`~pipeline.kinematics.ik.result.IKResult.branch_changed` set;
    4. the numpy iteration of :func:`pipeline.kinematics.ik.newton.newton_raphson`
       from the design start, which gives the status of a target it cannot
       solve either (its solution's branch flagged as in 3).

    The converged solution is then put inside the joint limits
    (:mod:`pipeline.control.limits`): shifted by ±2π, else its wrist flip
    ``(θ4 + π, −θ5, θ6 + π)`` polished by Newton-Raphson and shifted (flagged as
    another branch: its wrist flag is the other one), else the status ``out_of_limits``
    (not converged) with the solution kept.

    Parameters
    ----------
    chain : SerialChain
        The signature chain (unbatched, six joints), sensor frame, cm.
    design_base, flange_to_tool : ndarray, shape (4, 4)
        The design chain's base in the sensor frame (``X · base``) and the flange
        to the signature tool ``Y``.
    sensor_from_base : ndarray, shape (4, 4)
        ``X``: design base frame to sensor frame (for :meth:`solve_one`).
    branch : Branch
    resolution : ndarray, shape (6,)
        Encoder resolution, rad.
    limits : tuple of ndarray
        Lower and upper joint limits and the turn (2π) per joint, rad
        (:func:`pipeline.control.limits.limit_arrays`).
    margins : tuple of float
        The design inverse's clamp margins (elbow rad, shoulder cm).
    design : SerialChain, optional
        The design model in the sensor frame with the signature's tool, for
        :meth:`solve_jacobi`.
    nongeometric : NonGeometric, optional
        The signature's non-geometric terms: :meth:`solve_one` and :meth:`solve` return
        the readings that put the joints where the chain needs them (compiled:
        :mod:`pipeline.kinematics.nongeometric_compiled`); a reading pushed past a
        limit makes the target ``out_of_limits``.
    jacobi_margins : tuple of float
        The clamp margins of the design inverse inside the Jacobi iteration.
    """

    def __init__(
        self,
        chain: SerialChain,
        design_base: Array,
        flange_to_tool: Array,
        sensor_from_base: Array,
        branch: Branch,
        resolution: Array,
        limits: tuple[Array, Array, Array],
        margins: tuple[float, float],
        design: SerialChain | None = None,
        jacobi_margins: tuple[float, float] = (0.0, 0.0),
        max_iter: int = 50,
        position_tol_cm: float = 1e-7,
        orientation_tol_rad: float = 1e-10,
        max_step: float = 0.5,
        nongeometric: NonGeometric | None = None,
    ) -> None:
        n = chain.n_joints
        if not ik_compilable(chain) or chain.prismatic.any():
            raise ValueError("PumaSolver needs an unbatched six-revolute-joint chain")
        c = np.ascontiguousarray
        self.chain = chain
        self.branch = branch
        parts = (
            chain.base, chain.links, chain.tool, chain.joint_offsets,
            invert_transform(design_base), invert_transform(flange_to_tool),
            [branch.shoulder, branch.elbow, branch.wrist], margins,
            np.broadcast_to(resolution, (n,)), np.full(n, max_step),
            [max_iter, chain.length_scale, position_tol_cm, orientation_tol_rad],
            sensor_from_base, *limits,
        )  # fmt: skip
        #: Every constant array of the kernels, packed (:data:`.puma560_newton._PACK_SIZES`); the
        #: arrays below are views of it.
        self._packed = np.concatenate([np.asarray(a, float).ravel() for a in parts])
        views = np.split(self._packed, np.cumsum(_PACK_SIZES)[:-1])
        shapes = ((4, 4), (n, 4, 4), (4, 4), (n,), (4, 4), (4, 4)) + ((-1,),) * 5
        model = [v.reshape(shape) for v, shape in zip(views, shapes, strict=False)]
        self._prismatic = c(chain.prismatic, np.bool_)
        model.insert(4, self._prismatic)
        self.resolution = model[9]
        self.settings = (max_iter, position_tol_cm, orientation_tol_rad, max_step)
        self._model = tuple(model)
        if design is not None and not homogeneous(design.base, design.links, design.tool):
            raise ValueError("PumaSolver needs a design chain of homogeneous transforms")
        self.design = design
        self._design = None if design is None else (
            c(design.base, float), c(design.links, float), c(design.tool, float),
            c(design.joint_offsets, float), np.array(jacobi_margins, float),
        )  # fmt: skip
        self._frames = (design_base, flange_to_tool)  # for the numpy design inverse
        self._X = views[11].reshape(4, 4)
        self._limits = (views[12], views[13], views[14])
        self._q_ref = c(chain.joint_offsets, float)  # q^s: the default q_near
        #: Scratch of :meth:`solve_one`, packed (:data:`.puma560_newton._SCRATCH_SIZES`);
        #: the buffers below are views of it.
        self._scratch = np.empty(_S_END)
        S = self._scratch
        #: The last solution of :meth:`solve_one` (6,), rad; overwritten by the next call
        #: (before the first: q^s). May be passed back as ``q_near``.
        self.q = S[_S_Q:_S_DELTA]
        self.q[:] = self._q_ref
        #: The last start (the design inverse) of :meth:`solve_one` (6,), rad.
        self.q0 = S[_S_Q0:_S_Q]
        #: The last final δ of :meth:`solve_one` (6,): cm and rad.
        self.delta = S[_S_DELTA:_S_ERRORS]
        #: The last kernel outcome and iteration count of :meth:`solve_one`.
        self.info = np.zeros(2, np.int64)
        #: Whether the last solution of :meth:`solve_one` lies on another branch (step 3).
        self.branch_changed = False
        #: The last position (cm) and rotation (rad) error of :meth:`solve_one`.
        self.errors = S[_S_ERRORS:_S_TARGET]
        self._target = S[_S_TARGET:_S_TW].reshape(4, 4)
        #: :meth:`solve`'s scratch and outcome for one target (the real-time buffers
        #: above are :meth:`solve_one`'s alone).
        one = np.empty(_S_END)
        self._one = (one, np.zeros(2, np.int64), one[_S_Q:_S_DELTA].reshape(1, n),
                     one[_S_ERRORS:_S_TARGET])  # fmt: skip
        self._deflection = None if nongeometric is None else CompiledDeflection(
            nongeometric, self._limits[0], self._limits[1]
        )  # fmt: skip
        self._q_row, self._outside = self.q.reshape(1, n), np.zeros(1, np.bool_)

    def solve_one(self, T_base: Array, q_near: Array | None = None) -> bool:
        """Solve one pose (4, 4) given in the design base frame; True when converged
        inside the joint limits.

        The real-time call: no array is allocated when the kernel converges
        (all but ~1e-3 of random reachable targets); :attr:`q` then holds the
        joints (rad, inside the limits: shifted by ±2π, or the wrist flipped, as
        :meth:`pipeline.control.Controller.solve`, :mod:`pipeline.control.limits`)
        and :attr:`info` the iteration count. False with :attr:`info` ``[0]``
        :data:`.puma560_newton.OUT_OF_LIMITS` (or ``OUT_OF_LIMITS_OFF_BRANCH``): the
        solution in :attr:`q` has no equivalent inside the limits; do not send it.
        ``q_near`` (6,), rad (contiguous float): the 2π class and, at a wrist
        singularity, θ4 of the start; default q^s (pass the
        previous solution in a trajectory). A target the kernel defers is
        finished by the numpy iteration (allocates; ~1 ms), with the same
        result as ``Controller.solve``.
        """
        near = self._q_ref if q_near is None else q_near
        _PACKED.run(self._packed, self._prismatic, self._scratch, self.info, T_base, near)
        if self.info[0] == FAST_CONVERGED or self.info[0] == OFF_BRANCH:
            self.branch_changed = self.info[0] == OFF_BRANCH
            return self._to_readings()
        if self.info[0] == OUT_OF_LIMITS or self.info[0] == OUT_OF_LIMITS_OFF_BRANCH:
            self.branch_changed = self.info[0] == OUT_OF_LIMITS_OFF_BRANCH
            return False  # q: the solution, outside the limits
        res = self.finish(lambda _: self._target[None], near[None], self.q0[None],
                          self.q[None].copy(), self.info[:1].copy(), self.info[1:].copy(),
                          self.delta[None], self.errors[None].copy())  # fmt: skip
        self.q[:] = res.q[0]
        self.info[1] = res.iterations[0]
        self.branch_changed = bool(res.branch_changed is not None and res.branch_changed[0])
        return bool(res.converged[0]) and self._to_readings()

    def _to_readings(self) -> bool:
        """:attr:`q` (where the joints must sit) made the readings under the signature's
        non-geometric terms, in place; False (with :attr:`info` ``[0]`` ``OUT_OF_LIMITS``)
        when a reading left the limits. True without terms."""
        if self._deflection is None:
            return True
        self._deflection.readings_into(self._q_row, self._outside)
        if self._outside[0]:
            self.info[0] = OUT_OF_LIMITS
            return False
        return True

    def solve(self, T_base: Array, q_near: Array | None = None) -> IKResult:
        """Solve targets (m, 4, 4) given in the design base frame from ``q_near``
        ((6,) or (m, 6), rad; None: q^s).

        Batched: one kernel call (threads for large batches:
        :func:`~pipeline.kinematics.ik_compiled.run_in_shares`); every target
        is solved alone by the arithmetic of :meth:`solve_one`, so a batch
        equals a loop bit for bit. One target takes :meth:`solve_one`'s kernel
        call with buffers of its own (the result's arrays are the only allocations;
        :attr:`q` and the other real-time buffers are left alone). Joints
        are shifted into the limits by ±2π where that helps, as :meth:`solve_one`
        and :meth:`pipeline.control.Controller.solve` do.
        """
        Tb = np.ascontiguousarray(T_base, float)
        m, n = len(Tb), 6  # six joints (checked at construction)
        if m == 1:
            one = self._q_ref if q_near is None else np.ascontiguousarray(q_near, float).reshape(n)
            S, info, q_one, errors_one = self._one
            _PACKED.run(self._packed, self._prismatic, S, info, Tb[0], one)
            kind, count = info.tolist()
            if (kind == FAST_CONVERGED or kind == OFF_BRANCH) and self._deflection is None:
                # The result's arrays copied from small templates: ~0.1 µs each, where
                # np.ones(1, bool), np.array([count]) or a comparison ufunc take 0.2-1 µs.
                errors, iterations = errors_one.copy(), _ONE_ZERO.copy()
                iterations[0] = count
                return IKResult.of_one_target(
                    q_one.copy(), _ONE_TRUE.copy(), iterations, errors[:1], errors[1:],
                    _ONE_ZERO.copy(), (_ONE_FALSE if kind == FAST_CONVERGED else _ONE_TRUE).copy(),
                )  # fmt: skip
        near = np.ascontiguousarray(
            np.broadcast_to(self._q_ref if q_near is None else q_near, (m, n)), float
        )
        q0, q, delta = np.empty((m, n)), np.empty((m, n)), np.empty((m, 6))
        outcome, iterations = np.empty(m, np.int64), np.empty(m, np.int64)
        errors = np.empty((m, 2))

        def run(rows: slice) -> None:
            *model, X, lower, upper, turn = _own((*self._model, self._X, *self._limits))
            _solve_targets(*model, X, Tb[rows], near[rows], q0[rows], q[rows], delta[rows],
                           outcome[rows], iterations[rows], errors[rows], lower, upper,
                           turn)  # type: ignore[call-arg]  # fmt: skip

        run_in_shares(run, m)
        # The targets in the sensor frame for the rows finish needs only (issue 45: the
        # kernel keeps none, 128 bytes a target less to write and to page in).
        res = self.finish(lambda rows: in_sensor_frame(self._X, Tb[rows]), near, q0, q,
                          outcome, iterations, delta, errors)  # fmt: skip
        if self._deflection is None:
            return res
        outside = np.zeros(m, np.bool_)
        self._deflection.readings_into(res.q, outside)
        status = np.where(res.converged & outside, STATUS_OUT_OF_LIMITS, res.status)
        return replace(res, status=status, converged=status == STATUS_CONVERGED)

    def solve_jacobi(self, T_base: Array, q_near: Array | None = None) -> IKResult:
        """The Jacobi iteration (5.8) of targets (m, 4, 4) in the design base frame from
        the design start near ``q_near`` ((6,) or (m, 6), rad; None: q^s)
        (:meth:`solve`'s arguments).

        Compiled while the map contracts (:func:`.puma560_jacobi._jacobi_one`); the targets it
        defers run :func:`pipeline.kinematics.ik.jacobi.jacobi_iterative` (Anderson
        acceleration) from their start. Batch equals loop bit for bit.
        """
        if self.design is None or self._design is None:
            raise ValueError("PumaSolver made without the design chain: no Jacobi iteration")
        design = self._design
        Tb = np.ascontiguousarray(T_base, float)
        m, n = len(Tb), self.chain.n_joints
        near = np.ascontiguousarray(
            np.broadcast_to(self._q_ref if q_near is None else q_near, (m, n)), float
        )
        q0, q, delta, T = np.empty((m, n)), np.empty((m, n)), np.empty((m, 6)), np.empty_like(Tb)
        outcome, iterations = np.empty(m, np.int64), np.empty(m, np.int64)

        def run(rows: slice) -> None:
            *model, X = _own((*self._model, *design, self._X))
            _jacobi_targets(*model, X, Tb[rows], near[rows], q0[rows], q[rows], delta[rows],
                            T[rows], outcome[rows], iterations[rows])  # type: ignore[call-arg]  # fmt: skip

        run_in_shares(run, m)
        lost = np.flatnonzero(outcome == NO_START)
        status = np.full(m, STATUS_CONVERGED, np.int64)
        status[(outcome == J_STALLED) | (outcome == J_NO_INVERSE)] = STATUS_UNREACHABLE
        status[outcome == J_MAX_ITER] = STATUS_MAX_ITER
        if lost.size:  # no design start: the numpy iteration from near reports them
            rest = jacobi_iterative(
                self.chain, self.design, self._numpy_inverse(), T[lost], near[lost],
                self.resolution, self.settings[0], position_tol_cm=self.settings[1],
                orientation_tol_rad=self.settings[2],
            )  # fmt: skip
            q[lost], iterations[lost], status[lost] = rest.q, rest.iterations, rest.status
            delta[lost] = differential_motion(forward_kinematics(self.chain, rest.q), T[lost])
        mark_singular(self.chain, q, status)
        return _result(q, status, iterations, _errors(delta))

    def _numpy_inverse(self) -> DesignInverse:
        """The numpy design inverse of the Jacobi iteration (same branch and margins)."""
        from pipeline.control.puma560_inverse import puma_design_inverse

        assert self._design is not None
        margins = self._design[4]
        return puma_design_inverse(
            self.branch, tool=self._frames[1], base=self._frames[0],
            elbow_margin_rad=float(margins[0]), shoulder_margin_cm=float(margins[1]),
        )  # fmt: skip

    def finish(
        self, targets: Callable[[IntArray], Array], near: Array, q0: Array, q: Array,
        outcome: IntArray, iterations: IntArray, delta: Array, errors: Array,
    ) -> IKResult:  # fmt: skip
        """The result of kernel outputs (``errors`` (m, 2): the kernel's position and
        rotation errors; ``targets(rows)``: those rows' targets in the sensor frame,
        (k, 4, 4)): deferred targets by the numpy iteration from their start,
        targets without a start from ``near`` (the numpy design inverse's fallback),
        so the numpy iteration reports them; those rows put inside the limits as the
        kernel puts the rows it solves (:func:`pipeline.control.limits.honour_limits`),
        the kernel's out-of-limits rows marked so. Converged solutions off the
        requested branch are flagged (:attr:`.IKResult.branch_changed`)."""
        status = np.zeros(len(q), np.int64)
        limited = (outcome == OUT_OF_LIMITS) | (outcome == OUT_OF_LIMITS_OFF_BRANCH)
        status[limited] = STATUS_OUT_OF_LIMITS
        changed = (outcome == OFF_BRANCH) | (outcome == OUT_OF_LIMITS_OFF_BRANCH)
        rows = np.flatnonzero((outcome != FAST_CONVERGED) & ~changed & ~limited)
        if rows.size:
            start = np.where((outcome[rows] == NO_START)[:, None], near[rows], q0[rows])
            T_rows = targets(rows)
            max_iter, tol_p, tol_o, max_step = self.settings
            res = finish_deferred(
                self.chain, T_rows, start, self.resolution, q[rows],
                np.full(rows.size, FAST_DEFERRED), iterations[rows], delta[rows],
                max_iter=max_iter, position_tol_cm=tol_p, orientation_tol_rad=tol_o,
                max_step=max_step,
            )  # fmt: skip
            b = self.branch
            off = np.any(puma560.branch_of(res.q) != [b.shoulder, b.elbow, b.wrist], axis=-1)
            changed[rows] = res.converged & off
            res = honour_limits(
                res, self.chain, T_rows, self._limits, self.resolution, True,
                arm=lambda q: puma560.branch_of(q)[:, :2], near=near[rows],
            )  # the kernel's limits rule, in numpy  # fmt: skip
            # a solution moved into the limits with its wrist flipped: flagged too
            off = np.any(puma560.branch_of(res.q) != [b.shoulder, b.elbow, b.wrist], axis=-1)
            changed[rows] |= res.converged & off
            q[rows], iterations[rows], status[rows] = res.q, res.iterations, res.status
            errors[rows, 0], errors[rows, 1] = res.position_error_cm, res.orientation_error_rad
        return IKResult(
            q=q, converged=status == STATUS_CONVERGED, iterations=iterations,
            position_error_cm=errors[:, 0], orientation_error_rad=errors[:, 1], status=status,
            branch_changed=changed,
        )  # fmt: skip


def in_sensor_frame(X: Array, T_base: Array) -> Array:
    """``X · T_base`` of poses (k, 4, 4): the kernel's :func:`.puma560_start._to_sensor`,
    the same products summed in the same order (the same bits)."""
    T = T_base[:, :, None, :]  # T[k, j, 0, c]: row j of pose k
    out: Array = X[:, 0, None] * T[:, 0] + X[:, 1, None] * T[:, 1]
    return out + X[:, 2, None] * T[:, 2] + X[:, 3, None] * T[:, 3]


def _own(arrays: tuple[Array, ...]) -> tuple[Array, ...]:
    """Copies of the model's arrays for one share of a batch (one thread): a compiled
    call increments and decrements the reference count of each array it is passed
    and of each view it makes, atomically; on arrays shared by two threads these
    counts bounce between the cores. Measured on robot3 (100,000 targets, two
    threads, best of 5): Newton-Raphson 447,000 -> 486,000 targets/s, Jacobi unchanged."""
    return tuple(a.copy() for a in arrays)
