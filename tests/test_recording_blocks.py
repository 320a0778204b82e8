"""Issue 45: a pose set's rows as blocks of columns (``/points/block``).

The same rows imported as blocks and as per-row messages give the same ``Recording``
arrays bit for bit, blocks that stand for the per-row messages exactly, and the same
signature; the same rows from one file and from ten give the same signature; every check
of the reader refuses a bad block in one line; a plain numeric file read by polars gives
the rows the ``csv`` reader gives.
"""

from __future__ import annotations

import dataclasses
import functools
import json
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from import_data import UR10, pose_set_map, pose_set_table

from pipeline.contract.blocks import BLOCK_TOPIC, block_payload, row_messages
from pipeline.contract.channels import POINT_BLOCK_CHANNELS, SOURCE_METADATA
from pipeline.contract.mcap_read import read_mcap
from pipeline.errors import RecordingError
from pipeline.importers import import_file, session
from pipeline.importers.grid import delimited_block
from pipeline.importers.numeric import NumberRows
from pipeline.rig.recorder import Message, write_recording
from pipeline.stages.recording import read_recording

CHECK = "payload_kg = 2.5\n\n[check]\nfraction = 0.25\nseed = 7"


def _imported(
    folder: Path, n: int = 60, in_blocks: bool = True, plain: bool = False, **kw: Any
) -> Path:
    """A UR10 pose set (two reflectors, unequal σ, orientation, held-out rows, a payload);
    ``plain``: one stated σ, no orientation, no held-out rows, no payload."""
    folder.mkdir(parents=True, exist_ok=True)
    src, _ = pose_set_table(folder / "poses.csv", n=n, sep=",", decimal=".", unit="deg")
    mp = folder / "map.toml"
    text = pose_set_map(sep=",", decimal=".", unit="deg", extra=CHECK)
    if plain:
        text = pose_set_map(sep=",", decimal=".", unit="deg", sigma="stated")
        text = text.split("[orientation]")[0]
    mp.write_text(text)
    if not in_blocks:  # the per-row messages written before issue 45
        real = session.session_messages
        kw["monkeypatch"].setattr(
            "pipeline.importers.session_messages", functools.partial(real, in_blocks=False)
        )
    import_file(src, "table", UR10, folder / "s", mp)
    return folder / "s" / "recording.mcap"


def _arrays(path: Path) -> dict[str, Any]:
    rec = read_recording(path)
    return {f.name: getattr(rec, f.name) for f in dataclasses.fields(rec)
            if f.name not in ("path", "sha256")}  # fmt: skip


def _same(a: dict[str, Any], b: dict[str, Any]) -> None:
    assert a.keys() == b.keys()
    for k, x in a.items():
        y = b[k]
        if isinstance(x, np.ndarray):
            assert x.shape == y.shape and x.dtype.kind == y.dtype.kind, k
            assert np.array_equal(x, y, equal_nan=x.dtype.kind == "f"), k
        else:
            assert x == y, k


def _signature(session_dir: Path) -> dict[str, Any]:
    """The identified signature document but its provenance and self-digest."""
    from pipeline.identify import identify

    identify(session_dir, report=False)
    doc = json.loads((session_dir / "signature.json").read_text())
    return {k: v for k, v in doc.items() if k not in ("provenance", "sha256")}


@pytest.fixture(scope="module")
def pair(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, Path]:
    """The same rows imported as blocks and as per-row messages."""
    mp = pytest.MonkeyPatch()
    try:
        blocks = _imported(tmp_path_factory.mktemp("blocks"))
        rows = _imported(tmp_path_factory.mktemp("rows"), in_blocks=False, monkeypatch=mp)
    finally:
        mp.undo()
    return blocks, rows


