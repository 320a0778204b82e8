"""Seeded odd input on the surfaces of issue 44, run in this process (a sibling of
``tests/fuzz_import.py``, whose runner, classes and alarm it uses).

One UR10 pose set (``tests/import_data.py``) is imported and identified once; each case
then gives one command one odd value:

- ``plan``: ``--sigma-mm``, ``--target-rms-mm``, ``--center-sigma-mm`` or
  ``--plane-sigma-deg`` of a value drawn from non-finite, zero, negative, tiny, huge and
  ordinary numbers;
- ``map``: ``import`` with a map whose ``[orientation] convention`` is any three letters
  of ``XYZxyz`` (or junk) and whose stated ``sigma`` is such a number;
- ``validate``: ``validate --against`` a copy of a second file with one cell such a
  number (the session must stay byte-identical);
- ``name``: a session command (``status``, ``show``, ``fk``, ``ik``, ``audit``,
  ``export``, ``viz``, ``identify``) given a NAME of 200-400 bytes, ASCII or not;
- ``onto``: ``export --onto`` a device, a pipe, a folder, an empty file or random bytes.

Outcomes as ``fuzz_import``: ``refused`` / ``accepted``, and the failures (a traceback,
exit 70, a refusal of more than one line, a hang, a destroyed file) and ``silent``: a
plan or an import that took a number outside its range (not finite, not positive, a σ
under 1 nm) without a word.
"""

from __future__ import annotations

import argparse
import math
import os
import shutil
import sys
import tempfile
import time
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

import numpy as np
from fuzz_import import TIMEOUT_S, Outcome, cli, destroyed, snapshot, summary, verdict
from fuzz_recording import Timeout, alarm
from import_data import UR10, pose_set_map, pose_set_table

FAILURES = ("traceback", "exit70", "multiline", "hang", "destroyed", "silent")
KINDS = {"plan": 30, "map": 25, "validate": 20, "name": 15, "onto": 10}
NUMBERS = ("nan", "-nan", "inf", "-inf", "0", "-0", "-1", "1e-300", "1e-200", "1e-12",
           "1e-7", "1e-6", "1e300", "1e308", "1e9", "0.02", "0.1", "5")  # fmt: skip
OPTIONS = ("--sigma-mm", "--target-rms-mm", "--center-sigma-mm", "--plane-sigma-deg")
COMMANDS = {"status": [], "show": [], "audit": [], "identify": [], "viz": [],
            "fk": ["--q", "0 0 0 0 0 0"], "ik": ["--pose", "40", "20", "60", "180", "0", "90"],
            "export": ["--format", "dh"]}  # fmt: skip


def number(rng: np.random.Generator) -> str:
    """An odd or ordinary number as text: one of :data:`NUMBERS` or a log-uniform one."""
    if rng.random() < 0.7:
        return str(rng.choice(NUMBERS))
    mantissa = rng.uniform(1.0, 10.0) * rng.choice([-1, 1])
    return f"{mantissa:.3f}e{int(rng.integers(-320, 309))}"  # |x| from 1e-320 to 1e309


def _in_range(v: float, low: float) -> bool:
    """Finite, above 0 and at least ``low``."""
    return math.isfinite(v) and v > 0 and v >= low


def case_plan(d: Path, rng: np.random.Generator) -> tuple[str, str, str]:
    option = str(rng.choice(OPTIONS))
    value = number(rng)
    sweeps = option in ("--center-sigma-mm", "--plane-sigma-deg")
    extra = ["--sweeps", "--points", "20"] if sweeps else ["--poses", "5", "--candidates", "200"]
    r = cli(["plan", str(d / "p.csv"), "--robot", "puma560", *extra, f"{option}={value}"])
    res, detail = verdict(r)
    low = 1e-6 if option == "--sigma-mm" else 0.0  # mm: the σ floor (1e-7 cm)
    if res == "accepted" and not _in_range(float(value), low):
        res, detail = "silent", f"{option} {value} planned without a word"
    return f"{option} {value}", res, detail


def case_map(b: Path, d: Path, rng: np.random.Generator) -> tuple[str, str, str]:
    letters = "".join(rng.choice(list("XYZxyz"), 3)) if rng.random() < 0.9 else "X1!"
    sigma = number(rng)
    text = pose_set_map(sigma="stated").replace('convention = "XYZ"', f'convention = "{letters}"')
    text = text.replace("sigma = 0.02", f"sigma = {sigma}")
    (d / "map.toml").write_text(text)
    r = cli(["import", str(b / "poses.csv"), "--format", "table", "--map", str(d / "map.toml"),
             "--robot", str(UR10), str(d / "s")])  # fmt: skip
    res, detail = verdict(r)
    euler = (letters.isupper() or letters.islower()) and letters[0] != letters[1] != letters[2]
    if res == "accepted" and not (euler and _in_range(float(sigma), 1e-6)):  # mm: 1e-7 cm
        res, detail = "silent", f"convention {letters}, sigma {sigma} mm imported"
    return f"{letters} sigma={sigma}", res, detail


