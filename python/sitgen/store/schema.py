"""The store's schema: its tables as SQL, by the version that added them (docs/store.md
documents every column), and what each kind of store holds."""

from __future__ import annotations

import json
import sqlite3

from sitgen import _core

SCHEMA_VERSION = 13


SCHEMA = """
CREATE TABLE IF NOT EXISTS meta (
    key TEXT PRIMARY KEY,
    value TEXT NOT NULL
);
CREATE TABLE IF NOT EXISTS campaign (
    id INTEGER PRIMARY KEY CHECK (id = 1),
    spec TEXT NOT NULL,
    seed INTEGER NOT NULL,
    n INTEGER NOT NULL,
    sitgen_version TEXT NOT NULL,
    created_at TEXT NOT NULL
);
CREATE TABLE IF NOT EXISTS situations (
    id INTEGER PRIMARY KEY,
    seed INTEGER NOT NULL,
    spec TEXT NOT NULL,
    terrain TEXT,
    peers INTEGER,
    content_hash TEXT,
    situation TEXT
);
CREATE TABLE IF NOT EXISTS runs (
    id INTEGER PRIMARY KEY,
    situation_id INTEGER NOT NULL REFERENCES situations (id),
    controller TEXT NOT NULL,
    run_spec TEXT NOT NULL,
    run_seed INTEGER NOT NULL,
    outcome TEXT NOT NULL,
    reason TEXT NOT NULL,
    score REAL NOT NULL,
    breakdown TEXT NOT NULL,
    steps INTEGER NOT NULL,
    time_s REAL NOT NULL,
    collisions INTEGER NOT NULL,
    min_clearance_m REAL,
    waypoints_reached INTEGER NOT NULL,
    waypoints INTEGER NOT NULL,
    events_jsonl TEXT NOT NULL,
    failure_class TEXT,
    failure TEXT,
    generation INTEGER,
    parents TEXT,
    genes TEXT,
    coverage TEXT,
    kept INTEGER,
    events_sha256 TEXT
);
CREATE INDEX IF NOT EXISTS runs_by_score ON runs (score DESC, id);
CREATE INDEX IF NOT EXISTS runs_by_failure_class ON runs (failure_class, score DESC, id);
CREATE TABLE IF NOT EXISTS events (
    run_id INTEGER NOT NULL REFERENCES runs (id),
    seq INTEGER NOT NULL,
    kind TEXT NOT NULL,
    start_s REAL NOT NULL,
    end_s REAL,
    robot INTEGER NOT NULL,
    other TEXT,
    scored INTEGER NOT NULL,
    details TEXT NOT NULL,
    PRIMARY KEY (run_id, seq)
);
CREATE INDEX IF NOT EXISTS events_by_kind ON events (kind);
CREATE TABLE IF NOT EXISTS trajectories (
    run_id INTEGER PRIMARY KEY REFERENCES runs (id),
    robots INTEGER NOT NULL,
    rows INTEGER NOT NULL,
    encoding TEXT NOT NULL,
    data BLOB NOT NULL
);
"""


FAULT_SCHEMA = """
CREATE TABLE IF NOT EXISTS fault_evaluation (
    id INTEGER PRIMARY KEY CHECK (id = 1),
    plan TEXT NOT NULL
);
CREATE TABLE IF NOT EXISTS fault_kills (
    fault TEXT PRIMARY KEY,
    situation INTEGER NOT NULL,
    run_id INTEGER NOT NULL REFERENCES runs (id),
    by TEXT NOT NULL,
    classes TEXT NOT NULL,
    score_delta REAL NOT NULL
);
"""


KILL_TEST_SCHEMA = """
CREATE TABLE IF NOT EXISTS fault_trials (
    fault TEXT NOT NULL,
    situation INTEGER NOT NULL,
    by TEXT NOT NULL,
    classes TEXT NOT NULL,
    faulty_recurs INTEGER NOT NULL,
    correct_recurs INTEGER NOT NULL,
    copies INTEGER NOT NULL,
    p_value REAL NOT NULL,
    killed INTEGER NOT NULL,
    PRIMARY KEY (fault, situation)
);
CREATE TABLE IF NOT EXISTS fault_chunks (
    first INTEGER PRIMARY KEY,
    copies INTEGER NOT NULL
);
"""


KILL_TEST_COLUMNS = (
    "faulty_recurs INTEGER",
    "correct_recurs INTEGER",
    "copies INTEGER",
    "p_value REAL",
)


"""Columns of ``fault_kills`` since version 9: the robust kill's test (NULL before)."""


SHRINK_SCHEMA = """
CREATE TABLE IF NOT EXISTS shrinks (
    run_id INTEGER PRIMARY KEY REFERENCES runs (id),
    failure_class TEXT NOT NULL,
    situation TEXT NOT NULL,
    run_spec TEXT NOT NULL,
    run_seed INTEGER NOT NULL,
    before TEXT NOT NULL,
    after TEXT NOT NULL,
    reductions TEXT NOT NULL,
    probes INTEGER NOT NULL,
    skipped INTEGER NOT NULL,
    wall_s REAL NOT NULL,
    sitgen_version TEXT NOT NULL
);
"""


