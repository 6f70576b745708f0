"""Speed work leaves behaviour byte-identical: the event logs and trajectories of a fixed set of
runs match digests checked in before the work began (see ``tests/data/reference_runs.json``).

The set: the default campaign at seed 0, jobs 0-23 (every terrain preset the campaign draws,
zero to five peers), plus the reference scene of ``make bench`` (caves, five peers) under each
built-in agent controller. A mismatch names the runs whose log or trajectory changed."""

from __future__ import annotations

import hashlib
import json
import zlib
from typing import Any

from sitgen import _core
from sitgen.execution.jobs import build_job, parse_campaign
from tests.conftest import ROOT

DIGESTS = ROOT / "tests" / "data" / "reference_runs.json"

REFERENCE_SCENE = {"terrain": {"preset": "caves"}, "mission": {"peers_min": 5, "peers_max": 5}}
"""The benchmark's reference scene (benches/run.py)."""

CONTROLLERS = ("straight", "snd_follow", "follow", "vo", "dwa")


def reference_jobs() -> dict[str, tuple[str, int, str, int]]:
    """Name -> core job arguments (situation spec, seed, run spec, run seed)."""
    spec = parse_campaign(None)
    jobs: dict[str, tuple[str, int, str, int]] = {}
    for i in range(24):
        job = build_job(spec, 0, i)
        jobs[f"campaign/{i}"] = (json.dumps(job.situation), job.seed, json.dumps(job.run), job.seed)
    for name in CONTROLLERS:
        run = json.dumps({"controller": {"name": name}, "time_limit_s": 120.0})
        jobs[f"reference/{name}"] = (json.dumps(REFERENCE_SCENE), 1, run, 0)
    return jobs


def digests() -> dict[str, dict[str, Any]]:
    """Each reference run's event log digest, trajectory digest and step count."""
    jobs = reference_jobs()
    results = _core.run_jobs(list(jobs.values()), 2)
    out: dict[str, dict[str, Any]] = {}
    for name, result in zip(jobs, results, strict=True):
        assert result["ok"], f"{name}: {result.get('error')}"
        trajectory = zlib.decompress(result["trajectory"])
        out[name] = {
            "events": hashlib.sha256(result["events_jsonl"].encode()).hexdigest(),
            "trajectory": hashlib.sha256(trajectory).hexdigest(),
            "steps": json.loads(result["record"])["steps"],
        }
    return out


def test_event_logs_and_trajectories_are_byte_identical_to_the_checked_in_digests() -> None:
    expected: dict[str, dict[str, Any]] = json.loads(DIGESTS.read_text())
    got = digests()
    assert sorted(got) == sorted(expected)
    changed = [name for name in expected if got[name] != expected[name]]
    assert not changed, f"runs whose behaviour changed: {changed}"


if __name__ == "__main__":
    # Writes the digests: only when behaviour is meant to change, and say so in the commit.
    DIGESTS.write_text(json.dumps(digests(), indent=1, sort_keys=True) + "\n")
