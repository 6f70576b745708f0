"""Commands for an expert's judgements and the weights fitted to them: judge, judgements,
weights."""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING, Annotated

import typer
from rich.console import Console
from rich.table import Table

from sitgen import _core
from sitgen.store import require_store

if TYPE_CHECKING:
    pass
from sitgen.cli.app import UsageError, app, check_output


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
    check_output(output, "--output", db)
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
    check_output(output, "--output", db, judgements)
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
