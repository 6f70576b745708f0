"""Commands that run many situations: campaign, search, demo (faults, diff and robustness are in
:mod:`sitgen.cli.verdicts`)."""

from __future__ import annotations

import copy
import json
import os
import sys
import time
from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING, Annotated, Any

import typer
from rich.console import Console
from rich.table import Table

from sitgen import _core
from sitgen.store import StoreError
from sitgen.world.config import preset_names, preset_spec
from sitgen.world.requirements import gathered, with_requirements
from sitgen.world.situation import generate_situation

if TYPE_CHECKING:
    from sitgen.execution.campaign import CampaignResult
    from sitgen.execution.jobs import CampaignSpec
from sitgen.cli.app import (
    EXIT_FAILED,
    AddressOption,
    BackendOption,
    CampaignSeedOption,
    ControllerOption,
    KeepAliveOption,
    OnProgress,
    ParamOption,
    PerceptionOption,
    RequirementsOption,
    RequireOption,
    RerunsOption,
    SeedOption,
    StepTimeoutOption,
    T,
    TimeLimitOption,
    UsageError,
    WorkersOption,
    _progress,
    _read_text,
    _writing,
    app,
    check_output,
    parse_params,
)
from sitgen.cli.triage import failures
from sitgen.cli.world import _coverage_target


def _campaign_spec(
    spec: Path | None,
    controller: str | None = None,
    params: list[str] | None = None,
    perception: str | None = None,
    keep_alive: bool = False,
    step_timeout: float | None = None,
    time_limit: float | None = None,
    requirements: list[dict[str, Any]] | None = None,
) -> CampaignSpec:
    """The campaign spec in file ``spec``, or the paper's, with the agent's controller, its
    params, perception, keep_alive and step timeout, the runs' time limit and requirements,
    as ``--controller``, ``--param``, ``--perception``, ``--keep-alive``, ``--step-timeout``,
    ``--time-limit``, ``--require`` and ``--requirements`` give them
    (:func:`_with_controller`)."""
    from sitgen.execution.jobs import parse_campaign

    text = None if spec is None else _read_text(spec, "campaign spec")
    parsed = parse_campaign(text, str(spec) if spec else "paper campaign")
    return _with_controller(
        parsed, controller, params, perception, keep_alive, step_timeout, time_limit,
        requirements,
    )  # fmt: skip


def _with_controller(
    parsed: CampaignSpec,
    controller: str | None,
    params: list[str] | None,
    perception: str | None = None,
    keep_alive: bool = False,
    step_timeout: float | None = None,
    time_limit: float | None = None,
    requirements: list[dict[str, Any]] | None = None,
) -> CampaignSpec:
    """``parsed`` whose runs give the agent ``controller`` (over the spec's run controller, or
    its mission's) with ``params`` over its own, ``perception``, ``keep_alive`` and
    ``step_timeout`` (processor seconds a step), last ``time_limit`` simulated seconds, and
    judged by ``requirements`` too; unchanged without any."""
    from sitgen.execution.jobs import campaign_from_data
    from sitgen.run import run_spec_with

    given = parse_params(params)
    if time_limit is not None:
        source = copy.deepcopy(parsed.source)
        source["run"] = {**dict(source.get("run") or {}), "time_limit_s": time_limit}
        parsed = campaign_from_data(source)
    if requirements:
        source = copy.deepcopy(parsed.source)
        source["run"] = with_requirements(source.get("run"), requirements)
        parsed = campaign_from_data(source)
    if not controller and not given and not perception and not keep_alive and not step_timeout:
        return parsed
    if controller:
        _core.check_controller(controller, "--controller")
    varied = [p for p in parsed.vary if p.endswith(("controller.name", "agent_controller.name"))]
    if controller and varied:
        raise UsageError(f"--controller: the spec varies {varied[0]}; name one or the other")
    source = copy.deepcopy(parsed.source)
    mission = source.get("situation", {}).get("mission", {}).get("agent_controller")
    if controller and isinstance(source.get("situation"), dict):
        # The situations generated say which controller drives their agent, as a spec that
        # named it in its mission would: a stored situation must not name another.
        source["situation"].setdefault("mission", {})["agent_controller"] = {"name": controller}
    source["run"] = run_spec_with(
        source.get("run"),
        None,
        controller,
        given,
        mission or {"name": "snd_follow"},
        perception,
        keep_alive,
        step_timeout,
    )
    return campaign_from_data(source)


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
    controller: ControllerOption = None,
    param: ParamOption = None,
    perception: PerceptionOption = None,
    keep_alive: KeepAliveOption = False,
    step_timeout: StepTimeoutOption = None,
    time_limit: TimeLimitOption = None,
    require: RequireOption = None,
    requirements: RequirementsOption = None,
    where: Annotated[
        str | None,
        typer.Option(
            "--where",
            help="Only situations whose descriptors satisfy EXPR, e.g. 'crossing_peers >= 1 "
            "and route_clearance_m < 0.5' (docs/explain.md), generated by rejection.",
        ),
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
    junit: Annotated[
        Path | None,
        typer.Option(
            "--junit",
            help="Write the runs as JUnit XML here: a test case per situation, failed with its "
            "failure class, sentence and robustness.",
        ),
    ] = None,
    summary_json: Annotated[
        Path | None,
        typer.Option(
            "--summary",
            help="Write the summary as JSON here (sitgen failures's figures, outcomes, "
            "errors, top runs, distinct failures).",
        ),
    ] = None,
) -> None:
    """Generate N randomised situations, run them all, store them, rank the runs, and measure
    the robustness of each distinct failure. Ctrl-C stops after the runs in flight; the same
    command again resumes."""
    from sitgen.execution.campaign import DEFAULT_KEEP, run_campaign

    _check_reruns(reruns)
    check_output(junit, "--junit", db, spec)
    check_output(summary_json, "--summary", db, spec, junit)
    parsed = _campaign_spec(
        spec, controller, param, perception, keep_alive, step_timeout, time_limit,
        gathered(require, requirements),
    )  # fmt: skip
    total_n = parsed.n if n is None else n
    if where is not None:
        result = _in_region(parsed, db, where, seed, total_n, workers)
    else:
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
        _judge_avoidability(db, workers)
    partial = (result.total, total_n) if result.interrupted or result.total < total_n else None
    try:
        _echo_stored(db, result.ran, result.wall_s, result.total, total_n, result.interrupted, top)
    except typer.Exit as e:
        if e.exit_code in (EXIT_FAILED, 130) and db.exists():
            # Every run erred, or the campaign stopped early: CI still gets the results, and
            # partial ones say so.
            _write_results(db, junit, summary_json, partial)
        raise
    if shrink_top:
        _shrink_top(db, shrink_top, workers)
    _write_results(db, junit, summary_json, partial)