def test_a_plain_pose_set_identifies_as_its_per_row_recording(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """One stated σ, no orientation or payload: the blocks' absent columns read as the
    per-row recording's NaN (read-only, without memory) and identify alike."""
    blocks = _imported(tmp_path / "blocks", plain=True)
    rows = _imported(tmp_path / "rows", in_blocks=False, plain=True, monkeypatch=monkeypatch)
    a, b = _arrays(blocks), _arrays(rows)
    _same(a, b)
    assert np.isnan(a["point_cov_cm2"]).all() and np.isnan(a["point_wxyz"]).all()
    assert _signature(blocks.parent) == _signature(rows.parent)


def test_blocks_stand_for_the_per_row_messages(pair: tuple[Path, Path]) -> None:
    blocks, rows = pair
    a = read_mcap(blocks, POINT_BLOCK_CHANNELS, "test")
    b = read_mcap(rows, POINT_BLOCK_CHANNELS, "test")
    assert len(a.messages[BLOCK_TOPIC]) == 2 and not a.messages["/points"]  # poses, check
    assert not b.messages[BLOCK_TOPIC]
    per_row = {t: v for t, v in b.messages.items() if t != BLOCK_TOPIC}
    assert row_messages(blocks, a.messages) == per_row  # times and payloads, in order
    assert a.metadata[SOURCE_METADATA] == b.metadata[SOURCE_METADATA]


def test_blocks_read_to_the_same_arrays_and_signature(pair: tuple[Path, Path]) -> None:
    blocks, rows = pair
    a, b = _arrays(blocks), _arrays(rows)
    _same(a, b)
    assert np.isfinite(a["point_cov_cm2"]).any() and np.isfinite(a["point_wxyz"]).any()
    assert set(a["joint_sweep"].tolist()) == {-2, -1} and (a["joint_payload_kg"] == 2.5).all()
    assert _signature(blocks.parent) == _signature(rows.parent)


def test_one_file_and_ten_files_give_the_same_signature(tmp_path: Path) -> None:
    """3,000 rows from one file and the same rows in ten files (each with its header):
    the same signature bit for bit; each row keeps its file and line."""
    one = tmp_path / "one"
    path = _imported(one, n=3_000)
    head, *body = (one / "poses.csv").read_text().splitlines()
    ten = tmp_path / "ten"
    ten.mkdir()
    names = []
    for k, part in enumerate(np.array_split(np.array(body, dtype=object), 10)):
        names.append(str(ten / f"part_{k:02d}.csv"))
        Path(names[-1]).write_text("\n".join([head, *part]) + "\n")
    import_file(names, "table", UR10, ten / "s", one / "map.toml")
    a, b = _arrays(path), _arrays(ten / "s" / "recording.mcap")
    files = b.pop("joint_source_file")
    lines = b.pop("joint_source_line")
    assert set(files.tolist()) == {f"part_{k:02d}.csv" for k in range(10)}
    assert (a.pop("joint_source_file") == "poses.csv").all()
    first = a.pop("joint_source_line")  # lines 2 to 3,001; in each of ten files 2 to 301
    assert (lines == (first - 2) % 300 + 2).all()
    assert a.pop("rig")["instrument"] == "table file poses.csv (imported)"
    assert b.pop("rig")["instrument"] == "table files part_00.csv to part_09.csv (10) (imported)"
    _same(a, b)
    assert _signature(one / "s") == _signature(ten / "s")


def _rewritten(src: Path, dst: Path, edit: Any) -> Path:
    """``src``'s messages with ``edit(messages)`` applied, written to ``dst``."""
    content = read_mcap(src, POINT_BLOCK_CHANNELS, "test")
    msgs = [Message(t, time, m) for t, v in content.messages.items() for time, m in v]
    edit(msgs)
    dst.parent.mkdir(parents=True, exist_ok=True)
    write_recording(
        dst, msgs, POINT_BLOCK_CHANNELS, {SOURCE_METADATA: content.metadata[SOURCE_METADATA]}
    )
    return dst


def _block_edit(change: Any) -> Any:
    """An edit of the first block's decoded columns and fields, re-encoded."""
    from pipeline.contract.blocks import block_columns

    def edit(msgs: list[Message]) -> None:
        k = next(i for i, m in enumerate(msgs) if m.topic == BLOCK_TOPIC)
        m = dict(msgs[k].payload)
        cols = {n: a.copy() for n, a in block_columns(Path("x"), 0, m).items()}
        change(m, cols)
        fields = {f: m[f] for f in ("source_files", "orientation_sigma_deg") if f in m}
        new = block_payload(m["sweep"], m["first_step"], m["units"], m["targets"], cols, **fields)
        msgs[k] = dataclasses.replace(msgs[k], payload=new)

    return edit


def _set(name: str, index: Any, value: float) -> Any:
    def change(m: dict[str, Any], cols: dict[str, np.ndarray]) -> None:
        cols[name][index] = value

    return change


def _field(name: str, value: Any) -> Any:
    def change(m: dict[str, Any], cols: dict[str, np.ndarray]) -> None:
        m[name] = value

    return change


def _drop_row(m: dict[str, Any], cols: dict[str, np.ndarray]) -> None:
    """The pose set's step 0 left out."""
    for name in cols:
        cols[name] = cols[name][1:]
    m["first_step"] += 1


def _raw(name: str, text: str) -> Any:
    def edit(msgs: list[Message]) -> None:
        k = next(i for i, m in enumerate(msgs) if m.topic == BLOCK_TOPIC)
        payload = json.loads(json.dumps(msgs[k].payload))
        payload["columns"][name] = text
        msgs[k] = dataclasses.replace(msgs[k], payload=payload)

    return edit


def _twice(msgs: list[Message]) -> None:
    first = next(m for m in msgs if m.topic == BLOCK_TOPIC)
    msgs.append(dataclasses.replace(first, time_ns=first.time_ns + 1))


def _point_also_per_row(msgs: list[Message]) -> None:
    msgs.append(Message("/points", 1, {"sweep": "poses", "step": 3, "target": "tmac",
                                       "x_cm": 1.0, "y_cm": 2.0, "z_cm": 3.0}))  # fmt: skip


EDITS = {
    "point NaN": (_block_edit(_set("points_cm", (3, 0, 1), np.nan)),
                  "points_cm must be bigger than or equal to -100000, a finite number: nan at "
                  "(sweep poses, step 3)"),
    "point beyond 1,000 m": (_block_edit(_set("points_cm", (4, 1, 2), 2e5)),
                             "points_cm must be smaller than or equal to 100000"),
    "joint beyond its limits": (_block_edit(_set("q_commanded", (5, 1), 900.0)),
                                "/robot/joint_state (sweep poses, step 5) q_encoder of joint 2 "
                                "is outside its limits"),
    "σ zero": (_block_edit(_set("sigma_cm", (6, 0, 0), 0.0)), "sigma_cm must be bigger than 0"),
    "σ under 1 nm": (_block_edit(_set("sigma_cm", (7, 0), 1e-9)),
                     "/points (sweep poses, step 7, target tmac) sigma_cm is 1e-09 cm, under"),
    "not a unit quaternion": (_block_edit(_set("orientation_wxyz", (8, 0), 0.5)),
                              "(sweep poses, step 8, target tmac) orientation_wxyz is not a unit"),
    "negative time": (_block_edit(_set("dt_ns", 2, -5)), "dt_ns must be bigger than or equal"),
    "step gap": (_block_edit(_drop_row), "sweep poses has no step 0"),
    "unplanned step": (_block_edit(_field("first_step", 40)),
                       "/points/block (sweep poses, step 45) names no planned position"),
    "wrong units": (_block_edit(_field("units", ["deg"] * 5 + ["cm"])),
                    "/robot/joint_state (sweep poses, step 0) does not fit the robot"),
    "a key twice": (_twice, "/robot/joint_state key (sweep poses, step 0) is recorded twice"),
    "a block's point also per row": (_point_also_per_row,
                                     "/points key (sweep poses, step 3, target tmac) is recorded "
                                     "twice"),
    "short column": (_raw("dt_ns", "AAAAAAAAAAA="), "column dt_ns holds 8 bytes"),
    "not base64": (_raw("dt_ns", "AA*A"), "column dt_ns is not base64"),
}  # fmt: skip


@pytest.mark.parametrize("name", list(EDITS))
def test_a_bad_block_is_refused_in_one_line(pair: tuple[Path, Path], tmp_path: Path, name: str):
    edit, want = EDITS[name]
    path = _rewritten(pair[0], tmp_path / "s" / "recording.mcap", edit)
    with pytest.raises(RecordingError) as e:
        read_recording(path)
    assert want in str(e.value) and "\n" not in str(e.value), str(e.value)


def test_an_unedited_rewrite_reads(pair: tuple[Path, Path], tmp_path: Path) -> None:
    """The edits above change only what they name: the same rewrite without one reads."""
    path = _rewritten(pair[0], tmp_path / "s" / "recording.mcap", _block_edit(lambda m, c: None))
    _same(_arrays(path), _arrays(pair[0]))


def _normal(seed: int) -> np.ndarray:
    return np.random.default_rng(seed).normal(size=3)


TEXTS = {
    "plain": "a,b,c\n1,2.5,-3e-3\n4,5,6\n",
    "crlf and a byte-order mark": "\ufeffa,b,c\r\n1,2.5,-3e-3\r\n4,5,nan\r\n",
    "no final newline": "a;b;c\n0.1;0.2;0.3\n0.4;0.5;0.6",
    "spaces after the delimiter": "a, b, c\n1, 2, 3\n4, 5, 6\n",
    "a blank line": "a,b,c\n1,2,3\n\n4,5,6\n",
    "an empty cell": "a,b,c\n1,,3\n4,5,6\n",
    "a short row": "a,b,c\n1,2\n4,5,6\n",
    "a quoted cell": 'a,b,c\n1,"2",3\n4,5,6\n',
    "a text cell": "a,b,c\n1,x,3\n4,5,6\n",
    "17 digits": "a,b,c\n" + "\n".join(
        ",".join(repr(float(v)) for v in _normal(k) * 10.0 ** (k % 40 - 20))
        for k in range(200)) + "\n",
}  # fmt: skip


PLAIN = ("plain", "crlf and a byte-order mark", "no final newline", "spaces after the delimiter",
         "17 digits")  # fmt: skip


@pytest.mark.parametrize("skip", [0, 1])
@pytest.mark.parametrize("name", list(TEXTS))
def test_plain_numeric_file_reads_as_the_csv_reader_reads_it(
    tmp_path: Path, name: str, skip: int
) -> None:
    """polars' reading (a plain file) or its fallback gives the ``csv`` reader's header,
    lines and numbers (the same doubles); ``skip``: the header line skipped (skip_rows 1,
    no header)."""
    path = tmp_path / "t.csv"
    path.write_bytes(TEXTS[name].encode())
    fast = delimited_block(path, skip, (), not skip, None, ".", numeric=True)
    slow = delimited_block(path, skip, (), not skip, None, ".", numeric=False)
    assert fast.header == slow.header and fast.width == slow.width and fast.line == slow.line
    assert isinstance(fast.rows, NumberRows) == (name in PLAIN)
    assert [line for line, _ in fast.rows] == [line for line, _ in slow.rows]
    for (_, a), (_, b) in zip(fast.rows, slow.rows, strict=True):
        assert len(a) == len(b)
        for x, y in zip(map(_number, a), map(_number, b), strict=True):
            assert x == y or (x != x and y != y), (x, y)


def _number(cell: str | float) -> str | float:
    """A cell as the table reader takes it: a number, else its text."""
    try:
        return float(cell)
    except ValueError:
        return cell


def test_many_blocks_read_as_one(
    pair: tuple[Path, Path], tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """Blocks of at most 2,000 bytes of columns (a few rows each: the size bound of wide
    rows) read to the per-row recording's arrays."""
    from pipeline.contract import blocks

    monkeypatch.setattr(blocks, "BLOCK_BYTES", 2_000)
    path = _imported(tmp_path / "small")
    content = read_mcap(path, POINT_BLOCK_CHANNELS, "test")
    sizes = [m["rows"] for _, m in content.messages[BLOCK_TOPIC]]
    assert len(sizes) > 5 and sum(sizes) == 60 and max(sizes) <= 10, sizes
    _same(_arrays(path), _arrays(pair[1]))
