"""The ``evaluate`` command: grid-touching tasks under design-model and signature control,
and the design controller driven to compensated targets."""

from __future__ import annotations

import sys
from typing import Annotated

import typer

from pipeline.cli.options import JsonOption, SessionArg
from pipeline.cli.output import print_json, warn

commands = typer.Typer()


@commands.command()
def evaluate(
    session: SessionArg,
    as_json: JsonOption = False,
    perfect_servo: Annotated[
        bool, typer.Option(help="Simulated rig: no servo error, no encoder rounding.")
    ] = False,
    exact_instruments: Annotated[
        bool, typer.Option(help="Simulated rig: instrument readings not quantized.")
    ] = False,
    report: Annotated[bool, typer.Option(help="Write report/evaluation.md.")] = True,
) -> None:
    """Grid-touching tasks under design-model and signature control, and the design controller
    driven to compensated targets (`pipeline compensate`), recorded and scored."""
    from pipeline.evaluate import evaluate as run_evaluate

    rig = None
    if perfect_servo or exact_instruments:
        from pipeline.rig.evaluation import EvaluationRigOptions

        rig = EvaluationRigOptions(perfect_servo, exact_instruments)
    r = run_evaluate(session, rig=rig, report=report, progress=sys.stderr)
    if as_json:
        print_json(r.summary)
        return
    for run in r.runs:
        typer.echo(f"  {run.name:22s} {run.action}")
    if r.recorded:
        typer.echo(f"  rig recorded: {', '.join(r.recorded)}")
    for name, task in r.summary["tasks"].items():
        text = _factor(task["median_improvement"])
        extra = ""
        if "median_improvement_compensated" in task:
            comp = task["median_improvement_compensated"]
            extra = f"; compensated targets on the design controller {_factor(comp)}"
        typer.echo(f"{name:8s} {len(task['indices']):3d} indices, median improvement {text}{extra}")
    for name, why in r.summary["skipped"].items():
        warn(f"{name} skipped: {why}")
    if r.report:
        typer.echo(f"report: {r.report}")


def _factor(median: float | None) -> str:
    return "inf" if median is None else f"{median:.2f}"  # None: an error exactly 0 (JSON)
