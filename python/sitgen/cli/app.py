"""The ``sitgen`` command's frame: the typer app, the options every command group shares,
reading specs and stores, progress, and :func:`main`, which turns expected errors into one
line and an exit code: ``error: …`` naming the field or file, exit 2 (bad input) or 1
(generation or I/O failed); never a traceback."""

from __future__ import annotations

import contextlib
import json
import os
import sqlite3
import sys
import time
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import TYPE_CHECKING, Annotated, Any, Protocol, TypeVar

import typer

from sitgen import _core
from sitgen.store import StoreError, StoreMissing, require_store
from sitgen.world.config import read_utf8

if TYPE_CHECKING:
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
        help="snd_follow, snd, follow, vo, dwa, straight, python:MODULE:CLASS (or "
        "python:FILE.py:CLASS), 'cmd:PROGRAM ARGS', 'ros2:PROGRAM ARGS' or "
        "navground:BEHAVIOR (HL, ORCA, HRVO, SocialForce, …). Default: the spec's, else the "
        "situation's.",
    ),
]


ParamOption = Annotated[
    list[str] | None,
    typer.Option(
        "--param",
        "-p",
        help="NAME=VALUE: a parameter of the controller, a number, over the spec's "
        "(repeatable). A python: class gets them as keyword arguments, a cmd: program in its "
        "reset message, a ros2: node as ROS parameters.",
    ),
]


PerceptionOption = Annotated[
    str | None,
    typer.Option(
        "--perception",
        help="What the agent's controller is given of the other robots and the walls: sensed "
        "(its laser and the robots the laser sees, the default) or exact (every robot's true "
        "state, and the map's walls as segments). Over the spec's.",
    ),
]


KeepAliveOption = Annotated[
    bool,
    typer.Option(
        "--keep-alive",
        help="A ros2: agent: start its node once per worker and reset it between runs, not "
        "once per run (the controller table's keep_alive; checked before any run).",
    ),
]


StepTimeoutOption = Annotated[
    float | None,
    typer.Option(
        "--step-timeout",
        min=0.001,
        max=600.0,
        help="Seconds of processor time a user controller may spend on one step (default 1; "
        "10 for navground:), over the spec's step_timeout_s. A wall-clock backstop of ten "
        "times this ends one that waits; a loaded machine changes neither.",
    ),
]


def parse_params(items: list[str] | None, option: str = "--param") -> dict[str, float]:
    """``NAME=VALUE`` items as a controller's params; SpecError names the option and item."""
    import math

    params: dict[str, float] = {}
    for item in items or []:
        name, sep, text = item.partition("=")
        try:
            value = float(text)
        except ValueError:
            value = math.nan
        if not sep or not name.strip() or not math.isfinite(value):
            raise _core.SpecError(
                f"{option}: `{item}` is not NAME=VALUE with VALUE a finite number"
            )
        params[name.strip()] = value
    return params


RequireOption = Annotated[
    list[str] | None,
    typer.Option(
        "--require",
        help="NAME: FORMULA: a requirement in STL (rtamt's syntax) over the requirement "
        "signals, judged on every run (repeatable; docs/requirements.md).",
    ),
]


