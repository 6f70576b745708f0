"""The report: a static, self-contained HTML triage view of a campaign.

``sitgen report campaign.db -o report/`` writes ``index.html`` (first the campaign's distinct
failures, one card each with its sentence, runs, share, best score and its representative run's
figure; then campaign facts, the score distribution on a log scale, events by kind, every run
ranked in a table that sorts and filters by event kind and failure class) and, for the top runs
and every distinct failure's representative, ``run-<id>.html`` with the run's failure class and
the events that decided it, the situation figure (map, routes, driven paths, event markers), the
event timeline, the score breakdown, a replay (play, pause, scrub, speed; every robot's
footprint and the agent's laser rays) and the command that reruns it. No network:
styles and scripts are inline, each run's data sits beside its page as a script (``run-<id>.js``,
trajectories as base64 float32) so pages open from the file system and stay small for 600 s
runs. The replay's laser rays are cast in the page from the map and the poses with the
simulator's geometry (grid walk to the first occupied cell, robot rectangles).
"""

from __future__ import annotations

import html
import json
import math
import shutil
from pathlib import Path
from typing import Any

import numpy as np

from sitgen.generation.diff_report import DiffReport, diff_report
from sitgen.generation.fault_report import (
    FaultReport,
    evaluation,
    fault_report,
)
from sitgen.generation.search import SearchReplay, replay
from sitgen.presentation.page import _page
from sitgen.presentation.rosbag import is_report_bag, write_stored_run
from sitgen.presentation.run_page import run_page
from sitgen.presentation.sections import (
    coverage_section,
    diff_runs,
    diff_section,
    faults_section,
    search_section,
)
from sitgen.store import KINDS, Store
from sitgen.triage.failures import DistinctFailure, classes, distinct_failures
from sitgen.triage.robustness import tally
from sitgen.triage.weights import Weights


def _histogram_svg(scores: list[float]) -> str:
    """Runs per score bin on a log scale (scores are heavy-tailed): bin 0 holds scores below
    1, then one bin per power of 10 split in halves."""
    if not scores:
        return "<p>No runs.</p>"
    edges = [0.0, 1.0]
    top = max(scores)
    while edges[-1] <= top:
        edges.append(edges[-1] * math.sqrt(10))
    counts = [0] * (len(edges) - 1)
    for s in scores:
        i = 0 if s < 1 else min(len(counts) - 1, 1 + int(2 * math.log10(s)))
        counts[i] += 1
    width, height, pad = 640, 200, 30
    bar = (width - 2 * pad) / len(counts)
    peak = max(counts)
    parts = [f"<svg id='histogram' width='{width}' height='{height + 40}' role='img'>"]
    for i, c in enumerate(counts):
        h = (height - pad) * c / peak
        x = pad + i * bar
        label = "<1" if i == 0 else f"≥{edges[i]:,.3g}"
        parts.append(
            f"<rect x='{x:.1f}' y='{height - h:.1f}' width='{bar - 2:.1f}' height='{h:.1f}' "
            f"fill='#c0392b'><title>{label}: {c} runs</title></rect>"
            f"<text x='{x + bar / 2:.1f}' y='{height - h - 3:.1f}' font-size='11' "
            f"text-anchor='middle'>{c}</text>"
            f"<text x='{x + bar / 2:.1f}' y='{height + 14}' font-size='10' "
            f"text-anchor='middle'>{label}</text>"
        )
    parts.append(
        f"<text x='{width / 2}' y='{height + 34}' font-size='12' text-anchor='middle'>"
        "score (log scale, bins of half a decade)</text></svg>"
    )
    return "".join(parts)


INDEX_SCRIPT = """
<script>
(function () {
  const table = document.getElementById('runs');
  const body = table.tBodies[0];
  const filter = document.getElementById('filter');
  const classFilter = document.getElementById('class-filter');
  let order = {column: 'score', descending: true};
  function key(row, column) {
    const v = row.dataset[column];
    const n = Number(v);
    return v !== '' && !Number.isNaN(n) ? n : v;
  }
  function sortBy(column) {
    order = {column, descending: order.column === column ? !order.descending : column === 'score'};
    const rows = Array.from(body.rows);
    rows.sort((a, b) => {
      const x = key(a, column), y = key(b, column);
      const c = x < y ? -1 : x > y ? 1 : Number(a.dataset.run) - Number(b.dataset.run);
      return order.descending ? -c : c;
    });
    rows.forEach(r => body.appendChild(r));
  }
  table.querySelectorAll('th.sortable').forEach(th =>
    th.addEventListener('click', () => sortBy(th.dataset.column)));
  function applyFilters() {
    // Both filters at once: the event kind and the failure class ('-': runs with no class).
    const kind = filter.value, cls = classFilter.value;
    let shown = 0;
    Array.from(body.rows).forEach(r => {
      const visible = (!kind || r.dataset.kinds.split(' ').includes(kind)) &&
        (!cls || r.dataset.class === (cls === '-' ? '' : cls));
      r.hidden = !visible;
      if (visible) shown += 1;
    });
    document.getElementById('shown').textContent = shown;
  }
  filter.addEventListener('change', applyFilters);
  classFilter.addEventListener('change', applyFilters);
  window.sitgenIndex = {sortBy, applyFilters};
})();
</script>
"""


