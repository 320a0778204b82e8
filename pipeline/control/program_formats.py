"""Where the targets are in a robot program, and how to write them back: URScript, KUKA
KRL and ABB RAPID (``pipeline compensate --program``, docs/compensate.md).

Each dialect finds the motion targets of a program text (decoded as latin-1, one
character per byte, so that every other byte is written back as it was) and gives, per
target, the character spans of its numbers and their values as a pose (4, 4) in cm or
joint readings in deg / cm. A target is a literal that a motion instruction moves to:

- URScript: ``p[x, y, z, rx, ry, rz]`` (m, rotation vector in rad) or a joint list
  ``[q1, ..., qn]`` (rad) as the first argument of ``movej``, ``movel``, ``movep``,
  ``movec`` or ``servoj``, or assigned to a variable that is (a pose also through
  ``get_inverse_kin``); ``pose_trans`` offsets and ``set_tcp`` are not targets;
- KRL: ``E6POS``/``POS`` aggregates ``{X, Y, Z, A, B, C, ...}`` (mm; A about z, B about
  y, C about x, deg) and ``E6AXIS``/``AXIS`` ``{A1, ..., An}`` (deg), declared in a
  ``.dat`` or inline after ``PTP``, ``LIN``, ``CIRC`` (and their spline forms);
  ``FRAME`` (bases and tools) is not a target;
- RAPID: ``robtarget`` ``[[x, y, z], [q1, q2, q3, q4], [cf...], [eax...]]`` (mm,
  quaternion w x y z) and ``jointtarget`` ``[[j1, ..., j6], [eax...]]`` (deg), declared
  or inline in a ``Move...`` instruction; ``tooldata`` and ``wobjdata`` are not.

Comments (URScript ``#``, KRL ``;``, RAPID ``!``) are skipped; so are KRL aggregates
that state only some axes (a partial target keeps the others' current values, which a
file does not know): they are counted, not rewritten. Configuration data (KRL ``S``,
``T``; RAPID ``cf1 cf4 cf6 cfx``) and external axes are kept: the compensated joints are
within the corrections of the nominal ones, on the same configuration.
"""

from __future__ import annotations

import re
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from scipy.spatial.transform import Rotation

NUM = r"[-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?"
_N = rf"\s*({NUM})\s*"
M_CM, MM_CM = 100.0, 0.1
#: Program files by suffix.
SUFFIXES = {".script": "urscript", ".urscript": "urscript", ".src": "krl", ".dat": "krl",
            ".mod": "rapid", ".prg": "rapid", ".modx": "rapid"}  # fmt: skip
DIALECTS = ("urscript", "krl", "rapid")


@dataclass(frozen=True)
class Target:
    """One motion target: ``kind`` pose (``value`` (4, 4), cm) or joints (``value`` (n,),
    deg / cm), the spans of its numbers in the text, its line, and how to write it back
    (``render``: the new value -> the numbers' texts, in span order)."""

    kind: str
    value: np.ndarray
    spans: tuple[tuple[int, int], ...]
    line: int
    render: Callable[[np.ndarray], list[str]]


@dataclass(frozen=True)
class Found:
    """A program's targets, and the partial ones skipped (their lines)."""

    targets: list[Target]
    partial: list[int]


def _comments(text: str, mark: str) -> list[tuple[int, int]]:
    """Character spans of the comments: ``mark`` to the line's end, outside "strings"."""
    out, at = [], 0
    for line in text.splitlines(keepends=True):
        quoted = False
        for k, c in enumerate(line):
            if c == '"':
                quoted = not quoted
            elif c == mark and not quoted:
                out.append((at + k, at + len(line)))
                break
        at += len(line)
    return out


def _outside(spans: list[tuple[int, int]]) -> Callable[[int], bool]:
    starts = np.array([a for a, _ in spans] or [0])
    ends = np.array([b for _, b in spans] or [0])

    def ok(pos: int) -> bool:
        k = int(np.searchsorted(starts, pos, side="right")) - 1
        return not spans or k < 0 or pos >= ends[k]

    return ok


def _line(text: str, pos: int) -> int:
    return text.count("\n", 0, pos) + 1


def _fmt(v: float, decimals: int) -> str:
    s = f"{v:.{decimals}f}"
    return "0." + "0" * decimals if s.lstrip("-") == "0." + "0" * decimals else s


def _joints_render(scale: np.ndarray, decimals: int) -> Callable[[np.ndarray], list[str]]:
    """Readings (deg / cm) -> the file's numbers (its units: readings / ``scale``)."""
    return lambda q: [_fmt(x, decimals) for x in q / scale]


