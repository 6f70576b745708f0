"""Was a collision avoidable? End to end through the CLI (the exact cases — a known escape
whose witness replays collision-free, a peer striking a still agent from its blind side, a
dead end — are the core's tests, `cargo test -p sitgen-core avoidability`): a campaign
judges its peer-contact failures, `sitgen avoidability` any run, `failures` ranks
collisions no controller with this sensor could have escaped after the controller's own
mistakes, and the report draws the escape."""

from __future__ import annotations

import json
import re
import sqlite3
from pathlib import Path

import numpy as np
import pytest

from sitgen.store import Store
from sitgen.triage.avoidability import PEER_CONTACTS, VERDICTS, tier
from sitgen.triage.recall import stored_run, whole_run
from tests.conftest import ROOT, run_cli

SPEC = str(ROOT / "examples" / "campaigns" / "paper120.toml")


@pytest.fixture(scope="module")
def campaign(tmp_path_factory: pytest.TempPathFactory) -> Path:
    db = tmp_path_factory.mktemp("avoid") / "c.db"
    done = run_cli("campaign", SPEC, "--n", "120", "--db", str(db), "--reruns", "0")
    assert done.returncode == 0, done.stderr
    assert "collisions with robots judged" in done.stdout
    return db


def test_a_campaign_judges_its_peer_contact_failures_and_failures_ranks_by_it(
    campaign: Path,
) -> None:
    with Store(campaign) as store:
        judged = store.avoidability()
        classes = dict(store.db.execute("SELECT id, failure_class FROM runs").fetchall())
    assert judged, "the campaign has collisions with peers"
    assert all(classes[i] in PEER_CONTACTS for i in judged)
    assert {r["verdict"] for r in judged.values()} <= set(VERDICTS)
    done = run_cli("failures", str(campaign), "--format", "json")
    assert done.returncode == 0, done.stderr
    rows = [r for r in json.loads(done.stdout) if not r["class"].startswith("requirement:")]
    tiers = [tier(r["avoidability"]) for r in rows]
    assert tiers == sorted(tiers), "collisions nothing could have escaped rank last"
    for r in rows:
        if r["class"] in PEER_CONTACTS:
            assert r["avoidability"] == judged[r["representative"]]["verdict"]
            assert 0 <= r["avoidable"] <= r["judged"]
        else:
            assert r["avoidability"] is None and r["judged"] is None


def test_every_witness_starts_where_the_stored_run_stood_and_covers_its_horizon(
    campaign: Path,
) -> None:
    done = run_cli("avoidability", str(campaign), "--format", "json")
    assert done.returncode == 0, done.stderr
    rows = json.loads(done.stdout)
    with Store(campaign) as store:
        every = [
            i
            for (i,) in store.db.execute(
                f"SELECT id FROM runs WHERE failure_class IN ({','.join('?' * 8)})", PEER_CONTACTS
            )
        ]
        assert sorted(r["run_id"] for r in rows) == sorted(every)
        for r in rows[:12]:
            assert r["error"] is None
            w = r["witness"]
            if r["verdict"] == "unavoidable":
                assert w is None
                continue
            from_start = r["verdict"] == "unavoidable_with_this_sensor"
            assert w["from_s"] == (0.0 if from_start else pytest.approx(r["sighted_s"]))
            assert w["until_s"] >= r["collision_s"] + 5.0 - 1e-9
            total = sum(s["duration_s"] for s in w["segments"])
            assert total == pytest.approx(w["until_s"] - w["from_s"])
            # The branch is the stored run where the escape starts: the same pose (the store
            # keeps poses as float32).
            whole = whole_run(store, stored_run(store, r["run_id"]))
            assert whole is not None and whole.trajectory is not None
            robots = len(whole.situation.robots)
            poses = np.asarray(whole.trajectory).reshape(-1, robots, 3)
            at = poses[round(w["from_s"] / 0.1), 0]
            assert np.allclose(w["path"][0], at, atol=1e-4)
            assert len(w["path"]) == round((w["until_s"] - w["from_s"]) / 0.1) + 1


