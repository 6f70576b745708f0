"""Does sitgen reveal Velocity Obstacles' reciprocal oscillation? (``make bench-vo``)

Runs ``examples/campaigns/vo.toml`` (a ``vo`` agent among peers that run ``vo`` too) and the
same campaign with peers that avoid nothing (``straight``, the same 0.5 m/s), on the same
situations otherwise, for each seed, and prints per campaign:

- runs in which the agent oscillated (the monitor's ``oscillation`` event),
- runs with a *reciprocal* oscillation involving the agent: the agent and a peer oscillating at
  the same time, each naming the other as the nearest party (both robots dithering about each
  other, the failure van den Berg et al. describe), and such pairs among peers alone,
- runs with an agent collision, and routes completed.

It then draws the docs' figures from the highest-scoring run with a reciprocal oscillation of
the agent (seed 1): the situation with the driven paths, zoomed on the encounter
(``docs/vo-encounter.png``), and both robots' headings against time (``docs/vo-headings.png``).
Writes ``benches/results/vo.json``. ``SITGEN_BENCH_VO_SEEDS`` (default 3) and
``SITGEN_BENCH_VO_N`` (default 300) shrink it.
"""

from __future__ import annotations

import copy
import json
import os
import statistics
import tempfile
import tomllib
from pathlib import Path
from typing import Any

import numpy as np
from PIL import Image, ImageDraw

import sitgen
from sitgen.execution.campaign import run_campaign
from sitgen.execution.jobs import campaign_from_data
from sitgen.store import Store
from sitgen.triage.recall import stored_run
from sitgen.world.figure import AGENT, MARGIN_PX, PEER, TARGET_PX, draw_situation

ROOT = Path(__file__).resolve().parent.parent
RESULTS = ROOT / "benches" / "results"
DOCS = ROOT / "docs"
SPEC = ROOT / "examples" / "campaigns" / "vo.toml"


def campaigns() -> dict[str, dict[str, Any]]:
    """The example campaign, and the same with peers that avoid nothing."""
    vo = tomllib.loads(SPEC.read_text())
    blind = copy.deepcopy(vo)
    blind["situation"]["mission"]["peer_controller"] = {"name": "straight"}
    return {"vo peers": vo, "straight peers": blind}


def oscillations(store: Store) -> dict[int, list[dict[str, Any]]]:
    """Every oscillation event by run: robot, start, end, nearest party."""
    out: dict[int, list[dict[str, Any]]] = {}
    for run_id, robot, start, end, details in store.db.execute(
        "SELECT run_id, robot, start_s, end_s, details FROM events WHERE kind = 'oscillation'"
    ):
        nearest = json.loads(details).get("nearest")
        out.setdefault(run_id, []).append(
            {"robot": robot, "start": start, "end": end or start, "nearest": nearest}
        )
    return out


def reciprocal(events: list[dict[str, Any]]) -> list[tuple[int, int, float, float]]:
    """Pairs of robots oscillating at the same time, each naming the other as nearest: (a, b,
    from, to)."""
    pairs = []
    for i, a in enumerate(events):
        for b in events[i + 1 :]:
            mutual = a["nearest"] == b["robot"] and b["nearest"] == a["robot"]
            if mutual and a["start"] <= b["end"] and b["start"] <= a["end"]:
                lo, hi = sorted((a["robot"], b["robot"]))
                pairs.append((lo, hi, max(a["start"], b["start"]), min(a["end"], b["end"])))
    return pairs


def measure(db: Path, agent: int = 0) -> dict[str, Any]:
    with Store(db) as store:
        runs = store.db.execute("SELECT id, outcome, collisions, score FROM runs").fetchall()
        by_run = oscillations(store)
    pairs = {r: reciprocal(e) for r, e in by_run.items()}
    with_agent = {r: [p for p in ps if p[0] == agent] for r, ps in pairs.items()}
    scores = {r[0]: r[3] for r in runs}
    best = max((r for r, ps in with_agent.items() if ps), key=lambda r: scores[r], default=None)
    return {
        "runs": len(runs),
        "agent_oscillated": sum(any(e["robot"] == agent for e in es) for es in by_run.values()),
        "reciprocal_with_agent": sum(bool(ps) for ps in with_agent.values()),
        "reciprocal_peers_only": sum(any(p[0] != agent for p in ps) for ps in pairs.values() if ps),
        "agent_collided": sum(r[2] > 0 for r in runs),
        "completed": sum(r[1] == "completed" for r in runs),
        "example": None if best is None else {"run": best, "pair": with_agent[best][0]},
    }


