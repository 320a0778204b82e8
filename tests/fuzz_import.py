"""Seeded mutations of import inputs, and faults around armsig's outputs (issue 32, item 8).

Three small foreign sessions are the bases: the two-link arm as SScanSS-2 text and as a
table with a map (``examples/sscanss2/two_link.toml``), and robot_cal_tools' positioner as
YAML with its map (``examples/rct_positioner``), each written from the design model's FK.
Each is imported and identified once; a case then mutates one input or sets up one fault
in its own folder, runs the command line in this process and classifies what happened:

- ``import``: a mutated data file, map or robot description, imported and, if accepted,
  identified;
- ``harmless``: a mutation that leaves what was measured unchanged (CRLF line ends, a
  comment, trailing blanks): the signature must be the base's bit for bit, or be refused;
- ``validate``: a mutated second file for ``validate --against``; the session must stay
  byte-identical (``validate`` writes nothing);
- ``output``: ``export``, ``ik --targets --out``, ``fk --q-file --out`` or ``viz --out``
  onto a faulty target (a user's file, the session's recording, symlinks, an immutable
  file or folder, a file in place of a folder, a missing folder, a name too long), with
  and without ``--force``; ``import`` into a faulty NAME;
- ``stale``: the session changed under its signature (``import --force`` of other data,
  another recording copied in, a stage table or signature.json edited), then a consumer
  (``fk``, ``ik``, ``export``, ``validate``, ``viz``, ``show``) is run;
- ``concurrent`` (``--concurrent``, subprocesses): two imports into one new session, or
  ``import --force`` racing ``identify``.

Outcomes: ``refused`` (exit 1, one ``error:`` line), ``accepted`` (exit 0, 3 or 4; an
accepted import is identified, its outcome in the detail), ``same`` (a harmless mutation,
the base's signature bit for bit), and the failures: ``traceback`` (an exception escaped
the command line), ``exit70`` (armsig's internal error), ``multiline`` (a refusal not in
one line), ``hang`` (no answer within :data:`TIMEOUT_S`), ``destroyed`` (a file the
command did not create, changed or gone: a user's file without ``--force``, a session's
recording ever), ``stale`` (a consumer served a signature of other data, or ``show``
printed an edited table without a word) and ``changed`` (a harmless mutation changed the
signature).

``make fuzz-import`` runs the acceptance campaign (1,000 cases and the concurrent ones);
``tests/test_fuzz_import.py`` runs a seeded sample bounded in time in ``make test``.
"""

from __future__ import annotations

import argparse
import contextlib
import hashlib
import os
import re
import shutil
import subprocess
import sys
import tempfile
import time
from collections import Counter
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from fuzz_recording import Timeout, alarm, tool_positions
from import_data import (
    TWO_LINK,
    TWO_LINK_MAP,
    TWO_LINK_VALUES,
    sscanss2_text,
    two_link_table,
)

ROOT = Path(__file__).resolve().parent.parent
RCT = ROOT / "examples" / "rct_positioner"
TIMEOUT_S = 60.0  # issue 32: "0 hangs over 60 s"; a base imports and identifies in ~1 s
FAILURES = ("traceback", "exit70", "multiline", "hang", "destroyed", "stale", "changed")
KINDS = {"import": 30, "map": 20, "harmless": 8, "validate": 15, "output": 17, "stale": 10}

#: What a number in a data file is replaced with.
CELLS = ("nan", "NaN", "inf", "-inf", "-1e400", "1e400", "1e308", "", " ", "0", "-0", "1e6",
         "-99999", "x", "1,5", "1.5.5", "0x10", "١٢", "1e-320", "+5", "--1", "null", "~",
         "true", "[1, 2]", "{a: 1}", "&a 1", "*a", "!!python/object:os.system", "'", '"', "#",
         "1e", "∞", "é", "\x00", "a" * 140_000)  # fmt: skip
#: Characters a random one is replaced with (separators, line ends editors disagree on).
CHARS = "0123456789-.,;:\t \n\r\x0c\x0b\x85\u2028eE+naé\x00#\"'&*[]{}"
#: What a TOML value (map or robot description) is replaced with.
VALUES = ('"false"', "false", "true", "nan", "inf", "-inf", "-1", "0", "1.9", "2.7", "5", "99",
          '"one"', '"17"', '""', "[]", "{}", "[1, 2]", '{ "-1" = 0 }', '{ "99" = 0 }',
          '{ "1" = "x" }', "1e400", '"x1"', '"j2_rad"', '"mm"', '"furlong"', '"\\u0000"',
          '"' + "a" * 140_000 + '"', "[" * 3000 + "]" * 3000, "1979-05-27", "-0.0",
          "[[1, 2], [3]]", "[0, 0, 0, 0, 0, 0, 0, 0, 0]", "1e-300",
          "12345678901234567890")  # fmt: skip