def case_validate(b: Path, d: Path, rng: np.random.Generator) -> tuple[str, str, str]:
    lines = (b / "other.csv").read_text().splitlines()
    row = int(rng.integers(1, len(lines)))
    cells = lines[row].split(";")
    col = int(rng.integers(len(cells)))
    cells[col] = number(rng).replace(".", ",")
    lines[row] = ";".join(cells)
    (d / "v.csv").write_text("\n".join(lines) + "\n")
    before = snapshot(b / "s")
    r = cli(["validate", str(b / "s"), "--against", str(d / "v.csv"), "--format", "table",
             "--map", str(b / "map.toml")])  # fmt: skip
    res, detail = verdict(r)
    if lost := destroyed(before):
        res, detail = "destroyed", ", ".join(p.name for p in lost)
    return f"row {row} col {col} = {cells[col]}", res, detail


def case_name(b: Path, d: Path, rng: np.random.Generator) -> tuple[str, str, str]:
    command = str(rng.choice(list(COMMANDS)))
    unit = str(rng.choice(["n", "é", "段", "-"]))
    name = unit * int(rng.integers(200, 400) // len(unit.encode()))
    if rng.random() < 0.3:
        name = f"{d}/{name}/s"
    before = snapshot(b / "s")
    r = cli([command, name, *COMMANDS[command]])
    res, detail = verdict(r)
    if lost := destroyed(before):
        res, detail = "destroyed", ", ".join(p.name for p in lost)
    return f"{command} {unit}x{len(name.encode())} bytes", res, detail


def case_onto(b: Path, d: Path, rng: np.random.Generator) -> tuple[str, str, str]:
    what = str(rng.choice(["device", "null", "pipe", "folder", "empty", "bytes"]))
    path = {"device": Path("/dev/zero"), "null": Path("/dev/null")}.get(what, d / "v.urdf")
    if what == "pipe":
        os.mkfifo(path)
    elif what == "folder":
        path.mkdir()
    elif what in ("empty", "bytes"):
        path.write_bytes(rng.bytes(int(rng.integers(1, 4096))) if what == "bytes" else b"")
    before = snapshot(b / "s")
    r = cli(["export", str(b / "s"), "--onto", str(path), "--out", str(d / "out.urdf")])
    res, detail = verdict(r)
    if lost := destroyed(before):
        res, detail = "destroyed", ", ".join(p.name for p in lost)
    return what, res, detail


def make_base(work: Path) -> Path:
    """The UR10 pose set, its map, a second file, imported and identified."""
    from pipeline.identify import identify
    from pipeline.importers import import_file

    b = work / "base"
    b.mkdir()
    pose_set_table(b / "poses.csv", n=40, seed=1)
    pose_set_table(b / "other.csv", n=12, seed=2)
    (b / "map.toml").write_text(pose_set_map())
    import_file(b / "poses.csv", "table", UR10, b / "s", b / "map.toml")
    identify(b / "s", report=False)
    return b


def run_case(kind: str, b: Path, d: Path, rng: np.random.Generator) -> Outcome:
    d.mkdir()
    try:
        with alarm(TIMEOUT_S):
            if kind == "plan":
                label, res, detail = case_plan(d, rng)
            elif kind == "map":
                label, res, detail = case_map(b, d, rng)
            elif kind == "validate":
                label, res, detail = case_validate(b, d, rng)
            elif kind == "name":
                label, res, detail = case_name(b, d, rng)
            else:
                label, res, detail = case_onto(b, d, rng)
    except Timeout:
        label, res, detail = "?", "hang", f"no answer within {TIMEOUT_S:g} s"
    finally:
        shutil.rmtree(d, ignore_errors=True)
    return Outcome(kind, label, res, detail)


@contextmanager
def _workdir() -> Iterator[Path]:
    with tempfile.TemporaryDirectory(prefix="armsig-fuzz-inputs-") as tmp:
        yield Path(tmp)


def fuzz(n: int, seed: int = 0, budget_s: float | None = None) -> list[Outcome]:
    """``n`` seeded cases (kinds drawn with the weights :data:`KINDS`), stopping once
    ``budget_s`` seconds of this process's CPU time have passed."""
    rng = np.random.default_rng(seed)
    p = np.array(list(KINDS.values()), float)
    plan = [str(k) for k in rng.choice(list(KINDS), n, p=p / p.sum())]
    out: list[Outcome] = []
    t0 = time.process_time()
    with _workdir() as work:
        b = make_base(work)
        for k, kind in enumerate(plan):
            if budget_s is not None and time.process_time() - t0 > budget_s:
                break
            out.append(run_case(kind, b, work / f"c{k}", np.random.default_rng([seed, k])))
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--cases", type=int, default=1000)
    ap.add_argument("--seed", type=int, default=0)
    args = ap.parse_args()
    t0 = time.perf_counter()
    outcomes = fuzz(args.cases, args.seed)
    print(summary(outcomes, FAILURES))
    print(f"{time.perf_counter() - t0:.1f} s")
    sys.exit(1 if any(o.result in FAILURES for o in outcomes) else 0)


if __name__ == "__main__":
    main()
