"""Where a map's columns are: the blocks (files, ``.mat`` variables) that hold them,
stacked and joined into one row per pose (:mod:`pipeline.importers.grid`), and each
column's position in that row."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

from pipeline.errors import ImportFileError
from pipeline.importers.grid import Block, Grid, delimited_block, joined, matched, stacked
from pipeline.importers.mapping import ImportMap, TargetColumns

#: A block's key: its file and, in a ``.mat`` file, its variable.
Key = tuple[Path, str | None]
#: A map column's place before loading: its block and its column there.
Where = tuple[Key, str | int]


@dataclass(frozen=True)
class Columns:
    """Positions of the map's columns in the grid's rows (None: not in the map)."""

    grid: Grid
    targets: dict[str, list[int]]  # id -> x, y, z (tool target first)
    sigmas: dict[str, list[int]]  # id -> σ of x, y, z (the one σ column three times)
    joints: list[int]
    orientation: list[int]
    payload: int | None
    sweep: int | None
    check: int | None


def sigma_columns(t: TargetColumns) -> tuple[str | int, str | int, str | int] | None:
    """The σ columns of x, y, z: one per axis, or the one σ column three times."""
    if t.sigma_xyz is not None:
        return t.sigma_xyz
    return None if t.sigma is None else (t.sigma, t.sigma, t.sigma)


def ordered_targets(imap: ImportMap) -> list[TargetColumns]:
    """The map's targets, the tool target first (its id is plan.tool_target; default the
    first target not fixed in the world)."""
    tool = imap.tool_target or next((t.id for t in imap.targets if not t.fixed), "")
    return sorted(imap.targets, key=lambda t: t.id != tool)


def columns(
    paths: list[Path],
    imap: ImportMap,
    loader: Callable[[Path, set[str | None]], dict[str | None, Block]],
    variable: Callable[[str | int], tuple[str | None, str | int]] | None = None,
    sweep_column: str | int | None = None,
) -> Columns:
    """The grid of ``paths`` read with ``imap`` and the position of each map column.

    ``loader(path, variables)`` reads a file's blocks (one, keyed None, for a delimited
    file); ``variable(col)`` splits a ``.mat`` column ("Q:2") into its variable and its
    column there (None: a delimited file)."""
    main = paths[0]
    jfile = next((j.file for j in imap.joints if j.file), None)
    default = matched(jfile, paths, main, imap.name) if imap.joined else main

    def where(file: str | None, col: str | int) -> Where:
        path = default if file is None else matched(file, paths, main, imap.name)
        var, local = (None, col) if variable is None else variable(col)
        return (path, var), local

    targets = ordered_targets(imap)
    t_at = {t.id: [where(t.file, c) for c in (t.x, t.y, t.z)] for t in targets}
    s_at = {t.id: [where(t.file, c) for c in s]
            for t in targets if (s := sigma_columns(t)) is not None}  # fmt: skip
    j_at = [where(j.file, j.column) for j in imap.joints]
    o_at = [] if imap.orientation is None else [where(None, c) for c in imap.orientation.columns]
    extra = {"payload": imap.payload_column, "sweep": sweep_column,
             "check": None if imap.check is None else imap.check.column}  # fmt: skip
    e_at = {k: where(None, c) for k, c in extra.items() if c is not None}
    keys = list(dict.fromkeys([j_at[0][0], *(w[0] for v in t_at.values() for w in v),
                               *(w[0] for w in j_at), *(w[0] for v in s_at.values() for w in v),
                               *(w[0] for w in o_at), *(w[0] for w in e_at.values())]))  # fmt: skip
    unused = [p.name for p in paths if p not in {k[0] for k in keys}]
    if unused:
        raise ImportFileError(
            f"{unused[0]}: the map reads no column of this file (files joined by row)",
            expected="a file = ... in [[targets]] or [[joints]] naming each given file",
            fix="name it in the map, or leave it off the command line",
        )
    loaded: dict[Key, Block] = {}
    for path in dict.fromkeys(k[0] for k in keys):
        for var, block in loader(path, {k[1] for k in keys if k[0] == path}).items():
            loaded[(path, var)] = block
    subs = _stacked_blocks(imap, loaded, t_at, keys)
    order = [kb for k in keys for kb in subs[k]]
    grid = joined([b for _, b in order])
    pos = {kb[0]: i for i, kb in reversed(list(enumerate(order)))}  # a key's first sub-block

    def at(w: Where, what: str, sub: int = 0) -> int:
        return grid.index(pos[w[0]] + sub, w[1], what)

    sub_of = {t: _target_sub(t, t_at, subs) for t in t_at}
    return Columns(
        grid,
        {t: [at(w, f"target {t} {a}", sub_of[t]) for w, a in zip(v, "xyz", strict=True)]
         for t, v in t_at.items()},
        {t: [at(w, f"target {t} σ {a}", sub_of[t]) for w, a in zip(v, "xyz", strict=True)]
         for t, v in s_at.items()},
        [at(w, f"joint {k + 1}") for k, w in enumerate(j_at)],
        [at(w, f"orientation {a}") for w, a in zip(o_at, ("rx", "ry", "rz"), strict=False)],
        *(None if k not in e_at else at(e_at[k], k) for k in ("payload", "sweep", "check")),
    )  # fmt: skip


def _target_sub(
    t: str, t_at: dict[str, list[Where]], subs: dict[Key, list[tuple[Key, Block]]]
) -> int:
    """The sub-row of target ``t`` in its block: its order among the block's targets when
    the block is stacked, else 0."""
    key = t_at[t][0][0]
    if len(subs[key]) == 1:
        return 0
    return [u for u, v in t_at.items() if v[0][0] == key].index(t)


def _stacked_blocks(
    imap: ImportMap, loaded: dict[Key, Block], t_at: dict[str, list[Where]], keys: list[Key]
) -> dict[Key, list[tuple[Key, Block]]]:
    """Each key's blocks: its one block, or one per sub-row when the map stacks it (a
    block holding target columns with ``points_per_pose`` or ``pose_column``)."""
    out = {k: [(k, loaded[k])] for k in keys}
    if imap.points_per_pose is None and imap.pose_column is None:
        return out
    for t, ws in t_at.items():
        if len({w[0] for w in ws}) != 1:
            raise ImportFileError(
                f"{imap.name}: target {t}'s x, y, z are in different files or variables",
                expected="a stacked target's x, y, z in one block of rows",
                fix="read the target's three columns from one file (or one .mat matrix)",
            )
    for key in dict.fromkeys(ws[0][0] for ws in t_at.values()):
        n = sum(1 for ws in t_at.values() if ws[0][0] == key)
        block = loaded[key]
        k = imap.points_per_pose
        if k is not None and k != n:
            raise ImportFileError(
                f"{imap.name}: points_per_pose = {k}, but {block.name} holds {n} [[targets]]",
                expected=f"{k} [[targets]] read from {block.name}, one per row of a pose",
                fix="list one [[targets]] per row of a pose, in their order",
            )
        pcol = None
        if imap.pose_column is not None:
            pcol = block.column(imap.pose_column, "pose_column")
        out[key] = [(key, b) for b in stacked(block, n, pcol)]
    return out


def delimited_loader(imap: ImportMap) -> Callable[[Path, set[str | None]], dict[str | None, Block]]:
    """A delimited file's one block, read with the map's delimiter, skips and header."""

    # A map that reads no text cell (sweep, check), stacks no rows and joins no files
    # reads a plain numeric file with polars (issue 45).
    numeric = (
        imap.sweep_column in (None, "infer")
        and (imap.check is None or imap.check.column is None)
        and imap.points_per_pose is None
        and imap.pose_column is None
        and not imap.joined
    )

    def load(path: Path, variables: set[str | None]) -> dict[str | None, Block]:
        return {None: delimited_block(path, imap.skip_rows, imap.skip_lines, imap.header,
                                      imap.delimiter, imap.decimal, numeric)}  # fmt: skip

    return load