_NUMBER = re.compile(r"-?\d+(?:\.\d+)?(?:[eE][-+]?\d+)?")
_KEY_LINE = re.compile(r"^(\s*[\w\"\-.]+\s*=\s*)(.+)$", re.M)


# --------------------------------------------------------------------------- bases


def rct_yaml() -> str:
    """robot_cal_tools YAML of the positioner (design FK): a tilt x turntable grid,
    tilt -30..30 deg by 10, turntable 0..315 deg by 45 (the map's sweeps and checks)."""
    from scipy.spatial.transform import Rotation

    from pipeline.kinematics.chain import forward_kinematics
    from pipeline.robots.description import load_description
    from pipeline.units import joints_to_internal

    robot = load_description(RCT / "positioner.toml")
    q = np.array([(a, b) for a in range(-30, 31, 10) for b in range(0, 316, 45)], float)
    T = forward_kinematics(robot.design_chain(), joints_to_internal(q, robot.prismatic))
    out = []
    for k, (qk, Tk) in enumerate(zip(q, T, strict=True)):
        w = Rotation.from_matrix(Tk[:3, :3]).as_quat(scalar_first=True)
        x, y, z = Tk[:3, 3] / 100.0
        pose = f"x: {x:.15g}, y: {y:.15g}, z: {z:.15g}, qw: {w[0]:.15g}, qx: {w[1]:.15g}, "
        pose += f"qy: {w[2]:.15g}, qz: {w[3]:.15g}"
        joints = ", ".join(f"{v:.15g}" for v in np.deg2rad(qk))
        out.append(f"'{1593701755 + 50 * k}':\n  camera_joints: []\n  pose: {{{pose}}}\n"
                   f"  target_joints: [{joints}]\n")  # fmt: skip
    return "".join(out)


@dataclass
class Base:
    """A foreign session: its files (role -> text), format, and once identified, where."""

    name: str
    fmt: str
    files: dict[str, str]
    session: Path = Path()
    reference: np.ndarray = field(default_factory=lambda: np.zeros(0))
    targets: Path = Path()  # an `ik --targets` file of reachable poses
    q_file: Path = Path()  # an `fk --q-file` file

    def write(self, folder: Path, files: dict[str, str | bytes] | None = None) -> dict[str, Path]:
        """The files (``files`` replacing some) in ``folder``; role -> path."""
        folder.mkdir(parents=True, exist_ok=True)
        ext = {"data": {"sscanss2": "txt", "table": "csv", "rct": "yaml"}[self.fmt]}
        out = {}
        for role, text in {**self.files, **(files or {})}.items():
            p = folder / f"{role}.{ext.get(role, 'toml')}"
            p.write_bytes(text if isinstance(text, bytes) else text.encode("utf-8"))
            out[role] = p
        return out

    def import_args(self, paths: dict[str, Path], name: Path, force: bool = False) -> list[str]:
        args = ["import", str(paths["data"]), str(name), "--format", self.fmt,
                "--robot", str(paths["robot"])]  # fmt: skip
        if "map" in paths:
            args += ["--map", str(paths["map"])]
        return args + (["--force"] if force else [])

    def against_args(self, paths: dict[str, Path]) -> list[str]:
        args = ["--against", str(paths["data"]), "--format", self.fmt]
        return args + (["--map", str(paths["map"])] if "map" in paths else [])


def make_bases(work: Path) -> list[Base]:
    """The three bases, imported and identified in ``work`` (with their references)."""
    tmp = work / "base-files"
    tmp.mkdir(parents=True)
    two = TWO_LINK.read_text()
    big = tmp / "two_link_20cm.toml"  # the table's features need more than 1 cm of motion
    big.write_text(two.replace("a_cm = 0.1", "a_cm = 20.0"))
    bases = [
        Base("sscanss2", "sscanss2", {"data": sscanss2_text(TWO_LINK, TWO_LINK_VALUES, digits=15),
                                      "robot": two}),
        Base("table", "table", {"data": two_link_table(tmp / "t.csv", big).read_text(),
                                "map": TWO_LINK_MAP, "robot": big.read_text()}),
        Base("rct", "rct", {"data": rct_yaml(), "map": (RCT / "map.toml").read_text(),
                            "robot": (RCT / "positioner.toml").read_text()}),
    ]  # fmt: skip
    for b in bases:
        d = work / f"base-{b.name}"
        paths = b.write(d)
        b.session = d / "session"
        for args in (b.import_args(paths, b.session), ["identify", str(b.session), "--no-report"]):
            r = cli(args)
            assert r.code == 0, (args, r.stderr, r.error)
        b.reference = tool_positions(b.session / "signature.json")
        robot = paths["robot"]
        q = _readings(robot, 5)
        b.q_file = d / "q.csv"
        b.q_file.write_text(
            ",".join(f"q{j + 1}_deg" for j in range(q.shape[1])) + "\n"
            + "\n".join(",".join(f"{v:.6f}" for v in row) for row in q) + "\n"
        )  # fmt: skip
        b.targets = d / "targets.arrow"
        r = cli(["fk", str(b.session), "--q-file", str(b.q_file), "--out", str(b.targets)])
        assert r.code == 0, r.stderr
    return bases


