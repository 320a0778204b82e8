"""Options whose value is one of a fixed set are enums (issue 30 item 6): any case, a wrong
value a usage error (exit 2) listing the choices, offered by shell completion, and equal
to the tuple of the module that does the work (the CLI's enums live in
``pipeline.cli.options``, which imports no numpy).

The options are listed by hand (:data:`CHOICES`): telling from a help text that a free
text option names a fixed set is guesswork. The list is checked against the command line
both ways: every enum option found is listed, every listed option is an enum. Free text
on purpose: ``identify --from/--only`` and ``show STAGE`` (the stage names depend on the
session's sensor; the runner refuses an unknown one with the session's list), ``ik
--near``, ``--scheduler`` (a URL or ``local``), ``simulate --robot`` (a name or a file).
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
from enum import StrEnum
from pathlib import Path

import pytest
import typer
from typer.testing import CliRunner

from pipeline.cli import EXIT_USAGE, app
from pipeline.cli.options import (
    Air,
    ExportFormat,
    ExportFrame,
    Fault,
    ImportFormat,
    Method,
    PumaBranch,
    Sensor,
    Setup,
    Study,
    choices_of,
)

runner = CliRunner()
ROOT = typer.main.get_command(app)


def _work_tuples() -> dict[type[StrEnum], tuple[str, ...]]:
    """Each enum's tuple in the module doing the work."""
    from pipeline.control.controller import METHODS
    from pipeline.export import FORMATS as EXPORT_FORMATS
    from pipeline.importers import FORMATS as IMPORT_FORMATS
    from pipeline.montecarlo.studies import STUDY_NAMES
    from pipeline.rig.options import AIRS, FAULTS, SENSORS, SETUPS
    from pipeline.robots.puma560 import BRANCHES
    from pipeline.signature.alignment import FRAMES

    return {
        ExportFormat: EXPORT_FORMATS, ExportFrame: FRAMES, Method: METHODS,
        PumaBranch: tuple(b.label for b in BRANCHES), Sensor: SENSORS, Air: AIRS,
        Fault: FAULTS, ImportFormat: IMPORT_FORMATS, Study: STUDY_NAMES, Setup: SETUPS,
    }  # fmt: skip


#: (command, option) -> (its enum, the arguments before it, so that only it is wrong).
CHOICES: dict[tuple[str, str], tuple[type[StrEnum], list[str]]] = {
    ("export", "--format"): (ExportFormat, ["export", "S"]),
    ("export", "--frame"): (ExportFrame, ["export", "S", "--format", "urdf"]),
    ("fk", "--frame"): (ExportFrame, ["fk", "puma560", "--q", "0 0 0 0 0 0"]),
    ("ik", "--method"): (Method, ["ik", "S"]),
    ("ik", "--branch"): (PumaBranch, ["ik", "S"]),
    ("compensate", "--method"): (Method, ["compensate", "S", "--targets", "t", "--out", "o"]),
    ("simulate", "--sensor"): (Sensor, ["simulate", "NEW"]),
    ("plan", "--sensor"): (Sensor, ["plan", "OUT.csv", "--robot", "puma560", "--sweeps"]),
    ("simulate", "--air"): (Air, ["simulate", "NEW"]),
    ("simulate", "--setup"): (Setup, ["simulate", "NEW", "--sensor", "camera", "--poses", "8"]),
    ("plan", "--setup"): (Setup, ["plan", "OUT.csv", "--robot", "puma560", "--sensor", "camera"]),
    ("simulate", "--faults"): (Fault, ["simulate", "NEW"]),
    ("import", "--format"): (ImportFormat, ["import", "f.csv", "NEW", "--robot", "r.toml"]),
    ("validate", "--format"): (ImportFormat, ["validate", "S", "--against", "f.csv"]),
    ("montecarlo", "--study"): (Study, ["montecarlo", "--out", "NEW"]),
}
#: Options of comma-separated values of an enum (a text option with a callback).
LISTS = {("simulate", "--faults")}


def _option(command: str, option: str) -> typer.core.TyperOption:
    return next(p for p in ROOT.commands[command].params if option in p.opts)


def _enum_options() -> set[tuple[str, str]]:
    """(command, option) of every enum-typed option of the command line."""
    found = set()
    for name, cmd in ROOT.commands.items():
        for p in getattr(cmd, "params", []):
            bare = p.type_descriptor.annotation
            if isinstance(bare, type) and issubclass(bare, StrEnum):
                found.add((name, p.opts[0]))
    return found


