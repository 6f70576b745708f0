"""The ``sitgen`` command.

Errors a user can fix (a bad spec, an unwritable file) print one line, ``error: …``, naming
the field or file, and exit 2 (bad input) or 1 (generation or I/O failed); never a traceback.
"""

from __future__ import annotations

import json
import sys
from pathlib import Path
from typing import Annotated, Any

import typer
from rich.console import Console
from rich.table import Table

from sitgen import _core
from sitgen.config import preset_names, preset_spec
from sitgen.situation import Situation, generate_situation
from sitgen.terrain import Grid, generate_terrain

app = typer.Typer(
    name="sitgen",
    help="Procedurally generated situations for testing robot navigation software.",
    no_args_is_help=True,
    pretty_exceptions_enable=False,
    add_completion=False,
)

EXIT_BAD_INPUT = 2
EXIT_FAILED = 1
DEFAULT_PRESET = "rocky_desert"
"""The preset used when a command gets neither a spec nor --preset."""

SeedOption = Annotated[int, typer.Option("--seed", "-s", min=0, max=2**64 - 1, help="Master seed.")]


class UsageError(Exception):
    """Bad command-line input that is not a spec field (exit 2)."""


def _coverage_target(spec: dict[str, Any]) -> str:
    for f in spec.get("terrain", {}).get("filters", []):
        if f.get("kind") == "coverage":
            return f" (target {f['target']} ± {f.get('tolerance', 0.01)})"
    return ""


def _describe(grid: Grid) -> str:
    rows, cols = grid.occupied.shape
    width, height = grid.size_m
    return (
        f"{cols} × {rows} cells, {width:g} m × {height:g} m at {grid.resolution:g} m/cell, "
        f"coverage {grid.coverage:.4f}{_coverage_target(grid.spec)}"
    )


def _summary(grid: Grid, image: Path, yaml: Path | None) -> dict[str, Any]:
    rows, cols = grid.occupied.shape
    return {
        "image": str(image),
        "yaml": str(yaml) if yaml else None,
        "seed": grid.seed,
        "rows": rows,
        "cols": cols,
        "resolution_m": grid.resolution,
        "size_m": list(grid.size_m),
        "coverage": grid.coverage,
        "stages": [s.__dict__ for s in grid.stages],
        "spec": grid.spec,
    }


@app.command()
def terrain(
    spec: Annotated[
        Path | None, typer.Argument(help="Situation spec (TOML). Omit to use --preset.")
    ] = None,
    preset: Annotated[
        str | None, typer.Option("--preset", "-p", help="Built-in preset to generate.")
    ] = None,
    seed: SeedOption = 0,
    output: Annotated[
        Path, typer.Option("--output", "-o", help="Map image to write (.png or .pgm).")
    ] = Path("map.png"),
    as_json: Annotated[bool, typer.Option("--json", help="Print a JSON summary.")] = False,
) -> None:
    """Generate a terrain map: write the image and a ROS map_server YAML beside it."""
    if output.suffix.lower() not in (".png", ".pgm"):
        raise UsageError(f"--output: {output} must end in .png or .pgm")
    grid = generate_terrain(_spec_or_preset(spec, preset), seed=seed)
    output.parent.mkdir(parents=True, exist_ok=True)
    yaml = grid.save(output)
    if as_json:
        typer.echo(json.dumps(_summary(grid, output, yaml)))
    else:
        typer.echo(f"{output}: {_describe(grid)}")
        typer.echo(f"wrote {output} and {yaml}")


def _spec_or_preset(spec: Path | None, preset: str | None) -> Path | dict[str, Any]:
    if spec is not None and preset is not None:
        raise UsageError(
            "give a SPEC file or --preset, not both (a spec names its preset in terrain.preset)"
        )
    return spec if spec is not None else preset_spec(preset or DEFAULT_PRESET)