SEARCH_SCHEMA = """
CREATE TABLE IF NOT EXISTS search (
    id INTEGER PRIMARY KEY CHECK (id = 1),
    plan TEXT NOT NULL
);
"""


JUDGEMENT_SCHEMA = """
CREATE TABLE IF NOT EXISTS judgements (
    id INTEGER PRIMARY KEY,
    a INTEGER NOT NULL REFERENCES runs (id),
    b INTEGER NOT NULL REFERENCES runs (id),
    worse TEXT NOT NULL CHECK (worse IN ('a', 'b', 'equal')),
    who TEXT NOT NULL,
    at TEXT NOT NULL,
    source TEXT NOT NULL
);
"""


ROBUSTNESS_SCHEMA = """
CREATE TABLE IF NOT EXISTS robustness (
    run_id INTEGER PRIMARY KEY REFERENCES runs (id),
    failure_class TEXT NOT NULL,
    reruns INTEGER NOT NULL,
    recurs INTEGER NOT NULL,
    classes TEXT NOT NULL,
    perturbation TEXT NOT NULL,
    sitgen_version TEXT NOT NULL
);
"""


COST_SCHEMA = """
CREATE TABLE IF NOT EXISTS run_costs (
    run_id INTEGER PRIMARY KEY REFERENCES runs (id),
    wall_s REAL NOT NULL,
    cpu_s REAL NOT NULL
);
"""
"""What each run cost the machine that made it (wall and processor seconds): kept apart from
``runs`` because it is the machine's, not the run's: a run's row is the same bytes on any
machine, under any load, on any worker count."""


REQUIREMENT_SCHEMA = """
CREATE TABLE IF NOT EXISTS requirement_verdicts (
    run_id INTEGER NOT NULL REFERENCES runs (id),
    name TEXT NOT NULL,
    formula TEXT NOT NULL,
    robustness REAL,
    violated INTEGER NOT NULL,
    first_violation_s REAL,
    interval_start_s REAL,
    interval_end_s REAL,
    weight REAL NOT NULL,
    error TEXT,
    PRIMARY KEY (run_id, name)
);
CREATE INDEX IF NOT EXISTS requirement_verdicts_by_name
    ON requirement_verdicts (name, violated, robustness);
CREATE TABLE IF NOT EXISTS requirement_robustness (
    run_id INTEGER NOT NULL REFERENCES runs (id),
    name TEXT NOT NULL,
    reruns INTEGER NOT NULL,
    recurs INTEGER NOT NULL,
    copies TEXT NOT NULL,
    sitgen_version TEXT NOT NULL,
    PRIMARY KEY (run_id, name)
);
"""
"""Each run's verdict on each of its requirements (docs/requirements.md): robustness (NULL
where ``error`` says why there is none; ±inf as SQLite's), whether it was violated, when, and
the interval that decided it; and how often a violating run's violation recurred in its
perturbed copies."""


AVOIDABILITY_SCHEMA = """
CREATE TABLE IF NOT EXISTS avoidability (
    run_id INTEGER PRIMARY KEY REFERENCES runs (id),
    robot INTEGER,
    collision_s REAL,
    sighted_s REAL,
    speed_m_s REAL,
    turn_rate_rad_s REAL,
    at_rest INTEGER,
    verdict TEXT,
    witness TEXT,
    tried INTEGER,
    after_s REAL NOT NULL,
    error TEXT,
    sitgen_version TEXT NOT NULL
);
"""
"""Whether each judged run's first collision with a robot could have been escaped
(docs/avoidability.md): the robot, when contact and the sighting began, the agent's velocity
then and whether it stood at rest, the verdict (``avoidable``, ``unavoidable_with_this_sensor``,
``unavoidable``) and its witness manoeuvre (JSON; NULL where there is none), or ``error`` where
the run could not be judged (its verdict NULL)."""


DESCRIPTOR_SCHEMA = """
CREATE TABLE IF NOT EXISTS situation_descriptors (
    situation_id INTEGER PRIMARY KEY REFERENCES situations (id),
    descriptors TEXT NOT NULL
);
"""
"""Each situation's descriptors (docs/explain.md) as JSON, computed by the core when a
campaign generates it (or when `sitgen explain` first needs them), so that explaining a
campaign generates no situation again."""


DIFF_SCHEMA = """
CREATE TABLE IF NOT EXISTS diff (
    id INTEGER PRIMARY KEY CHECK (id = 1),
    plan TEXT NOT NULL
);
CREATE TABLE IF NOT EXISTS diff_results (
    situation INTEGER NOT NULL,
    failure_class TEXT NOT NULL,
    a_recurs INTEGER,
    b_recurs INTEGER,
    copies INTEGER NOT NULL,
    verdict TEXT NOT NULL,
    PRIMARY KEY (situation, failure_class)
);
CREATE TABLE IF NOT EXISTS diff_chunks (
    first INTEGER PRIMARY KEY,
    copies INTEGER NOT NULL
);
"""


