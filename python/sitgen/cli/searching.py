"""``sitgen search``: generation steered by results toward distinct failures (the mutation,
MAP-Elites, random and coverage strategies of :mod:`sitgen.generation.search`), into a store
like a campaign's, with the campaign's options and summary."""

from __future__ import annotations

import copy
from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING, Annotated

import typer

if TYPE_CHECKING:
    pass
from sitgen.cli.app import (
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
    StepTimeoutOption,
    TimeLimitOption,
    UsageError,
    WeightsOption,
    WorkersOption,
    _weights,
    app,
)
from sitgen.cli.campaigns import (
    _campaign_spec,
    _check_reruns,
    _echo_stored,
    _measure_robustness,
    _stored,
    _with_controller,
)
from sitgen.world.requirements import gathered


@app.command()
def search(
    spec: Annotated[
        Path | None,
        typer.Argument(
            help="Campaign spec (TOML) whose varied fields to search. Omit for the paper's."
        ),
    ] = None,
    controller: ControllerOption = None,
    param: ParamOption = None,
    perception: PerceptionOption = None,
    keep_alive: KeepAliveOption = False,
    step_timeout: StepTimeoutOption = None,
    time_limit: TimeLimitOption = None,
    require: RequireOption = None,
    requirements: RequirementsOption = None,
    requirement: Annotated[
        str | None,
        typer.Option(
            "--requirement",
            help="Falsify this requirement (one of the spec's, --require's or "
            "--requirements's): the search keeps and varies the runs that came nearest to "
            "violating it, by its robustness (docs/requirements.md).",
        ),
    ] = None,
    budget: Annotated[int, typer.Option("--budget", "-n", min=1, help="Runs to make.")] = 500,
    seed: CampaignSeedOption = 0,
    db: Annotated[Path, typer.Option("--db", help="Search store (SQLite).")] = Path("search.db"),
    strategy: Annotated[
        str,
        typer.Option(
            "--strategy",
            help="mutation (the default: situation operators on failing runs, the strategy "
            "that finds the most robust failure variants), map-elites (quality diversity over "
            "the spec's fields and seeds), random (the campaign's generation) or coverage "
            "(fields drawn toward uncovered cells of the interaction space); docs/search.md.",
        ),
    ] = "mutation",
    like: Annotated[
        str | None,
        typer.Option(
            "--like",
            help="DB:RUN: start from this failing run and find more, different variants of "
            "its failure (the mutation strategy).",
        ),
    ] = None,
    target_class: Annotated[
        str | None,
        typer.Option(
            "--class",
            help="Vary runs of this failure class, toward more variants of it (the mutation "
            "strategy).",
        ),
    ] = None,
    measures: Annotated[
        str,
        typer.Option(
            "--measures",
            help="The archive's one or two descriptors, comma-separated: failure_class, terrain, "
            "peers, min_clearance, approach_side, variant (default for mutation: "
            "failure_class,variant).",
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
    """Search toward distinct failures: by default mutation, which edits failing situations
    (moves a peer, reshapes terrain, mirrors a crossing…) toward failure variants not yet
    found; or MAP-Elites over the spec's varied fields and seeds, random generation, or
    generation steered toward situation coverage (--strategy).
    Writes a store like a campaign's (rank, failures, report, rerun, shrink, coverage work on
    it). Ctrl-C stops after the runs in flight; the same command resumes."""
    from sitgen.execution.jobs import campaign_from_data
    from sitgen.generation.search import SearchProgress, SearchResult, like_run, run_search
    from sitgen.generation.search.plan import plan_search
    from sitgen.triage.failures import FailureFilterError

    _check_reruns(reruns)
    parsed = _campaign_spec(spec)
    liked = like_run(like) if like is not None else None
    if liked is not None:
        # A directed search runs its variants as the run it starts from was run.
        parsed = campaign_from_data({**parsed.source, "run": liked.run_spec})
    learned = _weights(weights)
    if learned is not None:
        # The runs are scored by the weights as they run (the objective is their score), and
        # the stored spec says so: a summary's run is rebuilt and re-simulated from it.
        source = copy.deepcopy(parsed.source)
        source.setdefault("run", {})["scoring"] = learned.table()
        parsed = campaign_from_data(source)
    # Last: a directed search varies the run it starts from, driven by this controller.
    parsed = _with_controller(
        parsed, controller, param, perception, keep_alive, step_timeout, time_limit,
        gathered(require, requirements),
    )  # fmt: skip
    names = tuple(m.strip() for m in measures.split(",") if m.strip())
    try:
        plan = plan_search(
            parsed, strategy, names, objective, threshold, target_class, liked, requirement
        )
    except FailureFilterError as e:
        raise UsageError(str(e)) from None

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
        if plan.strategy == "mutation":
            _echo_variants(db, plan.target_class, reruns, workers)
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


def _echo_variants(db: Path, target_class: str | None, reruns: int, workers: int | None) -> None:
    """The variants a mutation search found (of its target class, if it has one), each best
    run measured for robustness."""
    from sitgen.store import Store
    from sitgen.triage.robustness import label, measure_runs, measured_as_now, verdict
    from sitgen.triage.variants import variants_of

    with Store(db) as store:
        found = variants_of(store, target_class)
        measured = store.robustness([v.best_run for v in found])
        todo = [v.best_run for v in found if not measured_as_now(measured.get(v.best_run), reruns)]
        if todo and reruns:
            for r in measure_runs(store, todo, reruns, workers or 1):
                measured[r.run_id] = r.as_row()
    what = f"of {target_class} " if target_class else ""
    robust = 0
    lines = []
    for v in found:
        m = measured.get(v.best_run)
        said = (
            "unmeasured"
            if m is None
            else f"{verdict(m['recurs'], m['reruns'])} {label(m['recurs'], m['reruns'])}"
        )
        robust += m is not None and verdict(m["recurs"], m["reruns"]) == "robust"
        lines.append(f"  {v.key:60} {v.runs:5} runs  best run {v.best_run:6}  {said}")
    typer.echo(f"{len(found)} variants {what}({robust} robust; sitgen failures {db}):")
    for line in lines:
        typer.echo(line)