@app.command()
def generate(
    spec: Annotated[
        Path | None, typer.Argument(help="Situation spec (TOML). Omit to use --preset.")
    ] = None,
    preset: Annotated[
        str | None, typer.Option("--preset", "-p", help="Built-in terrain preset.")
    ] = None,
    seed: SeedOption = 0,
    output: Annotated[
        Path, typer.Option("--output", "-o", help="Situation file to write (JSON).")
    ] = Path("situation.json"),
) -> None:
    """Generate a situation: terrain, robots and routes, as JSON."""
    situation = generate_situation(_spec_or_preset(spec, preset), seed=seed)
    output.parent.mkdir(parents=True, exist_ok=True)
    situation.save(output)
    agent = situation.agent
    width, height = situation.grid.size_m
    typer.echo(
        f"{output}: {width:g} m × {height:g} m, {len(situation.robots) - 1} peers, "
        f"agent route {len(agent.waypoints)} waypoints, {situation.content_hash}"
    )


@app.command()
def show(
    situation: Annotated[Path, typer.Argument(help="Situation file (JSON).")],
    output: Annotated[Path, typer.Option("--output", "-o", help="Figure to write (PNG).")] = Path(
        "situation.png"
    ),
) -> None:
    """Draw a situation in the paper's style: map, routes, starts and goals, scale bar."""
    from sitgen.figure import save_situation_figure

    loaded = Situation.load(situation)
    output.parent.mkdir(parents=True, exist_ok=True)
    save_situation_figure(loaded, output)
    typer.echo(f"wrote {output}")


@app.command()
def export(
    situation: Annotated[Path, typer.Argument(help="Situation file (JSON).")],
    format: Annotated[
        str,
        typer.Option("--format", "-f", help="stage (Player/Stage world) or ros (map YAML+PGM)."),
    ] = "stage",
    output: Annotated[Path, typer.Option("--output", "-o", help="Folder to write.")] = Path(
        "export"
    ),
) -> None:
    """Export a situation for Player/Stage or ROS."""
    if format not in ("stage", "ros"):
        raise UsageError(f"--format: `{format}` is not one of stage, ros")
    for path in Situation.load(situation).export(output, format):
        typer.echo(f"wrote {path}")


def _read_run_spec(path: Path | None) -> dict[str, Any]:
    if path is None:
        return {}
    import tomllib

    try:
        return tomllib.loads(path.read_text())
    except tomllib.TOMLDecodeError as e:
        raise _core.SpecError(f"{path}: TOML syntax error: {e}") from None


@app.command("run")
def run_command(
    situation: Annotated[Path, typer.Argument(help="Situation file (JSON).")],
    controller: Annotated[
        str | None,
        typer.Option(
            "--controller",
            "-c",
            help="snd_follow, snd, follow, vo, dwa, straight, python:MODULE:CLASS or "
            "'cmd:PROGRAM ARGS'. Default: the situation's.",
        ),
    ] = None,
    time_limit: Annotated[
        float | None,
        typer.Option("--time-limit", help="Simulated seconds before a timeout (default 600)."),
    ] = None,
    seed: Annotated[int, typer.Option("--seed", "-s", min=0, help="Sensor-noise seed.")] = 0,
    spec: Annotated[
        Path | None,
        typer.Option("--spec", help="Run spec (TOML): time_limit_s, [sim], [monitor], [scoring]."),
    ] = None,
    events: Annotated[
        Path | None, typer.Option("--events", help="Write the event log here (JSON Lines).")
    ] = None,
    as_json: Annotated[
        bool, typer.Option("--json", help="Print the record as JSON instead of text.")
    ] = False,
) -> None:
    """Run one situation: print the outcome, the score with its breakdown, and the event log.
    Exits 1 when the controller failed (outcome error)."""
    from sitgen.run import run

    record = run(
        Situation.load(situation),
        controller=controller,
        time_limit=time_limit,
        seed=seed,
        spec=_read_run_spec(spec),
    )
    if events is not None:
        events.parent.mkdir(parents=True, exist_ok=True)
        events.write_text(record.events_jsonl)
    if as_json:
        typer.echo(json.dumps(record.to_dict(), indent=2))
    else:
        typer.echo(
            f"{situation}: {record.controller}, outcome {record.outcome} after "
            f"{record.time_s:.1f} s ({record.reason}), score {record.score:g}"
        )
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
    if record.outcome == "error":
        raise typer.Exit(EXIT_FAILED)