def _readings(robot_toml: Path, n: int) -> np.ndarray:
    from pipeline.robots.description import load_description

    lim = load_description(robot_toml).limits
    return np.random.default_rng(1).uniform(lim[:, 0], lim[:, 1], (n, lim.shape[0])) * 0.5


# --------------------------------------------------------------------------- running


@dataclass(frozen=True)
class Run:
    """One command line run in this process."""

    code: int | None  # None: an exception escaped the command line
    stderr: str
    error: str  # the escaped exception


def cli(args: list[str]) -> Run:
    """``pipeline ARGS`` in this process; a :data:`TIMEOUT_S` alarm raises :class:`Timeout`,
    which the command line re-raises (a KeyboardInterrupt)."""
    import warnings

    from typer.testing import CliRunner

    from pipeline.cli import app

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        r = CliRunner().invoke(app, args)
    if isinstance(r.exception, Timeout):
        raise r.exception
    if r.exception is not None and not isinstance(r.exception, SystemExit):
        return Run(None, r.stderr, f"{type(r.exception).__name__}: {r.exception}")
    return Run(r.exit_code, r.stderr, "")


def verdict(r: Run, accepted: tuple[int, ...] = (0, 3, 4)) -> tuple[str, str]:
    """The class of one run: refused, accepted or a failure (module docstring)."""
    err = r.stderr.strip()
    if r.code is None:
        return "traceback", r.error[:300]
    if r.code == 70:
        return "exit70", err[:300]
    if "Traceback" in r.stderr:
        return "traceback", err[-300:]
    if r.code in accepted:
        return "accepted", f"exit {r.code}"
    lines = err.splitlines()
    if len(lines) != 1 or not lines[0].startswith("error: "):
        return "multiline", f"exit {r.code}: {err[:300]!r}"
    return "refused", lines[0][:300]


def snapshot(folder: Path) -> dict[Path, bytes]:
    """Every regular file under ``folder`` (symlinks not followed), with its bytes."""
    out = {}
    for p in folder.rglob("*"):
        if p.is_file() and not p.is_symlink():
            with contextlib.suppress(OSError):
                out[p] = p.read_bytes()
    return out


def destroyed(before: dict[Path, bytes], allowed: set[Path] = frozenset()) -> list[Path]:  # type: ignore[assignment]
    """Files of ``before`` changed or gone, except ``allowed`` ones."""
    return [p for p, data in before.items() if p not in allowed
            and (not p.is_file() or p.read_bytes() != data)]  # fmt: skip


def sha256(path: Path) -> str | None:
    return hashlib.sha256(path.read_bytes()).hexdigest() if path.is_file() else None


def immutable(path: Path, on: bool) -> bool:
    """``chattr +i`` / ``-i`` (False when the file system or the user cannot)."""
    r = subprocess.run(["chattr", "+i" if on else "-i", str(path)], capture_output=True)
    return r.returncode == 0


# --------------------------------------------------------------------------- mutations


DATA_MUTATIONS = ("cell", "cell", "cell", "nudge", "char", "char", "delete_line", "dup_line",
                  "swap_lines", "truncate", "blank", "garbage_line", "bom", "latin1", "utf16",
                  "nul", "empty", "sep", "drop_field", "swap_fields", "long_line")  # fmt: skip


