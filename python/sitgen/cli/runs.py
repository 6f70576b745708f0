"""Commands that run one situation or one controller: run, check-controller,
serve-controller, crosscheck."""

from __future__ import annotations

import json
import os
from pathlib import Path
from typing import TYPE_CHECKING, Annotated

import typer
from rich.console import Console
from rich.table import Table

from sitgen.controllers.ros2.dds_domain import unconfined
from sitgen.controllers.user import USER_PREFIXES
from sitgen.world.config import preset_spec
from sitgen.world.requirements import gathered, verdicts_text, with_requirements
from sitgen.world.situation import Situation, generate_situation

if TYPE_CHECKING:
    pass
from sitgen.cli.app import (
    EXIT_FAILED,
    AllowEditedOption,
    ControllerOption,
    ParamOption,
    PerceptionOption,
    RequirementsOption,
    RequireOption,
    RunSpecOption,
    SensorSeedOption,
    StepTimeoutOption,
    TimeLimitOption,
    UsageError,
    _read_run_spec,
    _writing,
    app,
    parse_params,
)


@app.command("serve-controller")
def serve_controller_command(
    situation: Annotated[Path, typer.Argument(help="Situation file (JSON).")],
    robot: Annotated[int, typer.Option("--robot", help="The robot's id.")],
    run_spec: Annotated[
        Path | None,
        typer.Option(
            "--run-spec", help="Run spec (TOML or JSON; `sitgen export` writes run.json)."
        ),
    ] = None,
    allow_edited: AllowEditedOption = False,
) -> None:
    """Answer the controller protocol on stdin/stdout with one robot's built-in controller:
    another simulator (Stage, through integrations/stage) sends observations, sitgen the
    commands (docs/stage.md)."""
    from sitgen.controllers.stage import serve_controller

    code = serve_controller(
        Situation.load(situation, allow_edited), _read_run_spec(run_spec), robot
    )
    if code:
        raise typer.Exit(code)


@app.command()
def crosscheck(
    situation: Annotated[Path, typer.Argument(help="Situation file (JSON).")],
    stage: Annotated[
        Path,
        typer.Option("--stage", help="The Stage 4.3 binary (integrations/stage/build.sh)."),
    ],
    plugin: Annotated[
        Path | None,
        typer.Option("--plugin", help="Folder of sitgen_stage.so (default: Stage's own)."),
    ] = None,
    spec: RunSpecOption = None,
    time_limit: TimeLimitOption = None,
    keep: Annotated[
        Path | None, typer.Option("--keep", help="Keep Stage's world and log in this folder.")
    ] = None,
    as_json: Annotated[
        Path | None, typer.Option("--json", help="Write the whole report here (JSON).")
    ] = None,
    allow_edited: AllowEditedOption = False,
) -> None:
    """Run a situation in sitgen and in the real Stage and compare them: pose divergence per
    robot, first stalls, both event logs from sitgen's monitor, and Stage's scans against
    sitgen's laser from the same poses (docs/stage.md says which differences are design)."""
    from sitgen.controllers.stage import StageError, StageTool, crosscheck, report_text
    from sitgen.run import run_spec_with

    try:
        tool = StageTool.find(stage, plugin)
        report = crosscheck(
            Situation.load(situation, allow_edited),
            run_spec_with(_read_run_spec(spec), time_limit),
            tool,
            keep,
        )
    except StageError as e:
        raise UsageError(str(e)) from None
    if as_json is not None:
        as_json.parent.mkdir(parents=True, exist_ok=True)
        as_json.write_text(json.dumps(report, indent=1))
    typer.echo(report_text(report), nl=False)


