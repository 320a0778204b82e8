"""Issue 32 item 4: bounded parsing and OS errors as refusals, for import and validate.

YAML aliases are refused (a "billion laughs" hung import and validate while memory grew),
nesting is bounded, a field over csv's limit, a robot description that is not UTF-8 or
nests thousands deep, and every OSError (a name too long, a full disk) end in one line
naming the path and the cause: never exit 70, never a hang."""

from __future__ import annotations

import errno
import subprocess
import sys
from pathlib import Path
from typing import Any

import pytest
from import_data import TWO_LINK, TWO_LINK_MAP, TWO_LINK_VALUES, sscanss2_text
from typer.testing import CliRunner

from pipeline.cli import EXIT_REFUSED, app

ROOT = Path(__file__).resolve().parent.parent
RCT = ROOT / "examples" / "rct_positioner"
#: Nine aliases of nine aliases ... nine deep: 9⁹ = 387 million scalars once expanded.
LAUGHS = (
    "a: &a [x, x, x, x, x, x, x, x, x]\n"
    + "".join(
        f"{c}: &{c} [{', '.join(['*' + p] * 9)}]\n"
        for p, c in zip("abcdefgh", "bcdefghi", strict=True)
    )
    + "1:\n  pose: *i\n  target_joints: [0, 0]\n"
)


def _cli(args: list[str], cwd: Path) -> subprocess.CompletedProcess[str]:
    """``pipeline ARGS`` in a fresh interpreter, killed after 60 s (a hang fails the test)."""
    return subprocess.run([sys.executable, "-m", "pipeline", *args], cwd=cwd, text=True,
                          capture_output=True, timeout=60, env={"PYTHONPATH": str(ROOT),
                          "PATH": "/usr/bin:/bin"})  # fmt: skip


def _refusal(r: Any, *words: str) -> str:
    """A CompletedProcess's or a CliRunner Result's one-line refusal holding ``words``."""
    code = getattr(r, "returncode", getattr(r, "exit_code", None))
    err = str(r.stderr)
    assert code == EXIT_REFUSED, (code, err)
    assert len(err.splitlines()) == 1 and err.startswith("error: "), err
    for w in words:
        assert w in err, err
    return err


