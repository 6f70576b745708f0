"""Commands that judge failures on perturbed copies: faults (the seeded faults' kill rate), diff
(what a controller change fixed and broke), robustness (of chosen runs)."""

from __future__ import annotations

import json
import os
import shlex
import sys
from collections.abc import Callable
from pathlib import Path
from typing import Annotated

import typer
from rich.console import Console
from rich.table import Table

from sitgen.cli.app import (
    EXIT_FAILED,
    AddressOption,
    BackendOption,
    CampaignSeedOption,
    OnProgress,
    RequirementsOption,
    RequireOption,
    StepTimeoutOption,
    TimeLimitOption,
    UsageError,
    WorkersOption,
    app,
    check_output,
    parse_params,
)
from sitgen.cli.campaigns import _campaign_spec, _stored
from sitgen.store import require_store
from sitgen.world.requirements import gathered


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
    time_limit: TimeLimitOption = None,
    workers: WorkersOption = None,
    backend: BackendOption = "local",
    address: AddressOption = None,
) -> None:
    """Measure fault-finding power: run the agent's controller and each of its seeded faults
    (docs/faults.md) on the same situations, and report which faults were killed, after how
    many situations, and the kill rate by budget. Ctrl-C stops; the same command resumes."""
    from sitgen.generation.fault_report import (
        fault_status,
        report_from,
        summary_lines,
        write_fault_report,
    )
    from sitgen.generation.faults import run_faults

    if format not in ("table", "json"):
        raise UsageError(f"--format: `{format}` is not one of table, json")
    chosen = None if fault_ids is None else [f.strip() for f in fault_ids.split(",") if f.strip()]
    result = _stored(
        "faults",
        budget,
        "situations",
        lambda on_progress, stop: run_faults(
            _campaign_spec(spec, time_limit=time_limit),
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
    param: Annotated[
        list[str] | None,
        typer.Option(
            "--param",
            "-p",
            help="NAME=VALUE: a parameter given to both A and B, over their own (repeatable; "
            "--a-param and --b-param give one side its own).",
        ),
    ] = None,
    a_param: Annotated[
        list[str] | None,
        typer.Option("--a-param", help="NAME=VALUE: a parameter of A only (repeatable)."),
    ] = None,
    b_param: Annotated[
        list[str] | None,
        typer.Option(
            "--b-param",
            help="NAME=VALUE: a parameter of B only, over --param (repeatable): "
            "--a snd_follow --b snd_follow --b-param safety_distance=0.3.",
        ),
    ] = None,
    reruns: Annotated[
        int,
        typer.Option(
            "--reruns",
            help="Perturbed copies a side of each difference (at least 7, the fewest that can "
            "show one at the test's level; more, the surer).",
        ),
    ] = 8,
    time_limit: TimeLimitOption = None,
    step_timeout: StepTimeoutOption = None,
    require: RequireOption = None,
    requirements: RequirementsOption = None,
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
    way. Exits 1 when B has robust new failures, or fails to run where A ran, or nothing could be
    compared. Ctrl-C stops; the same command resumes."""
    from sitgen.generation.diff import (
        FIXED,
        NEW,
        DiffPlan,
        check_copies,
        parse_controller,
        run_diff,
        with_params,
    )
    from sitgen.generation.diff_report import diff_report, summary_lines
    from sitgen.generation.diff_report import write_junit as write_diff_junit
    from sitgen.store import Store

    if format not in ("table", "json"):
        raise UsageError(f"--format: `{format}` is not one of table, json")
    if not b:
        raise UsageError("--b: the controller to compare with A is required")
    check_output(junit, "--junit", db, spec, situations)
    given = parse_params(param)
    sides = [
        with_params(
            parse_controller(text, f"--{side}"),
            {**given, **parse_params(own, f"--{side}-param")},
            f"--{side}",
            step_timeout,
        )
        for side, text, own in (("a", a, a_param), ("b", b, b_param))
    ]
    plan = DiffPlan(
        sides[0],
        sides[1],
        "stored" if situations else "random",
        str(situations) if situations else None,
        check_copies(reruns),
    )
    parsed = _campaign_spec(
        spec, time_limit=time_limit, requirements=gathered(require, requirements)
    )
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
        columns = ("class", "verdict", "B broke (copies B vs A)", "B fixed (copies A vs B)",
                   "unchanged", "not robust")  # fmt: skip
        for column in columns:
            table.add_column(column, justify="right" if column in columns[4:] else "left")
        broke = [c for c in report.classes if c.new]
        fixed = [c for c in report.classes if c.fixed and not c.new]
        rest = [c for c in report.classes if not c.new and not c.fixed]
        for c in [*broke, *fixed, *rest]:
            new = f"{len(c.new)}: {c.recurrence(NEW)}" if c.new else ""
            gone = f"{len(c.fixed)}: {c.recurrence(FIXED)}" if c.fixed else ""
            table.add_row(
                c.failure_class, c.verdict, new, gone, str(len(c.unchanged)),
                str(len(c.not_robust)),
            )  # fmt: skip
        Console(width=200).print(table)
        for line in summary_lines(report):
            typer.echo(line)
    if result.interrupted:
        typer.echo("stopped early: run the same command again to finish")
        raise typer.Exit(130)
    if report.failed:
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
        erred = len(r["classes"]) - r["reruns"]
        left_out = f" ({erred} erred, left out)" if erred else ""
        table.add_row(
            str(r["run_id"]), r["failure_class"], f"{r['recurs']}/{r['reruns']}{left_out}",
            verdict(r["recurs"], r["reruns"]), tally(r["classes"]),
        )  # fmt: skip
    Console(width=200).print(table)


@app.command("compare")
def compare_command(
    spec: Annotated[
        Path | None,
        typer.Argument(help="Campaign spec (TOML) whose situations to use. Omit for the paper's."),
    ] = None,
    controllers: Annotated[
        str,
        typer.Option(
            "--controllers",
            help="The controllers, comma-separated: names (snd_follow, vo, python:m:C, "
            "navground:ORCA, snd_follow+FAULT), or a JSON list of controller tables.",
        ),
    ] = "",
    param: Annotated[
        list[str] | None,
        typer.Option("--param", help="NAME=VALUE for every controller (repeatable)."),
    ] = None,
    controller_param: Annotated[
        list[str] | None,
        typer.Option(
            "--controller-param",
            help="K:NAME=VALUE for the K-th controller of --controllers, from 1 (repeatable).",
        ),
    ] = None,
    n: Annotated[int, typer.Option("--n", "-n", min=1, help="Situations.")] = 100,
    seed: CampaignSeedOption = 0,
    folder: Annotated[
        Path, typer.Option("--dir", help="Where each controller's campaign store is written.")
    ] = Path("compare"),
    reruns: Annotated[
        int,
        typer.Option(
            "--reruns", min=0, help="Perturbed copies of each distinct failure (0: none)."
        ),
    ] = 0,
    time_limit: TimeLimitOption = None,
    require: RequireOption = None,
    requirements: RequirementsOption = None,
    format: Annotated[str, typer.Option("--format", "-f", help="table, json or csv.")] = "table",
    workers: WorkersOption = None,
) -> None:
    """Controllers compared on the same situations (docs/failures.md, "Comparing
    controllers"): each runs the campaign's first N jobs into DIR/LABEL.db; per controller
    the failure rate with an exact 95 % interval, distinct failures (robust ones with
    --reruns), median time to goal and path efficiency; per pair the exact McNemar test;
    the distinct failures only one controller shows. Beside the stores: comparison.json and
    comparison.html, the comparison page."""
    import copy
    import csv

    from sitgen.cli.campaigns import _check_reruns, _judge_avoidability, _measure_robustness
    from sitgen.execution.campaign import CampaignResult, run_campaign
    from sitgen.execution.jobs import CampaignSpec, campaign_from_data
    from sitgen.generation.compare import comparison, labels_of
    from sitgen.generation.diff import parse_controller
    from sitgen.presentation.comparison import comparison_page

    if format not in ("table", "json", "csv"):
        raise UsageError(f"--format: `{format}` is not one of table, json, csv")
    text = controllers.strip()
    items = json.loads(text) if text.startswith("[") else [t for t in text.split(",") if t.strip()]
    if len(items) < 2:
        raise UsageError("--controllers: give two or more controllers, comma-separated")
    tables = [
        parse_controller(c if isinstance(c, str) else json.dumps(c), f"--controllers[{k + 1}]")
        for k, c in enumerate(items)
    ]
    shared = parse_params(param)
    for item in controller_param or []:
        k, sep, given = item.partition(":")
        if not sep or not k.isdigit() or not 1 <= int(k) <= len(tables):
            raise UsageError(
                f"--controller-param: `{item}` is not K:NAME=VALUE, K in 1…{len(tables)}"
            )
        tables[int(k) - 1] = {
            **tables[int(k) - 1],
            "params": {**tables[int(k) - 1].get("params", {}), **parse_params([given])},
        }
    tables = [{**t, "params": {**shared, **t.get("params", {})}} for t in tables]
    if reruns:
        _check_reruns(reruns)
    labels = labels_of(tables)
    folder.mkdir(parents=True, exist_ok=True)
    base = _campaign_spec(spec, time_limit=time_limit, requirements=gathered(require, requirements))
    for label, table in zip(labels, tables, strict=True):
        source = copy.deepcopy(base.source)
        # The situations are generated as for every other controller; only the run's differs.
        source["run"] = {**dict(source.get("run") or {}), "controller": table}
        parsed = campaign_from_data(source)
        db = folder / f"{label}.db"

        def work(
            on_progress: OnProgress,
            stop: Callable[[], bool],
            parsed: CampaignSpec = parsed,
            db: Path = db,
        ) -> CampaignResult:
            return run_campaign(
                parsed, db, seed=seed, n=n, workers=workers, on_progress=on_progress,
                stop=stop, keep_trajectories="all",
            )  # fmt: skip

        _stored(f"compare {label}", n, "runs", work)
        # Only the table's output may carry a line of its own: JSON and CSV are read whole.
        _measure_robustness(db, reruns, workers, say=format == "table")
        _judge_avoidability(db, workers, say=format == "table")
    result = comparison(labels, tables, folder)
    # Beside the stores: the figures for a paper's table, and the comparison page.
    (folder / "comparison.json").write_text(json.dumps(result, indent=2) + "\n")
    command = "sitgen " + " ".join(shlex.quote(a) for a in sys.argv[1:])
    (folder / "comparison.html").write_text(comparison_page(result, command))
    if format == "json":
        typer.echo(json.dumps(result, indent=2))
        return
    if format == "csv":
        writer = csv.writer(sys.stdout)
        writer.writerow(
            ["controller", "runs", "failed", "failure_rate", "low", "high", "distinct",
             "robust", "median_time_to_goal_s", "median_path_efficiency", "only"]
        )  # fmt: skip
        for s in result["controllers"]:
            writer.writerow(
                [s["label"], s["runs"], s["failed"], s["failure_rate"], *s["interval"],
                 len(s["distinct"]), len(s["robust"]), s["median_time_to_goal_s"],
                 s["median_path_efficiency"], " ".join(s["only"])]
            )  # fmt: skip
        return
    shown = Table(title=f"{len(labels)} controllers on the same {n} situations")
    for column in ("controller", "failure rate (95 %)", "distinct (robust)", "time to goal",
                   "path efficiency", "only it shows"):  # fmt: skip
        shown.add_column(column)
    for s in result["controllers"]:
        low, high = s["interval"]
        goal, eff = s["median_time_to_goal_s"], s["median_path_efficiency"]
        shown.add_row(
            s["label"],
            f"{100 * s['failure_rate']:.1f}% ({100 * low:.1f}–{100 * high:.1f}%)",
            f"{len(s['distinct'])} ({len(s['robust'])})",
            "" if goal is None else f"{goal:.1f} s",
            "" if eff is None else f"{eff:.2f}",
            ", ".join(s["only"]),
        )
    Console(width=200).print(shown)
    pairs = Table(title="pairwise: exact McNemar on the situations both ran")
    for column in ("A", "B", "situations", "A fails, B not", "B fails, A not", "p", "verdict"):
        pairs.add_column(column)
    for p in result["pairs"]:
        pairs.add_row(
            p["a"], p["b"], str(p["situations"]), str(p["a_only"]), str(p["b_only"]),
            f"{p['p_value']:.3g}", p["verdict"],
        )  # fmt: skip
    Console(width=200).print(pairs)


@app.command()
def avoidability(
    db: Annotated[Path, typer.Argument(help="Campaign or search store (SQLite).")],
    run_ids: Annotated[
        list[int] | None,
        typer.Argument(
            help="Runs to judge (default: every run whose failure is a contact with a robot)."
        ),
    ] = None,
    after_s: Annotated[
        float,
        typer.Option("--after-s", help="Seconds past the collision an escape must stay clear."),
    ] = 5.0,
    again: Annotated[bool, typer.Option("--again", help="Judge runs judged before again.")] = False,
    workers: WorkersOption = None,
    format: Annotated[str, typer.Option("--format", "-f", help="table or json.")] = "table",
) -> None:
    """Could the agent have escaped its collision with a robot? For each run's first contact
    with one, search the agent's admissible manoeuvres (within its speed, turn-rate and
    acceleration limits) for one that touches nothing, from the moment its laser first saw
    that robot and from the start: avoidable, unavoidable with this sensor, or unavoidable,
    with the escape found and whether the agent stood at rest when struck
    (docs/avoidability.md). Stored; `failures` and `report` rank by it."""
    from sitgen.store import Store
    from sitgen.triage.avoidability import PEER_CONTACTS, describe, judge

    if format not in ("table", "json"):
        raise UsageError(f"--format: `{format}` is not one of table, json")
    if not 0 < after_s <= 3600:
        raise UsageError(f"--after-s: {after_s} is not in (0, 3600] seconds")
    require_store(db)
    with Store(db) as store:
        if run_ids:
            missing = sorted(set(run_ids) - store.has_runs(run_ids))
            if missing:
                raise UsageError(f"run {missing[0]}: no such run in {db}")
            wanted = list(run_ids)
        else:
            marks = ", ".join("?" * len(PEER_CONTACTS))
            wanted = [
                i
                for (i,) in store.db.execute(
                    f"SELECT id FROM runs WHERE failure_class IN ({marks}) ORDER BY id",
                    PEER_CONTACTS,
                )
            ]
        judge(store, wanted, workers or os.cpu_count() or 1, after_s, again)
        judged = store.avoidability(wanted)
    rows = [judged[i] for i in wanted if i in judged]
    if format == "json":
        json.dump(rows, sys.stdout, indent=2)
        sys.stdout.write("\n")
        return
    counts = {v: sum(r["verdict"] == v for r in rows) for v in ("avoidable",)}
    table = Table(
        title=f"{db}: {len(rows)} collisions with robots judged, {counts['avoidable']} avoidable"
    )
    for column in ("run", "verdict"):
        table.add_column(column, justify="right" if column == "run" else "left")
    for r in rows:
        table.add_row(str(r["run_id"]), describe(r))
    Console(width=200).print(table)