def _distinct_section(
    failures: list[DistinctFailure],
    pages: set[int],
    ranks: dict[int, int],
    total: int,
    shrunk: dict[int, dict[str, Any]],
) -> str:
    """One card per distinct failure, most dangerous first: its sentence, runs, share, best
    score and its representative run's figure, linked to the run's page (and to its minimal
    repro where the representative was shrunk)."""
    body = ["<section id='distinct'><h2>Distinct failures</h2>"]
    if not failures:
        body.append("<p id='no-failures'>No failures: no run has a failure class.</p></section>")
        return "".join(body)
    failing = sum(f.runs for f in failures)
    body.append(
        f"<p class='muted'>{failing} of {total} runs fall into {len(failures)} distinct "
        "failures (a failure class, a broad one split by behaviour), most dangerous first; "
        "each shows its representative: its highest-scoring run that recurs robustly under "
        "perturbation where one does, else its highest-scoring run.</p><div class='cards'>"
    )
    for f in failures:
        run_id = f.representative
        rank = ranks.get(run_id)
        where = f"run {run_id}" + (f" (rank {rank})" if rank is not None else "")
        if run_id in pages:
            figure = (
                f"<a href='run-{run_id}.html'><img src='run-{run_id}.png' loading='lazy' "
                f"alt='situation figure of run {run_id}'></a>"
            )
            link = f"<a class='representative' href='run-{run_id}.html'>{where} →</a>"
            if run_id in shrunk:
                after = shrunk[run_id]
                link += (
                    f"; <a class='minimal' href='run-{run_id}.html#minimal'>minimal repro</a>: "
                    f"{after['peers']} peer{'s' if after['peers'] != 1 else ''}, fails after "
                    f"{after['time_to_failure_s']:.1f} s"
                )
        else:
            figure = ""
            link = f"<span class='representative'>{where} (no stored trajectory)</span>"
        body.append(
            f"<div class='card' data-key='{html.escape(f.key)}' "
            f"data-class='{html.escape(f.failure_class)}' data-runs='{f.runs}' "
            f"data-representative='{run_id}'>"
            f"<h3 title='{html.escape(f.key)}'>{html.escape(f.description)}</h3>"
            f"<p>{f.runs} run{'s' if f.runs != 1 else ''} ({f.share:.1%} of all), "
            f"best score <b>{f.best_score:.1f}</b>, median duration "
            f"{f.median_duration_s:.1f} s</p>{_robustness_line(f)}{figure}"
            f"<p>representative: {link}</p></div>"
        )
    body.append("</div></section>")
    return "".join(body)