@pytest.fixture(scope="module")
def identified(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The two-link arm, identified: a signature for ``validate``."""
    from pipeline.identify import identify
    from pipeline.importers import import_file

    tmp = tmp_path_factory.mktemp("two")
    (tmp / "two.txt").write_text(sscanss2_text(TWO_LINK, TWO_LINK_VALUES, digits=15))
    import_file(tmp / "two.txt", "sscanss2", TWO_LINK, tmp / "s")
    identify(tmp / "s", report=False)
    return tmp / "s"


@pytest.mark.parametrize(
    ("name", "text", "words"),
    [
        ("laughs.yaml", LAUGHS, ("laughs.yaml: line 2", "alias")),
        ("deep.yaml", "[" * 5000 + "]" * 5000 + "\n", ("deep.yaml: line 1", "nested deeper than")),
        ("deepmap.yaml", "1: " + "{a: " * 3000 + "1" + "}" * 3000 + "\n", ("nested deeper",)),
    ],
)
def test_bounded_yaml_import_and_validate(
    tmp_path: Path, identified: Path, name: str, text: str, words: tuple[str, ...]
) -> None:
    (tmp_path / name).write_text(text)
    imp = ["import", name, "--format", "rct", "--robot", str(RCT / "positioner.toml"),
           "--map", str(RCT / "map.toml"), "s"]  # fmt: skip
    err = _refusal(_cli(imp, tmp_path), *words)
    assert len(err) < 600  # the document is never formatted into the message
    assert not (tmp_path / "sessions" / "s" / "recording.mcap").exists()
    val = ["validate", str(identified), "--against", name, "--format", "rct"]
    _refusal(_cli(val, tmp_path), *words)


def test_robot_description_not_utf8_or_deep(tmp_path: Path) -> None:
    src = tmp_path / "two.txt"
    src.write_text(sscanss2_text(TWO_LINK, TWO_LINK_VALUES))
    (tmp_path / "latin.toml").write_bytes(b'name = "r\xe9"\n')
    (tmp_path / "deep.toml").write_text("x = " + "[" * 5000 + "]" * 5000 + "\n")
    for robot, words in (("latin.toml", ("latin.toml", "utf-8")), ("deep.toml", ("deep.toml",))):
        args = ["import", str(src), "--format", "sscanss2", "--robot", robot, "s"]
        _refusal(_cli(args, tmp_path), *words)


def test_field_over_csv_limit(tmp_path: Path) -> None:
    big = "9" * 200_000
    (tmp_path / "big.txt").write_text(f"1\t{big}\t0\t0\t0\trevolute\t0\n")
    (tmp_path / "big.csv").write_text(
        f'# x\nj1_deg,j2_rad,x1,y1,z1,x2,y2,z2\n"{big}",1,2,3,4,5,6,7\n'
    )
    (tmp_path / "map.toml").write_text(TWO_LINK_MAP)
    for args in (["big.txt", "--format", "sscanss2"],
                 ["big.csv", "--format", "table", "--map", "map.toml"]):  # fmt: skip
        r = _cli(["import", *args, "--robot", str(TWO_LINK), "s"], tmp_path)
        _refusal(r, f"{args[0]}: line", "131072 characters")


def test_name_too_long(tmp_path: Path) -> None:
    src = tmp_path / "two.txt"
    src.write_text(sscanss2_text(TWO_LINK, TWO_LINK_VALUES))
    r = _cli(["import", str(src), "--format", "sscanss2", "--robot", str(TWO_LINK), "n" * 300],
             tmp_path)  # fmt: skip
    _refusal(r, "nnnn", "File name too long")


def test_full_disk_is_one_line(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    import pipeline.importers.write as write

    def full(path: Path, *args: object, **kw: object) -> None:
        raise OSError(errno.ENOSPC, "No space left on device")

    monkeypatch.setattr(write, "write_recording", full)
    src = tmp_path / "two.txt"
    src.write_text(sscanss2_text(TWO_LINK, TWO_LINK_VALUES))
    r = CliRunner().invoke(app, ["import", str(src), "--format", "sscanss2", "--robot",
                                 str(TWO_LINK), str(tmp_path / "s")])  # fmt: skip
    _refusal(r, str(tmp_path / "s" / "recording.mcap"), "No space left on device")


def test_more_rows_than_memory_takes_is_one_line(tmp_path: Path, monkeypatch) -> None:
    """Issue 32 item 6, issue 45: no fixed row limit; a file whose identify would not fit
    in the memory available is refused in one line with the count and the estimate,
    nothing written. The available memory is set here to what 10 rows need, so that 14
    rows exceed it."""
    from pipeline.importers import memory

    monkeypatch.setattr(memory, "available_bytes", lambda: memory.needed_bytes(10))
    src = tmp_path / "two.txt"
    src.write_text(sscanss2_text(TWO_LINK, TWO_LINK_VALUES))
    r = CliRunner().invoke(app, ["import", str(src), "--format", "sscanss2", "--robot",
                                 str(TWO_LINK), str(tmp_path / "s")])  # fmt: skip
    _refusal(r, "two.txt: 14 rows need about 0.4 GB to import and identify", "at most ~10 rows",
             "1 row in 2 of each sweep")  # fmt: skip
    assert not (tmp_path / "s").exists()


def test_memory_estimate_reads_this_machine() -> None:
    """The estimate grows with the rows, and this machine's available memory is read
    (positive, below its total)."""
    from pipeline.importers import memory

    assert memory.needed_bytes(1_000_000) > memory.needed_bytes(100_000) > 0
    avail = memory.available_bytes()
    assert avail is not None and 0 < avail


@pytest.mark.parametrize("index", ["nan", "-1e400", "inf", "1.5", "3"])
def test_sscanss2_joint_index_that_is_no_joint(tmp_path: Path, index: str) -> None:
    src = tmp_path / "j.txt"
    src.write_text(f"1\t1\t2\t3\t0\trevolute\t0\n{index}\t1\t2\t3\t10\trevolute\t0\n")
    r = CliRunner().invoke(app, ["import", str(src), "--format", "sscanss2", "--robot",
                                 str(TWO_LINK), str(tmp_path / "s")])  # fmt: skip
    _refusal(r, "j.txt: line 2: joint index", "names no joint")
