"""Which non-geometric model a session carries, chosen by cross-validation (issue 41).

``refine.nongeometric=auto`` fits the candidates :data:`CANDIDATES` (the rigid chain, joint
compliance, first-harmonic joint-angle errors, both) to the same session and scores each
on positions it did not see: k-fold over blocks of the measurement order
(:func:`pipeline.refine.holdout.fold_of_blocks`: each sweep's steps, a pose set's poses,
cut into ``k`` contiguous blocks; fold ``f`` holds out block ``f`` of every sweep, so a
slow drift cannot leak into the held-out fold). Each fold is refit by one Gauss-Newton step
from the candidate's full fit without the fold (:class:`pipeline.refine.holdout.StepRefit`)
and scored by the mean squared distance measured − predicted of its held-out positions
(``MSE_f``, cm²).

The rule (:func:`choose`). The candidates nest: rigid ⊂ compliance ⊂ compliance+harmonic
and rigid ⊂ harmonic ⊂ compliance+harmonic. A candidate *passes* against a simpler one it
nests when it beats it by more than the fold-to-fold spread of the gain: the paired
differences ``d_f = MSE_simple,f − MSE_complex,f`` have ``mean(d) > 0`` and
``mean(d) > sd(d)`` (the sample standard deviation over the folds). The rigid chain always
passes; every other candidate must pass against every simpler candidate it nests that was
fitted. Of those that pass, the one with the lowest CV error (the held-out RMS over every
fold) is taken. A candidate nesting one that fits the data to rounding
(:data:`ROUNDING`: noiseless data of a robot that candidate describes) cannot pass against
it: what it adds is fitted to round-off.

A joint's harmonic is a candidate term only when the readings span enough of a turn
(:func:`harmonic_extrapolation`, :data:`HARMONIC_EXTRAPOLATION`). The encoder offset
already takes the harmonic's constant part, so over part of a turn the data see only how
``a cos q + b sin q`` bends there; its continuation beyond the range is the model's
assumption, not the data's, and the cross-validation cannot see it: its folds hold out
blocks of time, not of the joint's range. Fitted on the UR10's Series C (joints 1, 2, 3
and 5 cover 96-147°), the harmonics won the cross-validation and tripled the error on
every other series, whose configurations lie outside those ranges (issue 27,
docs/nongeometric.md).

This module takes the readings and the folds' errors and returns the choice and its
record; the stage module (:mod:`pipeline.stages.refine`) fits the candidates.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
import numpy.typing as npt

Array = npt.NDArray[np.float64]

#: The candidates, simplest first: names of ``refine.nongeometric`` settings (``none`` is
#: called ``rigid`` here).
CANDIDATES = ("rigid", "compliance", "harmonic", "compliance+harmonic")
#: A full fit whose χ²/dof (whitened) is at most this fits to rounding: residuals ~1e-7 σ
#: of the stated noise, where noisy data sit at ~1 (a noiseless session: 1e-20 to 1e-24).
ROUNDING = 1e-14
#: A joint's harmonic is a candidate when its variance anywhere on the turn is at most this
#: many times its variance at the readings (:func:`harmonic_extrapolation`): its σ at most
#: doubles away from the data. Uniform readings reach it over ~165° of the joint (a full
#: turn: 1, 180°: 3.1, 128°: 9.4); the UR10's Series C passes joint 4 (3.9) and not joints
#: 1, 2, 3, 5 and 6 (21, 220, 28, 12, 6.7: joint 6 spans 513°, but nine readings in ten
#: lie within 45° of 0° modulo a turn).
HARMONIC_EXTRAPOLATION = 4.0
#: A session of more positions than this chooses its model on 1 in every ``⌈K /
#: CHOICE_POSITIONS⌉`` of its poses (:func:`choice_rows`), then fits the chosen candidate
#: to every position (issue 45). The choice is a test of whether a term's held-out gain
#: beats its spread over the folds; 100,000 positions (300,000 coordinates for at most
#: ~20 terms more) estimate that gain and spread as well as a million do, and the
#: candidates' fits and scores on a million positions took 3/4 of a million-row identify
#: (134 of 180 s). Every session of at most this many positions is chosen as before.
CHOICE_POSITIONS = 100_000


def harmonic_extrapolation(q: Array) -> float:
    """How much a first harmonic of a joint, fitted at its readings ``q`` (m,) (rad) with
    the encoder offset, extrapolates: the mean over a full turn of its deflection's
    variance over the mean at the readings, for coefficients of covariance ``C⁻¹/m``
    (white noise), ``C`` the covariance of ``(cos q, sin q)`` over the readings (the
    offset removed): ``tr(C⁻¹)/4`` (over a full turn ``C = I/2``: 1). Infinite when the
    readings cannot tell the harmonic from the offset (one angle, or two)."""
    X = np.stack([np.cos(q), np.sin(q)], axis=1)
    lam = np.linalg.eigvalsh(np.cov(X.T, bias=True)) if len(q) > 1 else np.zeros(2)
    # 1e-12: the rounding of a rank-1 covariance (one or two distinct angles); a sweep of
    # 1° has λ_min ~1e-10
    return float(np.sum(1.0 / lam) / 4.0) if lam[0] > 1e-12 else float("inf")


def harmonic_joints(theta: Array, revolute: npt.NDArray[np.bool_]) -> dict[int, float]:
    """Per revolute joint (1-based) of the configurations ``theta`` (m, n) (rad; a constant
    offset per joint changes nothing), its :func:`harmonic_extrapolation`."""
    q = np.unique(np.asarray(theta, float), axis=0)
    return {int(j) + 1: harmonic_extrapolation(q[:, j]) for j in np.flatnonzero(revolute)}


def choice_rows(
    sweep: npt.ArrayLike, step: npt.ArrayLike, most: int | None = None
) -> npt.NDArray[np.int64] | None:
    """The positions the model is chosen on when there are more than ``most``
    (:data:`CHOICE_POSITIONS`): of each sweep's distinct steps in step order (the order
    they were measured in), 1 in every ``⌈K / most⌉``, each with all its targets, so the
    folds' blocks of the measurement order stay blocks of it
    (:func:`pipeline.refine.holdout.fold_of_blocks`); None when there are at most
    ``most`` (every position)."""
    from pipeline.refine.holdout import step_ranks

    most = CHOICE_POSITIONS if most is None else most
    K = np.size(step)
    if K <= most:
        return None
    return np.flatnonzero(step_ranks(sweep, step)[0] % -(-K // most) == 0)  # 1 in ⌈K / most⌉


def fits_to_rounding(chi2: float, dof: int) -> bool:
    """Whether a fit of χ² ``chi2`` (whitened) on ``dof`` degrees of freedom is at
    :data:`ROUNDING`."""
    return bool(dof > 0 and chi2 / dof <= ROUNDING)


def candidate_kinds(candidate: str) -> frozenset[str]:
    """The term kinds of a candidate (``rigid``: none)."""
    return frozenset() if candidate == "rigid" else frozenset(candidate.split("+"))


def nests(simple: str, complex_: str) -> bool:
    """Whether candidate ``complex_`` holds every term kind of ``simple`` and more."""
    return candidate_kinds(simple) < candidate_kinds(complex_)


@dataclass(frozen=True)
class Scored:
    """One candidate's cross-validation: its parameter count in terms (``n_terms``), per
    fold the held-out positions (``fold_n``) and their mean squared error (``fold_mse``,
    cm²; NaN for a fold without any), and whether its full fit is at rounding."""

    name: str
    n_terms: int
    fold_mse: Array
    fold_n: npt.NDArray[np.int64]
    exact: bool = False

    @property
    def rms_cm(self) -> float:
        """The held-out RMS over every fold (cm)."""
        n = self.fold_n.sum()
        sse = np.nansum(self.fold_mse * self.fold_n)
        return float(np.sqrt(sse / n)) if n else float("nan")


@dataclass(frozen=True)
class Comparison:
    """A candidate against a simpler one it nests: the paired gain ``mean(d)`` and its
    spread ``sd(d)`` (cm², module docstring), and whether it passed."""

    simpler: str
    gain_cm2: float
    spread_cm2: float
    passed: bool


def paired_gain(simple: Array, complex_: Array) -> tuple[float, float]:
    """``mean(d)`` and ``sd(d)`` (ddof 1) of ``d_f = simple_f − complex_f`` over the folds
    where both are scored."""
    d = np.asarray(simple, float) - np.asarray(complex_, float)
    d = d[np.isfinite(d)]
    if len(d) < 2:  # one fold or none: no spread to beat
        return float("nan"), float("nan")
    return float(d.mean()), float(d.std(ddof=1))


def compare(simple: Scored, complex_: Scored) -> Comparison:
    """``complex_`` against ``simple`` (module docstring): a gain above its spread, and
    ``simple`` not at rounding."""
    gain, spread = paired_gain(simple.fold_mse, complex_.fold_mse)
    passed = bool(not simple.exact and gain > 0 and gain > spread)
    return Comparison(simple.name, gain, spread, passed)


@dataclass(frozen=True)
class Choice:
    """The candidate taken, the one-line reason, and per candidate its comparisons with
    the simpler ones it nests and the short text of why it was taken or not."""

    chosen: str
    why: str
    comparisons: Mapping[str, tuple[Comparison, ...]]
    verdicts: Mapping[str, str]


def _gain_text(c: Comparison) -> str:
    return f"{c.gain_cm2:.3g} ± {c.spread_cm2:.2g} cm² over {c.simpler}"


def choose(scored: Sequence[Scored]) -> Choice:
    """The rule of the module docstring over the fitted candidates ``scored`` (the rigid
    chain among them)."""
    by_name = {s.name: s for s in scored}
    comparisons = {
        s.name: tuple(
            compare(by_name[o], s) for o in CANDIDATES if o in by_name and nests(o, s.name)
        )
        for s in scored
    }
    passing = [s for s in scored if all(c.passed for c in comparisons[s.name])]
    best = min(passing, key=lambda s: (s.rms_cm, len(candidate_kinds(s.name))))
    verdicts: dict[str, str] = {}
    for s in scored:
        failed = [c for c in comparisons[s.name] if not c.passed]
        if failed:
            c = failed[0]
            if by_name[c.simpler].exact:
                verdicts[s.name] = f"{c.simpler} fits the data to rounding"
            else:
                verdicts[s.name] = f"gain {_gain_text(c)} not above its spread"
        elif s is best and s.name == "rigid":
            verdicts[s.name] = "simplest; no candidate passes with a lower CV error"
        elif s is best:
            verdicts[s.name] = "passes; the lowest CV error of those that pass"
        else:
            verdicts[s.name] = f"passes, but {best.name} has the lower CV error"
    rigid = by_name["rigid"]
    if best.name == "rigid":
        why = (
            f"rigid chain: no candidate beat its CV error ({rigid.rms_cm:.4g} cm) by more "
            "than the fold-to-fold spread of the gain"
        )
    else:
        gains = "; ".join(_gain_text(c) for c in comparisons[best.name])
        why = (
            f"{best.name}: CV error {best.rms_cm:.4g} cm against the rigid chain's "
            f"{rigid.rms_cm:.4g} cm, gain {gains}, each above its spread"
        )
    return Choice(best.name, why, comparisons, verdicts)


def record(
    scored: Sequence[Scored], choice: Choice, k: int, skipped: Mapping[str, str]
) -> dict[str, Any]:
    """The choice as the refine summary records it (``nongeometric.cv``, JSON): the folds,
    the reason, and per candidate (in :data:`CANDIDATES` order) its terms, CV RMS (cm),
    per-fold MSE (cm²), gains over the simpler ones it nests with their spreads, taken
    or not and why; a candidate not fitted with why (``skipped``)."""

    def num(v: float) -> float | None:
        return float(v) if np.isfinite(v) else None

    by_name = {s.name: s for s in scored}
    rows: list[dict[str, Any]] = []
    for name in CANDIDATES:
        if name in skipped:
            rows.append({"candidate": name, "taken": False, "why": skipped[name]})
            continue
        if name not in by_name:
            continue
        s = by_name[name]
        rows.append(
            {
                "candidate": name,
                "terms": s.n_terms,
                "rms_cm": num(s.rms_cm),
                "fold_mse_cm2": [num(v) for v in s.fold_mse],
                "gains": [
                    {
                        "over": c.simpler,
                        "gain_cm2": num(c.gain_cm2),
                        "spread_cm2": num(c.spread_cm2),
                        "passed": c.passed,
                    }
                    for c in choice.comparisons[name]
                ],
                "taken": name == choice.chosen,
                "why": choice.verdicts[name],
            }
        )
    return {"folds": k, "blocks": "measurement order", "chosen": choice.chosen,
            "why": choice.why, "candidates": rows}  # fmt: skip