@app.command("check-controller")
def check_controller_command(
    controller: Annotated[str, typer.Argument(help="python:MODULE:CLASS or 'cmd:PROGRAM ARGS'.")],
    situation: Annotated[
        Path | None,
        typer.Option("--situation", help="Situation to drive (default: open_field, seed 0)."),
    ] = None,
    steps: Annotated[int, typer.Option("--steps", min=1, help="Steps to drive.")] = 50,
) -> None:
    """Check that a user controller speaks the interface: loads, resets, replies with finite
    commands in time, stays within the limits, and shuts down. Exits 1 if a check fails."""
    from sitgen.run import check_controller

    if not controller.startswith(("python:", "cmd:")):
        raise UsageError(f"controller `{controller}`: expected python:MODULE:CLASS or cmd:PROGRAM")
    loaded = (
        Situation.load(situation)
        if situation is not None
        else generate_situation(preset_spec("open_field"), seed=0)
    )
    checks = check_controller(controller, loaded, steps=steps)
    for c in checks:
        typer.echo(f"{'ok  ' if c.ok else 'FAIL'} {c.name:8} {c.detail}")
    if not all(c.ok for c in checks):
        raise typer.Exit(EXIT_FAILED)


@app.command()
def demo(
    output: Annotated[Path, typer.Option("--output", "-o", help="Folder for the maps.")] = Path(
        "demo"
    ),
    seed: SeedOption = 0,
) -> None:
    """Generate one situation of every built-in preset: its map (PNG + ROS YAML), the situation
    (JSON) and its figure (the main job on built-in defaults)."""
    from sitgen.figure import save_situation_figure

    output.mkdir(parents=True, exist_ok=True)
    table = Table(title=f"sitgen presets, seed {seed}")
    for column in ("preset", "size", "coverage", "target", "peers", "waypoints"):
        table.add_column(column)
    for name in preset_names():
        situation = generate_situation(preset_spec(name), seed=seed)
        grid = situation.grid
        grid.save(output / f"{name}.png")
        situation.save(output / f"{name}.json")
        save_situation_figure(situation, output / f"{name}-situation.png")
        width, height = grid.size_m
        target = _coverage_target(situation.spec)
        table.add_row(
            name,
            f"{width:g} × {height:g} m",
            f"{grid.coverage:.4f}",
            target.strip(" ()").removeprefix("target "),
            str(len(situation.robots) - 1),
            str(len(situation.agent.waypoints)),
        )
    Console().print(table)
    typer.echo(
        f"wrote {len(preset_names())} maps (PNG + ROS YAML), situations (JSON) and figures "
        f"to {output}/"
    )


@app.command()
def presets(
    name: Annotated[str | None, typer.Argument(help="Print this preset's TOML.")] = None,
) -> None:
    """List the built-in terrain presets, or print one."""
    if name is None:
        for preset in preset_names():
            first = _core.preset_text(preset).splitlines()[0].lstrip("# ")
            typer.echo(f"{preset:14} {first}")
    else:
        typer.echo(_core.preset_text(name), nl=False)


@app.command()
def schema(
    situation: Annotated[
        bool, typer.Option("--situation", help="The schema of situation files instead.")
    ] = False,
) -> None:
    """Print the JSON Schema of the situation spec (or of situation files)."""
    text = _core.situation_json_schema() if situation else _core.spec_json_schema()
    typer.echo(text, nl=False)


def main() -> None:
    """Entry point: run the command, turning expected errors into one line and an exit code."""
    try:
        app()
    except (_core.SpecError, UsageError) as e:
        print(f"error: {e}", file=sys.stderr)
        sys.exit(EXIT_BAD_INPUT)
    except (_core.GenerationFailed, OSError) as e:
        print(f"error: {e}", file=sys.stderr)
        sys.exit(EXIT_FAILED)


if __name__ == "__main__":
    main()