def mutate_data(
    text: str, rng: np.random.Generator, fmt: str, kinds: tuple[str, ...] = DATA_MUTATIONS
) -> tuple[str, str | bytes]:
    """One random mutation of a data file (of ``kinds``): its label and the new content."""
    kind = str(rng.choice(kinds))
    lines = text.splitlines(keepends=True)
    k = int(rng.integers(len(lines)))
    nums = list(_NUMBER.finditer(text))
    if kind in ("cell", "nudge"):
        m = nums[int(rng.integers(len(nums)))]
        if kind == "cell":
            new = CELLS[int(rng.integers(len(CELLS)))]
        else:
            new = f"{float(m.group()) + float(rng.choice([-1, 1])) * 10 ** rng.uniform(-6, 1):.12g}"
        return f"{kind}@{m.start()}={new[:20]!r}", text[: m.start()] + new + text[m.end() :]
    if kind == "char":
        at = int(rng.integers(len(text)))
        c = CHARS[int(rng.integers(len(CHARS)))]
        return f"char@{at}={c!r}", text[:at] + c + text[at + 1 :]
    if kind == "delete_line":
        return f"delete_line{k}", "".join(lines[:k] + lines[k + 1 :])
    if kind == "dup_line":
        return f"dup_line{k}", "".join(lines[: k + 1] + lines[k:])
    if kind == "swap_lines":
        j = int(rng.integers(len(lines)))
        lines[k], lines[j] = lines[j], lines[k]
        return f"swap_lines{k},{j}", "".join(lines)
    if kind == "truncate":
        at = int(rng.integers(len(text)))
        return f"truncate@{at}", text[:at]
    if kind == "blank":
        return f"blank@{k}", "".join(lines[:k] + ["\n"] + lines[k:])
    if kind == "garbage_line":
        return f"garbage@{k}", "".join(lines[:k] + ["1;2;3 x ::: ]]\n"] + lines[k:])
    if kind == "bom":
        return "bom", "\ufeff" + text
    if kind == "latin1":
        return "latin1", ("# mesuré\n" + text if fmt != "sscanss2" else text).encode("latin-1")
    if kind == "utf16":
        return "utf16", text.encode("utf-16")
    if kind == "nul":
        at = int(rng.integers(len(text)))
        return f"nul@{at}", text[:at] + "\x00" * 8 + text[at:]
    if kind == "empty":
        return "empty", ""
    if kind == "sep":
        a, b = (str(c) for c in rng.choice(list(",;\t :"), 2, replace=False))
        return f"sep{a!r}->{b!r}", text.replace(a, b)
    if kind in ("drop_field", "swap_fields"):
        sep = "\t" if fmt == "sscanss2" else ","
        out = []
        f = int(rng.integers(8))
        for line in lines:
            cells = line.rstrip("\n").split(sep)
            if f < len(cells) and kind == "drop_field":
                del cells[f]
            elif f + 1 < len(cells):
                cells[f], cells[f + 1] = cells[f + 1], cells[f]
            out.append(sep.join(cells) + "\n")
        return f"{kind}{f}", "".join(out)
    return "long_line", text + "9" * 1_000_000 + "\n"


def mutate_toml(text: str, rng: np.random.Generator) -> tuple[str, str | bytes]:
    """One random mutation of a map or robot description."""
    kinds = ["value", "value", "value", "value", "number", "number", "delete_line", "dup_line",
             "unknown_key", "rename_key", "char", "truncate", "not_utf8", "deep"]  # fmt: skip
    kind = str(rng.choice(kinds))
    lines = text.splitlines(keepends=True)
    k = int(rng.integers(len(lines)))
    keyed = list(_KEY_LINE.finditer(text))
    if kind == "value" and keyed:
        m = keyed[int(rng.integers(len(keyed)))]
        v = VALUES[int(rng.integers(len(VALUES)))]
        return f"value:{m.group(1).strip()}{v[:20]}", text[: m.start(2)] + v + text[m.end(2) :]
    if kind == "number":
        nums = list(_NUMBER.finditer(text))
        m = nums[int(rng.integers(len(nums)))]
        v = str(rng.choice(["nan", "inf", "-1", "0", "1e400", "99", "1.5", "-0.0", "1e9"]))
        return f"number@{m.start()}={v}", text[: m.start()] + v + text[m.end() :]
    if kind == "delete_line":
        return f"delete_line{k}", "".join(lines[:k] + lines[k + 1 :])
    if kind == "dup_line":
        return f"dup_line{k}", "".join(lines[: k + 1] + lines[k:])
    if kind == "unknown_key":
        return f"unknown_key@{k}", "".join(lines[:k] + ["colour = 3\n"] + lines[k:])
    if kind == "rename_key" and keyed:
        m = keyed[int(rng.integers(len(keyed)))]
        return f"rename:{m.group(1).strip()}", text[: m.end(1) - 3] + "x" + text[m.end(1) - 3 :]
    if kind == "char":
        at = int(rng.integers(len(text)))
        c = CHARS[int(rng.integers(len(CHARS)))]
        return f"char@{at}={c!r}", text[:at] + c + text[at + 1 :]
    if kind == "truncate":
        at = int(rng.integers(len(text)))
        return f"truncate@{at}", text[:at]
    if kind == "not_utf8":
        at = int(rng.integers(len(text)))
        return f"not_utf8@{at}", text[:at].encode() + b"\xff\xfe" + text[at:].encode()
    return "deep", text + "deep = " + "[" * 5000 + "]" * 5000 + "\n"