def _index(
    store: Store,
    rows: list[dict[str, Any]],
    failures: list[DistinctFailure],
    pages: set[int],
    faults: FaultReport | None = None,
    search: SearchReplay | None = None,
    weights_name: str = "",
    diff: DiffReport | None = None,
) -> str:
    campaign = store.campaign() or {}
    scores = [r["score"] for r in rows]
    # From each run's summary, which every run keeps (a run kept as a summary has no rows in
    # the events table): the penalised kinds' counts, the agent's waypoints and its route.
    kinds: dict[str, list[int]] = {}
    run_kinds: dict[int, set[str]] = {}
    for r in rows:
        counts = {k: int(b["count"]) for k, b in r["breakdown"].items()}
        counts["waypoint_reached"] = r["waypoints_reached"]
        counts["route_completed"] = int(r["outcome"] == "completed")
        for kind, count in counts.items():
            if count:
                kinds.setdefault(kind, [0, 0])
                kinds[kind][0] += count
                kinds[kind][1] += 1
                run_kinds.setdefault(r["run"], set()).add(kind)
    kinds = dict(sorted(kinds.items()))
    outcomes: dict[str, int] = {}
    present: dict[str, tuple[str, int]] = {}
    for r in rows:
        outcomes[r["outcome"]] = outcomes.get(r["outcome"], 0) + 1
        if r["failure_class"] is not None:
            _, n = present.get(r["failure_class"], ("", 0))
            present[r["failure_class"]] = (r["failure"] or r["failure_class"], n + 1)
    severity = {key: i for i, (key, _) in enumerate(classes())}
    class_options = sorted(present, key=lambda k: (severity.get(k, len(severity)), k))
    unclassified = sum(r["failure_class"] is None for r in rows)
    mean = sum(scores) / len(scores) if scores else 0.0
    median = float(np.median(scores)) if scores else 0.0
    facts = [
        ("runs", f"{len(rows)} of {campaign.get('n', 0)}"),
        ("seed", campaign.get("seed", "")),
        ("sitgen", campaign.get("sitgen_version", "")),
        ("started", campaign.get("created_at", "")),
        ("outcomes", ", ".join(f"{k} {v}" for k, v in sorted(outcomes.items())) or "none"),
        ("mean score", f"{mean:.1f}"),
        ("median score", f"{median:.1f}"),
        (
            "under 10 points",
            f"{100 * sum(s < 10 for s in scores) / len(scores):.0f}%" if scores else "n/a",
        ),
    ]
    spec = json.dumps(campaign.get("spec", {}), indent=2, sort_keys=True)
    ranks = {r["run"]: rank for rank, r in enumerate(rows, 1)}
    title = f"sitgen {KINDS[store.kind()]} report"
    body = [f"<h1>{title}</h1>"]
    if weights_name:
        body.append(
            f"<p id='weights'>Scores, ranks and representatives under the learned weights of "
            f"<code>{html.escape(weights_name)}</code> (<code>--weights</code>), rescored from "
            "each run's breakdown and failure class.</p>"
        )
    if faults is not None:
        body.append(faults_section(faults, pages))
    if search is not None:
        body.append(search_section(search, pages))
    if diff is not None:
        classes_of = {r["run"]: r["failure_class"] for r in rows}
        body.append(diff_section(diff, pages, classes_of))
    shrunk = {
        run_id: json.loads(after)
        for run_id, after in store.db.execute("SELECT run_id, after FROM shrinks")
    }
    body.append(_distinct_section(failures, pages, ranks, len(rows), shrunk))
    body.append(coverage_section(store, pages))
    body.append("<h2>Campaign</h2><table class='facts'>")
    body += [f"<tr><td>{k}</td><td>{html.escape(str(v))}</td></tr>" for k, v in facts]
    body.append("</table><details><summary>campaign spec</summary><pre>")
    body.append(html.escape(spec) + "</pre></details>")
    body.append("<h2>Score distribution</h2>" + _histogram_svg(scores))
    body.append("<h2>Events by kind (scored)</h2><table id='kinds'>")
    body.append("<tr><th>kind</th><th>events</th><th>runs</th></tr>")
    for kind, (count, runs) in kinds.items():
        body.append(
            f"<tr><td>{kind}</td><td class='num'>{count}</td><td class='num'>{runs}</td></tr>"
        )
    body.append("</table><h2>Runs, most dangerous first</h2><p class='controls'>")
    body.append("Show runs with <select id='filter'><option value=''>any event</option>")
    body += [f"<option value='{k}'>{k}</option>" for k in kinds]
    body.append("</select> of class <select id='class-filter'><option value=''>any class</option>")
    body += [
        f"<option value='{html.escape(k)}' title='{html.escape(k)}'>"
        f"{html.escape(present[k][0])} ({present[k][1]})</option>"
        for k in class_options
    ]
    if unclassified:
        body.append(f"<option value='-'>no failure ({unclassified})</option>")
    body.append(f"</select> <span id='shown'>{len(rows)}</span> shown. Click a heading to sort.")
    body.append("</p><table id='runs'><thead><tr>")
    columns = [
        ("rank", "rank"),
        ("run", "run"),
        ("score", "score"),
        ("outcome", "outcome"),
        ("failure", "class"),
        ("events", "main events"),
        ("terrain", "terrain"),
        ("peers", "peers"),
    ]
    body += [f"<th class='sortable' data-column='{c}'>{label}</th>" for c, label in columns]
    body.append("</tr></thead><tbody>")
    for rank, r in enumerate(rows, 1):
        run_id = r["run"]
        link = f"<a href='run-{run_id}.html'>{run_id}</a>" if run_id in pages else str(run_id)
        events = html.escape(r["main_events"])
        key = html.escape(r["failure_class"] or "")
        sentence = html.escape(r["failure"] or r["failure_class"] or "")
        body.append(
            f"<tr data-rank='{rank}' data-run='{run_id}' data-score='{r['score']}' "
            f"data-outcome='{r['outcome']}' data-events='{events}' "
            f"data-class='{key}' data-failure='{sentence}' "
            f"data-terrain='{html.escape(str(r['terrain']))}' data-peers='{r['peers'] or 0}' "
            f"data-kinds='{' '.join(sorted(run_kinds.get(run_id, ())))}'>"
            f"<td class='num'>{rank}</td><td class='num'>{link}</td>"
            f"<td class='num'>{r['score']:.1f}</td><td>{r['outcome']}</td>"
            f"<td class='class' title='{key}'>{sentence or '<span class=muted>none</span>'}</td>"
            f"<td>{events}</td>"
            f"<td>{html.escape(str(r['terrain']))}</td><td class='num'>{r['peers']}</td></tr>"
        )
    body.append("</tbody></table>")
    return _page("sitgen campaign report", "".join(body), INDEX_SCRIPT)


