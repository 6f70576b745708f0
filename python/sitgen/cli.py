"""The ``sitgen`` command.

Errors a user can fix (a bad spec, an unwritable file) print one line, ``error: …``, naming
the field or file, and exit 2 (bad input) or 1 (generation or I/O failed); never a traceback.
"""

from __future__ import annotations

import contextlib
import copy
import json
import os
import sqlite3
import sys
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import TYPE_CHECKING, Annotated, Any, Protocol, TypeVar

import typer
from rich.console import Console
from rich.table import Table

from sitgen import _core
from sitgen.store import StoreError, StoreMissing, require_store
from sitgen.world.config import preset_names, preset_spec, read_utf8
from sitgen.world.situation import Situation, generate_situation
from sitgen.world.terrain import Grid, generate_terrain

if TYPE_CHECKING:
    from sitgen.execution.jobs import CampaignSpec
    from sitgen.triage.weights import Weights

T = TypeVar("T")

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
CampaignSeedOption = Annotated[int, typer.Option("--seed", "-s", min=0, max=2**63 - 1)]
WorkersOption = Annotated[
    int | None, typer.Option("--workers", "-w", min=1, help="Parallel runs (default: cores).")
]
BackendOption = Annotated[str, typer.Option("--backend", help="local or ray.")]
RerunsOption = Annotated[
    int,
    typer.Option(
        "--reruns",
        help="Perturbed copies of each distinct failure's representative run at the end, to "
        "tell robust failures from knife-edge ones (docs/failures.md); 0: none.",
    ),
]
AddressOption = Annotated[
    str | None, typer.Option("--address", help="Ray cluster address (with --backend ray).")
]
ControllerOption = Annotated[
    str | None,
    typer.Option(
        "--controller",
        "-c",
        help="snd_follow, snd, follow, vo, dwa, straight, python:MODULE:CLASS or "
        "'cmd:PROGRAM ARGS'. Default: the situation's.",
    ),
]
TimeLimitOption = Annotated[
    float | None,
    typer.Option("--time-limit", help="Simulated seconds before a timeout (default 600)."),
]
SensorSeedOption = Annotated[int, typer.Option("--seed", "-s", min=0, help="Sensor-noise seed.")]
RunSpecOption = Annotated[
    Path | None,
    typer.Option(
        "--spec",
        help="Run spec (TOML, or JSON as sitgen shrink writes): time_limit_s and the sim, "
        "monitor and scoring tables.",
    ),
]
AllowEditedOption = Annotated[
    bool,
    typer.Option(
        "--allow-edited",
        help="Read a situation file edited by hand after it was generated (its content hash "
        "no longer matches).",
    ),
]


class UsageError(Exception):
    """Bad command-line input that is not a spec field (exit 2)."""


WeightsOption = Annotated[
    Path | None,
    typer.Option(
        "--weights",
        help="Learned weights (TOML, from `sitgen weights fit`): score runs by them.",
    ),
]


def _weights(path: Path | None, db: Path | None = None) -> Weights | None:
    """The weights file ``path`` (None if not given), checked; with ``db``, checked to rescore
    its stored runs."""
    if path is None:
        return None
    from sitgen.store import Store
    from sitgen.triage.weights import JudgementError, check_rescorable, load_weights

    try:
        weights = load_weights(path)
        if db is not None:
            require_store(db)
            with Store(db) as store:
                check_rescorable(store, weights, str(path))
    except JudgementError as e:
        raise UsageError(str(e)) from None
    return weights


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
def report(
    db: Annotated[Path, typer.Argument(help="Campaign store (SQLite).")],
    output: Annotated[Path, typer.Option("--output", "-o", help="Folder for the site.")] = Path(
        "report"
    ),
    top: Annotated[
        int,
        typer.Option("--top", min=0, help="Top runs that get a page (and every representative)."),
    ] = 50,
    weights: WeightsOption = None,
) -> None:
    """Write an HTML triage report of a campaign: distinct failures first, ranked runs, score
    distribution, and for the top runs and each distinct failure's representative a page with
    the figure, failure class, timeline, score breakdown and a replay. Opens from disk."""
    from sitgen.presentation.report import write_report

    require_store(db)
    learned = _weights(weights, db)
    with _writing(output, "the report"):
        pages = write_report(db, output, top, learned, str(weights or ""))
    typer.echo(f"wrote {output / 'index.html'} and {len(pages) - 1} run pages")


@app.command()
def export(
    source: Annotated[Path, typer.Argument(help="Situation file (JSON) or campaign store (.db).")],
    format: Annotated[
        str,
        typer.Option(
            "--format",
            "-f",
            help="Situation: stage (Player/Stage world) or ros (map YAML+PGM). "
            "Campaign: parquet or csv (one file per table).",
        ),
    ] = "stage",
    output: Annotated[Path, typer.Option("--output", "-o", help="Folder to write.")] = Path(
        "export"
    ),
    spec: RunSpecOption = None,
    allow_edited: AllowEditedOption = False,
) -> None:
    """Export a situation for Stage (with how it is run: --spec's laser, limits and time limit,
    every robot driven by its sitgen controller, docs/stage.md) or ROS, or a campaign's tables
    for analysis (pandas, polars, DuckDB)."""
    if _is_store(source):
        from sitgen.triage.rank import export_tables

        require_store(source)
        if format == "stage":
            format = "parquet"
        if format not in ("parquet", "csv"):
            raise UsageError(f"--format: `{format}` is not one of parquet, csv for a campaign")
        with _writing(output, "the tables"):
            for path in export_tables(source, output, format):
                typer.echo(f"wrote {path}")
        return
    if format not in ("stage", "ros"):
        raise UsageError(f"--format: `{format}` is not one of stage, ros")
    run_spec = _read_run_spec(spec)
    with _writing(output, "the export"):
        for path in Situation.load(source, allow_edited).export(output, format, run=run_spec):
            typer.echo(f"wrote {path}")


@contextlib.contextmanager
def _writing(output: Path, what: str) -> Iterator[None]:
    """Name ``output`` in an error that names no file (a full disk fails a write, not an open,
    and Python's error then says only "File too large")."""
    try:
        yield
    except OSError as e:
        if e.filename is not None or str(output) in str(e):
            raise
        raise OSError(f"{output}: cannot write {what}: {e.strerror or e}") from None


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


