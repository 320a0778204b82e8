"""The ``montecarlo`` command: studies of design-model and signature control (Chapter 7)."""

from __future__ import annotations

import sys
from typing import Annotated

import typer

from pipeline.cli.options import JsonOption, Study, choice
from pipeline.cli.output import print_json

commands = typer.Typer()


@commands.command()
def montecarlo(
    study: Annotated[
        Study,
        choice(
            "encoder, machining, noise, points, radius, misalignment, features, refine "
            "(S-Model against refined signature; whole simulate + identify sessions, seconds of "
            "CPU per robot and setting: docs/montecarlo.md), compliance (rigid fit against a "
            "fit with joint compliance on compliant robots; seconds of CPU per robot), verdict "
            "(the verdict's false alarms on clean sessions of six kinds, --robots sessions per "
            "kind, seeds --seed onwards; ~1 s of CPU per session) or all (refine, compliance, "
            "verdict last)."
        ),
    ],
    robots: Annotated[
        int, typer.Option(min=2, max=100_000, help="Simulated robots per setting.")
    ] = 500,
    seed: Annotated[int, typer.Option(min=0, help="Study seed (same seed, same numbers).")] = 0,
    out: Annotated[str, typer.Option(help="Output folder.")] = "montecarlo",
    workers: Annotated[
        int, typer.Option(min=1, max=256, help="Worker processes (or local Dask workers).")
    ] = 1,
    scheduler: Annotated[
        str | None,
        typer.Option(
            help="Run the batches on Dask: tcp://HOST:PORT, or `local` for a local cluster "
            "of --workers (same numbers as without)."
        ),
    ] = None,
    as_json: JsonOption = False,
) -> None:
    """Monte-Carlo study of design-model and signature control (Chapter 7, Appendix G)."""
    from pipeline.montecarlo.studies import run_montecarlo

    if scheduler is None:
        done = run_montecarlo(study.value, robots, seed, out, workers, progress=sys.stderr)
    else:
        from pipeline.fleet.engine import dask_client

        with dask_client(scheduler, workers, progress=sys.stderr) as client:
            done = run_montecarlo(
                study.value, robots, seed, out, progress=sys.stderr, client=client
            )
    if as_json:
        print_json(done.to_dict())
        return
    for line in done.lines:
        typer.echo(line)