TRAJECTORY_ENCODING = "f32le-zlib"


"""Trajectories: (x, y, heading) per robot per step as little-endian float32, zlib'd."""


KINDS = {
    "campaign": "campaign",
    "fault_evaluation": "fault evaluation",
    "search": "search",
    "diff": "controller diff",
}


"""What a store can hold, as a sentence names it."""


PLAN_PARTS = {
    "fault_evaluation": "its controller, faults or strategy",
    "search": "its strategy, measures or objective",
    "diff": "its controllers or situations",
}


TABLES = ("meta", "campaign", "situations", "runs", "events", "trajectories")


def upgrade(db: sqlite3.Connection, version: int) -> None:
    """Bring store ``db``, written by an older sitgen at schema ``version``, up to this schema
    (the caller holds it in one transaction): columns are added, never dropped, so nothing
    stored is lost."""
    if version < 2:
        # Version 2 adds each run's failure class, classified from its stored log (logs
        # written before attribution classify by whose move was refused).
        db.execute("ALTER TABLE runs ADD COLUMN failure_class TEXT")
        db.execute("ALTER TABLE runs ADD COLUMN failure TEXT")
        runs = db.execute("SELECT id, events_jsonl FROM runs").fetchall()
        for run_id, events in runs:
            failure = _core.classify_events(events, 0)
            db.execute(
                "UPDATE runs SET failure_class = ?, failure = ? WHERE id = ?",
                (json.loads(failure)["class"] if failure else None, failure, run_id),
            )
        db.executescript(
            "CREATE INDEX IF NOT EXISTS runs_by_failure_class "
            "ON runs (failure_class, score DESC, id)"
        )
    if version < 3:
        # Version 3 adds fault evaluations (sitgen faults): two tables, empty for a
        # campaign.
        db.executescript(FAULT_SCHEMA)
    if version < 4:
        # Version 4 adds shrink results (sitgen shrink): one table, empty until then.
        db.executescript(SHRINK_SCHEMA)
    if version < 5:
        # Version 5 adds searches (sitgen search): each run's generation, parents and
        # genes (NULL for a campaign's runs) and the search's plan.
        add_columns(db, "runs", "generation INTEGER", "parents TEXT", "genes TEXT")
        db.executescript(SEARCH_SCHEMA)
    if version < 6:
        # Version 6 adds each run's situation coverage (NULL for runs stored before:
        # coverage is observed during a run and cannot be read back from its log).
        add_columns(db, "runs", "coverage TEXT")
    if version < 7:
        # Version 7 stores some runs as a summary only (kept = 0) and each run's event
        # log digest; runs stored before are whole (kept NULL) with their log.
        add_columns(db, "runs", "kept INTEGER", "events_sha256 TEXT")
    if version < 8:
        # Version 8 adds an expert's pairwise judgements of runs (sitgen judge): one
        # table, empty until then.
        db.executescript(JUDGEMENT_SCHEMA)
    if version < 9:
        # Version 9 adds the robustness of failing runs (reruns under perturbation):
        # one table, empty until a campaign, search or `sitgen robustness` fills it.
        db.executescript(ROBUSTNESS_SCHEMA)
        # And the robust kill rule's trials: each candidate situation's test, the
        # copies each chunk ran, and the killing test's counts on each kill.
        db.executescript(KILL_TEST_SCHEMA)
        add_columns(db, "fault_kills", *KILL_TEST_COLUMNS)
        # And controller diffs (sitgen diff): their plan and verdicts.
        db.executescript(DIFF_SCHEMA)
    if version < 10:
        # Version 10 adds what each run cost (wall and processor seconds); runs stored
        # before have none.
        db.executescript(COST_SCHEMA)
    if version < 11:
        # Version 11 adds each run's requirement verdicts; runs stored before had no
        # requirements.
        db.executescript(REQUIREMENT_SCHEMA)
    if version < 12:
        # Version 12 adds whether a collision with a robot could have been escaped; runs
        # stored before are judged when asked (sitgen avoidability).
        db.executescript(AVOIDABILITY_SCHEMA)
    if version < 13:
        # Version 13 stores each situation's descriptors; those of situations stored before
        # are computed when first asked for.
        db.executescript(DESCRIPTOR_SCHEMA)
    db.execute("UPDATE meta SET value = ? WHERE key = 'schema_version'", (str(SCHEMA_VERSION),))


def add_columns(db: sqlite3.Connection, table: str, *columns: str) -> None:
    """Add the columns (``name TYPE``) ``table`` lacks."""
    present = {c[1] for c in db.execute(f"PRAGMA table_info({table})")}
    for column in columns:
        if column.split()[0] not in present:
            db.execute(f"ALTER TABLE {table} ADD COLUMN {column}")