RequirementsOption = Annotated[
    list[Path] | None,
    typer.Option(
        "--requirements",
        help="A TOML file of \\[\\[requirement]] tables (name, formula, weight), judged on every "
        "run with the spec's own and --require's (repeatable).",
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


def check_output(output: Path | None, option: str, *inputs: Path | None) -> None:
    """Refuse an output file that would overwrite what the command reads or stores: one that
    is (or links to) an input or the store, or any SQLite store. Checked before any work, so
    nothing stored is ever turned into a report."""
    if output is None:
        return
    target = os.path.realpath(output)
    for given in inputs:
        if given is not None and target == os.path.realpath(given):
            raise UsageError(
                f"{option}: {output} is {given}, which this command reads or stores; "
                "give another file"
            )
        # SQLite's own files beside a store: one overwritten is read as a hot journal.
        for sidecar in ("-journal", "-wal", "-shm"):
            if given is not None and target == os.path.realpath(f"{given}{sidecar}"):
                raise UsageError(
                    f"{option}: {output} is the {sidecar.lstrip('-')} file of {given}, which "
                    "SQLite keeps beside that store; give another file"
                )
    if _is_sqlite(Path(target)):
        raise UsageError(f"{option}: {output} is a sitgen store (SQLite); give another file")


def _is_store(path: Path) -> bool:
    """Whether ``path`` is an SQLite file (a campaign store) rather than a situation."""
    return path.suffix == ".db" or _is_sqlite(path)


def _is_sqlite(path: Path) -> bool:
    """Whether ``path`` is a file that starts as an SQLite database does."""
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


class OnProgress(Protocol):
    """A progress bar's update: work done of total, and a line of what it found so far."""

    def __call__(self, done: int, total: int, status: str = "") -> None: ...


PROGRESS_AFTER_S = 10.0
"""Off a terminal, no progress line for work done sooner than this (``SITGEN_PROGRESS_AFTER_S``
sets it): a quick command's output stays its own..."""
PROGRESS_STEP = 0.05
"""...then a line each time this share of the work is done..."""
PROGRESS_EVERY_S = 60.0
"""...or this many seconds have passed since the last, whichever comes first."""


@contextmanager
def _progress(label: str, total: int, unit: str) -> Iterator[OnProgress]:
    """A progress bar on a terminal (or with SITGEN_PROGRESS set); elsewhere (a CI log, a
    pipe, nohup), once the work has taken :data:`PROGRESS_AFTER_S`, a line to stderr every few
    percent and at least every minute: work done, rate, time left and what was found so far.
    Yields the ``on_progress(done, total, status)`` to call."""

    from rich.progress import (
        BarColumn,
        MofNCompleteColumn,
        Progress,
        TextColumn,
        TimeElapsedColumn,
        TimeRemainingColumn,
    )

    started = time.perf_counter()
    bar = sys.stderr.isatty() or "SITGEN_PROGRESS" in os.environ
    quiet_s = float(os.environ.get("SITGEN_PROGRESS_AFTER_S", PROGRESS_AFTER_S))
    with Progress(
        TextColumn(f"[bold]{label}"),
        BarColumn(),
        MofNCompleteColumn(),
        TextColumn("{task.fields[rate]}"),
        TimeElapsedColumn(),
        TextColumn("ETA"),
        TimeRemainingColumn(),
        TextColumn("{task.fields[status]}"),
        disable=not bar,
    ) as progress:
        task = progress.add_task(unit, total=total, rate="", status="")
        first: list[int] = []
        said = [-1.0, started]  # share and time of the last line written

        def on_progress(done: int, total: int, status: str = "") -> None:
            if not first:
                first.append(done)
            now = time.perf_counter()
            elapsed = now - started
            rate = (done - first[0]) / elapsed if elapsed > 0 else 0.0
            progress.update(
                task, completed=done, total=total, rate=f"{rate:.1f} {unit}/s", status=status
            )
            share = done / total if total else 1.0
            due = share >= said[0] + PROGRESS_STEP or now - said[1] >= PROGRESS_EVERY_S
            if bar or elapsed < quiet_s or not (due or done == total):
                return
            said[:] = [share, now]
            left = (total - done) / rate if rate > 0 else None
            eta = "" if left is None else f", ETA {_clock(left)}"
            found = f"; {status}" if status else ""
            print(
                f"{label}: {done}/{total} {unit} ({100 * share:.0f}%), {rate:.2g} {unit}/s, "
                f"{_clock(elapsed)} so far{eta}{found}",
                file=sys.stderr,
                flush=True,
            )

        yield on_progress


def _clock(seconds: float) -> str:
    """``1:02:03`` or ``2:03``."""
    whole = round(seconds)
    hours, rest = divmod(whole, 3600)
    return f"{hours}:{rest // 60:02d}:{rest % 60:02d}" if hours else f"{rest // 60}:{rest % 60:02d}"


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