def test_the_list_is_the_command_lines_enums() -> None:
    assert _enum_options() == set(CHOICES) - LISTS
    for command, option in set(CHOICES) - LISTS:
        assert _option(command, option).type_descriptor.case_sensitive is False


@pytest.mark.parametrize("enum", list(_work_tuples()), ids=lambda e: e.__name__)
def test_each_enum_is_the_tuple_of_the_work(enum: type[StrEnum]) -> None:
    assert tuple(e.value for e in enum) == _work_tuples()[enum]


@pytest.mark.parametrize(("command", "option"), list(CHOICES), ids="{0[0]} {0[1]}".format)
def test_a_wrong_value_is_a_usage_error_listing_the_choices(
    command: str, option: str, tmp_path: Path
) -> None:
    enum, before = CHOICES[(command, option)]
    args = [str(tmp_path / "new") if a == "NEW" else a for a in before]
    r = runner.invoke(app, [*args, option, "nope"])
    assert r.exit_code == EXIT_USAGE, r.output
    lines = r.stderr.splitlines()
    listed = ", ".join(f"'{e.value}'" for e in enum)
    assert len(lines) == 1 and lines[0].startswith("error: ") and listed in lines[0], lines
    assert f"'{option}'" in lines[0] and r.stdout == ""
    assert not (tmp_path / "new").exists()


@pytest.mark.parametrize(("command", "option"), list(CHOICES), ids="{0[0]} {0[1]}".format)
def test_any_case_is_taken(command: str, option: str) -> None:
    enum, before = CHOICES[(command, option)]
    value = list(enum)[-1]
    args = [a for a in before[1:] if a != "NEW"] + (["x"] if "NEW" in before else [])
    ctx = ROOT.commands[command].make_context(command, [*args, option, value.value.upper()])
    param = _option(command, option).name
    got = ctx.params[param]
    assert (choices_of(got, enum) if (command, option) in LISTS else got) in (value, (value,))


def test_a_list_of_choices_in_any_case_and_order() -> None:
    assert choices_of("Outliers, BIAS", Fault) == ("outliers", "bias")
    with pytest.raises(typer.BadParameter, match="'smoke' is not one of 'bias'"):
        choices_of("bias,smoke", Fault)


def test_simulate_records_the_choices_lower_case(tmp_path: Path) -> None:
    d = tmp_path / "s"
    args = ["simulate", str(d), "--points", "6", "--repeats", "1"]
    r = runner.invoke(app, [*args, "--air", "DRIFTING", "--faults", "Bias,Outliers"])
    assert r.exit_code == 0, r.output
    truth = json.loads((d / "rig-truth.json").read_text())
    assert truth["options"]["air"] == "drifting"
    assert truth["options"]["faults"] == ["bias", "outliers"]


@pytest.mark.parametrize(("command", "option"), list(CHOICES), ids="{0[0]} {0[1]}".format)
def test_completion_offers_the_choices(command: str, option: str) -> None:
    """Click's completion of the option's value (what the shell script asks for)."""
    enum, _ = CHOICES[(command, option)]
    param, ctx = _option(command, option), typer.Context(ROOT.commands[command])
    values = [e.value for e in enum]
    assert [c.value for c in param.shell_complete(ctx, "")] == values
    first = values[-1][0]
    want = [v for v in values if v.startswith(first)]
    assert [c.value for c in param.shell_complete(ctx, first)] == want


def test_completion_of_a_list_offers_the_items_not_given_yet() -> None:
    param, ctx = _option("simulate", "--faults"), typer.Context(ROOT.commands["simulate"])
    assert [c.value for c in param.shell_complete(ctx, "bias,")] == [
        "bias,dropouts",
        "bias,outliers",
    ]
    assert [c.value for c in param.shell_complete(ctx, "bias,o")] == ["bias,outliers"]


def test_shell_completion_protocol_offers_an_enums_choices() -> None:
    """The protocol the installed completion script speaks (`--install-completion`)."""
    words = "pipeline export sessions/robot3 --format "
    env = {"_PIPELINE_COMPLETE": "complete_bash", "COMP_WORDS": words, "COMP_CWORD": "4"}
    cmd = [sys.executable, "-m", "pipeline"]
    done = subprocess.run(cmd, env={**os.environ, **env}, capture_output=True, text=True)
    assert done.returncode == 0, done.stderr
    assert done.stdout.split() == [e.value for e in ExportFormat]