def _is_store(path: Path) -> bool:
    """Whether ``path`` is an SQLite file (a campaign store) rather than a situation."""
    if path.suffix == ".db":
        return True
    try:
        with path.open("rb") as f:
            return f.read(16) == b"SQLite format 3\x00"
    except OSError:
        return False


def _read_text(path: Path, what: str) -> str:
    """A spec file's text, or a one-line error naming the file."""
    try:
        return read_utf8(path, what)
    except OSError as e:
        raise UsageError(f"{path}: cannot read the {what}: {e.strerror}") from None


def _read_run_spec(path: Path | None) -> dict[str, Any]:
    """A run spec file: TOML, or JSON (``.json``, as ``sitgen shrink`` writes beside a shrunk
    situation)."""
    if path is None:
        return {}
    import tomllib

    text = _read_text(path, "run spec")
    if path.suffix == ".json":
        try:
            spec = json.loads(text)
        except json.JSONDecodeError as e:
            raise _core.SpecError(f"{path}: JSON syntax error: {e}") from None
        if not isinstance(spec, dict):
            raise _core.SpecError(f"{path}: a run spec is a JSON object, not {type(spec).__name__}")
        return spec
    try:
        return tomllib.loads(text)
    except tomllib.TOMLDecodeError as e:
        raise _core.SpecError(f"{path}: TOML syntax error: {e}") from None