def _robustness_line(f: DistinctFailure) -> str:
    """A distinct failure's robustness as a card shows it: robust or knife-edge, how often
    its representative's class recurred, and what the copies did instead."""
    if f.recurs is None or f.reruns is None:
        return (
            "<p class='robustness' data-robust=''>robustness: not measured "
            "(<code>sitgen robustness</code>)</p>"
        )
    word = "robust" if f.robust else "knife-edge"
    return (
        f"<p class='robustness {word}' data-robust='{str(f.robust).lower()}' "
        f"data-recurs='{f.recurs}' data-reruns='{f.reruns}'><b>{word}</b>: recurs in "
        f"{f.recurs} of {f.reruns} perturbed reruns "
        f"<span class='muted'>({html.escape(tally(f.rerun_classes))})</span></p>"
    )


def write_report(
    db: str | Path,
    out: str | Path,
    top: int = 50,
    weights: Weights | None = None,
    weights_name: str = "",
    rosbags: int = 0,
) -> list[Path]:
    """Write the report of campaign store ``db`` into ``out``; returns the pages written. The
    ``top`` runs get a page, and so does every distinct failure's representative. With
    ``weights`` (read from ``weights_name``) every score is rescored by them. The ``rosbags``
    top runs are written as rosbag2 folders too (``rosbag2/run-ID``), linked from their
    pages."""
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    written = []
    with Store(db) as store:
        if weights is not None:
            store.rescore(weights)
        ranked = store.ranked()
        ranks = {r["run"]: rank for rank, r in enumerate(ranked, 1)}
        failures = distinct_failures(store)
        part_of = {run_id: f for f in failures for run_id in f.run_ids}
        wanted = [r["run"] for r in ranked[: max(0, top)]] + [f.representative for f in failures]
        faults = fault_report(store) if evaluation(store) is not None else None
        if faults is not None:
            # Each kill is shown as its faulty run beside the correct run on the same situation.
            wanted += [r for f in faults.faults for r in (f.run, f.correct_run) if r is not None]
        search = replay(store) if store.kind() == "search" else None
        if search is not None:
            # Every elite of the archive gets a page: the grid links them.
            wanted += search.archive.elites()
        diff = diff_report(store) if store.kind() == "diff" else None
        if diff is not None:
            # A diff's differing situations are shown as A's run beside B's.
            wanted += diff_runs(diff)
        for r in ranked[: max(0, rosbags)]:
            bag = out / "rosbag2" / f"run-{r['run']}"
            if bag.is_symlink() or bag.exists():
                if not is_report_bag(bag):
                    raise OSError(
                        f"{bag}: is there and is not a rosbag2 a report wrote; move it, or give "
                        "another --output"
                    )
                shutil.rmtree(bag)  # the report's own, from an earlier writing
            bag.parent.mkdir(exist_ok=True)
            write_stored_run(store, r["run"], bag)
        pages: set[int] = set()
        for run_id in dict.fromkeys(wanted):
            made = run_page(store, run_id, ranks[run_id], out, Path(db).name, part_of.get(run_id))
            if made is None:
                continue
            page, script = made
            (out / f"run-{run_id}.js").write_text(script)
            path = out / f"run-{run_id}.html"
            path.write_text(page)
            pages.add(run_id)
            written.append(path)
        index = out / "index.html"
        index.write_text(_index(store, ranked, failures, pages, faults, search, weights_name, diff))
    return [index, *written]
