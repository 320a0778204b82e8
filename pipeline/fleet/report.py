"""``pipeline fleet report DIR``: Markdown and figures from ``DIR/fleet.arrow``.

Figures: design-vs-signature gain per robot model, the accuracy distribution, and the
drift of each arm's signature between its sessions. An arm is its robot id (its serial,
recorded by ``simulate``/``import --robot-id``; issue 43), not its model: two arms of one
model are two robots. Sessions without a robot id are not compared with any other (the
drift table says so). An arm's sessions are ordered by their identification time. Every
session's verdict (PASS, CHECK, FAIL) is a column of the table and counted in the title.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from pipeline.errors import ArmsigError, one_line
from pipeline.fleet.run import SCHEMA_VERSION, TABLE_NAME
from pipeline.report.figures import panel_figure, save_png
from pipeline.report.identification import markdown_table, sig
from pipeline.signature.alignment import chain_alignment
from pipeline.signature.checks import DIGEST_KEY
from pipeline.signature.file import FILE_NAME

REPORT_DIR = "fleet-report"


def load_rows(folder: Path) -> list[dict[str, Any]]:
    """The rows of ``folder/fleet.arrow`` (checked on read, as every armsig table); one
    written by an older armsig (another schema version: no robot ids) is refused in one
    line."""
    from pipeline.stages.tables import read_table

    path = folder / TABLE_NAME
    if not path.is_file():
        raise ArmsigError(f"{path}: no such file", fix=f"`pipeline fleet identify {folder}`")
    table = read_table(path)
    version = (table.schema.metadata or {}).get(b"schema_version", b"?").decode()
    if version != SCHEMA_VERSION:
        raise ArmsigError(
            f"{path}: written by another armsig (fleet.arrow schema {version})",
            expected=f"schema {SCHEMA_VERSION} (with robot ids)",
            fix=f"`pipeline fleet identify {folder}` again (the stages are cached)",
        )
    return table.to_pylist()


def current_signatures(rows: list[dict[str, Any]]) -> dict[str, tuple[Any, str]]:
    """Per session identified without error: its signature and ``""`` if it is still the
    one ``fleet.arrow`` recorded and still the session's (checked as every consumer of a
    signature checks it: :func:`~pipeline.signature.session.load_session_document`), else
    None and why not (changed since fleet.arrow, or stale: the recording or a stage table
    changed, or an older armsig built it)."""
    from pipeline.signature.file import signature_from_document
    from pipeline.signature.session import load_session_document

    out: dict[str, tuple[Any, str]] = {}
    for r in rows:
        if r["error"] is not None:
            continue
        path = Path(r["session"]) / FILE_NAME
        try:
            doc = load_session_document(path)
        except ArmsigError as exc:
            out[r["session"]] = None, f"stale: {one_line(str(exc).removeprefix(f'{path}: '), 160)}"
            continue
        if doc[DIGEST_KEY] != r["signature_sha256"]:
            out[r["session"]] = None, "signature changed since fleet.arrow"
        else:
            out[r["session"]] = signature_from_document(doc, str(path)), ""
    return out


#: The drift table's word for sessions that record no robot id.
NO_ROBOT_ID = "no robot id recorded: not compared with other sessions (import --robot-id)"


def drift(
    rows: list[dict[str, Any]], current: dict[str, tuple[Any, str]]
) -> dict[str, list[tuple[str, float | None, str]]]:
    """Per robot id (the arm, not its model) with two or more identified sessions, in
    identification order: each later session's RMS tool position difference (cm) from the
    one before, after aligning the two signatures' bases and tools
    (:func:`~pipeline.signature.alignment.chain_alignment`: no ground truth, independent
    of each session's sensor frame). None, with why, when either signature is not
    ``current`` (:func:`current_signatures`). Two arms of one model are never compared."""
    by_robot: dict[str, list[dict[str, Any]]] = {}
    for r in rows:
        if r["error"] is None and r["robot_id"] is not None:
            by_robot.setdefault(r["robot_id"], []).append(r)
    out: dict[str, list[tuple[str, float | None, str]]] = {}
    for robot, rs in sorted(by_robot.items()):
        rs.sort(key=lambda r: (r["identified_utc"], r["session"]))
        steps: list[tuple[str, float | None, str]] = []
        for a, b in zip(rs, rs[1:], strict=False):
            (sa, why_a), (sb, why_b) = current[a["session"]], current[b["session"]]
            if sa is None or sb is None:
                steps.append((b["session"], None, why_b or f"{a['session']}: {why_a}"))
            else:
                steps.append((b["session"], chain_alignment(sb.chain, sa.chain, sb.robot)[2], ""))
        if steps:
            out[robot] = steps
    return out


def arm(row: dict[str, Any]) -> str:
    """What the figures call a session's arm: its robot id, else its session (no id)."""
    return row["robot_id"] or f"{Path(row['session']).name} (no id)"


def laid_out(fig: Any) -> Any:
    """``fig`` with its panels moved so that no label, tick or title is cut off
    (matplotlib's tight layout: the fixed margins of :func:`panel_figure` cut rotated
    robot ids and long axis labels)."""
    fig.tight_layout()
    return fig


def gain_figure(rows: list[dict[str, Any]]) -> Any:
    robots = sorted({arm(r) for r in rows if r["error"] is None})
    fig, (ax_g, ax_m) = panel_figure(2)
    for k, robot in enumerate(robots):
        rs = [r for r in rows if r["error"] is None and arm(r) == robot]
        g = [r["gain_evaluation"] for r in rs if r["gain_evaluation"] is not None]
        ax_g.plot([k] * len(g), g, "o", color="C0")
        ax_m.plot([k] * len(rs), [r["design_misfit_rms_cm"] for r in rs], "o", color="C1")
    for ax, label in (
        (ax_g, "gain: design / signature\nerror (evaluation)"),
        (ax_m, "design vs signature\nRMS difference (cm)"),
    ):
        ax.set_xticks(range(len(robots)), robots, rotation=30, ha="right")
        ax.set_ylabel(label, fontsize=8)
        ax.grid(alpha=0.3)
    fig.suptitle("Design model against signature, per robot")
    return laid_out(fig)


def accuracy_figure(rows: list[dict[str, Any]]) -> Any:
    fig, axes = panel_figure(2)
    for ax, col, label in (
        (axes[0], "check_rms_cm", "validation RMS error (cm)"),
        (axes[1], "sigma_normal_max_cm", "largest feature normal σ (cm)"),
    ):
        v = [r[col] for r in rows if r[col] is not None]
        if v:
            ax.hist(v, bins="auto" if np.ptp(v) > 1e-12 else 1, color="C0", alpha=0.7)
        else:
            ax.text(0.5, 0.5, "no session has it", ha="center", transform=ax.transAxes)
        ax.set_xlabel(label)
        ax.set_ylabel("sessions")
    fig.suptitle("Accuracy across the fleet")
    return laid_out(fig)


def drift_figure(steps: dict[str, list[tuple[str, float | None, str]]]) -> Any:
    fig, (ax,) = panel_figure(1)
    for robot, s in steps.items():
        ax.plot(range(1, len(s) + 1), [np.nan if v is None else v for _, v, _ in s], "o-",
                label=robot)  # fmt: skip
    longest = max((len(s) for s in steps.values()), default=1)
    ax.set_xticks(range(1, longest + 1))
    ax.set_xlabel("session vs the one before\n(identification order)")
    ax.set_ylabel("RMS tool position difference\nafter alignment (cm)")
    ax.grid(alpha=0.3)
    if steps:
        ax.legend(fontsize=7, title="robot id", title_fontsize=7)
    fig.suptitle("Drift of each robot's signature\nbetween its sessions")
    return laid_out(fig)


def write_fleet_report(folder: str | Path) -> Path:
    """Write ``folder/fleet-report/fleet.md`` and its figures; returns the Markdown path."""
    from pipeline.atomic import write_text_atomic

    d = Path(folder)
    rows = load_rows(d)
    out = d / REPORT_DIR
    out.mkdir(parents=True, exist_ok=True)
    current = current_signatures(rows)
    steps = drift(rows, current)
    figs = {
        name: save_png(make, out / name)
        for name, make in (
            ("gain.png", gain_figure(rows)),
            ("accuracy.png", accuracy_figure(rows)),
            ("drift.png", drift_figure(steps)),
        )
    }
    failed = [r for r in rows if r["error"] is not None]
    fail = [r for r in rows if r["error"] is None and r["verdict"] == "FAIL"]
    stale = {s: why for s, (_, why) in current.items() if why}
    table = markdown_table(
        ["session", "robot", "robot id", "sensor", "verdict", "points", "σ normal max (cm)",
         "check RMS (cm)", "gain", "warnings", "error"],
        [
            [r["session"], r["robot"] or "—", r["robot_id"] or "—", r["sensor"] or "—",
             r["verdict"] or "—", r["points"] or "—", sig(r["sigma_normal_max_cm"]),
             sig(r["check_rms_cm"]), sig(r["gain_evaluation"]), len(r["warnings"] or []),
             r["error"] or stale.get(r["session"], "")]
            for r in rows
        ],
    )  # fmt: skip
    drift_rows = [
        [robot, s, why if v is None else sig(v)] for robot, vs in steps.items() for s, v, why in vs
    ]
    drift_rows += [["—", r["session"], NO_ROBOT_ID] for r in rows
                   if r["error"] is None and r["robot_id"] is None]  # fmt: skip
    parts = [
        f"# Fleet: {len(rows)} sessions, {len(failed)} failed, {len(fail)} with verdict FAIL"
        + (f", {len(stale)} no longer as fleet.arrow recorded them (column error)" if stale else "")
        + "\n",
        table,
        "\n## Design model against signature\n",
        "Gain: the median over the evaluation's tasks of the median |design| / |signature| "
        "index, measured on the rig (`pipeline fleet evaluate`; no ground truth). The design "
        "vs signature difference is the RMS position difference of the two models after "
        "aligning their bases and tools (from signature.json).\n",
        f"![gain]({figs['gain.png'].name})",
        "\n## Accuracy\n",
        f"![accuracy]({figs['accuracy.png'].name})",
        "\n## Drift between sessions\n",
        "Each session against the same arm's (robot id's) session before it: RMS tool "
        "position difference of the two signatures over 500 random configurations after "
        "aligning their bases and tools (sensor frames differ between sessions). Arms of one "
        "model are different robots; a session without a robot id is compared with none.\n",
        markdown_table(["robot id", "session", "RMS difference (cm)"], drift_rows)
        if drift_rows else "No robot has two identified sessions.",
        f"\n![drift]({figs['drift.png'].name})\n",
    ]  # fmt: skip
    md = out / "fleet.md"
    write_text_atomic(md, "\n".join(parts))
    return md
