"""The non-geometric signature: joint deflections under gravity and joint-angle errors
periodic in the joint's own angle (the thesis's open problem, Section 8.3; issue 27).

The rigid signature maps readings ``q`` to a pose, ``T(q)``. A real arm sits at
``q + Δ(q)`` instead, with, per revolute joint ``j`` (rad):

- **compliance under gravity**: the joint deflects in proportion to the gravity torque
  about its axis from the links beyond it. Each link ``k`` is lumped into a point mass
  ``m_k`` at the origin of its frame ``F_k`` (after joint ``k``'s motion; two such masses,
  at both ends of a link, place its centre of mass anywhere along it), so
  ``τ_j = g Σ_{k≥j} m_k · h_jk(q)`` with the lever
  ``h_jk(q) = z_{j−1} · ((o_k − o_{j−1}) × ĝ)`` (cm): the moment arm of a unit weight
  at ``o_k`` about joint ``j``'s axis (``z_{j−1}``, through ``o_{j−1}``). With the joint's
  compliance ``c_j`` the deflection is ``Σ_k β_jk h_jk(q)``, ``β_jk = c_j g m_k``
  (rad/cm): compliance × mass-moment, neither need be known apart;
- **first-harmonic joint-angle errors** (an encoder's or gear's eccentricity):
  ``a_j cos q_j + b_j sin q_j`` (rad). The constant term is the encoder offset, already
  in the signature's ``q̄^s``.

Both are linear in their coefficients, ``Δ(q) = Φ(q) β``, and the regressor ``Φ`` is
evaluated on the **design** chain at the readings, gravity ``−z`` of the design's base
frame: a function of the readings alone, the same in the fit, the simulator and the
controller, so noiseless data identify ``β`` exactly. (The true levers differ from the
design's by the geometric errors, ~1e-3 of them: ~1e-7 rad on a 1e-4 rad deflection.)
Prismatic joints have neither term.

- **payload**: a payload of mass ``m_p`` (kg) at the flange (the origin of ``F_n``) adds
  ``γ_j m_p h_jn(q)``, ``γ_j = c_j g`` (rad per kg and cm of lever), term
  ``payload.j<j>``. It is a parameter only when the session measured more than one
  payload: with one, ``γ_j m_p`` is the flange's own lumped mass term (the same lever)
  and a changed payload cannot be predicted. With it, it is: the coefficients do not
  depend on the payload, the regressor does.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np
import numpy.typing as npt

from pipeline.errors import ArmsigError
from pipeline.kinematics.chain import SerialChain, link_frames

Array = npt.NDArray[np.float64]

#: The term kinds, in the order of their coefficients (and the refine table's groups).
KINDS = ("compliance", "payload", "harmonic")
#: :meth:`NonGeometric.readings_for` stops when a step moves no reading by more than this
#: (relative to max(1, |q|)): 1e-13 rad is 1e-11 cm at a 1 m lever, far inside the IK's
#: 1e-7 cm, and one fixed-point iteration of five fewer.
READINGS_TOLERANCE = 1e-13
#: :meth:`NonGeometric.with_payload` predicts payloads up to this many times the largest the
#: session measured (the payload terms are linear in the mass; a joint's sag is linear only
#: while its gear stays in its linear range, which no calibration of smaller loads shows).
PAYLOAD_EXTRAPOLATION = 2.0
#: Gravity in the design's base frame (unit vector).
GRAVITY = np.array([0.0, 0.0, -1.0])


@dataclass(frozen=True)
class Terms:
    """Which non-geometric terms a model has: compliance pairs ``(j, k)`` (joint ``j``
    deflected by the lumped mass of link ``k ≥ j``, 1-based), the joints deflected by the
    payload, and first-harmonic components ``(j, "cos" | "sin")`` of joint ``j``'s angle
    error."""

    compliance: tuple[tuple[int, int], ...] = ()
    harmonic: tuple[tuple[int, str], ...] = ()
    payload: tuple[int, ...] = ()

    @property
    def size(self) -> int:
        return len(self.compliance) + len(self.payload) + len(self.harmonic)

    def __bool__(self) -> bool:
        return self.size > 0

    @property
    def names(self) -> tuple[str, ...]:
        c = [f"compliance.j{j}.link{k}" for j, k in self.compliance]
        p = [f"payload.j{j}" for j in self.payload]
        h = [f"harmonic.j{j}.{f}" for j, f in self.harmonic]
        return (*c, *p, *h)

    @property
    def units(self) -> tuple[str, ...]:
        """Internal units: rad per cm of lever (compliance), rad per kg and cm of lever
        (payload), rad (harmonics)."""
        c, p, h = len(self.compliance), len(self.payload), len(self.harmonic)
        return ("rad/cm",) * c + ("rad/kg/cm",) * p + ("rad",) * h

    @property
    def groups(self) -> tuple[str, ...]:
        c, p, h = len(self.compliance), len(self.payload), len(self.harmonic)
        return ("compliance",) * c + ("payload",) * p + ("harmonic",) * h

    @classmethod
    def from_names(cls, names: list[str] | tuple[str, ...]) -> Terms:
        """The terms of parameter names as :attr:`names` gives them (any order kept)."""
        comp: list[tuple[int, int]] = []
        harm: list[tuple[int, str]] = []
        payload: list[int] = []
        for name in names:
            kind, joint, *rest = name.split(".")
            if kind == "compliance" and len(rest) == 1 and rest[0].startswith("link"):
                comp.append((int(joint[1:]), int(rest[0][len("link") :])))
            elif kind == "harmonic" and rest in (["cos"], ["sin"]):
                harm.append((int(joint[1:]), rest[0]))
            elif kind == "payload" and not rest:
                payload.append(int(joint[1:]))
            else:
                raise ValueError(f"not a non-geometric term: {name!r}")
        return cls(tuple(comp), tuple(harm), tuple(payload))


#: A rigid model's terms: none.
NO_TERMS = Terms()


def all_terms(prismatic: npt.ArrayLike, kinds: tuple[str, ...]) -> Terms:
    """Every term of ``kinds`` for joints ``prismatic`` (n,): compliance of every revolute
    joint under every link from its own on, a harmonic on every revolute joint."""
    pris = np.asarray(prismatic, bool)
    n = len(pris)
    revolute = [j for j in range(1, n + 1) if not pris[j - 1]]
    comp = tuple((j, k) for j in revolute for k in range(j, n + 1))
    harm = tuple((j, f) for j in revolute for f in ("cos", "sin"))
    return Terms(
        comp if "compliance" in kinds else (),
        harm if "harmonic" in kinds else (),
        tuple(revolute) if "payload" in kinds else (),
    )


def gravity_levers(design: SerialChain, q: npt.ArrayLike) -> Array:
    """``h[..., j−1, k−1]`` (cm) of the module docstring, shape (..., n, n): zero for
    ``k < j`` and for prismatic ``j``. ``q`` (..., n): readings (rad / cm)."""
    F = link_frames(design, q)  # (..., n + 2, 4, 4): F[i] has joint i+1's axis, i < n
    n = design.n_joints
    z = F[..., :n, :3, 2]  # joint j's axis, j = 1..n
    o = F[..., :n, :3, 3]  # a point on it
    masses = F[..., 1 : n + 1, :3, 3]  # o_k, k = 1..n
    arm = masses[..., None, :, :] - o[..., :, None, :]  # (..., j, k, 3)
    moment = np.cross(arm, GRAVITY)
    h = np.einsum("...jkc,...jc->...jk", moment, z)
    keep = np.triu(np.ones((n, n), bool)) & ~np.asarray(design.prismatic, bool)[:, None]
    return np.where(keep, h, 0.0)


def regressor(
    terms: Terms, design: SerialChain, q: npt.ArrayLike, payload_kg: npt.ArrayLike = 0.0
) -> Array:
    """``Φ(q)`` (..., n, size): ``∂Δ_j/∂β`` of every term at readings ``q`` (..., n) with
    the payload ``payload_kg`` (kg; a number or one per configuration (...,))."""
    q = np.asarray(q, float)
    n = q.shape[-1]
    out = np.zeros((*q.shape, terms.size))
    if terms.compliance or terms.payload:
        h = gravity_levers(design, q)
        for m, (j, k) in enumerate(terms.compliance):
            out[..., j - 1, m] = h[..., j - 1, k - 1]
        mass = np.asarray(payload_kg, float)
        for i, j in enumerate(terms.payload):
            out[..., j - 1, len(terms.compliance) + i] = mass * h[..., j - 1, n - 1]
    base = len(terms.compliance) + len(terms.payload)
    for i, (j, f) in enumerate(terms.harmonic):
        out[..., j - 1, base + i] = (np.cos if f == "cos" else np.sin)(q[..., j - 1])
    assert out.shape[-2] == n
    return out


@dataclass(frozen=True, eq=False)
class NonGeometric:
    """The identified non-geometric terms of a signature: ``q ↦ q + Φ(q) β``, under the
    payload ``payload_kg``; ``measured_payloads_kg``: the payloads the session measured
    (kg; which payloads the signature predicts without payload terms)."""

    terms: Terms
    coefficients: Array  # (size,) internal units (Terms.units)
    design: SerialChain
    payload_kg: float = 0.0
    measured_payloads_kg: tuple[float, ...] = ()

    def deflection(self, q: npt.ArrayLike, payload_kg: npt.ArrayLike | None = None) -> Array:
        """``Δ(q)`` (..., n), rad / cm, at readings ``q`` (..., n) under ``payload_kg``
        (None: :attr:`payload_kg`; or one per configuration)."""
        mass = self.payload_kg if payload_kg is None else payload_kg
        Phi = regressor(self.terms, self.design, q, mass)
        return np.asarray(Phi @ self.coefficients, float)

    def effective(self, q: npt.ArrayLike, payload_kg: npt.ArrayLike | None = None) -> Array:
        """The joint values the arm sits at, ``q + Δ(q)``, for readings ``q`` (..., n)."""
        q = np.asarray(q, float)
        return q + self.deflection(q, payload_kg)

    def with_payload(self, kg: float) -> NonGeometric:
        """The terms under a payload of ``kg``: predicted when the fit has payload terms
        (the session measured two payloads or more), else refused unless ``kg`` is the
        payload the session measured (one line)."""
        if not (np.isfinite(kg) and kg >= 0):
            raise ArmsigError("bad payload", expected="a mass >= 0 kg", got=repr(kg))
        measured = self.measured_payloads_kg or (0.0,)
        top = PAYLOAD_EXTRAPOLATION * max(measured)
        if self.terms.payload and kg > top:
            raise ArmsigError(
                f"the signature cannot predict a payload of {kg:g} kg",
                expected=f"at most {top:g} kg ({PAYLOAD_EXTRAPOLATION:g}× the largest payload "
                f"measured, {max(measured):g} kg: the payload terms are linear fits over "
                f"{min(measured):g}-{max(measured):g} kg)",
                got=f"{kg:g} kg",
                fix="measure the arm under that payload (docs/nongeometric.md#payload)",
            )
        if not self.terms.payload and not any(abs(kg - m) <= 1e-9 for m in measured):
            said = ", ".join(f"{m:g} kg" for m in self.measured_payloads_kg)
            raise ArmsigError(
                f"the signature cannot predict a payload of {kg:g} kg",
                expected="the payload the session measured: "
                + (said or "none recorded, so 0 kg means that one"),
                got=f"{kg:g} kg",
                fix="identify from a session measured with two payloads or more "
                "(docs/nongeometric.md#payload)",
            )
        return replace(self, payload_kg=float(kg))

    def payload_extrapolated(self) -> str | None:
        """A warning when :attr:`payload_kg` lies outside the payloads the session measured
        (the linear payload terms extrapolated), else None."""
        measured = self.measured_payloads_kg
        if not self.terms.payload or not measured:
            return None
        lo, hi = min(measured), max(measured)
        if lo - 1e-9 <= self.payload_kg <= hi + 1e-9:
            return None
        return (
            f"payload {self.payload_kg:g} kg is outside the {lo:g}-{hi:g} kg the session "
            "measured: the payload terms are extrapolated"
        )

    def readings_for(
        self, q_eff: npt.ArrayLike, tol: float = READINGS_TOLERANCE, max_iter: int = 50
    ) -> Array:
        """The readings ``q`` with ``q + Δ(q) = q_eff`` (..., n): the fixed point of
        ``q ← q_eff − Δ(q)``, a contraction while ``|∂Δ/∂q| < 1`` (deflections of 1e-3
        rad change by ~1e-3 per radian: ~4 iterations), stopped when a step moves no
        reading by more than ``tol`` × max(1, |q|)."""
        q_eff = np.asarray(q_eff, float)
        scale = tol * max(1.0, float(np.max(np.abs(q_eff), initial=0.0)))
        q = q_eff.copy()
        for _ in range(max_iter):
            nxt = q_eff - self.deflection(q)
            step = float(np.max(np.abs(nxt - q), initial=0.0))
            q = nxt
            if step <= scale:
                break
        return q
