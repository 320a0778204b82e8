"""The ``pipeline`` command line. Commands are thin; the work is in importable functions.

One module per command group, in the order of the data's path:
:mod:`~pipeline.cli.record` (robots, simulate, import), :mod:`~pipeline.cli.plan`,
:mod:`~pipeline.cli.session` (identify, status, show, audit, validate),
:mod:`~pipeline.cli.control` (fk, ik, ik-convergence), :mod:`~pipeline.cli.evaluate`,
:mod:`~pipeline.cli.outputs` (viz, export), :mod:`~pipeline.cli.montecarlo` and the ``fleet`` group
(:mod:`~pipeline.cli.fleet`); :mod:`~pipeline.cli.options` and
:mod:`~pipeline.cli.output` hold what they share. Each command imports numpy and the
modules doing its work when it runs, not when the command line starts (issue 18).

Only this module turns exceptions into exit codes, in one place (:class:`_Pipeline`):

===  =====================================================================
0    done
1    refused input or data (an :class:`~pipeline.errors.ArmsigError`)
2    usage error (unknown command or option, missing or malformed argument)
3    ``ik``: a target was not reached, or has no solution inside the joint limits on
     its branch (status ``out_of_limits``; the joints are still printed / written)
4    the signature's verdict is FAIL (docs/verdict.md): ``identify`` after writing the
     signature and the report and printing the verdict; ``export`` and ``ik`` refuse it
     unless ``--accept-verdict`` (a :class:`~pipeline.errors.VerdictFailError`)
70   internal error: a bug in armsig (the traceback with ``ARMSIG_DEBUG=1``, which also
     shows other packages' warnings and Dask's logs: :mod:`pipeline.quiet`)
130  interrupted (Ctrl-C), with no traceback, also while the command line loads
===  =====================================================================

Every error is one line on stderr starting ``error:``.
"""

from __future__ import annotations

import os
import shlex
import sys
import traceback
from collections.abc import Sequence
from typing import Annotated, Any

import typer
from typer.core import TyperGroup

from pipeline.cli import control, evaluate, fleet, montecarlo, outputs, plan, record, session
from pipeline.cli.output import NotReached
from pipeline.errors import EXIT_INTERRUPTED, ArmsigError, VerdictFailError, one_line
from pipeline.quiet import DEBUG_ENV, quiet

EXIT_REFUSED = 1
EXIT_USAGE = 2
EXIT_NOT_REACHED = 3
EXIT_VERDICT_FAIL = 4
EXIT_INTERNAL = 70  # EX_SOFTWARE of sysexits.h


def _fail(message: str, code: int) -> int:
    typer.echo(f"error: {one_line(message)}", err=True)
    return code


def _missing_command(ctx: Any) -> str:
    """The message of a group called without its command (click's is empty after the
    help it printed: ``pipeline fleet`` said "error: ; try: ...", issue 44)."""
    names = ctx.command.list_commands(ctx) if hasattr(ctx, "command") else []
    return "Missing command" + (f"; expected one of {', '.join(names)}" if names else "")


class _Pipeline(TyperGroup):
    """The command group: maps every outcome of a command to one exit code."""

    def main(  # type: ignore[override]
        self,
        args: Sequence[str] | None = None,
        prog_name: str | None = None,
        complete_var: str | None = None,
        standalone_mode: bool = True,
        **extra: Any,
    ) -> Any:
        argv = list(sys.argv[1:] if args is None else args)
        prog = prog_name or "pipeline"
        debug = os.environ.get(DEBUG_ENV) == "1"
        try:
            with quiet(debug):  # other packages' warnings and logs: pipeline.quiet
                rv = super().main(argv, prog, complete_var, standalone_mode=False, **extra)
            code = rv if isinstance(rv, int) else 0  # an int: typer.Exit's code (--help: 0)
        except typer.TyperException as exc:  # the parser's: unknown option, bad value, ...
            ctx = getattr(exc, "ctx", None)
            where = getattr(ctx, "command_path", None) or prog
            what = exc.format_message().rstrip(".") or _missing_command(ctx)
            code = _fail(f"{what}; try: {where} --help", EXIT_USAGE)
        except typer.Abort:
            code = _fail("aborted", EXIT_REFUSED)
        except VerdictFailError as exc:  # before ArmsigError, its base
            code = _fail(str(exc), EXIT_VERDICT_FAIL)
        except ArmsigError as exc:
            code = _fail(str(exc), EXIT_REFUSED)
        except NotReached:  # the output is complete; the exit code says a target was missed
            code = EXIT_NOT_REACHED
        except KeyboardInterrupt:  # Ctrl-C outside typer's own handling: as typer's
            code = EXIT_INTERRUPTED
        except SystemExit:
            raise
        except BaseException as exc:  # noqa: B036  (also a Rust panic of polars / pyarrow)
            if debug:
                traceback.print_exc()
            command = shlex.join([prog, *argv])
            code = _fail(
                f"internal error (a bug in armsig): {type(exc).__name__}: {exc}; "
                f"try: report it with the output of {DEBUG_ENV}=1 {command}",
                EXIT_INTERNAL,
            )
        if not standalone_mode:
            return code
        sys.exit(code)


app = typer.Typer(
    name="pipeline",
    help="armsig: identify a robot arm's kinematic signature and control it with it.",
    cls=_Pipeline,
    add_completion=True,
    pretty_exceptions_enable=False,
)


def _version(value: bool) -> None:
    if value:
        from pipeline import __version__

        typer.echo(f"armsig {__version__}")
        raise typer.Exit()


@app.callback()
def _main(
    version: Annotated[
        bool,
        typer.Option(
            "--version", callback=_version, is_eager=True, help="Print the version and exit."
        ),
    ] = False,
) -> None:
    pass  # the group's options; its help is the app's


# `pipeline --help` lists the commands in this order.
for _group in (record, plan, session, control, evaluate, outputs, montecarlo):
    app.add_typer(_group.commands)
app.add_typer(fleet.commands, name="fleet")

__all__ = [
    "DEBUG_ENV",
    "EXIT_INTERNAL",
    "EXIT_INTERRUPTED",
    "EXIT_NOT_REACHED",
    "EXIT_REFUSED",
    "EXIT_USAGE",
    "EXIT_VERDICT_FAIL",
    "app",
]
