"""Commands that read a store: report, shrink, rank, failures, coverage, rerun."""

from __future__ import annotations

import json
import sys
from pathlib import Path
from typing import TYPE_CHECKING, Annotated

import typer
from rich.console import Console
from rich.table import Table

from sitgen.store import StoreError, require_store
from sitgen.world.requirements import gathered, with_requirements
from sitgen.world.situation import Situation

if TYPE_CHECKING:
    pass
from sitgen.cli.app import (
    EXIT_FAILED,
    AllowEditedOption,
    ControllerOption,
    ParamOption,
    RequirementsOption,
    RequireOption,
    RunSpecOption,
    SensorSeedOption,
    TimeLimitOption,
    UsageError,
    WeightsOption,
    WorkersOption,
    _is_store,
    _progress,
    _read_run_spec,
    _weights,
    _writing,
    app,
    parse_params,
)


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
    rosbag2: Annotated[
        int,
        typer.Option(
            "--rosbag2",
            min=0,
            help="Also write this many top runs as rosbag2 folders (MCAP; needs sitgen[ros2]), "
            "linked from their pages.",
        ),
    ] = 0,
) -> None:
    """Write an HTML triage report of a campaign: distinct failures first, ranked runs, score
    distribution, and for the top runs and each distinct failure's representative a page with
    the figure, failure class, timeline, score breakdown and a replay. Opens from disk."""
    from sitgen.presentation.report import write_report
    from sitgen.presentation.rosbag import RosbagUnavailable

    require_store(db)
    learned = _weights(weights, db)
    with _writing(output, "the report"):
        try:
            pages = write_report(db, output, top, learned, str(weights or ""), rosbag2)
        except RosbagUnavailable as e:
            raise UsageError(f"--rosbag2: {e}") from None
    typer.echo(f"wrote {output / 'index.html'} and {len(pages) - 1} run pages")


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
    param: ParamOption = None,
    failure_class: Annotated[
        str | None,
        typer.Option(
            "--class",
            help="Keep this failure class among those the run shows (default: keep the run's "
            "class).",
        ),
    ] = None,
    requirement: Annotated[
        str | None,
        typer.Option(
            "--requirement",
            help="Keep this requirement violated (one of the run's; for a situation file, of "
            "--spec's, --require's or --requirements's) instead of a failure class.",
        ),
    ] = None,
    require: RequireOption = None,
    requirements: RequirementsOption = None,
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
    the result is also kept in the store (its report shows it). --controller, --spec and
    --seed are for a situation file: a stored run keeps its own (--time-limit caps its time
    limit). Each probe is watched only until its failure is decided."""
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
    if requirement is not None:
        if failure_class is not None:
            raise UsageError("--requirement and --class: keep one or the other")
        failure_class = f"requirement:{requirement}"
    is_store = _is_store(source)
    with _progress("shrink", max_probes, "probes") as on_progress:
        try:
            if is_store:
                if run_id is None:
                    raise UsageError(f"{source}: give the run to shrink: sitgen shrink DB RUN")
                if controller or param or spec is not None or require or requirements:
                    raise UsageError(
                        "--controller, --param, --spec and --require(ments) are for a situation "
                        "file; a stored run is shrunk with its own controller, run spec and "
                        "requirements (--time-limit caps its time limit)"
                    )
                require_store(source)
                result = shrink_run(
                    source, run_id, workers, max_probes, failure_class, on_progress, time_limit
                )
            else:
                if run_id is not None:
                    raise UsageError(f"{source}: a run id is for a campaign store (.db)")
                loaded = Situation.load(source, allow_edited)
                result = shrink_situation(
                    loaded,
                    run_spec_with(
                        with_requirements(_read_run_spec(spec), gathered(require, requirements)),
                        time_limit,
                        controller,
                        parse_params(param),
                        loaded.agent.controller,
                    ),
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
    """One row per distinct failure of a campaign, the most dangerous (best score) first,
    collisions no controller with this sensor could have escaped after the rest: its class,
    sentence, runs, share of runs, best score, representative run, median duration, median
    processor seconds a run cost, robustness and, for a collision with a robot, whether it
    was avoidable; then one per violated requirement (class requirement:NAME, its
    worst-robustness run as representative)."""
    from sitgen.store import Store
    from sitgen.triage.avoidability import in_words
    from sitgen.triage.failures import distinct_failures, write_failures
    from sitgen.triage.requirements import requirement_failures

    if format not in ("table", "csv", "json"):
        raise UsageError(f"--format: `{format}` is not one of table, json, csv")
    require_store(db)
    learned = _weights(weights, db)
    with Store(db) as store:
        if learned is not None:
            store.rescore(learned)
        # sitgen's own distinct failures, then each violated requirement's (class
        # requirement:NAME, its runs by robustness, worst first).
        found = distinct_failures(store) + requirement_failures(store)
    if format != "table":
        write_failures(found, format, sys.stdout)
        return
    table = Table(title=f"{db}: {len(found)} distinct failures")
    columns = (
        "class", "failure", "runs", "share", "best score", "run", "median s", "cpu s/run",
        "robustness", "collision",
    )  # fmt: skip
    for column in columns:
        left = column in ("class", "failure", "robustness", "collision")
        table.add_column(column, justify="left" if left else "right")
    for f in found:
        table.add_row(
            f.key, f.description, str(f.runs), f"{100 * f.share:.1f}%", f"{f.best_score:.1f}",
            str(f.representative), f"{f.median_duration_s:.1f}",
            "" if f.median_cpu_s is None else f"{f.median_cpu_s:.2g}", f.robustness,
            in_words(f.avoidability, f.avoidable, f.judged),
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


@app.command("explain")
def explain_command(
    db: Annotated[Path, typer.Argument(help="Campaign store (SQLite).")],
    failure_class: Annotated[
        str | None,
        typer.Option(
            "--class", help="Explain this failure class (`collision`: any collision class)."
        ),
    ] = None,
    outcome: Annotated[
        str | None, typer.Option("--outcome", help="Explain this outcome (e.g. timeout).")
    ] = None,
    requirement: Annotated[
        str | None, typer.Option("--requirement", help="Explain this requirement's violations.")
    ] = None,
    confirm: Annotated[
        int,
        typer.Option(
            "--confirm",
            min=0,
            help="Test each rule on N fresh situations generated inside its region and N "
            "outside (docs/explain.md); 0: do not.",
        ),
    ] = 0,
    confirm_dir: Annotated[
        Path, typer.Option("--confirm-dir", help="Where the confirming campaigns are stored.")
    ] = Path("confirm"),
    workers: WorkersOption = None,
    format: Annotated[str, typer.Option("--format", "-f", help="table or json.")] = "table",
) -> None:
    """Which situation descriptors (computed before any run: docs/explain.md) separate the
    runs that failed the given way from the others: a few rules, each with its support and an
    exact 95 % interval, and the model's cross-validated balanced accuracy (0.5: no better
    than the base rate)."""
    from sitgen.generation.region import confirm as confirm_rules
    from sitgen.store import Store
    from sitgen.triage.explain import explain, target_of

    given = [x for x in (failure_class, outcome, requirement) if x is not None]
    if len(given) != 1:
        raise UsageError("explain: give one of --class, --outcome, --requirement")
    if format not in ("table", "json"):
        raise UsageError(f"--format: `{format}` is not one of table, json")
    require_store(db)
    try:
        with Store(db) as store:
            result = explain(store, failure_class, outcome, requirement)
            if confirm:
                confirm_dir.mkdir(parents=True, exist_ok=True)
                result["confirmed"] = confirm_rules(
                    store, result["rules"], confirm, confirm_dir,
                    lambda fresh: target_of(fresh, failure_class, outcome, requirement), workers,
                )  # fmt: skip
    except StoreError as e:
        raise UsageError(str(e)) from None
    if format == "json":
        typer.echo(json.dumps(result, indent=2))
        return
    typer.echo(
        f"{db}: {result['failed']} of {result['runs']} runs are {given[0]} "
        f"({100 * result['base_rate']:.1f} %); the rules' cross-validated balanced accuracy "
        f"{result['balanced_accuracy']:.2f} (0.50 is the base rate's)"
    )
    for rule in result["rules"]:
        typer.echo(f"  - {rule['text']}")
    for c in result.get("confirmed", []):
        inside, outside = c["inside"], c["outside"]
        said = "confirmed" if c["confirmed"] else "NOT confirmed"
        typer.echo(
            f"{said}: {c['where']}: fresh inside {inside['failed']} of {inside['runs']} "
            f"({100 * inside['rate']:.0f} %, {100 * inside['interval'][0]:.0f}–"
            f"{100 * inside['interval'][1]:.0f} %), outside {outside['failed']} of "
            f"{outside['runs']} ({100 * outside['rate']:.0f} %); "
            + ("separates" if c["separates"] else "does not separate")
            + f" (Fisher p = {c['p_value']:.2g})"
        )
