"""Tables, figure and the ``montecarlo.md`` section of the ``verdict`` study (issue 41).

``OUT/verdict/sessions.arrow``  one row per session: kind, seed, the verdict, the rules
                                that fired and their levels, predicted, held-out and
                                audited RMS, audited / predicted, χ²/dof
``OUT/verdict/summary.arrow``   one row per kind: PASS / CHECK / FAIL counts and rates,
                                percentiles of audited / predicted, median RMS
``OUT/verdict/rules.arrow``     one row per kind and (rule, level) that fired: in how many
                                sessions
``OUT/verdict/ratio.png``       audited / predicted RMS per session, by kind

The rules are the verdict table's names (``reason_rules``), whatever rules the verdict
stage has when the study runs; its version is in the tables' provenance.
"""

from __future__ import annotations

from dataclasses import asdict, replace
from pathlib import Path

import numpy as np
import pyarrow as pa

from pipeline.montecarlo.output import write_montecarlo_table
from pipeline.montecarlo.refine_report import finish, one_panel
from pipeline.montecarlo.refine_study import simulate_command
from pipeline.montecarlo.stats import arrow_field
from pipeline.montecarlo.verdict_study import LEVELS, UNCLEAN, KindSummary, VerdictResult
from pipeline.stages.tables import read_provenance, read_table

#: A column of a table: its field (unit, description) and its values.
Column = tuple[pa.Field, pa.Array]
HEADING = "## False alarms of the verdict on clean sessions (issue 41)"
FIGURE = ("ratio.png", "audited / predicted RMS tool error per session, by kind")


def _column(name: str, typ: pa.DataType, unit: str, description: str, values: list) -> Column:
    """A column of the study's tables; NaN floats are nulls."""
    if typ == pa.float64():
        v = np.array(values, float)
        return arrow_field(name, typ, unit, description), pa.array(v, typ, mask=np.isnan(v))
    return arrow_field(name, typ, unit, description), pa.array(values, typ)


def _table(cols: list[Column]) -> pa.Table:
    return pa.table([c for _, c in cols], schema=pa.schema([f for f, _ in cols]))


def sessions_table(res: VerdictResult) -> pa.Table:
    """One row per session (the module docstring)."""
    s, text, f64 = res.sessions, pa.string(), pa.float64()
    return _table([
        _column("kind", text, "", "kind of session", [x.kind for x in s]),
        _column("seed", pa.int64(), "", "pipeline simulate --seed", [x.seed for x in s]),
        _column("verdict", text, "", "PASS, CHECK or FAIL", [x.verdict for x in s]),
        _column("reason_rules", pa.list_(text), "", "the rules that fired",
                [list(x.rules) for x in s]),
        _column("reason_levels", pa.list_(text), "", "their levels", [list(x.levels) for x in s]),
        _column("predicted_rms_cm", f64, "cm", "predicted RMS tool error (verdict table)",
                [x.predicted_rms_cm for x in s]),
        _column("holdout_rms_cm", f64, "cm", "held-out RMS error (verdict table)",
                [x.holdout_rms_cm for x in s]),
        _column("chi2_per_dof", f64, "", "χ²/dof of the refinement (verdict table)",
                [x.chi2_per_dof for x in s]),
        _column("audited_rms_cm", f64, "cm", "RMS tool error against the truth (1,000 "
                "configurations)", [x.audited_rms_cm for x in s]),
        _column("audited_over_predicted", f64, "", "audited / predicted RMS",
                [x.audited_over_predicted for x in s]),
    ])  # fmt: skip


def summary_table(summaries: list[KindSummary]) -> pa.Table:
    """One row per kind (the module docstring)."""
    k, f64, i64 = summaries, pa.float64(), pa.int64()
    cols = [
        _column("kind", pa.string(), "", "kind of session", [x.kind for x in k]),
        _column("clean", pa.bool_(), "", "no error the model lacks", [x.clean for x in k]),
        _column("sessions", i64, "", "sessions of the kind", [x.sessions for x in k]),
    ]
    for level in LEVELS:
        low = level.lower()
        cols.append(_column(low, i64, "", f"{level} verdicts", [x.counts[level] for x in k]))
        cols.append(
            _column(f"{low}_rate", f64, "", f"{level} fraction", [x.rate(level) for x in k])
        )
    for i, (name, what) in enumerate(
        (
            ("ratio_p05", "5th percentile"),
            ("ratio_median", "median"),
            ("ratio_p95", "95th percentile"),
        )
    ):
        desc = f"{what} of audited / predicted"
        cols.append(_column(name, f64, "", desc, [x.ratio_percentiles[i] for x in k]))
    cols.append(_column("predicted_median_cm", f64, "cm", "median predicted RMS",
                        [x.predicted_median_cm for x in k]))  # fmt: skip
    cols.append(_column("audited_median_cm", f64, "cm", "median audited RMS",
                        [x.audited_median_cm for x in k]))  # fmt: skip
    return _table(cols)