def heading_plot(
    times: np.ndarray, series: dict[str, tuple[np.ndarray, Any]], span: tuple[float, float]
) -> Image.Image:
    """Headings (degrees, unwrapped) against time, one line per robot, the oscillation's span
    shaded."""
    w, h, left, bottom, top = 900, 360, 70, 50, 30
    image = Image.new("RGB", (w, h), "white")
    draw = ImageDraw.Draw(image)
    lo = min(float(s.min()) for s, _ in series.values())
    hi = max(float(s.max()) for s, _ in series.values())
    lo, hi = np.floor(lo / 30) * 30, np.ceil(hi / 30) * 30
    t0, t1 = float(times[0]), float(times[-1])

    def px(t: float, deg: float) -> tuple[float, float]:
        x = left + (t - t0) / (t1 - t0) * (w - left - 20)
        y = top + (hi - deg) / max(hi - lo, 1.0) * (h - top - bottom)
        return x, y

    draw.rectangle((*px(span[0], hi), *px(span[1], lo)), fill=(240, 240, 200))
    for deg in np.arange(lo, hi + 1, 30):
        x, y = px(t0, float(deg))
        draw.line((left, y, w - 20, y), fill=(225, 225, 225))
        draw.text((8, y - 6), f"{deg:.0f} deg", fill="black")
    for t in range(int(np.ceil(t0)), int(t1) + 1, 2):
        x, y = px(float(t), lo)
        draw.text((x - 8, y + 6), f"{t} s", fill="black")
    for values, colour in series.values():
        draw.line(
            [px(float(t), float(v)) for t, v in zip(times, values, strict=True)],
            fill=colour,
            width=2,
        )
    draw.text(
        (left, 8),
        "heading against time; shaded: both oscillating, each nearest the other",
        fill="black",
    )
    x = w - 20 - 8 * sum(len(k) + 4 for k in series)
    for label, (_, colour) in series.items():
        draw.line((x, 14, x + 20, 14), fill=colour, width=3)
        draw.text((x + 24, 8), label, fill=colour)
        x += 8 * (len(label) + 4)
    return image


def figures(db: Path, example: dict[str, Any]) -> None:
    """The docs' figures of run ``example["run"]``: the encounter and the headings."""
    with Store(db) as store:
        row = stored_run(store, example["run"])
    situation = sitgen.Situation(row["situation"])
    record = sitgen.run(situation, spec=row["run_spec"], seed=row["run_seed"])
    a, b, start, end = example["pair"]
    dt = 0.1
    image = draw_situation(situation, record.trajectory, record.events, dt)
    # Zoom on where the agent was when the pair began to oscillate.
    grid = situation.grid
    rows, cols = grid.occupied.shape
    px_per_m = max(1, TARGET_PX // max(rows, cols)) / grid.resolution
    x, y = record.trajectory[round(start / dt), a, :2]
    cx, cy = MARGIN_PX + x * px_per_m, MARGIN_PX + (rows * grid.resolution - y) * px_per_m
    half = 6.0 * px_per_m
    zoom = image.crop((int(cx - half), int(cy - half), int(cx + half), int(cy + half)))
    zoom.resize((600, 600), Image.Resampling.LANCZOS).save(DOCS / "vo-encounter.png")
    lo, hi = max(0, round((start - 8) / dt)), min(len(record.trajectory) - 1, round((end + 8) / dt))
    times = np.arange(lo, hi + 1) * dt
    series = {
        ("agent" if r == 0 else f"peer {r}"): (
            np.degrees(np.unwrap(record.trajectory[lo : hi + 1, r, 2])),
            AGENT if r == 0 else PEER,
        )
        for r in (a, b)
    }
    heading_plot(times, series, (start, end)).save(DOCS / "vo-headings.png")
    print(
        f"figures: run {example['run']} (score {row['score']:.1f}), robots {a} and {b}, "
        f"{start:.1f}-{end:.1f} s -> docs/vo-encounter.png, docs/vo-headings.png"
    )


def main() -> None:
    seeds = range(1, 1 + int(os.environ.get("SITGEN_BENCH_VO_SEEDS", "3")))
    n = int(os.environ.get("SITGEN_BENCH_VO_N", "300"))
    results: dict[str, list[dict[str, Any]]] = {}
    with tempfile.TemporaryDirectory() as tmp:
        for name, data in campaigns().items():
            spec = campaign_from_data(data)
            for seed in seeds:
                db = Path(tmp) / f"{name.split()[0]}-{seed}.db"
                run_campaign(spec, db, seed=seed, n=n)
                figures_ = measure(db)
                results.setdefault(name, []).append(figures_)
                counts = {k: v for k, v in figures_.items() if k != "example"}
                print(f"{name:15} seed {seed}: {json.dumps(counts)}", flush=True)
                if name == "vo peers" and seed == seeds[0] and figures_["example"]:
                    figures(db, figures_["example"])
    print(f"\nmedian over seeds {list(seeds)}, {n} runs each:")
    print(f"{'':38}" + "".join(f"{name:>16}" for name in results))
    for label, key in [
        ("agent oscillated", "agent_oscillated"),
        ("reciprocal oscillation with the agent", "reciprocal_with_agent"),
        ("reciprocal oscillation, peers only", "reciprocal_peers_only"),
        ("agent collided", "agent_collided"),
        ("completed", "completed"),
    ]:
        cells = "".join(
            f"{statistics.median(r[key] for r in results[name]):>16.0f}" for name in results
        )
        print(f"{label:38}{cells}")
    RESULTS.mkdir(parents=True, exist_ok=True)
    (RESULTS / "vo.json").write_text(json.dumps({"runs": n, "campaigns": results}, indent=2) + "\n")


if __name__ == "__main__":
    main()