def harmless(text: str, rng: np.random.Generator, role: str) -> tuple[str, str]:
    """A mutation that leaves what the file says unchanged."""
    kind = str(rng.choice(["crlf", "final_blank"] if role == "data" else
                          ["crlf", "comment", "trailing_blanks"]))  # fmt: skip
    if kind == "crlf":
        return "crlf", text.replace("\n", "\r\n")
    if kind == "final_blank":
        return "final_blank", text + "\n"
    lines = text.splitlines(keepends=True)
    if kind == "comment":
        k = int(rng.integers(len(lines) + 1))
        return f"comment@{k}", "".join(lines[:k] + ["# a comment = 3 [x]\n"] + lines[k:])
    return "trailing_blanks", "".join(line.replace("\n", "  \t\n") for line in lines)


# --------------------------------------------------------------------------- cases


@dataclass(frozen=True)
class Outcome:
    kind: str
    label: str
    result: str  # refused, accepted, same, or one of FAILURES
    detail: str


def _identify_after(b: Base, session: Path, label: str, same: bool) -> tuple[str, str]:
    """Identify an accepted import; for a harmless mutation compare with the base."""
    r = cli(["identify", str(session), "--no-report"])
    res, detail = verdict(r)
    if res in FAILURES:
        return res, "identify: " + detail
    if res == "refused":
        return ("refused" if same else "accepted"), "imported; identify: " + detail
    if not same:
        return "accepted", f"identified ({detail})"
    diff = float(np.max(np.abs(tool_positions(session / "signature.json") - b.reference)))
    return ("same", "bit for bit") if diff == 0.0 else ("changed", f"moved {diff:.3e} cm")


def case_import(b: Base, d: Path, rng: np.random.Generator, kind: str) -> tuple[str, str, str]:
    if kind == "import":
        role = "data"
        label, text = mutate_data(b.files["data"], rng, b.fmt)
    elif kind == "map":
        role = str(rng.choice([r for r in ("map", "robot") if r in b.files]))
        label, text = mutate_toml(b.files[role], rng)
    else:
        role = str(rng.choice(list(b.files)))
        label, text = harmless(b.files[role], rng, role)
    paths = b.write(d, {role: text})
    res, detail = verdict(cli(b.import_args(paths, d / "s")))
    if res == "accepted":
        res, detail = _identify_after(b, d / "s", label, kind == "harmless")
    return f"{role}:{label}", res, detail


def case_validate(b: Base, d: Path, rng: np.random.Generator) -> tuple[str, str, str]:
    role = "data" if "map" not in b.files or rng.random() < 0.7 else "map"
    label, text = (mutate_data(b.files["data"], rng, b.fmt) if role == "data"
                   else mutate_toml(b.files["map"], rng))  # fmt: skip
    paths = b.write(d / "in", {role: text})
    s = d / "s"
    shutil.copytree(b.session, s, symlinks=True)
    before = snapshot(s)
    res, detail = verdict(cli(["validate", str(s), *b.against_args(paths)]))
    gone = destroyed(before)
    if gone:
        return f"{role}:{label}", "destroyed", f"{gone[0]} changed by validate ({detail})"
    return f"{role}:{label}", res, detail


TARGETS = ("new", "user_file", "user_file_immutable", "recording", "link_to_recording",
           "link_to_user_file", "dangling_link", "immutable_folder", "file_as_folder",
           "missing_folder", "folder", "long_name", "evaluation")  # fmt: skip