def rules_table(summaries: list[KindSummary]) -> pa.Table:
    """One row per kind and (rule, level) that fired (the module docstring)."""
    rows = [(k.kind, r, lv, c, c / k.sessions) for k in summaries for r, lv, c in k.rules]
    text = pa.string()
    return _table([
        _column("kind", text, "", "kind of session", [r[0] for r in rows]),
        _column("rule", text, "", "the verdict table's rule (reason_rules)", [r[1] for r in rows]),
        _column("level", text, "", "its level (reason_levels)", [r[2] for r in rows]),
        _column("sessions", pa.int64(), "", "sessions it fired in", [r[3] for r in rows]),
        _column("rate", pa.float64(), "", "fraction of the kind's sessions", [r[4] for r in rows]),
    ])  # fmt: skip


def _provenance(res: VerdictResult) -> dict[str, object]:
    from pipeline.stages.verdict import STAGE

    first = {k: simulate_command(replace(o, seed=res.seed)) for k, o in res.kinds.items()}
    return {
        "study": "verdict",
        "settings": list(res.kinds),
        "robots": res.per_kind,
        "seed": res.seed,
        "wall_s": round(res.wall_s, 3),
        "verdict_stage_version": STAGE.version,
        "options": {k: {**asdict(o), "seed": None} for k, o in res.kinds.items()},
        "commands": first,
    }


def write_tables(out_dir: Path, res: VerdictResult) -> Path:
    """The study's tables and figure under ``out_dir/verdict``; returns that folder."""
    d = Path(out_dir) / "verdict"
    d.mkdir(parents=True, exist_ok=True)
    prov = _provenance(res)
    summaries = res.summaries()
    for name, table in (
        ("sessions", sessions_table(res)),
        ("summary", summary_table(summaries)),
        ("rules", rules_table(summaries)),
    ):
        write_montecarlo_table(d / f"{name}.arrow", table, f"montecarlo_verdict_{name}", prov)
    write_figures(res, d)
    return d


def write_figures(res: VerdictResult, folder: Path) -> None:
    """``ratio.png``: audited / predicted per session, one column of dots per kind."""
    fig, ax = one_panel(7.0, 4.2, 0.14, 0.3)
    kinds = list(res.kinds)
    jitter = np.random.default_rng(0)  # fixed: the same figure for the same sessions
    for i, kind in enumerate(kinds):
        y = np.array([s.audited_over_predicted for s in res.sessions if s.kind == kind])
        x = i + jitter.uniform(-0.2, 0.2, len(y))
        ax.semilogy(x, y, "o", ms=3, alpha=0.6, label=kind)
    ax.axhline(1.0, color="0.3", lw=0.8)
    ax.set_xticks(range(len(kinds)), kinds, rotation=30, ha="right", fontsize=8)
    labels = ("", "audited / predicted RMS", f"verdict study: {res.per_kind} sessions per kind")
    finish(fig, ax, labels, folder / FIGURE[0], grid="both")


def _rules_cell(out: Path, kind: str) -> str:
    t = read_table(out / "verdict" / "rules.arrow").to_pylist()
    cells = [f"{r['rule']} ({r['level']}) {r['sessions']}" for r in t if r["kind"] == kind]
    return "; ".join(cells) or "—"


def section(out: Path, wall_s: float) -> list[str]:
    """The study's section of ``montecarlo.md``: what was run, the figure, one row per kind."""
    folder = out / "verdict"
    prov = read_provenance(folder / "summary.arrow")
    rows = read_table(folder / "summary.arrow").to_pylist()
    n, seed = int(prov["robots"]), int(prov["seed"])
    unclean = ", ".join(f"`{k}`" for k in UNCLEAN)
    lines = [
        f"### verdict ({n} sessions per kind, {wall_s:.1f} s)",
        "",
        f"Whole `pipeline simulate` + `pipeline identify` sessions of a Puma 560, seeds {seed}",
        f"to {seed + n - 1} of each kind, judged by the `verdict` stage (version "
        f"{prov['verdict_stage_version']}) and",
        "audited against the truth over 1,000 random configurations. A CHECK or FAIL on a",
        f"clean kind is a false alarm; {unclean} has error no signature can express",
        "(docs/rig.md). Rules: the verdict table's `reason_rules` (their level) and in how",
        "many sessions each fired.",
        "",
    ]
    if (folder / FIGURE[0]).is_file():
        lines += [f"![verdict: {FIGURE[1]}](verdict/{FIGURE[0]})", ""]
    lines += [
        "| kind | sessions | PASS | CHECK | FAIL | rules fired (sessions) "
        "| median predicted (cm) | median audited (cm) | audited / predicted: median "
        "| 5-95 % |",
        "|---|---|---|---|---|---|---|---|---|---|",
    ]
    for r in rows:
        kind = r["kind"] if r["clean"] else f"{r['kind']} (not clean)"
        counts = [f"{r[lv.lower()]} ({r[lv.lower() + '_rate']:.0%})" for lv in LEVELS]
        lines.append(
            f"| {kind} | {r['sessions']} | {' | '.join(counts)} | {_rules_cell(out, r['kind'])} "
            f"| {r['predicted_median_cm']:.4f} | {r['audited_median_cm']:.4f} "
            f"| {r['ratio_median']:.2f} | {r['ratio_p05']:.2f}-{r['ratio_p95']:.2f} |"
        )
    lines += ["", f"Sessions re-recorded (seed {seed} of each kind; another seed: its --seed):", ""]
    lines += [f"- {k}: `{prov['commands'][k]}`" for k in prov["settings"]]
    lines += ["", "then `pipeline identify sessions/NAME` and `pipeline audit sessions/NAME`.", ""]
    return lines