# --- URScript -------------------------------------------------------------------------

_MOVE = r"\b(?:movej|movel|movep|movec|servoj)\s*\(\s*"
_UR_POSE = re.compile(r"p\[" + ",".join([_N] * 6) + r"\]")


def _ur_joints(n: int) -> re.Pattern[str]:
    return re.compile(r"(?<![\w\]])\[" + ",".join([_N] * n) + r"\]")


def _ur_pose_value(v: np.ndarray) -> np.ndarray:
    T = np.eye(4)
    T[:3, :3] = Rotation.from_rotvec(v[3:]).as_matrix()
    T[:3, 3] = v[:3] * M_CM
    return T


def _ur_render_pose(T: np.ndarray) -> list[str]:
    rv = Rotation.from_matrix(T[:3, :3]).as_rotvec()
    return [_fmt(x, 9) for x in (*(T[:3, 3] / M_CM), *rv)]


def urscript(text: str, n: int, prismatic: np.ndarray) -> Found:
    """URScript targets (module docstring); joint lists need ``n`` values."""
    ok = _outside(_comments(text, "#"))
    used = set(re.findall(_MOVE + r"(\w+)\b", text))
    used |= set(re.findall(r"\bget_inverse_kin\s*\(\s*(\w+)\b", text))
    assigned = {m.end(): m.group(1) for m in re.finditer(r"\b(\w+)\s*=\s*(?!=)", text)}
    moves = {m.end() for m in re.finditer(_MOVE, text)}
    solved = {m.end() for m in re.finditer(r"\bget_inverse_kin\s*\(\s*", text)}
    scale = np.where(prismatic, M_CM, np.degrees(1.0))
    out: list[Target] = []
    for kind, pattern in (("pose", _UR_POSE), ("joints", _ur_joints(n))):
        for m in pattern.finditer(text):
            at = m.start()
            inline = at in moves or (kind == "pose" and at in solved)
            if not ok(at) or not (inline or assigned.get(at) in used):
                continue
            v = np.array([float(m.group(k)) for k in range(1, m.lastindex + 1)])  # type: ignore[operator]
            spans = tuple(m.span(k) for k in range(1, m.lastindex + 1))  # type: ignore[operator]
            where = _line(text, at)
            if kind == "pose":
                out.append(Target("pose", _ur_pose_value(v), spans, where, _ur_render_pose))
            else:
                out.append(Target("joints", v * scale, spans, where, _joints_render(scale, 9)))
    return Found(sorted(out, key=lambda t: t.spans[0]), [])


# --- KRL ------------------------------------------------------------------------------

_AGG = re.compile(r"\{([^{}]*)\}")
_PAIR = re.compile(r"([A-Za-z]\w*)\s+(" + NUM + r")")
_KRL_DECL = re.compile(r"\b(?:DECL\s+)?(?:GLOBAL\s+)?(E6POS|POS|E6AXIS|AXIS)\s+\w+\s*=\s*\{",
                       re.IGNORECASE)  # fmt: skip
_KRL_MOVE = re.compile(r"^\s*(?:PTP|LIN|CIRC|SPTP|SLIN|SCIRC)\b", re.IGNORECASE | re.MULTILINE)


Spans = tuple[tuple[int, int], ...]


def _krl_value(
    pairs: dict[str, tuple[float, tuple[int, int]]], kind: str, n: int, scale: np.ndarray
) -> tuple[np.ndarray, Spans] | None:
    """The pose (4, 4) cm or readings of an aggregate's ``pairs``; None when it lacks one."""
    axes = tuple(f"A{i}" for i in range(1, n + 1))
    keys = ("X", "Y", "Z", "A", "B", "C") if kind == "pose" else axes
    if not all(k in pairs for k in keys):
        return None
    v = np.array([pairs[k][0] for k in keys])
    spans = tuple(pairs[k][1] for k in keys)
    if kind == "joints":
        return v * scale, spans
    T = np.eye(4)
    T[:3, :3] = Rotation.from_euler("ZYX", v[3:], degrees=True).as_matrix()
    T[:3, 3] = v[:3] * MM_CM
    return T, spans


def _krl_render_pose(T: np.ndarray) -> list[str]:
    abc = Rotation.from_matrix(T[:3, :3]).as_euler("ZYX", degrees=True)
    return [_fmt(x, 6) for x in (*(T[:3, 3] / MM_CM), *abc)]