def _target(kind: str, d: Path, s: Path) -> tuple[Path, list[Path]]:
    """The output path of a target fault, and what to undo (chattr -i) afterwards."""
    user = d / "user.txt"
    user.write_text("a user's file\n")
    undo: list[Path] = []
    if kind == "new":
        return d / "new.out", undo
    if kind == "user_file":
        return user, undo
    if kind == "user_file_immutable":
        if immutable(user, True):
            undo.append(user)
        return user, undo
    if kind == "recording":
        return s / "recording.mcap", undo
    if kind == "evaluation":
        (s / "evaluation.mcap").write_bytes(b"measured on the rig")
        return s / "evaluation.mcap", undo
    if kind in ("link_to_recording", "link_to_user_file", "dangling_link"):
        link = d / "link.out"
        link.symlink_to({"link_to_recording": s / "recording.mcap", "link_to_user_file": user,
                         "dangling_link": d / "nowhere" / "x"}[kind])  # fmt: skip
        return link, undo
    if kind == "immutable_folder":
        (d / "ro").mkdir()
        if immutable(d / "ro", True):
            undo.append(d / "ro")
        return d / "ro" / "x.out", undo
    if kind == "file_as_folder":
        return user / "x.out", undo
    if kind == "missing_folder":
        return d / "no" / "such" / "x.out", undo
    if kind == "folder":
        (d / "adir").mkdir()
        return d / "adir", undo
    return d / ("n" * 300 + ".out"), undo


def case_output(b: Base, d: Path, rng: np.random.Generator) -> tuple[str, str, str]:
    s = d / "s"
    shutil.copytree(b.session, s, symlinks=True)
    kind = str(rng.choice(TARGETS))
    force = bool(rng.random() < 0.5)
    command = str(rng.choice(["export", "ik", "fk", "viz", "import"]))
    if command == "import":  # a faulty NAME: the session folder is the target
        return case_import_name(b, d, kind, force)
    out, undo = _target(kind, d, s)
    before = snapshot(d)
    args = {
        "export": ["export", str(s), "--format", str(rng.choice(["urdf", "dh", "mdh", "json"]))],
        "ik": ["ik", str(s), "--targets", str(b.targets)],
        "fk": ["fk", str(s), "--q-file", str(b.q_file)],
        "viz": ["viz", str(s)],
    }[command] + ["--out", str(out)]
    if force and command != "viz":
        args.append("--force")
    label = f"{command}:{kind}{':force' if force else ''}"
    try:
        res, detail = verdict(cli(args))
    finally:
        for p in undo:
            immutable(p, False)
    target = out.resolve() if os.path.islink(out) else out  # islink: False on a long name
    allowed = (
        {target} if force and target.name not in ("recording.mcap", "evaluation.mcap") else set()
    )
    gone = destroyed(before, allowed)
    if gone:
        return label, "destroyed", f"{gone[0].relative_to(d)} ({detail})"
    return label, res, detail


def case_import_name(b: Base, d: Path, kind: str, force: bool) -> tuple[str, str, str]:
    """``import`` into a faulty NAME (the session folder as the output)."""
    paths = b.write(d / "in")
    undo: list[Path] = []
    name = {"new": d / "new", "user_file": paths["data"], "recording": d / "s",
            "dangling_link": d / "link", "link_to_recording": d / "link",
            "link_to_user_file": d / "link", "file_as_folder": paths["robot"] / "x",
            "missing_folder": d / "a" / "b", "long_name": d / ("n" * 300),
            "immutable_folder": d / "ro" / "x", "folder": d / "empty",
            "user_file_immutable": paths["data"]}.get(kind, d / "s")  # fmt: skip
    if kind in ("dangling_link", "link_to_recording", "link_to_user_file"):
        name.symlink_to({"dangling_link": d / "nowhere", "link_to_recording": d / "s",
                         "link_to_user_file": paths["data"]}[kind])  # fmt: skip
    elif kind == "folder":
        name.mkdir()
    elif kind == "user_file_immutable" and immutable(name, True):
        undo.append(name)
    elif kind == "immutable_folder":
        (d / "ro").mkdir()
        if immutable(d / "ro", True):
            undo.append(d / "ro")
    before = snapshot(d)
    try:
        res, detail = verdict(cli(b.import_args(paths, name, force)))
    finally:
        for p in undo:
            immutable(p, False)
    # --force may replace the recording of an existing session, but not the user's inputs
    allowed = {d / "s" / "recording.mcap"} if force else set()
    allowed |= {p for p in before if "stages" in p.parts or p.name == "signature.json"}
    gone = destroyed(before, allowed)
    label = f"import:{kind}{':force' if force else ''}"
    if gone:
        return label, "destroyed", f"{gone[0].relative_to(d)} ({detail})"
    return label, res, detail