def _in_region(
    parsed: CampaignSpec, db: Path, where: str, seed: int, n: int, workers: int | None
) -> CampaignResult:
    """A campaign of ``n`` runs inside the region ``where`` (docs/explain.md): its situations
    generated by rejection, and how many it generated a situation kept."""
    from sitgen.execution.campaign import CampaignResult
    from sitgen.generation.region import run_region
    from sitgen.store import Store

    done = _stored(
        "campaign",
        n,
        "runs",
        lambda on_progress, stop: run_region(
            parsed, db, where, seed=seed, n=n, workers=workers, on_progress=on_progress, stop=stop
        ),
    )
    typer.echo(
        f"--where: {done.tried} situations generated to keep {done.kept} "
        f"({done.tried / max(done.kept, 1):.1f} a situation kept)"
    )
    with Store(db) as store:
        total = store.run_count()
    return CampaignResult(done.ran, total, done.interrupted, done.wall_s)


def _write_results(
    db: Path,
    junit: Path | None,
    summary_json: Path | None,
    partial: tuple[int, int] | None = None,
) -> None:
    """The campaign's runs as JUnit XML and its summary as JSON, for CI; ``partial`` (runs
    stored, runs asked) marks both as a campaign stopped early: a failed ``partial`` test case,
    and ``partial``, ``stored`` and ``asked`` in the summary."""
    from sitgen.store import Store
    from sitgen.triage.failures import summary
    from sitgen.triage.junit import Case, campaign_cases, write_junit

    if junit is None and summary_json is None:
        return
    with Store(db) as store:
        if junit is not None:
            cases = campaign_cases(store)
            if partial is not None:
                text = (
                    f"partial: {partial[0]} of {partial[1]} runs stored; the campaign stopped "
                    "early: run the same command again to finish"
                )
                cases = [
                    *cases,
                    Case("partial", "sitgen.campaign", failure=("partial", text, text)),
                ]
            junit.parent.mkdir(parents=True, exist_ok=True)
            with _writing(junit, "the JUnit file"), junit.open("w") as out:
                write_junit(f"sitgen campaign {db.name}", cases, out)
            typer.echo(f"wrote {junit}")
        if summary_json is not None:
            figures = summary(store)
            figures["partial"] = partial is not None
            if partial is not None:
                figures["stored"], figures["asked"] = partial
            summary_json.parent.mkdir(parents=True, exist_ok=True)
            with _writing(summary_json, "the summary"):
                summary_json.write_text(json.dumps(figures, indent=2) + "\n")
            typer.echo(f"wrote {summary_json}")


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
    from sitgen.triage.avoidability import in_words
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
        collision = in_words(f["avoidability"], f["avoidable"], f["judged"])
        typer.echo(
            f"  {f['runs']:>5} runs  best {f['best_score']:>10.1f}  run {f['representative']:>5}  "
            f"{f['robustness']:<17}  {f['description']}" + (f"; {collision}" if collision else "")
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


def _measure_robustness(db: Path, reruns: int, workers: int | None, say: bool = True) -> None:
    """Measure the robustness of the store's distinct failures with ``reruns`` copies each
    (none if 0) and (if ``say``) say what it cost."""
    from sitgen.store import Store
    from sitgen.triage.failures import measure_robustness
    from sitgen.triage.requirements import measure_requirements

    if reruns == 0:
        return
    started = time.perf_counter()
    with Store(db) as store:
        ran = measure_robustness(store, reruns, workers or os.cpu_count() or 1)
        # A violated requirement's worst run, copied as a distinct failure's representative.
        ran += reruns * len(measure_requirements(store, reruns, workers or os.cpu_count() or 1))
    if ran and say:
        typer.echo(
            f"robustness: {ran} perturbed copies of distinct failures' runs in "
            f"{time.perf_counter() - started:.1f} s"
        )


def _judge_avoidability(db: Path, workers: int | None, say: bool = True) -> None:
    """Judge whether the collisions of the store's peer-contact distinct failures' top runs
    could have been escaped (docs/avoidability.md), and (if ``say``) say what it cost."""
    from sitgen.store import Store
    from sitgen.triage.avoidability import measure_avoidability
    from sitgen.triage.failures import distinct_failures

    started = time.perf_counter()
    with Store(db) as store:
        judged = measure_avoidability(
            store, distinct_failures(store), workers or os.cpu_count() or 1
        )
    if judged and say:
        typer.echo(
            f"avoidability: {judged} collisions with robots judged in "
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
    _judge_avoidability(db, None)
    report_dir = output / "report"
    write_report(db, report_dir, 50)
    failures(db, "table")
    typer.echo(f"report: {report_dir / 'index.html'}")