@app.command("run")
def run_command(
    situation: Annotated[Path, typer.Argument(help="Situation file (JSON).")],
    controller: ControllerOption = None,
    time_limit: TimeLimitOption = None,
    seed: SensorSeedOption = 0,
    spec: RunSpecOption = None,
    events: Annotated[
        Path | None, typer.Option("--events", help="Write the event log here (JSON Lines).")
    ] = None,
    as_json: Annotated[
        bool, typer.Option("--json", help="Print the record as JSON instead of text.")
    ] = False,
    allow_edited: AllowEditedOption = False,
) -> None:
    """Run one situation: print the outcome, the score with its breakdown, and the event log.
    Exits 1 when the controller failed (outcome error)."""
    from sitgen.run import run

    record = run(
        Situation.load(situation, allow_edited),
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
    if record.outcome == "error":
        raise typer.Exit(EXIT_FAILED)


@app.command("check-controller")
def check_controller_command(
    controller: Annotated[str, typer.Argument(help="python:MODULE:CLASS or 'cmd:PROGRAM ARGS'.")],
    situation: Annotated[
        Path | None,
        typer.Option("--situation", help="Situation to drive (default: open_field, seed 0)."),
    ] = None,
    steps: Annotated[int, typer.Option("--steps", min=1, max=100_000, help="Steps to drive.")] = 50,
    allow_edited: AllowEditedOption = False,
) -> None:
    """Check that a user controller speaks the interface: loads, resets, replies with finite
    commands in time, stays within the limits, and shuts down. Exits 1 if a check fails."""
    from sitgen.run import check_controller

    if not controller.startswith(("python:", "cmd:")):
        raise UsageError(f"controller `{controller}`: expected python:MODULE:CLASS or cmd:PROGRAM")
    loaded = (
        Situation.load(situation, allow_edited)
        if situation is not None
        else generate_situation(preset_spec("open_field"), seed=0)
    )
    checks = check_controller(controller, loaded, steps=steps)
    for c in checks:
        typer.echo(f"{'ok  ' if c.ok else 'FAIL'} {c.name:8} {c.detail}")
    if not all(c.ok for c in checks):
        raise typer.Exit(EXIT_FAILED)


class OnProgress(Protocol):
    """A progress bar's update: work done of total, and a line of what it found so far."""

    def __call__(self, done: int, total: int, status: str = "") -> None: ...


@contextmanager
def _progress(label: str, total: int, unit: str) -> Iterator[OnProgress]:
    """A progress bar on a terminal (or with SITGEN_PROGRESS set): yields the
    ``on_progress(done, total, status)`` to call, which also shows the rate of this call's
    work."""
    import os
    import time

    from rich.progress import (
        BarColumn,
        MofNCompleteColumn,
        Progress,
        TextColumn,
        TimeElapsedColumn,
        TimeRemainingColumn,
    )

    started = time.perf_counter()
    with Progress(
        TextColumn(f"[bold]{label}"),
        BarColumn(),
        MofNCompleteColumn(),
        TextColumn("{task.fields[rate]}"),
        TimeElapsedColumn(),
        TextColumn("ETA"),
        TimeRemainingColumn(),
        TextColumn("{task.fields[status]}"),
        disable=not sys.stderr.isatty() and "SITGEN_PROGRESS" not in os.environ,
    ) as progress:
        task = progress.add_task(unit, total=total, rate="", status="")
        first: list[int] = []

        def on_progress(done: int, total: int, status: str = "") -> None:
            if not first:
                first.append(done)
            elapsed = time.perf_counter() - started
            rate = (done - first[0]) / elapsed if elapsed > 0 else 0.0
            progress.update(
                task, completed=done, total=total, rate=f"{rate:.1f} {unit}/s", status=status
            )

        yield on_progress


def _campaign_spec(spec: Path | None) -> CampaignSpec:
    """The campaign spec in file ``spec``, or the paper's."""
    from sitgen.execution.jobs import parse_campaign

    text = None if spec is None else _read_text(spec, "campaign spec")
    return parse_campaign(text, str(spec) if spec else "paper campaign")


def _stored(
    label: str,
    total: int,
    unit: str,
    work: Callable[[OnProgress, Callable[[], bool]], T],
) -> T:
    """``work(on_progress, stop)`` with a progress bar and Ctrl-C asking it to stop; a store
    it cannot use is bad input."""
    from sitgen.execution.campaign import StopOnInterrupt

    with _progress(label, total, unit) as on_progress, StopOnInterrupt() as stop:
        try:
            return work(on_progress, stop)
        except StoreError as e:
            raise UsageError(str(e)) from None


@app.command()
def campaign(
    spec: Annotated[
        Path | None,
        typer.Argument(help="Campaign spec (TOML). Omit for the paper's experiment."),
    ] = None,
    n: Annotated[
        int | None, typer.Option("--n", "-n", min=0, help="Runs (default: the spec's, 500).")
    ] = None,
    seed: CampaignSeedOption = 0,
    db: Annotated[Path, typer.Option("--db", help="Campaign store (SQLite).")] = Path(
        "campaign.db"
    ),
    workers: WorkersOption = None,
    backend: BackendOption = "local",
    address: AddressOption = None,
    top: Annotated[int, typer.Option("--top", min=0, help="Top runs in the summary.")] = 5,
    shrink_top: Annotated[
        int,
        typer.Option(
            "--shrink-top",
            min=0,
            help="At the end, shrink the representatives of the top K distinct failures "
            "(sitgen shrink; kept in the store).",
        ),
    ] = 0,
    keep_trajectories: Annotated[
        str | None,
        typer.Option(
            "--keep-trajectories",
            help="Runs stored whole (situation, event log, trajectory): all, failures, top:K "
            "or none; the rest keep a summary (under 1 KB) and are re-simulated when shown. "
            "Default top:50, the runs the report shows.",
        ),
    ] = None,
    reruns: RerunsOption = 8,
) -> None:
    """Generate N randomised situations, run them all, store them, rank the runs, and measure
    the robustness of each distinct failure. Ctrl-C stops after the runs in flight; the same
    command again resumes."""
    from sitgen.execution.campaign import DEFAULT_KEEP, run_campaign

    _check_reruns(reruns)
    parsed = _campaign_spec(spec)
    total_n = parsed.n if n is None else n
    result = _stored(
        "campaign",
        total_n,
        "runs",
        lambda on_progress, stop: run_campaign(
            parsed,
            db,
            seed=seed,
            n=n,
            workers=workers,
            backend=backend,
            address=address,
            on_progress=on_progress,
            stop=stop,
            keep_trajectories=keep_trajectories or DEFAULT_KEEP,
        ),
    )
    if not result.interrupted:
        _measure_robustness(db, reruns, workers)
    _echo_stored(db, result.ran, result.wall_s, result.total, total_n, result.interrupted, top)
    if shrink_top:
        _shrink_top(db, shrink_top, workers)


def _echo_stored(
    db: Path,
    ran: int,
    wall_s: float,
    total: int,
    asked: int,
    interrupted: bool,
    top: int,
    extra: str = "",
) -> None:
    """What a campaign or search did and what its store holds: the paper's figures, the top
    runs and the distinct failures; exits 130 if it was stopped early."""
    from sitgen.store import Store
    from sitgen.triage.failures import summary

    rate = ran / wall_s if wall_s > 0 else 0.0
    typer.echo(
        f"{db}: {ran} runs in {wall_s:.1f} s ({rate:.1f} runs/s), {total} of {asked} stored{extra}"
    )
    if interrupted:
        typer.echo("stopped early: run the same command again to finish")
        if not db.exists():
            raise typer.Exit(130)
    with Store(db) as store:
        s = summary(store, top)
    typer.echo(
        f"runs {s['runs']}, mean score {s['mean_score']:.1f}, median {s['median_score']:.1f}, "
        f"{100 * s['share_under_10']:.0f}% under 10 points; outcomes "
        + ", ".join(f"{k} {v}" for k, v in sorted(s["outcomes"].items()))
    )
    for e in s["errors"]:
        typer.echo(f"  {e['runs']} runs were errors (first run {e['first_run']}): {e['reason']}")
    for r in s["top"]:
        typer.echo(f"  run {r['run']:>5}  score {r['score']:>10.1f}  {r['main_events']}")
    typer.echo(f"{len(s['distinct'])} distinct failures (sitgen failures {db}):")
    for f in s["distinct"][:top]:
        typer.echo(
            f"  {f['runs']:>5} runs  best {f['best_score']:>10.1f}  run {f['representative']:>5}  "
            f"{f['robustness']:<17}  {f['description']}"
        )
    if interrupted:
        raise typer.Exit(130)
    if s["runs"] and s["outcomes"].get("error", 0) == s["runs"]:
        # Nothing was tested: every run failed to be made or its controller failed.
        print(
            f"error: {db}: every run is an error; the commonest: {s['errors'][0]['reason']}",
            file=sys.stderr,
        )
        raise typer.Exit(EXIT_FAILED)


def _check_reruns(reruns: int) -> None:
    """``--reruns``: 0 (measure nothing) or a number of copies, checked before any run."""
    from sitgen.triage.robustness import check_reruns

    if reruns != 0:
        check_reruns(reruns)


def _measure_robustness(db: Path, reruns: int, workers: int | None) -> None:
    """Measure the robustness of the store's distinct failures with ``reruns`` copies each
    (none if 0) and say what it cost."""
    from sitgen.store import Store
    from sitgen.triage.failures import measure_robustness

    if reruns == 0:
        return
    started = time.perf_counter()
    with Store(db) as store:
        ran = measure_robustness(store, reruns, workers or os.cpu_count() or 1)
    if ran:
        typer.echo(
            f"robustness: {ran} perturbed copies of distinct failures' runs in "
            f"{time.perf_counter() - started:.1f} s"
        )


def _shrink_top(db: Path, k: int, workers: int | None) -> None:
    """Shrink the top ``k`` distinct failures' representatives and print what shrank."""
    from sitgen.triage.shrink import shrink_top

    typer.echo(f"shrinking the top {k} distinct failures (sitgen shrink {db} RUN):")
    for run_id, r in shrink_top(db, k, workers):
        if r is None:
            typer.echo(f"  run {run_id:>5}  already shrunk")
            continue
        a, b = r.before, r.after
        typer.echo(
            f"  run {run_id:>5}  shrunk {r.failure_class}: peers {a.peers} → {b.peers}, "
            f"obstacle cells {a.obstacle_cells} → {b.obstacle_cells}, failure after "
            f"{a.time_to_failure_s:.1f} → {b.time_to_failure_s:.1f} s ({r.probes} probes, "
            f"{r.wall_s:.1f} s)"
        )


@app.command()
def faults(
    spec: Annotated[
        Path | None,
        typer.Argument(help="Campaign spec (TOML) whose situations to use. Omit for the paper's."),
    ] = None,
    budget: Annotated[
        int, typer.Option("--budget", "-n", min=1, help="Situations to generate and run.")
    ] = 100,
    seed: CampaignSeedOption = 0,
    db: Annotated[Path, typer.Option("--db", help="Evaluation store (SQLite).")] = Path(
        "faults.db"
    ),
    strategy: Annotated[
        str,
        typer.Option(
            "--strategy",
            help="How situations are drawn: random (the campaign's generation), barn (the 300 "
            "BARN worlds, shuffled by the seed) or stored (a campaign's or search's situations, "
            "in the order it ran them: --situations).",
        ),
    ] = "random",
    barn_dir: Annotated[
        Path | None,
        typer.Option("--barn-dir", help="The BARN data folder (with --strategy barn)."),
    ] = None,
    situations: Annotated[
        Path | None,
        typer.Option("--situations", help="A campaign or search store (with --strategy stored)."),
    ] = None,
    fault_ids: Annotated[
        str | None,
        typer.Option("--faults", help="Comma-separated fault ids (default: all the controller's)."),
    ] = None,
    format: Annotated[str, typer.Option("--format", "-f", help="table or json.")] = "table",
    workers: WorkersOption = None,
    backend: BackendOption = "local",
    address: AddressOption = None,
) -> None:
    """Measure fault-finding power: run the agent's controller and each of its seeded faults
    (docs/faults.md) on the same situations, and report which faults were killed, after how
    many situations, and the kill rate by budget. Ctrl-C stops; the same command resumes."""
    from sitgen.generation.faults import (
        fault_status,
        report_from,
        run_faults,
        summary_lines,
        write_fault_report,
    )

    if format not in ("table", "json"):
        raise UsageError(f"--format: `{format}` is not one of table, json")
    chosen = None if fault_ids is None else [f.strip() for f in fault_ids.split(",") if f.strip()]
    result = _stored(
        "faults",
        budget,
        "situations",
        lambda on_progress, stop: run_faults(
            _campaign_spec(spec),
            db,
            seed=seed,
            budget=budget,
            faults=chosen,
            strategy=strategy,
            workers=workers,
            backend=backend,
            address=address,
            on_progress=on_progress,
            stop=stop,
            barn_dir=barn_dir,
            situations_db=situations,
        ),
    )
    if result.interrupted:
        typer.echo(
            f"stopped early after {result.situations} of {budget} situations: run the same "
            "command again to finish",
            err=True,
        )
        if not db.exists():
            raise typer.Exit(130)
    report = report_from(db)
    if format == "json":
        write_fault_report(report, sys.stdout)
    else:
        table = Table(title=f"{db}: seeded faults of {report.controller}")
        for column in ("fault", "result", "killing run", "stands for"):
            table.add_column(column)
        for row in report.faults:
            table.add_row(
                row.id,
                fault_status(row, report.situations),
                "" if row.run is None else f"{row.run} (correct: {row.correct_run})",
                row.stands_for,
            )
        Console(width=200).print(table)
        for line in summary_lines(report):
            typer.echo(line)
    if result.interrupted:
        raise typer.Exit(130)


@app.command()
def search(
    spec: Annotated[
        Path | None,
        typer.Argument(
            help="Campaign spec (TOML) whose varied fields to search. Omit for the paper's."
        ),
    ] = None,
    budget: Annotated[int, typer.Option("--budget", "-n", min=1, help="Runs to make.")] = 500,
    seed: CampaignSeedOption = 0,
    db: Annotated[Path, typer.Option("--db", help="Search store (SQLite).")] = Path("search.db"),
    strategy: Annotated[
        str,
        typer.Option(
            "--strategy",
            help="map-elites (quality diversity), random (the campaign's generation) or "
            "coverage (fields drawn toward uncovered cells of the interaction space).",
        ),
    ] = "map-elites",
    measures: Annotated[
        str,
        typer.Option(
            "--measures",
            help="The archive's one or two descriptors, comma-separated: failure_class, terrain, "
            "peers, min_clearance, approach_side.",
        ),
    ] = "failure_class,terrain",
    objective: Annotated[
        str,
        typer.Option(
            "--objective",
            help="score (the most dangerous run per cell) or threshold (the paper's: fewer runs "
            "under --threshold points).",
        ),
    ] = "score",
    threshold: Annotated[
        float, typer.Option("--threshold", help="Low-score threshold (points).")
    ] = 10.0,
    workers: WorkersOption = None,
    backend: BackendOption = "local",
    address: AddressOption = None,
    top: Annotated[int, typer.Option("--top", min=0, help="Distinct failures in the summary.")] = 5,
    weights: WeightsOption = None,
    reruns: RerunsOption = 8,
) -> None:
    """Search toward distinct failures: MAP-Elites over the spec's varied fields and the
    situation seed, each cell of the archive (failure class × terrain by default) holding its
    highest-scoring run; or (--strategy coverage) generation steered toward situation coverage.
    Writes a store like a campaign's (rank, failures, report, rerun, shrink, coverage work on
    it). Ctrl-C stops after the runs in flight; the same command resumes."""
    from sitgen.generation.search import SearchPlan, SearchProgress, SearchResult, run_search

    _check_reruns(reruns)
    parsed = _campaign_spec(spec)
    learned = _weights(weights)
    if learned is not None:
        from sitgen.execution.jobs import campaign_from_data

        # The runs are scored by the weights as they run (the objective is their score), and
        # the stored spec says so: a summary's run is rebuilt and re-simulated from it.
        source = copy.deepcopy(parsed.source)
        source.setdefault("run", {})["scoring"] = learned.table()
        parsed = campaign_from_data(source)
    names = tuple(m.strip() for m in measures.split(",") if m.strip())
    plan = SearchPlan(strategy, names, objective, threshold)

    def work(on_progress: OnProgress, stop: Callable[[], bool]) -> SearchResult:
        def show(p: SearchProgress) -> None:
            on_progress(
                p.runs,
                p.budget,
                f"cells {p.cells}  failure classes {p.classes}  best {p.best:,.0f}",
            )

        return run_search(
            parsed,
            db,
            seed=seed,
            budget=budget,
            plan=plan,
            workers=workers,
            backend=backend,
            address=address,
            on_progress=show,
            stop=stop,
        )

    result = _stored("search", budget, "runs", work)
    if not result.interrupted:
        _measure_robustness(db, reruns, workers)
    _echo_stored(
        db,
        result.ran,
        result.wall_s,
        result.total,
        budget,
        result.interrupted,
        top,
        f"; archive {result.cells} cells, QD score {result.qd_score:,.0f}",
    )


@app.command()
def shrink(
    source: Annotated[Path, typer.Argument(help="Campaign store (.db) or situation file (JSON).")],
    run_id: Annotated[
        int | None, typer.Argument(help="The run to shrink (with a campaign store).")
    ] = None,
    output: Annotated[
        Path | None,
        typer.Option(
            "--output",
            "-o",
            help="The minimal situation (JSON); its run spec and figure are written beside it. "
            "Default: run-RUN.min.json, or SITUATION.min.json.",
        ),
    ] = None,
    controller: ControllerOption = None,
    failure_class: Annotated[
        str | None,
        typer.Option(
            "--class",
            help="Keep this failure class among those the run shows (default: keep the run's "
            "class).",
        ),
    ] = None,
    time_limit: TimeLimitOption = None,
    spec: RunSpecOption = None,
    seed: SensorSeedOption = 0,
    max_probes: Annotated[
        int, typer.Option("--max-probes", help="Runs one shrink may make (default 500).")
    ] = 500,
    workers: WorkersOption = None,
    format: Annotated[str, typer.Option("--format", "-f", help="table or json.")] = "table",
    allow_edited: AllowEditedOption = False,
) -> None:
    """Shrink a failing run to the smallest situation found that still fails with the same
    failure class for the same controller and run spec (docs/shrink.md): write it, its run
    spec and a figure of the original beside it, and print what shrank. With a campaign store
    the result is also kept in the store (its report shows it). --controller, --time-limit,
    --spec and --seed are for a situation file: a stored run keeps its own."""
    from sitgen.run import run_spec_with
    from sitgen.triage.failures import FailureFilterError, check_class
    from sitgen.triage.shrink import ShrinkError, save_side_by_side, shrink_run
    from sitgen.triage.shrink import shrink as shrink_situation

    if format not in ("table", "json"):
        raise UsageError(f"--format: `{format}` is not one of table, json")
    if failure_class is not None:
        try:
            check_class(failure_class)
        except FailureFilterError as e:
            raise UsageError(str(e)) from None
    is_store = _is_store(source)
    with _progress("shrink", max_probes, "probes") as on_progress:
        try:
            if is_store:
                if run_id is None:
                    raise UsageError(f"{source}: give the run to shrink: sitgen shrink DB RUN")
                if controller or time_limit is not None or spec is not None:
                    raise UsageError(
                        "--controller, --time-limit and --spec are for a situation file; a "
                        "stored run is shrunk with its own controller and run spec"
                    )
                require_store(source)
                result = shrink_run(source, run_id, workers, max_probes, failure_class, on_progress)
            else:
                if run_id is not None:
                    raise UsageError(f"{source}: a run id is for a campaign store (.db)")
                result = shrink_situation(
                    Situation.load(source, allow_edited),
                    run_spec_with(_read_run_spec(spec), time_limit, controller),
                    seed,
                    failure_class,
                    workers,
                    max_probes,
                    on_progress,
                )
        except ShrinkError as e:
            what = f"run {run_id}" if is_store else str(source)
            raise UsageError(f"{what}: {e}") from None
        except StoreError as e:
            raise UsageError(str(e)) from None
    if output is None:
        output = Path(f"run-{run_id}.min.json") if is_store else source.with_suffix(".min.json")
    run_spec_path = output.with_suffix(".run.json")
    figure_path = output.with_suffix(".png")
    output.parent.mkdir(parents=True, exist_ok=True)
    result.minimal.save(output)
    run_spec_path.write_text(json.dumps(result.run_spec, indent=2, sort_keys=True) + "\n")
    save_side_by_side(result, figure_path)
    rerun = f"sitgen run {output} --spec {run_spec_path} --seed {result.run_seed}"
    if format == "json":
        summary = result.summary()
        summary.update(
            situation=str(output), run_spec=str(run_spec_path), figure=str(figure_path), rerun=rerun
        )
        typer.echo(json.dumps(summary, indent=2))
        return
    before, after = result.before, result.after
    table = Table(title=f"shrunk: {result.failure_class}")
    for column in ("", "before", "after"):
        table.add_column(column, justify="left" if not column else "right")
    table.add_row("peers", str(before.peers), str(after.peers))
    table.add_row("obstacle cells", str(before.obstacle_cells), str(after.obstacle_cells))
    table.add_row("route length", f"{before.route_length_m:.1f} m", f"{after.route_length_m:.1f} m")
    table.add_row(
        "time to failure", f"{before.time_to_failure_s:.1f} s", f"{after.time_to_failure_s:.1f} s"
    )
    table.add_row(
        "map",
        f"{before.map_m[0]:g} × {before.map_m[1]:g} m",
        f"{after.map_m[0]:g} × {after.map_m[1]:g} m",
    )
    Console().print(table)
    budget = " (the probe budget ran out: --max-probes)" if result.exhausted else ""
    typer.echo(
        f"{result.probes} probes ({result.skipped} invalid candidates skipped) in "
        f"{result.wall_s:.1f} s{budget}"
    )
    for step in result.reductions:
        typer.echo(f"  {step}")
    typer.echo(f"wrote {output}, {run_spec_path}, {figure_path} (original left, minimal right)")
    typer.echo(f"rerun: {rerun}")


@app.command()
def rank(
    db: Annotated[Path, typer.Argument(help="Campaign store (SQLite).")],
    top: Annotated[int, typer.Option("--top", min=0, help="How many runs.")] = 20,
    format: Annotated[str, typer.Option("--format", "-f", help="table, csv or json.")] = "table",
    distinct: Annotated[
        bool,
        typer.Option(
            "--distinct", help="The representative of each distinct failure first, then the rest."
        ),
    ] = False,
    failure_class: Annotated[
        str | None,
        typer.Option("--class", help="Only runs of this failure class (see `sitgen failures`)."),
    ] = None,
    weights: WeightsOption = None,
) -> None:
    """The runs of a campaign, most dangerous first."""
    from sitgen.triage.failures import FailureFilterError
    from sitgen.triage.rank import ranked_rows, write_ranking

    if format not in ("table", "csv", "json"):
        raise UsageError(f"--format: `{format}` is not one of table, csv, json")
    require_store(db)
    learned = _weights(weights, db)
    try:
        rows = ranked_rows(db, top, failure_class, distinct, learned)
    except FailureFilterError as e:
        raise UsageError(str(e)) from None
    if format == "table":
        table = Table(title=f"{db}: top {len(rows)} runs")
        columns = (
            "rank", "run", "score", "outcome", "failure class", "main events", "terrain",
            "robustness",
        )  # fmt: skip
        for column in columns:
            table.add_column(
                column, justify="right" if column in ("rank", "run", "score") else "left"
            )
        for r in rows:
            table.add_row(
                str(r["rank"]), str(r["run"]), f"{r['score']:.1f}", r["outcome"],
                r.get("distinct") or r["failure_class"] or "", r["main_events"],
                str(r["terrain"]), r["robustness"],
            )  # fmt: skip
        Console(width=160).print(table)
    else:
        write_ranking(rows, format, sys.stdout)


@app.command()
def failures(
    db: Annotated[Path, typer.Argument(help="Campaign store (SQLite).")],
    format: Annotated[str, typer.Option("--format", "-f", help="table, json or csv.")] = "table",
    weights: WeightsOption = None,
) -> None:
    """One row per distinct failure of a campaign, the most dangerous (best score) first: its
    class, sentence, runs, share of runs, best score, representative run and median duration."""
    from sitgen.store import Store
    from sitgen.triage.failures import distinct_failures, write_failures

    if format not in ("table", "csv", "json"):
        raise UsageError(f"--format: `{format}` is not one of table, json, csv")
    require_store(db)
    learned = _weights(weights, db)
    with Store(db) as store:
        if learned is not None:
            store.rescore(learned)
        found = distinct_failures(store)
    if format != "table":
        write_failures(found, format, sys.stdout)
        return
    table = Table(title=f"{db}: {len(found)} distinct failures")
    columns = ("class", "failure", "runs", "share", "best score", "run", "median s", "robustness")
    for column in columns:
        table.add_column(
            column, justify="left" if column in ("class", "failure", "robustness") else "right"
        )
    for f in found:
        table.add_row(
            f.key, f.description, str(f.runs), f"{100 * f.share:.1f}%", f"{f.best_score:.1f}",
            str(f.representative), f"{f.median_duration_s:.1f}", f.robustness,
        )  # fmt: skip
    Console(width=200).print(table)


@app.command("coverage")
def coverage_command(
    db: Annotated[Path, typer.Argument(help="Campaign or search store (SQLite).")],
    format: Annotated[str, typer.Option("--format", "-f", help="table or json.")] = "table",
) -> None:
    """Situation coverage of a store: how many cells of the interaction space (interaction
    type × clearance × terrain context × agent speed) its runs exercised, each dimension's
    marginals, pairwise coverage of the dimensions, and which failures began in which cells
    (docs/coverage.md)."""
    from sitgen.store import Store
    from sitgen.triage.coverage import coverage_report

    if format not in ("table", "json"):
        raise UsageError(f"--format: `{format}` is not one of table, json")
    require_store(db)
    with Store(db) as store:
        report = coverage_report(store)
    if format == "json":
        typer.echo(json.dumps(report, indent=2))
        return
    console = Console(width=200)
    console.print(
        f"{db}: {report['covered']} of {report['total']} cells covered "
        f"({100 * report['ratio']:.1f}%) by {report['runs']} runs"
        + (
            f"; {report['runs_without_coverage']} runs without coverage (errors, or stored "
            "before coverage was observed)"
            if report["runs_without_coverage"]
            else ""
        )
    )
    for d in report["dimensions"]:
        table = Table(title=d["name"])
        for column in ("value", "covered", "of", "runs"):
            table.add_column(column, justify="left" if column == "value" else "right")
        for v in d["values"]:
            table.add_row(v["value"], str(v["covered"]), str(v["total"]), str(v["runs"]))
        console.print(table)
    table = Table(title="pairwise: value pairs covered")
    for column in ("dimensions", "covered", "of", "missing (first 4)"):
        table.add_column(column, justify="right" if column in ("covered", "of") else "left")
    for p in report["pairwise"]:
        missing = [" + ".join(q["values"]) for q in p["pairs"] if not q["runs"]]
        table.add_row(
            " × ".join(p["dimensions"]), str(p["covered"]), str(p["total"]),
            ", ".join(missing[:4]) + (" …" if len(missing) > 4 else ""),
        )  # fmt: skip
    console.print(table)
    table = Table(title="failures: the cells they began in")
    for column in ("class", "runs", "cells (most runs first)", "outside"):
        table.add_column(column, justify="right" if column in ("runs", "outside") else "left")
    for f in report["failures"]:
        cells = ", ".join(f"{c} ({n})" for c, n in list(f["cells"].items())[:3])
        more = " …" if len(f["cells"]) > 3 else ""
        table.add_row(f["class"], str(f["runs"]), cells + more, str(f["outside"]))
    console.print(table)


@app.command()
def rerun(
    db: Annotated[Path, typer.Argument(help="Campaign store (SQLite).")],
    run_id: Annotated[int, typer.Argument(help="Run id (see `sitgen rank`).")],
) -> None:
    """Regenerate a run's situation from its spec and seed, run it again, and confirm the
    identical situation, event log and score. Exits 1 if anything differs."""
    from sitgen.triage.rank import rerun as rerun_run

    require_store(db)
    check = rerun_run(db, run_id)
    for line in check.lines:
        typer.echo(line)
    if not check.identical:
        raise typer.Exit(EXIT_FAILED)


@app.command("diff")
def diff_command(
    spec: Annotated[
        Path | None,
        typer.Argument(help="Campaign spec (TOML) whose situations to use. Omit for the paper's."),
    ] = None,
    a: Annotated[
        str,
        typer.Option(
            "--a",
            help="Controller A (the old version): a name, NAME+FAULT, python:MODULE:CLASS, "
            "'cmd:PROGRAM ARGS', or a JSON controller table with params.",
        ),
    ] = "snd_follow",
    b: Annotated[str, typer.Option("--b", help="Controller B (the new version), as --a.")] = "",
    n: Annotated[int, typer.Option("--n", "-n", min=1, help="Situations.")] = 100,
    seed: CampaignSeedOption = 0,
    situations: Annotated[
        Path | None,
        typer.Option(
            "--situations",
            help="Use a stored campaign's or search's situations (its first N runs) instead of "
            "generating them.",
        ),
    ] = None,
    db: Annotated[Path, typer.Option("--db", help="Diff store (SQLite).")] = Path("diff.db"),
    junit: Annotated[
        Path | None, typer.Option("--junit", help="Write the verdict as JUnit XML here.")
    ] = None,
    format: Annotated[str, typer.Option("--format", "-f", help="table or json.")] = "table",
    workers: WorkersOption = None,
) -> None:
    """What a controller change fixed and what it broke: run the same situations with A and B
    and judge each difference in failure on perturbed copies of both (docs/failures.md):
    each distinct failure robustly new in B, robustly fixed, unchanged, or not robust either
    way. Exits 1 when B has robust new failures. Ctrl-C stops; the same command resumes."""
    from sitgen.generation.diff import (
        DiffPlan,
        diff_report,
        parse_controller,
        run_diff,
        summary_lines,
    )
    from sitgen.generation.diff import write_junit as write_diff_junit
    from sitgen.store import Store

    if format not in ("table", "json"):
        raise UsageError(f"--format: `{format}` is not one of table, json")
    if not b:
        raise UsageError("--b: the controller to compare with A is required")
    plan = DiffPlan(
        parse_controller(a, "--a"),
        parse_controller(b, "--b"),
        "stored" if situations else "random",
        str(situations) if situations else None,
    )
    parsed = _campaign_spec(spec)
    result = _stored(
        "diff",
        n,
        "situations",
        lambda on_progress, stop: run_diff(
            parsed,
            db,
            plan,
            seed=seed,
            n=n,
            workers=workers or os.cpu_count() or 1,
            on_progress=on_progress,
            stop=stop,
            situations_db=situations,
        ),
    )
    with Store(db) as store:
        report = diff_report(store)
    if junit is not None:
        junit.parent.mkdir(parents=True, exist_ok=True)
        with junit.open("w") as out:
            write_diff_junit(report, out)
    if format == "json":
        json.dump(report.as_dict(), sys.stdout, indent=2)
        sys.stdout.write("\n")
    else:
        table = Table(title=f"{db}: distinct failures, A against B")
        for column in ("class", "verdict", "new in B", "fixed", "unchanged", "not robust"):
            table.add_column(column, justify="left" if column in ("class", "verdict") else "right")
        for c in report.classes:
            table.add_row(
                c.failure_class, c.verdict, str(len(c.new)), str(len(c.fixed)),
                str(len(c.unchanged)), str(len(c.not_robust)),
            )  # fmt: skip
        Console(width=160).print(table)
        for line in summary_lines(report):
            typer.echo(line)
    if result.interrupted:
        typer.echo("stopped early: run the same command again to finish")
        raise typer.Exit(130)
    if report.robust_new:
        raise typer.Exit(EXIT_FAILED)


@app.command()
def robustness(
    db: Annotated[Path, typer.Argument(help="Campaign or search store (SQLite).")],
    run_ids: Annotated[
        list[int] | None,
        typer.Argument(help="Failing runs to measure (default: every distinct failure's)."),
    ] = None,
    reruns: Annotated[int, typer.Option("--reruns", help="Perturbed copies of each run.")] = 8,
    workers: WorkersOption = None,
    format: Annotated[str, typer.Option("--format", "-f", help="table or json.")] = "table",
) -> None:
    """Rerun failing runs under perturbations a real robot would not notice (laser noise at
    the LMS200's level, starts jittered by a centimetre and half a degree) and say in how
    many copies each one's failure class recurs: robust or knife-edge (docs/failures.md).
    Stored; `failures`, `rank` and `report` show it."""
    from sitgen.store import Store
    from sitgen.triage.failures import distinct_failures, measure_robustness
    from sitgen.triage.robustness import check_reruns, measure_runs, tally, verdict

    if format not in ("table", "json"):
        raise UsageError(f"--format: `{format}` is not one of table, json")
    check_reruns(reruns)
    require_store(db)
    with Store(db) as store:
        if run_ids:
            for run_id in run_ids:
                if store.run_row(run_id)["failure"] is None:
                    raise UsageError(f"run {run_id}: it did not fail; robustness is a failure's")
            measure_runs(store, run_ids, reruns, workers or os.cpu_count() or 1)
            wanted = list(run_ids)
        else:
            measure_robustness(store, reruns, workers or os.cpu_count() or 1)
            wanted = [f.representative for f in distinct_failures(store)]
        measured = store.robustness(wanted)
    rows = [measured[r] for r in wanted if r in measured]
    if format == "json":
        for r in rows:
            r["robust"] = verdict(r["recurs"], r["reruns"]) == "robust"
        json.dump(rows, sys.stdout, indent=2)
        sys.stdout.write("\n")
        return
    table = Table(title=f"{db}: robustness of {len(rows)} failing runs")
    for column in ("run", "class", "recurs", "verdict", "copies' classes"):
        table.add_column(column, justify="right" if column == "run" else "left")
    for r in rows:
        table.add_row(
            str(r["run_id"]), r["failure_class"], f"{r['recurs']}/{r['reruns']}",
            verdict(r["recurs"], r["reruns"]), tally(r["classes"]),
        )  # fmt: skip
    Console(width=200).print(table)


@app.command()
def demo(
    output: Annotated[Path, typer.Option("--output", "-o", help="Folder for everything.")] = Path(
        "demo"
    ),
    seed: SeedOption = 0,
    n: Annotated[int, typer.Option("--n", min=1, help="Runs of the paper's campaign.")] = 500,
) -> None:
    """The main job on built-in defaults: one situation of every preset (map PNG + ROS YAML,
    situation JSON, figure), then the paper's campaign (500 runs, seed 1: --n) into
    OUTPUT/paper.db, its HTML report in OUTPUT/report/, and its distinct failures."""
    from sitgen.execution.campaign import StopOnInterrupt, run_campaign
    from sitgen.execution.jobs import parse_campaign
    from sitgen.presentation.report import write_report
    from sitgen.world.figure import save_situation_figure

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
    db = output / "paper.db"
    typer.echo(f"running the paper's campaign ({n} runs, seed 1) into {db} ...")
    with StopOnInterrupt() as stop:
        result = run_campaign(parse_campaign(None), db, seed=1, n=n, stop=stop)
    if result.interrupted:
        typer.echo("stopped early: run the same command again to finish")
        raise typer.Exit(130)
    typer.echo(f"{result.total} runs stored ({result.ran} run now in {result.wall_s:.1f} s)")
    _measure_robustness(db, 8, None)
    report_dir = output / "report"
    write_report(db, report_dir, 50)
    failures(db, "table")
    typer.echo(f"report: {report_dir / 'index.html'}")


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


@app.command()
def judge(
    db: Annotated[Path, typer.Argument(help="Campaign store (SQLite).")],
    who: Annotated[
        str | None, typer.Option("--who", help="Who is judging (default: the login name).")
    ] = None,
    port: Annotated[
        int, typer.Option("--port", min=0, max=65535, help="Port on 127.0.0.1 (0: any free).")
    ] = 8765,
    open_browser: Annotated[
        bool, typer.Option("--open/--no-open", help="Open the page in a browser.")
    ] = True,
) -> None:
    """Judge pairs of runs in a local web page: two runs side by side (failure class, replay,
    timeline, figure, events; not their scores), and which is more dangerous, or equal. Each
    judgement goes into the store with who and when; the next pair is the most informative
    left. Then `sitgen weights fit`. Serves on 127.0.0.1 only, until Ctrl-C."""
    import getpass
    import webbrowser

    from sitgen.presentation.judge import JudgingServer
    from sitgen.store import Store

    require_store(db)
    with Store(db):
        pass  # an old store is upgraded (its judgements table made) before serving
    try:
        server = JudgingServer(db, who or getpass.getuser(), port)
    except OSError as e:
        raise UsageError(f"--port: cannot listen on 127.0.0.1:{port} ({e.strerror})") from None
    typer.echo(f"judging runs of {db} as {server.who} at {server.url} (Ctrl-C to stop)")
    if open_browser:
        webbrowser.open(server.url)
    try:
        server.serve_forever()
    except KeyboardInterrupt:
        pass
    finally:
        server.shutdown()
    with Store(db) as store:
        typer.echo(f"{len(store.judgements())} judgements in {db}")


judgements_app = typer.Typer(
    help="Import or export an expert's pairwise judgements of runs (JSON).",
    no_args_is_help=True,
)
app.add_typer(judgements_app, name="judgements")


@judgements_app.command("import")
def judgements_import(
    db: Annotated[Path, typer.Argument(help="Campaign store (SQLite).")],
    source: Annotated[
        Path,
        typer.Argument(help='JSON: a list of {"a": RUN, "b": RUN, "worse": "a" | "b" | "equal"}.'),
    ],
    who: Annotated[
        str | None, typer.Option("--who", help="Who judged, for entries that do not say.")
    ] = None,
) -> None:
    """Add judgements from a JSON file to the store (all of them, or none if one is bad)."""
    import dataclasses

    from sitgen.store import Store
    from sitgen.triage.weights import JudgementError, read_judgements

    require_store(db)
    with Store(db) as store:
        try:
            read = read_judgements(source, store)
        except JudgementError as e:
            raise UsageError(str(e)) from None
        read = [dataclasses.replace(j, who=j.who or who or "") for j in read]
        added = store.add_judgements(read, f"import {source.name}", new_only=True)
        total = len(store.judgements())
    held = f" ({len(read) - added} already in the store, skipped)" if added < len(read) else ""
    typer.echo(f"imported {added} judgements from {source}{held}; {total} in {db}")


@judgements_app.command("export")
def judgements_export(
    db: Annotated[Path, typer.Argument(help="Campaign store (SQLite).")],
    output: Annotated[Path, typer.Option("--output", "-o", help="JSON file to write.")] = Path(
        "judgements.json"
    ),
) -> None:
    """Write the store's judgements as JSON (with who made each and when)."""
    from sitgen.store import Store
    from sitgen.triage.weights import write_judgements

    require_store(db)
    with Store(db) as store:
        written = write_judgements(store.judgements(), output)
    typer.echo(f"wrote {written} judgements to {output}")


weights_app = typer.Typer(help="Penalty weights learned from judgements.", no_args_is_help=True)
app.add_typer(weights_app, name="weights")


@weights_app.command("fit")
def weights_fit(
    db: Annotated[Path, typer.Argument(help="Campaign store (SQLite) holding the judged runs.")],
    judgements: Annotated[
        Path | None,
        typer.Option(
            "--judgements", help="Fit to this JSON file's judgements instead of the store's."
        ),
    ] = None,
    output: Annotated[Path, typer.Option("--output", "-o", help="Weights to write (TOML).")] = Path(
        "weights.toml"
    ),
) -> None:
    """Fit non-negative penalties (start points and points per second per event kind, points
    per failure class where they help) to pairwise judgements with a Bradley–Terry model, and
    print how well they reproduce held-out judgements (agreement, Kendall τ) beside the stored
    scores. The file is a scoring table: `--weights` for rank, report, failures and search,
    or paste it under a run spec's [scoring]."""
    from sitgen.store import Store
    from sitgen.triage.weights import JudgementError, fit, read_judgements, weights_toml

    require_store(db)
    with Store(db) as store:
        try:
            judged = (
                read_judgements(judgements, store) if judgements is not None
                else store.judgements()
            )  # fmt: skip
            if not judged:
                raise JudgementError(
                    f"{db}: no judgements yet; judge runs with `sitgen judge {db}` or give "
                    "--judgements FILE"
                )
            fitted = fit(store, judged)
        except JudgementError as e:
            raise UsageError(str(e)) from None
    source = judgements or db
    lines = fitted.summary()
    comment = [
        f"sitgen weights fitted by sitgen {_core.__version__} to {fitted.judgements} "
        f"judgements ({source.name}) of {db.name}",
        f"held-out agreement {fitted.held_out.agreement:.3f}, Kendall tau "
        f"{fitted.held_out.tau:+.3f} (stored scores: {fitted.stored.agreement:.3f}, "
        f"{fitted.stored.tau:+.3f})",
        "A run spec's scoring table: use with --weights, or under [scoring] / [run.scoring].",
    ]
    output.write_text(weights_toml(fitted.weights, comment))
    for line in lines:
        typer.echo(line)
    table = Table(title="fitted penalties (points)")
    for column in ("event", "start", "per s"):
        table.add_column(column, justify="left" if column == "event" else "right")
    for kind, (start, per_s) in fitted.weights.penalties.items():
        if start or per_s:
            table.add_row(kind, f"{start:.1f}", f"{per_s:.2f}")
    for key, points in fitted.weights.failure_classes.items():
        table.add_row(f"class {key}", f"{points:.1f}", "")
    Console().print(table)
    typer.echo(f"wrote {output}; use it: sitgen rank {db} --weights {output}")


def main() -> None:
    """Entry point: run the command, turning expected errors into one line and an exit code."""
    try:
        app()
    except (_core.SpecError, UsageError, StoreMissing) as e:
        print(f"error: {e}", file=sys.stderr)
        sys.exit(EXIT_BAD_INPUT)
    except (_core.GenerationFailed, OSError, StoreError) as e:
        print(f"error: {e}", file=sys.stderr)
        sys.exit(EXIT_FAILED)
    except sqlite3.Error as e:
        # A store damaged on disk, or a disk that filled up: every run committed before is
        # still there (each is its own transaction).
        print(f"error: {e}; the runs stored before are kept", file=sys.stderr)
        sys.exit(EXIT_FAILED)


if __name__ == "__main__":
    main()