def krl(text: str, n: int, prismatic: np.ndarray) -> Found:
    """KRL targets (module docstring)."""
    ok = _outside(_comments(text, ";"))
    scale = np.where(prismatic, MM_CM, 1.0)
    starts: dict[int, str | None] = {}
    for m in _KRL_DECL.finditer(text):
        if ok(m.start()):
            starts[m.end() - 1] = "joints" if "AXIS" in m.group(1).upper() else "pose"
    for m in _KRL_MOVE.finditer(text):
        end = text.find("\n", m.end())
        for a in _AGG.finditer(text, m.end(), len(text) if end < 0 else end):
            if ok(a.start()):
                starts.setdefault(a.start(), None)
    out, partial = [], []
    for at, kind in sorted(starts.items()):
        agg = _AGG.match(text, at)
        if agg is None:
            continue
        a = agg
        pairs = {p.group(1).upper(): (float(p.group(2)), p.span(2))
                 for p in _PAIR.finditer(text, a.start(1), a.end(1))}  # fmt: skip
        kind = kind or ("pose" if "X" in pairs else "joints")
        got = _krl_value(pairs, kind, n, scale)
        if got is None:
            partial.append(_line(text, at))
            continue
        render = _krl_render_pose if kind == "pose" else _joints_render(scale, 6)
        out.append(Target(kind, got[0], got[1], _line(text, at), render))
    return Found(out, partial)


# --- RAPID ----------------------------------------------------------------------------

_ROBTARGET = re.compile(r"\[\s*\[" + ",".join([_N] * 3) + r"\]\s*,\s*\[" + ",".join([_N] * 4)
                        + r"\]\s*,\s*\[[^\[\]]*\]\s*,\s*\[[^\[\]]*\]\s*\]")  # fmt: skip


def _jointtarget(n: int) -> re.Pattern[str]:
    return re.compile(r"\[\s*\[" + ",".join([_N] * n) + r"\]\s*,\s*\[[^\[\]]*\]\s*\]")


def _rapid_render_pose(T: np.ndarray, before: np.ndarray) -> list[str]:
    x, y, z, w = Rotation.from_matrix(T[:3, :3]).as_quat()
    q = np.array([w, x, y, z])
    q = -q if q @ before < 0 else q  # the file's sign (the same rotation either way)
    return [_fmt(v, 6) for v in T[:3, 3] / MM_CM] + [_fmt(v, 9) for v in q]


def _rapid_render(before: np.ndarray) -> Callable[[np.ndarray], list[str]]:
    """A pose (4, 4) cm -> a robtarget's numbers, the quaternion's sign as ``before``'s."""
    return lambda T: _rapid_render_pose(T, before)


def rapid(text: str, n: int, prismatic: np.ndarray) -> Found:
    """RAPID targets (module docstring): in statements that declare a robtarget or a
    jointtarget, or that move (``Move...``)."""
    ok = _outside(_comments(text, "!"))
    scale = np.where(prismatic, MM_CM, 1.0)
    out: list[Target] = []
    start = 0
    for end in [m.start() for m in re.finditer(";", text)] + [len(text)]:
        statement = text[start:end]
        head = re.match(r"\s*(?:LOCAL\s+|TASK\s+)?(?:(?:CONST|PERS|VAR)\s+(robtarget|jointtarget)\b"
                        r"|(Move\w*)\b)", statement, re.IGNORECASE)  # fmt: skip
        if head is not None and ok(start + head.start(1 if head.group(1) else 2)):
            for m in _ROBTARGET.finditer(text, start, end):
                if not ok(m.start()):
                    continue
                v = np.array([float(m.group(k)) for k in range(1, 8)])
                T = np.eye(4)
                T[:3, :3] = Rotation.from_quat([*v[4:], v[3]]).as_matrix()
                T[:3, 3] = v[:3] * MM_CM
                spans = tuple(m.span(k) for k in range(1, 8))
                q0 = v[3:].copy()
                where = _line(text, m.start())
                out.append(Target("pose", T, spans, where, _rapid_render(q0)))
            for m in _jointtarget(n).finditer(text, start, end):
                if not ok(m.start()):
                    continue
                v = np.array([float(m.group(k)) for k in range(1, n + 1)])
                spans = tuple(m.span(k) for k in range(1, n + 1))
                where = _line(text, m.start())
                out.append(Target("joints", v * scale, spans, where, _joints_render(scale, 6)))
        start = end + 1
    return Found(sorted(out, key=lambda t: t.spans[0]), [])


READERS = {"urscript": urscript, "krl": krl, "rapid": rapid}


def rewrite(text: str, edits: list[tuple[tuple[int, int], str]]) -> str:
    """``text`` with each span replaced by its text (spans do not overlap)."""
    parts, at = [], 0
    for (a, b), new in sorted(edits):
        parts += [text[at:a], new]
        at = b
    return "".join(parts) + text[at:]
