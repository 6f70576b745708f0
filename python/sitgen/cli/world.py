"""Commands on situations and their world: terrain, generate, show, export, presets,
profiles, schema."""

from __future__ import annotations

import json
from pathlib import Path
from typing import TYPE_CHECKING, Annotated, Any

import typer

from sitgen import _core
from sitgen.store import StoreError, require_store
from sitgen.world.config import preset_names, preset_spec
from sitgen.world.situation import Situation, generate_situation
from sitgen.world.terrain import Grid, generate_terrain

if TYPE_CHECKING:
    pass
from sitgen.cli.app import (
    DEFAULT_PRESET,
    AllowEditedOption,
    RunSpecOption,
    SeedOption,
    UsageError,
    _is_store,
    _read_run_spec,
    _writing,
    app,
)


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
    source: Annotated[
        Path, typer.Argument(help="Situation file (JSON), or a campaign store with --run.")
    ],
    run_id: Annotated[
        int | None,
        typer.Option("--run", help="Draw this run of the campaign store: paths and events."),
    ] = None,
    output: Annotated[Path, typer.Option("--output", "-o", help="Figure to write (PNG).")] = Path(
        "situation.png"
    ),
    allow_edited: AllowEditedOption = False,
) -> None:
    """Draw a situation in the paper's style: map, routes, starts and goals, scale bar; with
    --run, also the paths driven and where the agent's scored events began."""
    from sitgen.world.figure import save_situation_figure

    output.parent.mkdir(parents=True, exist_ok=True)
    if run_id is None:
        if _is_store(source):
            raise UsageError(f"{source} is a campaign store: give --run RUN_ID")
        save_situation_figure(Situation.load(source, allow_edited), output)
    else:
        from sitgen.store import Store

        if not _is_store(source):
            raise UsageError("--run needs a campaign store (.db), not a situation file")
        require_store(source)
        from sitgen.triage.recall import stored_run, whole_run

        with Store(source) as store:
            row = stored_run(store, run_id)
            whole = whole_run(store, row)
        if whole is None:
            raise UsageError(f"run {run_id} has no situation (generation failed)")
        events = [json.loads(line) for line in whole.events_jsonl.splitlines()]
        dt_s = float(row["run_spec"].get("sim", {}).get("dt_s", 0.1))
        # Drawn as it was run, even where an older sitgen placed a robot across the map's edge.
        save_situation_figure(whole.situation, output, whole.trajectory, events, dt_s)
    typer.echo(f"wrote {output}")


@app.command()
def export(
    source: Annotated[Path, typer.Argument(help="Situation file (JSON) or campaign store (.db).")],
    format: Annotated[
        str,
        typer.Option(
            "--format",
            "-f",
            help="Situation: stage (Player/Stage world) or ros (map YAML+PGM). "
            "Campaign: parquet or csv (one file per table); with --run, rosbag2 (the run as "
            "a rosbag2) or situation (its situation file and run spec, to run, shrink or "
            "edit).",
        ),
    ] = "stage",
    output: Annotated[Path, typer.Option("--output", "-o", help="Folder to write.")] = Path(
        "export"
    ),
    spec: RunSpecOption = None,
    allow_edited: AllowEditedOption = False,
    run_id: Annotated[
        int | None,
        typer.Option("--run", help="With --format rosbag2 or situation: the stored run to write."),
    ] = None,
) -> None:
    """Export a situation for Stage (with how it is run: --spec's laser, limits and time limit,
    every robot driven by its sitgen controller, docs/stage.md) or ROS, a campaign's tables
    for analysis (pandas, polars, DuckDB), or one stored run as a rosbag2 (MCAP) for ROS tools
    (docs/ros2.md)."""
    if _is_store(source):
        from sitgen.triage.rank import (
            export_descriptors,
            export_run_descriptors,
            export_signals,
            export_tables,
        )

        require_store(source)
        if format == "situation":
            _export_situation(source, run_id, output)
            return
        if format == "rosbag2" or run_id is not None:
            _export_rosbag2(source, run_id, format, output)
            return
        if format == "stage":
            format = "parquet"
        if format not in ("parquet", "csv"):
            raise UsageError(f"--format: `{format}` is not one of parquet, csv for a campaign")
        with _writing(output, "the tables"):
            for path in export_tables(source, output, format):
                typer.echo(f"wrote {path}")
            signals = export_signals(source, output, format)
            if signals is not None:
                typer.echo(f"wrote {signals} (every judged run made again for its signals)")
            descriptors = export_descriptors(source, output, format)
            if descriptors is not None:
                typer.echo(f"wrote {descriptors} (every run's situation described)")
            measured = export_run_descriptors(source, output, format)
            if measured is not None:
                typer.echo(f"wrote {measured} (every failing run made again and measured)")
        return
    if format not in ("stage", "ros"):
        raise UsageError(f"--format: `{format}` is not one of stage, ros")
    run_spec = _read_run_spec(spec)
    with _writing(output, "the export"):
        for path in Situation.load(source, allow_edited).export(output, format, run=run_spec):
            typer.echo(f"wrote {path}")