def edit_arrow_value(path: Path, rng: np.random.Generator) -> str:
    """Change one float of a stage table, keeping it a valid Arrow file with its metadata."""
    import pyarrow as pa
    import pyarrow.ipc as ipc

    with pa.memory_map(str(path)) as src:
        table = ipc.open_file(src).read_all()
    cols = [i for i, f in enumerate(table.schema) if pa.types.is_floating(f.type)]
    if not cols or table.num_rows == 0:
        return ""  # nothing to edit
    i = int(rng.choice(cols))
    values = table.column(i).to_numpy(zero_copy_only=False).copy()
    values[int(rng.integers(len(values)))] += 0.5
    table = table.set_column(i, table.schema.field(i), pa.array(values, table.schema.field(i).type))
    with ipc.new_file(str(path), table.schema) as w:
        w.write_table(table)
    return table.schema.field(i).name


CONSUMERS = ("fk", "ik", "export", "validate", "viz", "show")


def case_stale(
    b: Base, bases: list[Base], d: Path, rng: np.random.Generator
) -> tuple[str, str, str]:
    s = d / "s"
    shutil.copytree(b.session, s, symlinks=True)
    change = str(rng.choice(["reimport", "copy_recording", "edit_stage", "edit_signature"]))
    consumer = str(rng.choice(CONSUMERS))
    rec = sha256(s / "recording.mcap")
    stage = "refine"
    if change == "reimport":
        _, text = mutate_data(b.files["data"], rng, b.fmt, ("nudge",))  # other measurements
        paths = b.write(d / "in", {"data": text})
        cli(b.import_args(paths, s, force=True))
        what = "recording changed" if sha256(s / "recording.mcap") != rec else ""
    elif change == "copy_recording":
        other = [o for o in bases if o is not b][int(rng.integers(len(bases) - 1))]
        shutil.copyfile(other.session / "recording.mcap", s / "recording.mcap")
        what = "recording changed" if sha256(s / "recording.mcap") != rec else ""
    elif change == "edit_stage":
        tables = sorted((s / "stages").glob("*.arrow"))
        p = tables[int(rng.integers(len(tables)))]
        stage = p.stem
        column = edit_arrow_value(p, rng)
        what = f"edited {p.name}:{column}" if column else ""
    else:
        doc = (s / "signature.json").read_text()
        m = list(_NUMBER.finditer(doc))[int(rng.integers(40, 200))]
        (s / "signature.json").write_text(doc[: m.start()] + "7" + doc[m.end() :])
        what = "signature.json edited" if m.group() != "7" else ""  # "7" over 7: unchanged
    paths = b.write(d / "in2")
    args = {
        "fk": ["fk", str(s), "--q", "10 10"],  # every base is a two-joint arm
        "ik": ["ik", str(s), "--targets", str(b.targets), "--out", str(d / "j.arrow")],
        "export": ["export", str(s), "--format", "urdf", "--out", str(d / "x.urdf")],
        "validate": ["validate", str(s), *b.against_args(paths)],
        "viz": ["viz", str(s), "--out", str(d / "v.mcap")],
        "show": ["show", str(s), stage],
    }[consumer]
    r = cli(args)
    res, detail = verdict(r)
    label = f"{change}->{consumer}"
    served = res == "accepted" and bool(what)  # nothing changed: serving is right
    if served and consumer == "show":  # show prints what is there, saying if it was edited
        if change != "edit_stage" or "warning" in r.stderr:
            return label, "accepted", f"{what}; {r.stderr.strip()[:200]}"
    if served:
        return label, "stale", f"{what}; {consumer} exit {r.code}"
    return label, res, f"{what or 'unchanged'}; {detail}"