@app.command("run")
def run_command(
    situation: Annotated[Path, typer.Argument(help="Situation file (JSON).")],
    controller: ControllerOption = None,
    param: ParamOption = None,
    perception: PerceptionOption = None,
    step_timeout: StepTimeoutOption = None,
    time_limit: TimeLimitOption = None,
    require: RequireOption = None,
    requirements: RequirementsOption = None,
    seed: SensorSeedOption = 0,
    spec: RunSpecOption = None,
    events: Annotated[
        Path | None, typer.Option("--events", help="Write the event log here (JSON Lines).")
    ] = None,
    as_json: Annotated[
        bool, typer.Option("--json", help="Print the record as JSON instead of text.")
    ] = False,
    rosbag2: Annotated[
        Path | None,
        typer.Option("--rosbag2", help="Write the run as a rosbag2 (MCAP) into this new folder."),
    ] = None,
    allow_edited: AllowEditedOption = False,
) -> None:
    """Run one situation: print the outcome, the score with its breakdown, and the event log.
    Exits 1 when the controller failed (outcome error)."""
    from sitgen.presentation.rosbag import RosbagUnavailable, write_rosbag2
    from sitgen.run import run, run_spec_with

    if rosbag2 is not None and (rosbag2.is_symlink() or rosbag2.exists()):
        raise UsageError(f"--rosbag2: {rosbag2} already exists; a rosbag2 is written anew")
    loaded = Situation.load(situation, allow_edited)
    run_spec = run_spec_with(
        with_requirements(_read_run_spec(spec), gathered(require, requirements)),
        None,
        controller,
        parse_params(param),
        loaded.agent.controller,
        perception,
        step_timeout_s=step_timeout,
    )
    record = run(
        loaded,
        time_limit=time_limit,
        seed=seed,
        spec=run_spec,
        sensed=rosbag2 is not None,
    )
    if events is not None:
        events.parent.mkdir(parents=True, exist_ok=True)
        events.write_text(record.events_jsonl)
    if rosbag2 is not None:
        try:
            with _writing(rosbag2, "the rosbag2"):
                write_rosbag2(rosbag2, loaded, record, run_spec_with(run_spec, time_limit))
        except RosbagUnavailable as e:
            raise UsageError(f"--rosbag2: {e}") from None
        except FileExistsError as e:
            raise UsageError(f"--rosbag2: {e}") from None
    if as_json:
        typer.echo(json.dumps(record.to_dict(), indent=2))
    else:
        typer.echo(
            f"{situation}: {record.controller}, outcome {record.outcome} after "
            f"{record.time_s:.1f} s ({record.reason}), score {record.score:g}"
        )
        if record.failure is not None:
            typer.echo(f"failure: {record.failure['description']} ({record.failure['class']})")
        if record.breakdown:
            table = Table(title="score breakdown")
            for column in ("event", "count", "seconds", "points"):
                table.add_column(column, justify="left" if column == "event" else "right")
            for kind, line in record.breakdown.items():
                table.add_row(
                    kind, str(line["count"]), f"{line['seconds']:.1f}", f"{line['points']:g}"
                )
            Console().print(table)
        typer.echo(record.events_text, nl=False)
        if record.requirements:
            typer.echo(verdicts_text(record.requirements), nl=False)
    if record.outcome == "error":
        raise typer.Exit(EXIT_FAILED)


@app.command("check-controller")
def check_controller_command(
    controller: Annotated[
        str, typer.Argument(help="python:MODULE:CLASS, 'cmd:PROGRAM ARGS' or 'ros2:PROGRAM ARGS'.")
    ],
    situation: Annotated[
        Path | None,
        typer.Option("--situation", help="Situation to drive (default: open_field, seed 0)."),
    ] = None,
    steps: Annotated[int, typer.Option("--steps", min=1, max=100_000, help="Steps to drive.")] = 50,
    param: ParamOption = None,
    step_timeout: StepTimeoutOption = None,
    allow_edited: AllowEditedOption = False,
    keep_alive: Annotated[
        bool,
        typer.Option(
            "--keep-alive",
            help="A ros2: node: also check that, kept alive across runs (keep_alive), it runs "
            "the situation after another as a fresh node does.",
        ),
    ] = False,
) -> None:
    """Check that a user controller speaks the interface: loads, resets, replies with finite
    commands in time, stays within the limits, and shuts down. Exits 1 if a check fails."""
    from sitgen.conformance import check_controller

    if not controller.startswith(USER_PREFIXES):
        raise UsageError(
            f"controller `{controller}`: expected python:MODULE:CLASS, cmd:PROGRAM, "
            "ros2:PROGRAM or navground:BEHAVIOR"
        )
    if keep_alive and not controller.startswith("ros2:"):
        raise UsageError(f"--keep-alive: `{controller}` is not a ros2: node")
    loaded = (
        Situation.load(situation, allow_edited)
        if situation is not None
        else generate_situation(preset_spec("open_field"), seed=0)
    )
    # Another situation for the node's run before, where it is kept alive.
    before = generate_situation(preset_spec("open_field"), seed=1) if keep_alive else None
    checks = check_controller(
        controller,
        loaded,
        steps=steps,
        params=parse_params(param),
        kept_after=before,
        step_timeout_s=step_timeout,
    )
    for c in checks:
        typer.echo(f"{'ok  ' if c.ok else 'FAIL'} {c.name:8} {c.detail}")
    if controller.startswith("ros2:") and (heard := unconfined(os.environ)) is not None:
        typer.echo(f"note {'network':8} {heard}")
    if not all(c.ok for c in checks):
        raise typer.Exit(EXIT_FAILED)
