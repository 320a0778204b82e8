"""A signature's verdict as data (``signature.json`` ``refinement.verdict``, the row of the
stage ``verdict``), and the gate ``export`` and ``ik`` pass a signature through: a FAIL is
refused unless accepted, a CHECK is a warning (docs/verdict.md)."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

from pipeline.errors import VerdictFailError
from pipeline.refine.verdict import FAIL, PASS

#: The per-reason columns of the verdict row (stage version 3; older rows lack them).
REASON_KEYS = {"reason_levels": "level", "reason_rules": "rule",
               "reason_values": "value", "reason_thresholds": "threshold"}  # fmt: skip
ACCEPT_OPTION = "--accept-verdict"


@dataclass(frozen=True)
class SignatureVerdict:
    """``status`` PASS / CHECK / FAIL; ``reasons``: per rule that fired, its ``text``,
    ``level``, ``rule`` (the threshold parameter), ``value`` and ``threshold`` (None where
    the row predates them or the rule has no number); ``numbers``: what it was judged on."""

    status: str
    line: str
    reasons: tuple[dict[str, Any], ...] = ()
    numbers: dict[str, float | None] = field(default_factory=dict)

    @property
    def failed(self) -> bool:
        """FAIL: do not ship (``identify`` exits 4, ``export`` and ``ik`` refuse it)."""
        return self.status == FAIL

    def to_dict(self) -> dict[str, Any]:
        """JSON types (``identify --json``)."""
        return {"status": self.status, "line": self.line, "reasons": list(self.reasons),
                "numbers": self.numbers}  # fmt: skip

    def summary(self) -> str:
        """``FAIL (first reason; +N more)``, or the bare status without reasons."""
        if not self.reasons:
            return self.status
        more = f"; +{len(self.reasons) - 1} more" if len(self.reasons) > 1 else ""
        return f"{self.status} ({self.reasons[0]['text']}{more})"


def verdict_from_row(row: dict[str, Any] | None) -> SignatureVerdict | None:
    """The verdict of a verdict row (None: the session's stage list has no verdict)."""
    if not row:
        return None
    texts = list(row.get("reasons") or [])
    columns = {k: row.get(k) or [None] * len(texts) for k in REASON_KEYS}
    reasons = tuple(
        {"text": t, **{REASON_KEYS[k]: columns[k][i] for k in REASON_KEYS}}
        for i, t in enumerate(texts)
    )
    skip = {"verdict", "reasons", "line", *REASON_KEYS}
    numbers = {k: v for k, v in row.items() if k not in skip}
    return SignatureVerdict(str(row["verdict"]), str(row["line"]), reasons, numbers)


def verdict_of(doc: dict[str, Any]) -> SignatureVerdict | None:
    """The verdict of a signature document (None: none recorded)."""
    return verdict_from_row((doc.get("refinement") or {}).get("verdict"))


def verdict_failed(verdict: SignatureVerdict, source: str, fix: str) -> VerdictFailError:
    """The one-line error of a FAIL verdict of the signature of ``source``."""
    return VerdictFailError(
        f"{source}: the signature's verdict is {verdict.summary()}",
        expected="PASS or CHECK (docs/verdict.md)",
        fix=fix,
    )


def verdict_gate(verdict: SignatureVerdict | None, source: str, accept: bool) -> str | None:
    """Pass a signature through its verdict before using it: None for PASS or no verdict;
    a warning for CHECK or an accepted FAIL; a FAIL not ``accept``-ed raises
    :class:`~pipeline.errors.VerdictFailError`."""
    if verdict is None or verdict.status == PASS:
        return None
    if verdict.failed and not accept:
        raise verdict_failed(
            verdict,
            source,
            f"see {source}/report/report.md and identify a better session, or give "
            f"{ACCEPT_OPTION} to use this signature anyway",
        )
    accepted = f" (accepted by {ACCEPT_OPTION})" if verdict.failed else ""
    return f"{source}: the signature's verdict is {verdict.summary()}{accepted}"