def case_concurrent(b: Base, d: Path, rng: np.random.Generator) -> tuple[str, str, str]:
    """Two subprocesses at once: two imports into one new session, or ``import --force``
    racing ``identify`` on an identified one. Each ends accepted or refused in one line;
    afterwards a served signature is that of the session's recording."""
    s = d / "s"
    paths = b.write(d / "in")
    _, text = mutate_data(b.files["data"], np.random.default_rng(int(rng.integers(1 << 30))), "x")
    other = b.write(d / "in2", {"data": text})
    if rng.random() < 0.5:
        label = "import||import"
        runs = [b.import_args(paths, s), b.import_args(other, s)]
    else:
        label = "import--force||identify"
        shutil.copytree(b.session, s, symlinks=True)
        runs = [b.import_args(other, s, force=True), ["identify", str(s), "--no-report"]]
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    procs = [subprocess.Popen([sys.executable, "-m", "pipeline", *a], env=env, text=True,
                              stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
             for a in runs]  # fmt: skip
    results = []
    for p in procs:
        try:
            _, err = p.communicate(timeout=TIMEOUT_S)
        except subprocess.TimeoutExpired:
            p.kill()
            return label, "hang", " ".join(runs[procs.index(p)][:1])
        results.append(verdict(Run(p.returncode, err, "")))
    for res, detail in results:
        if res in FAILURES:
            return label, res, detail
    r = cli(["fk", str(s), "--json", "--q", "10 10"])
    if r.code == 0:
        import json

        doc = json.loads((s / "signature.json").read_text())
        if doc["provenance"]["recording_sha256"] != sha256(s / "recording.mcap"):
            return label, "stale", "fk served a signature of another recording"
    return label, "accepted", "; ".join(f"{res}: {detail[:80]}" for res, detail in results)


def run_case(kind: str, b: Base, bases: list[Base], d: Path, rng: np.random.Generator) -> Outcome:
    try:
        with alarm(TIMEOUT_S):
            if kind in ("import", "map", "harmless"):
                label, res, detail = case_import(b, d, rng, kind)
            elif kind == "validate":
                label, res, detail = case_validate(b, d, rng)
            elif kind == "output":
                label, res, detail = case_output(b, d, rng)
            elif kind == "stale":
                label, res, detail = case_stale(b, bases, d, rng)
            else:
                label, res, detail = case_concurrent(b, d, rng)
    except Timeout:
        label, res, detail = "?", "hang", f"no answer within {TIMEOUT_S:g} s"
    finally:
        subprocess.run(["chattr", "-R", "-i", str(d)], capture_output=True)
        shutil.rmtree(d, ignore_errors=True)
    return Outcome(kind, f"{b.name}:{label}", res, detail)


def fuzz(
    n: int,
    seed: int = 0,
    budget_s: float | None = None,
    concurrent: int = 0,
    progress: Callable[[int, Outcome], None] | None = None,
) -> list[Outcome]:
    """``n`` seeded cases (kinds drawn with the weights :data:`KINDS`) and ``concurrent``
    concurrent ones, stopping once ``budget_s`` seconds of this process's CPU time have
    passed (CPU, not wall-clock, as :func:`fuzz_recording.fuzz`: a loaded machine does not
    shrink the sample)."""
    rng = np.random.default_rng(seed)
    kinds = list(KINDS)
    p = np.array(list(KINDS.values()), float)
    plan = [str(k) for k in rng.choice(kinds, n, p=p / p.sum())] + ["concurrent"] * concurrent
    out: list[Outcome] = []
    t0 = time.process_time()
    with _workdir() as work:
        bases = make_bases(work)
        for k, kind in enumerate(plan):
            if budget_s is not None and time.process_time() - t0 > budget_s:
                break
            b = bases[int(rng.integers(len(bases)))]
            case_rng = np.random.default_rng([seed, k])
            outcome = run_case(kind, b, bases, work / f"c{k}", case_rng)
            out.append(outcome)
            if progress:
                progress(k, outcome)
    return out


@contextlib.contextmanager
def _workdir() -> Iterator[Path]:
    with tempfile.TemporaryDirectory(prefix="armsig-fuzz-import-") as tmp:
        try:
            yield Path(tmp)
        finally:
            subprocess.run(["chattr", "-R", "-i", tmp], capture_output=True)


def summary(outcomes: list[Outcome], failures: tuple[str, ...] = FAILURES) -> str:
    """Counts per result and per kind, and every failure (one of ``failures``) with its
    detail."""
    counts = Counter(o.result for o in outcomes)
    kinds = Counter(o.kind for o in outcomes)
    lines = [f"{len(outcomes)} cases: " + ", ".join(f"{k} {v}" for k, v in sorted(counts.items())),
             "  by kind: " + ", ".join(f"{k} {v}" for k, v in sorted(kinds.items()))]  # fmt: skip
    lines += [f"  {o.result:10s} {o.kind}:{o.label}: {o.detail}" for o in outcomes
              if o.result in failures]  # fmt: skip
    return "\n".join(lines)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--cases", type=int, default=1000)
    ap.add_argument("--concurrent", type=int, default=20, help="concurrent cases (subprocesses)")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--verbose", action="store_true", help="print every case")
    args = ap.parse_args()
    t0 = time.perf_counter()

    def show(k: int, o: Outcome) -> None:
        if args.verbose or o.result in FAILURES:
            print(f"[{k}] {o.result}: {o.kind}:{o.label}: {o.detail}", flush=True)

    outcomes = fuzz(args.cases, args.seed, concurrent=args.concurrent, progress=show)
    print(summary(outcomes))
    print(f"{time.perf_counter() - t0:.1f} s")
    sys.exit(1 if any(o.result in FAILURES for o in outcomes) else 0)


if __name__ == "__main__":
    main()