def _export_situation(db: Path, run_id: int | None, output: Path) -> None:
    """Stored run ``run_id``'s situation file and run spec, written into folder ``output``
    (the situation as stored, or generated again from its spec and seed: no run is made)."""
    from sitgen.store import Store
    from sitgen.triage.recall import regenerate, stored_run

    if run_id is None:
        raise UsageError("--format situation: give the run to write with --run ID")
    try:
        with Store(db) as store:
            row = stored_run(store, run_id)
    except StoreError as e:
        raise UsageError(str(e)) from None
    if row["content_hash"] is None:
        raise UsageError(f"run {run_id}: its situation was never generated: {row['reason']}")
    situation = (
        Situation(row["situation"], check_start=False)
        if row["situation"] is not None
        else regenerate(row)
    )
    situation_path = output / f"run-{run_id}.json"
    spec_path = output / f"run-{run_id}.run.json"
    with _writing(output, "the run's files"):
        output.mkdir(parents=True, exist_ok=True)
        situation.save(situation_path)
        spec_path.write_text(json.dumps(row["run_spec"], indent=2, sort_keys=True) + "\n")
    typer.echo(f"wrote {situation_path}, {spec_path}")
    typer.echo(f"rerun: sitgen run {situation_path} --spec {spec_path} --seed {row['run_seed']}")


def _export_rosbag2(db: Path, run_id: int | None, format: str, output: Path) -> None:
    from sitgen.presentation.rosbag import RosbagUnavailable, write_stored_run
    from sitgen.store import Store

    if format != "rosbag2":
        raise UsageError(f"--run: a single run is exported as --format rosbag2, not `{format}`")
    if run_id is None:
        raise UsageError("--format rosbag2: give the run to write with --run ID")
    if output.is_symlink() or output.exists():
        raise UsageError(f"{output}: already exists; a rosbag2 is written into a new folder")
    try:
        with Store(db) as store, _writing(output, "the rosbag2"):
            path = write_stored_run(store, run_id, output)
    except RosbagUnavailable as e:
        raise UsageError(f"--format rosbag2: {e}") from None
    except FileExistsError as e:
        # Made since the check above: another export into the same folder at the same time.
        raise UsageError(str(e)) from None
    typer.echo(f"wrote {output} ({path.name}, metadata.yaml)")


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
def profiles(
    name: Annotated[str | None, typer.Argument(help="Print this profile's TOML.")] = None,
) -> None:
    """List the run profiles (`[run] profile = NAME`), or print one with its sources."""
    if name is None:
        for profile in _core.profile_names():
            text = _core.profile_text(profile).splitlines()[0].lstrip("# ")
            typer.echo(f"{profile:10} {text}")
    else:
        typer.echo(_core.profile_text(name), nl=False)


@app.command()
def schema(
    situation: Annotated[
        bool, typer.Option("--situation", help="The schema of situation files instead.")
    ] = False,
) -> None:
    """Print the JSON Schema of the situation spec (or of situation files)."""
    text = _core.situation_json_schema() if situation else _core.spec_json_schema()
    typer.echo(text, nl=False)