def test_a_judgement_is_stored_once_and_made_again_only_when_asked(campaign: Path) -> None:
    with Store(campaign) as store:
        run_id = next(iter(store.avoidability()))
    con = sqlite3.connect(campaign)
    con.execute("UPDATE avoidability SET tried = -1 WHERE run_id = ?", (run_id,))
    con.commit()
    con.close()
    assert run_cli("avoidability", str(campaign), str(run_id)).returncode == 0
    with Store(campaign) as store:
        assert store.avoidability([run_id])[run_id]["tried"] == -1, "kept, not judged again"
    done = run_cli("avoidability", str(campaign), str(run_id), "--again")
    assert done.returncode == 0, done.stderr
    assert re.search(rf"│\s+{run_id} │ (avoidable|unavoidable)", done.stdout), done.stdout
    with Store(campaign) as store:
        assert store.avoidability([run_id])[run_id]["tried"] > 0


def test_the_run_page_draws_the_escape(campaign: Path, tmp_path: Path) -> None:
    with Store(campaign) as store:
        judged = store.avoidability()
    run_id = next(i for i, r in judged.items() if r["witness"])
    out = tmp_path / "report"
    done = run_cli("report", str(campaign), "-o", str(out), "--top", "0")
    assert done.returncode == 0, done.stderr
    pages = {p.name for p in out.glob("run-*.html")}
    page_of = next((i for i in judged if f"run-{i}.html" in pages and judged[i]["witness"]), run_id)
    text = (out / f"run-{page_of}.html").read_text()
    verdict = judged[page_of]["verdict"]
    assert f"data-verdict='{verdict}'" in text
    assert "<polyline class='escape'" in text
    assert "id='avoidability-plan'" in text


@pytest.mark.parametrize(
    ("args", "words"),
    [
        (["--after-s", "0"], "--after-s: 0.0 is not in (0, 3600] seconds"),
        (["99999"], "run 99999: no such run"),
        (["--format", "yaml"], "--format: `yaml` is not one of table, json"),
    ],
)
def test_bad_input_is_one_line_naming_the_option(
    campaign: Path, args: list[str], words: str
) -> None:
    done = run_cli("avoidability", str(campaign), *args)
    assert done.returncode != 0
    assert words in done.stderr, done.stderr


def test_a_users_class_is_judged_from_its_recorded_path(tmp_path: Path) -> None:
    db = tmp_path / "u.db"
    braking = "python:" + str(ROOT / "examples" / "controllers" / "braking.py") + ":Braking"
    done = run_cli(
        "campaign", SPEC, "--n", "40", "--db", str(db), "--reruns", "0", "--controller", braking
    )
    assert done.returncode == 0, done.stderr
    done = run_cli("avoidability", str(db), "--format", "json")
    assert done.returncode == 0, done.stderr
    rows = json.loads(done.stdout)
    assert rows, "the braking follower is struck by peers"
    with Store(db) as store:
        failures = {
            i: json.loads(f)
            for i, f in store.db.execute("SELECT id, failure FROM runs WHERE failure IS NOT NULL")
        }
        for r in rows:
            assert r["error"] is None, r["error"]
            # The contact judged is the one that decided the failure.
            assert r["collision_s"] == pytest.approx(failures[r["run_id"]]["features"]["start_s"])
            if failures[r["run_id"]]["class"].endswith("_unseen"):
                assert r["verdict"] != "avoidable", "not seen within a second of contact"
            w = r["witness"]
            if w:
                whole = whole_run(store, stored_run(store, r["run_id"]))
                assert whole is not None and whole.trajectory is not None
                poses = np.asarray(whole.trajectory).reshape(-1, len(whole.situation.robots), 3)
                assert np.allclose(w["path"][0], poses[round(w["from_s"] / 0.1), 0], atol=1e-4)
    # Kept as summaries, the runs are made again through the class on the workers (a process
    # pool), checked to be the stored runs, and judged the same.
    summaries = tmp_path / "summaries.db"
    done = run_cli("campaign", SPEC, "--n", "40", "--db", str(summaries), "--reruns", "0",
                   "--controller", braking, "--keep-trajectories", "none",
                   "--workers", "2")  # fmt: skip
    assert done.returncode == 0, done.stderr
    done = run_cli("avoidability", str(summaries), "--format", "json")
    assert done.returncode == 0, done.stderr
    assert json.loads(done.stdout) == rows
