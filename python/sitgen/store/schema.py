"""The store's schema: its tables as SQL, by the version that added them (docs/store.md
documents every column), and what each kind of store holds."""

from __future__ import annotations

SCHEMA_VERSION = 9


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
