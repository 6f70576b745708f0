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

import base64
import html
import json
import math
from pathlib import Path
from typing import Any

import numpy as np

from sitgen.generation.diff import NEW, DiffReport, Pair, controller_label, diff_report
from sitgen.generation.diff import summary_lines as diff_summary_lines
from sitgen.generation.faults import (
    FaultReport,
    evaluation,
    fault_report,
    fault_status,
    summary_lines,
)
from sitgen.generation.search import SearchReplay, elite_grid, replay
from sitgen.run import run
from sitgen.store import KINDS, Store, main_events
from sitgen.triage.coverage import RunCoverage, dimensions, stored, summarise
from sitgen.triage.failures import DistinctFailure, classes, distinct_failures
from sitgen.triage.recall import stored_run, whole_run
from sitgen.triage.robustness import tally, verdict
from sitgen.triage.weights import Weights
from sitgen.world.figure import EVENT_COLOURS, save_situation_figure
from sitgen.world.situation import Situation

STYLE = """
body { font: 14px/1.4 system-ui, sans-serif; margin: 1.5em; color: #222; max-width: 1200px; }
h1 { font-size: 1.5em; } h2 { font-size: 1.15em; margin-top: 1.6em; }
table { border-collapse: collapse; } td, th { padding: 3px 8px; border-bottom: 1px solid #ddd; }
th { text-align: left; background: #f3f3f3; } th.sortable { cursor: pointer; }
td.num { text-align: right; font-variant-numeric: tabular-nums; }
.facts td:first-child { color: #666; } code { background: #f3f3f3; padding: 2px 4px; }
.controls button, .controls select { margin-right: .5em; } #scrub { width: 60%; }
canvas { border: 1px solid #ccc; image-rendering: pixelated; max-width: 100%; }
.figure { max-width: 100%; border: 1px solid #ccc; }
.cards { display: grid; grid-template-columns: repeat(auto-fill, minmax(270px, 1fr)); gap: 12px; }
.card { border: 1px solid #ddd; border-radius: 6px; padding: 8px 10px; background: #fafafa; }
.card h3 { font-size: 1em; margin: .1em 0 .3em; } .card p { margin: .3em 0; }
.pair { display: grid; grid-template-columns: 1fr 1fr; gap: 12px; margin-bottom: 12px; }
.pair p { grid-column: 1 / 3; margin: .3em 0; }
.side img { width: 100%; height: 250px; object-fit: contain; }
.card img { width: 100%; height: 250px; object-fit: contain; background: #fff;
  border: 1px solid #ccc; display: block; } .muted { color: #666; }
td.class { max-width: 22em; } [data-seek] { cursor: pointer; }
.robustness.robust b, #robustness.robust b { color: #1e7b34; }
.robustness.knife-edge b, #robustness.knife-edge b { color: #a15c00; }
mark { background: #fde2b8; } #archive td { min-width: 4em; font-size: 12px; }
#archive td.empty { background: #fafafa; }
#coverage-grid td { width: 1.4em; height: 1.1em; font-size: 10px; text-align: center;
  padding: 0; } #coverage-grid td.uncovered { background: #f4f4f4; }
#coverage-grid td.failed { outline: 2px solid #c0392b; }
#coverage-grid th { font-size: 11px; font-weight: normal; }
#coverage-grid th.speed { writing-mode: vertical-rl; }
#failure-events span:hover { background: #f3f3f3; }
"""


def _page(title: str, body: str, scripts: str = "") -> str:
    return (
        "<!DOCTYPE html>\n<html lang='en'><head><meta charset='utf-8'>"
        f"<title>{html.escape(title)}</title><style>{STYLE}</style></head>"
        f"<body>{body}{scripts}</body></html>\n"
    )


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


def _faults_section(report: FaultReport, pages: set[int]) -> str:
    """A fault evaluation's results: the kill rate and its curve, then one row per fault with
    what it changes, what it stands for, and the faulty and correct runs that killed it."""

    def link(run_id: int | None) -> str:
        if run_id is None:
            return ""
        return f"<a href='run-{run_id}.html'>{run_id}</a>" if run_id in pages else str(run_id)

    body = ["<section id='faults'><h2>Seeded faults</h2><p>"]
    body += [html.escape(line) + "<br>" for line in summary_lines(report)]
    body.append(
        "</p><p class='muted'>A fault is killed at the first situation where its run fails with "
        "a failure class the correct run does not show, or scores worse by more than the "
        "margin, and its perturbed copies then show that failure significantly more often "
        "than the correct controller's (one-sided Fisher exact test at 0.001; docs/faults.md). "
        "Equivalent mutants, the correct controller with a parameter nudged by 10⁻⁵ or less, "
        "go through the same rule: a kill of one is a false kill.</p><table><tr><th>fault</th>"
        "<th>result</th><th>killing run</th><th>correct run</th><th>changes</th>"
        "<th>stands for</th></tr>"
    )
    for f in [*report.faults, *report.mutants]:
        body.append(
            f"<tr data-fault='{html.escape(f.id)}' data-killed='{str(f.killed).lower()}'>"
            f"<td><code>{html.escape(f.id)}</code></td>"
            f"<td>{html.escape(fault_status(f, report.situations))}</td>"
            f"<td class='num'>{link(f.run)}</td><td class='num'>{link(f.correct_run)}</td>"
            f"<td>{html.escape(f.changes)}</td><td>{html.escape(f.stands_for)}</td></tr>"
        )
    body.append("</table></section>")
    return "".join(body)


DIFF_PAIRS_SHOWN = 6
"""Pairs shown side by side per distinct failure of a diff (the JSON has every one)."""


def diff_runs(report: DiffReport) -> list[int]:
    """The runs a diff's section shows side by side: A's and B's for each class's first
    :data:`DIFF_PAIRS_SHOWN` robust differences."""
    shown = [p for c in report.classes for p in _robust_pairs(c.pairs)[:DIFF_PAIRS_SHOWN]]
    return [r for p in shown for r in (p.a_run, p.b_run)]


def _robust_pairs(pairs: list[Pair]) -> list[Pair]:
    """Robust differences first (new in B, then fixed), then those not robust either way."""
    return sorted(pairs, key=lambda p: (p.verdict != NEW, p.verdict.startswith("not"), p.situation))


def _diff_section(report: DiffReport, pages: set[int], classes_of: dict[int, str | None]) -> str:
    """A controller diff's verdict: per distinct failure what B's change did, and its
    differing situations as A's run beside B's run, with their perturbed copies' counts."""

    def side(run_id: int, label: str) -> str:
        cls = classes_of.get(run_id) or "no failure"
        if run_id not in pages:
            return f"<div class='side'>{label}: run {run_id}, {html.escape(cls)}</div>"
        return (
            f"<div class='side'><a href='run-{run_id}.html'><img src='run-{run_id}.png' "
            f"loading='lazy' alt='situation figure of run {run_id}'></a><br>{label}: "
            f"<a href='run-{run_id}.html'>run {run_id}</a>, {html.escape(cls)}</div>"
        )

    body = ["<section id='diff'><h2>Controller diff</h2><p>"]
    body += [html.escape(line) + "<br>" for line in diff_summary_lines(report)]
    body.append(
        f"</p><p class='muted'>A is <code>{html.escape(controller_label(report.a))}</code>, B "
        f"is <code>{html.escape(controller_label(report.b))}</code>, on the same situations and "
        "run seeds. Where they differ in a failure class, the class is robustly new in B (or "
        "fixed) when B's perturbed copies show it significantly more often than A's (or "
        "fewer), by the kill rule's test (docs/failures.md).</p>"
    )
    body.append(
        "<table><tr><th>distinct failure</th><th>verdict</th><th>new in B</th><th>fixed</th>"
        "<th>unchanged</th><th>not robust</th></tr>"
    )
    for c in report.classes:
        body.append(
            f"<tr data-class='{html.escape(c.failure_class)}' data-verdict='"
            f"{html.escape(c.verdict)}'><td>{html.escape(c.description)}</td>"
            f"<td>{html.escape(c.verdict)}</td><td class='num'>{len(c.new)}</td>"
            f"<td class='num'>{len(c.fixed)}</td><td class='num'>{len(c.unchanged)}</td>"
            f"<td class='num'>{len(c.not_robust)}</td></tr>"
        )
    body.append("</table>")
    for c in report.classes:
        shown = _robust_pairs(c.pairs)[:DIFF_PAIRS_SHOWN]
        if not shown:
            continue
        body.append(f"<h3>{html.escape(c.description)}: {html.escape(c.verdict)}</h3>")
        for p in shown:
            body.append(
                f"<div class='pair' data-situation='{p.situation}' data-verdict='"
                f"{html.escape(p.verdict)}'><p>situation {p.situation}: "
                f"{html.escape(p.verdict)}; copies showing it: A {p.a_recurs}/{p.copies}, "
                f"B {p.b_recurs}/{p.copies}</p>{side(p.a_run, 'A')}{side(p.b_run, 'B')}</div>"
            )
        if len(c.pairs) > len(shown):
            body.append(f"<p class='muted'>and {len(c.pairs) - len(shown)} more situations.</p>")
    body.append("</section>")
    return "".join(body)


def _line_svg(
    element_id: str, points: list[tuple[float, float]], x_label: str, y_label: str
) -> str:
    """A line chart of ``points`` (x ascending) with its axes' ranges written at the ends."""
    width, height, pad = 640, 180, 40
    if not points:
        return "<p>No runs.</p>"
    xs, ys = [p[0] for p in points], [p[1] for p in points]
    x_hi, y_hi = max(max(xs), 1.0), max(max(ys), 1e-9)

    at = [
        (pad + (width - 2 * pad) * x / x_hi, height - (height - pad) * y / y_hi) for x, y in points
    ]
    line = " ".join(f"{u:.1f},{v:.1f}" for u, v in at)
    dots = "".join(
        f"<circle cx='{u:.1f}' cy='{v:.1f}' r='2.5' fill='#2c3e50'>"
        f"<title>{x:g} runs: {y:,.4g}</title></circle>"
        for (u, v), (x, y) in zip(at, points, strict=True)
    )
    return (
        f"<svg id='{element_id}' width='{width}' height='{height + 40}' role='img'>"
        f"<line x1='{pad}' y1='{height}' x2='{width - pad}' y2='{height}' stroke='#999'/>"
        f"<line x1='{pad}' y1='{pad}' x2='{pad}' y2='{height}' stroke='#999'/>"
        f"<polyline points='{line}' fill='none' stroke='#c0392b' stroke-width='2'/>{dots}"
        f"<text x='{pad - 4}' y='{pad + 4}' font-size='10' text-anchor='end'>{y_hi:,.4g}</text>"
        f"<text x='{pad - 4}' y='{height}' font-size='10' text-anchor='end'>0</text>"
        f"<text x='{width - pad}' y='{height + 14}' font-size='10' text-anchor='end'>"
        f"{x_hi:g}</text><text x='{width / 2}' y='{height + 30}' font-size='12' "
        f"text-anchor='middle'>{html.escape(x_label)}</text><text x='8' y='{pad - 10}' "
        f"font-size='12'>{html.escape(y_label)}</text></svg>"
    )


def _search_section(search: SearchReplay, pages: set[int]) -> str:
    """A search's archive as a grid of cells by its measures (each cell: its elite's run and
    objective, shaded by it on a log scale), then distinct failure classes and QD score over
    the budget."""
    archive = search.archive
    plan = archive.plan
    grid = elite_grid(archive)
    names = [m.name for m in archive.measures]
    labels = [m.labels for m in archive.measures]
    columns = labels[1] if len(labels) > 1 else ("",)
    filled = sum(cell is not None for row in grid for cell in row)
    top = max((c["objective"] for row in grid for c in row if c is not None), default=0.0)
    stats = archive.stats()
    body = [
        "<section id='search'><h2>Search</h2><p>",
        f"strategy <b>{html.escape(plan.strategy)}</b>, objective "
        f"<b>{html.escape(plan.objective)}</b>"
        + (f" ({plan.threshold:g} points)" if plan.objective == "threshold" else "")
        + f", {len(search.curve)} generations, {archive.told} runs; archive: {filled} of "
        f"{sum(len(r) for r in grid)} cells filled, QD score {stats.qd_score:,.1f}.</p>",
        f"<table id='archive' data-cells='{filled}'><tr><th>{html.escape(names[0])} \\ "
        f"{html.escape(names[1] if len(names) > 1 else '')}</th>",
    ]
    body += [f"<th>{html.escape(c)}</th>" for c in columns]
    body.append("</tr>")
    for label, row in zip(labels[0], grid, strict=True):
        body.append(f"<tr><th>{html.escape(label)}</th>")
        for col, cell in zip(columns, row, strict=True):
            if cell is None:
                body.append("<td class='empty'></td>")
                continue
            run_id = cell["run"]
            shade = math.log1p(cell["objective"]) / math.log1p(top) if top > 0 else 0.0
            link = f"<a href='run-{run_id}.html'>{run_id}</a>" if run_id in pages else str(run_id)
            body.append(
                f"<td class='num elite' data-run='{run_id}' data-row='{html.escape(label)}' "
                f"data-col='{html.escape(col)}' style='background: rgba(192, 57, 43, "
                f"{0.1 + 0.6 * shade:.2f})' title='{cell['objective']:,.1f}'>run {link}<br>"
                f"{cell['objective']:,.1f}</td>"
            )
        body.append("</tr>")
    body.append("</table>")
    curve = search.curve
    body.append("<h3>Failure classes found over the budget</h3>")
    body.append(
        _line_svg(
            "classes-curve",
            [(c["runs"], c["classes"]) for c in curve],
            "runs",
            "failure classes",
        )
    )
    body.append("<h3>QD score over the budget</h3>")
    body.append(
        _line_svg("qd-curve", [(c["runs"], c["qd_score"]) for c in curve], "runs", "QD score")
    )
    body.append("</section>")
    return "".join(body)


def _coverage_section(store: Store, pages: set[int]) -> str:
    """Situation coverage as a heat grid: rows interaction × clearance, columns terrain context
    × agent speed, one cell of the interaction space each, shaded by the runs that exercised it
    (log scale); a cell where a failure began is outlined and marked with how many, linking the
    most dangerous such run when it has a page."""
    runs, unobserved = stored(store)
    report = summarise(runs, unobserved)
    dims = dimensions()
    interaction, clearance, context, speed = (d.values for d in dims)
    hits = {c["cell"]: c["runs"] for c in report["cells"]}
    failed: dict[str, list[RunCoverage]] = {}
    for r in runs:
        if r.failure_cell is not None:
            failed.setdefault(r.failure_cell, []).append(r)
    top = max(hits.values(), default=0)
    body = [
        "<section id='coverage'><h2>Situation coverage</h2><p>",
        f"{report['covered']} of {report['total']} cells of the interaction space covered "
        f"({100 * report['ratio']:.1f}%) by {report['runs']} runs; "
        f"{sum(len(v) for v in failed.values())} failures began with a peer in a cell "
        "(outlined; the number is how many). Rows: interaction × clearance; columns: terrain "
        "context × agent speed (docs/coverage.md).</p>",
        f"<table id='coverage-grid' data-covered='{report['covered']}' "
        f"data-total='{report['total']}'><tr><th></th><th></th>",
    ]
    body += [f"<th colspan='{len(speed)}'>{html.escape(c)}</th>" for c in context]
    body.append("</tr><tr><th></th><th></th>")
    body += [f"<th class='speed'>{html.escape(v)}</th>" for _ in context for v in speed]
    body.append("</tr>")
    for i in interaction:
        for k, c in enumerate(clearance):
            body.append("<tr>")
            if k == 0:
                body.append(f"<th rowspan='{len(clearance)}'>{html.escape(i)}</th>")
            body.append(f"<th class='clearance'>{html.escape(c)}</th>")
            for x in context:
                for v in speed:
                    key = f"{i}/{c}/{x}/{v}"
                    n = hits.get(key, 0)
                    if not n:
                        body.append(f"<td class='uncovered' data-cell='{key}'></td>")
                        continue
                    shade = math.log1p(n) / math.log1p(top)
                    fails = failed.get(key, [])
                    title = f"{key}: {n} runs" + (
                        f", {len(fails)} failures began here" if fails else ""
                    )
                    mark = ""
                    if fails:
                        worst = max(fails, key=lambda r: (r.score, -r.id)).id
                        mark = (
                            f"<a href='run-{worst}.html'>{len(fails)}</a>"
                            if worst in pages
                            else str(len(fails))
                        )
                    body.append(
                        f"<td class='covered{' failed' if fails else ''}' data-cell='{key}' "
                        f"data-runs='{n}' style='background: rgba(39, 174, 96, "
                        f"{0.15 + 0.6 * shade:.2f})' title='{html.escape(title)}'>{mark}</td>"
                    )
            body.append("</tr>")
    body.append("</table></section>")
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
        body.append(_faults_section(faults, pages))
    if search is not None:
        body.append(_search_section(search, pages))
    if diff is not None:
        classes_of = {r["run"]: r["failure_class"] for r in rows}
        body.append(_diff_section(diff, pages, classes_of))
    shrunk = {
        run_id: json.loads(after)
        for run_id, after in store.db.execute("SELECT run_id, after FROM shrinks")
    }
    body.append(_distinct_section(failures, pages, ranks, len(rows), shrunk))
    body.append(_coverage_section(store, pages))
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


RUN_SCRIPT = """
<script>
(function () {
  const d = window.SITGEN_RUN;
  const canvas = document.getElementById('replay');
  const ctx = canvas.getContext('2d');
  const bytes = Uint8Array.from(atob(d.trajectory), c => c.charCodeAt(0));
  const poses = new Float32Array(bytes.buffer);
  const n = d.robots.length, frames = poses.length / (n * 3);
  const cells = Uint8Array.from(atob(d.map.cells), c => c.charCodeAt(0));
  const {rows, cols, res} = d.map;
  const scale = Math.max(1, Math.floor(800 / Math.max(rows, cols)));
  canvas.width = cols * scale; canvas.height = rows * scale;
  const background = document.createElement('canvas');
  background.width = cols; background.height = rows;
  const bctx = background.getContext('2d');
  const image = bctx.createImageData(cols, rows);
  for (let i = 0; i < rows * cols; i++) {
    const v = cells[i] ? 60 : 250;
    image.data.set([v, v, v, 255], 4 * i);
  }
  bctx.putImageData(image, 0, 0);
  const occupied = (c, r) => c < 0 || r < 0 || c >= cols || r >= rows || cells[r * cols + c] === 1;
  const px = (x, y) => [x / res * scale, (rows - y / res) * scale];
  function pose(f, i) { const k = (f * n + i) * 3; return [poses[k], poses[k + 1], poses[k + 2]]; }
  function rect(i, p) {
    const b = d.robots[i].body, c = Math.cos(p[2]), s = Math.sin(p[2]);
    return {cx: p[0] + c * b.origin_x_m, cy: p[1] + s * b.origin_x_m, c, s,
            hl: b.length_m / 2, hw: b.width_m / 2};
  }
  function rayGrid(ox, oy, dx, dy, max) {
    // The simulator's walk: cell by cell to the first occupied cell.
    let cu = Math.floor(ox / res), cw = Math.floor(oy / res);
    if (occupied(cu, rows - 1 - cw)) return 0;
    const su = dx > 0 ? 1 : -1, sw = dy > 0 ? 1 : -1;
    const du = dx !== 0 ? res / Math.abs(dx) : Infinity;
    const dw = dy !== 0 ? res / Math.abs(dy) : Infinity;
    let tu = dx > 0 ? ((cu + 1) * res - ox) / dx : dx < 0 ? (ox - cu * res) / -dx : Infinity;
    let tw = dy > 0 ? ((cw + 1) * res - oy) / dy : dy < 0 ? (oy - cw * res) / -dy : Infinity;
    for (;;) {
      let t;
      if (tu < tw) { cu += su; t = tu; tu += du; } else { cw += sw; t = tw; tw += dw; }
      if (t >= max) return max;
      if (cu < 0 || cw < 0 || cu >= cols || cw >= rows) return max;
      if (occupied(cu, rows - 1 - cw)) return t;
    }
  }
  function rayRect(q, ox, oy, dx, dy, max) {
    // Slab test in the rectangle's frame.
    const rx = ox - q.cx, ry = oy - q.cy;
    const lo = [rx * q.c + ry * q.s, -rx * q.s + ry * q.c];
    const ld = [dx * q.c + dy * q.s, -dx * q.s + dy * q.c];
    const h = [q.hl, q.hw];
    let t0 = 0, t1 = max;
    for (let a = 0; a < 2; a++) {
      if (Math.abs(ld[a]) < 1e-12) { if (Math.abs(lo[a]) > h[a]) return max; continue; }
      let ta = (-h[a] - lo[a]) / ld[a], tb = (h[a] - lo[a]) / ld[a];
      if (ta > tb) [ta, tb] = [tb, ta];
      t0 = Math.max(t0, ta); t1 = Math.min(t1, tb);
      if (t0 > t1) return max;
    }
    return t0;
  }
  const state = {frame: 0, playing: false, speed: 1};
  function draw() {
    const f = state.frame;
    ctx.drawImage(background, 0, 0, canvas.width, canvas.height);
    const agent = pose(f, 0);
    const laser = d.laser, others = [];
    for (let i = 1; i < n; i++) others.push(rect(i, pose(f, i)));
    ctx.strokeStyle = 'rgba(230, 60, 60, 0.35)'; ctx.lineWidth = 1;
    const fov = laser.fov_deg * Math.PI / 180, beams = laser.beams;
    const ox = agent[0] + Math.cos(agent[2]) * laser.offset_x_m;
    const oy = agent[1] + Math.sin(agent[2]) * laser.offset_x_m;
    ctx.beginPath();
    for (let b = 0; b < beams; b++) {
      const a = agent[2] - fov / 2 + (beams > 1 ? b * fov / (beams - 1) : fov / 2);
      const dx = Math.cos(a), dy = Math.sin(a);
      let t = rayGrid(ox, oy, dx, dy, laser.range_m);
      for (const q of others) t = Math.min(t, rayRect(q, ox, oy, dx, dy, t));
      const [x0, y0] = px(ox, oy), [x1, y1] = px(ox + t * dx, oy + t * dy);
      ctx.moveTo(x0, y0); ctx.lineTo(x1, y1);
    }
    ctx.stroke();
    for (let i = n - 1; i >= 0; i--) {
      const q = rect(i, pose(f, i));
      const corners = [[1, 1], [1, -1], [-1, -1], [-1, 1]].map(([a, b]) =>
        px(q.cx + a * q.hl * q.c - b * q.hw * q.s, q.cy + a * q.hl * q.s + b * q.hw * q.c));
      ctx.beginPath(); corners.forEach(([x, y], k) => k ? ctx.lineTo(x, y) : ctx.moveTo(x, y));
      ctx.closePath();
      ctx.fillStyle = i === 0 ? 'rgba(200, 30, 30, 0.85)' : 'rgba(30, 80, 200, 0.6)';
      ctx.fill();
    }
    const t = f * d.dt_s;
    document.getElementById('time').textContent = t.toFixed(1) + ' s';
    document.getElementById('scrub').value = f;
    canvas.dataset.frame = f;
    canvas.dataset.agent = agent[0].toFixed(3) + ',' + agent[1].toFixed(3);
  }
  let last = null;
  function tick(now) {
    if (!state.playing) { last = null; return; }
    if (last !== null) {
      const advance = Math.floor((now - last) / 1000 / d.dt_s * state.speed);
      if (advance > 0) {
        state.frame = Math.min(frames - 1, state.frame + advance); last = now; draw();
      }
    } else { last = now; }
    if (state.frame >= frames - 1) { state.playing = false; updateButton(); return; }
    requestAnimationFrame(tick);
  }
  const button = document.getElementById('play');
  function updateButton() { button.textContent = state.playing ? 'pause' : 'play'; }
  button.addEventListener('click', () => {
    if (state.frame >= frames - 1) state.frame = 0;
    state.playing = !state.playing; updateButton();
    if (state.playing) requestAnimationFrame(tick);
  });
  const scrub = document.getElementById('scrub');
  scrub.max = frames - 1;
  scrub.addEventListener('input', () => { state.frame = Number(scrub.value); draw(); });
  document.getElementById('speed').addEventListener('change', e => {
    state.speed = Number(e.target.value);
  });
  document.querySelectorAll('[data-seek]').forEach(el => el.addEventListener('click', () => {
    state.frame = Math.min(frames - 1, Math.round(Number(el.dataset.seek) / d.dt_s)); draw();
  }));
  window.sitgenReplay = {state, draw, frames};
  draw();
})();
</script>
"""


def _timeline_svg(
    events: list[dict[str, Any]], end_s: float, deciding: frozenset[int] = frozenset()
) -> str:
    """One lane per event kind: lasting events as bars, instant ones as ticks; click to seek.
    The events that decided the run's failure class (positions in ``events``) are outlined."""
    kinds = [k for k in EVENT_COLOURS if any(e["kind"] == k for e in events)]
    kinds += sorted({e["kind"] for e in events} - set(kinds))
    width, lane, left = 900, 22, 130
    height = lane * max(1, len(kinds)) + 30
    span = max(end_s, 1e-9)
    scale = (width - left - 10) / span
    parts = [f"<svg id='timeline' width='{width}' height='{height}' role='img'>"]
    for j, kind in enumerate(kinds):
        y = j * lane + 4
        parts.append(f"<text x='0' y='{y + 13}' font-size='12'>{kind}</text>")
        colour = f"rgb{EVENT_COLOURS.get(kind, (40, 140, 60))}"
        for i, e in ((i, e) for i, e in enumerate(events) if e["kind"] == kind):
            x = left + e["start_s"] * scale
            w = max(2.0, ((e["end_s"] or e["start_s"]) - e["start_s"]) * scale)
            opacity = 1.0 if e["scored"] else 0.35
            tip = html.escape(f"{e['start_s']:.1f} s, robot {e['robot']}, {kind}")
            outline = ""
            if i in deciding:
                tip += " (decided the failure class)"
                outline = " stroke='#000' stroke-width='1.5' class='deciding'"
            parts.append(
                f"<rect x='{x:.1f}' y='{y}' width='{w:.1f}' height='{lane - 6}' fill='{colour}' "
                f"opacity='{opacity}' data-seek='{e['start_s']}' data-event='{i}'{outline}>"
                f"<title>{tip}</title></rect>"
            )
    axis_y = height - 12
    parts.append(f"<line x1='{left}' y1='{axis_y}' x2='{width - 10}' y2='{axis_y}' stroke='#999'/>")
    for k in range(6):
        t = span * k / 5
        parts.append(
            f"<text x='{left + t * scale:.1f}' y='{axis_y + 11}' font-size='10' "
            f"text-anchor='middle'>{t:.0f} s</text>"
        )
    parts.append("</svg>")
    return "".join(parts)


def run_page(
    store: Store,
    run_id: int,
    rank: int,
    out: Path,
    db_name: str,
    distinct: DistinctFailure | None = None,
    blind: bool = False,
) -> tuple[str, str] | None:
    """The page and its data script for one run; None if the run has no situation.
    ``distinct`` is the distinct failure the run belongs to, if any. ``blind`` leaves out its
    rank, score and breakdown (for judging runs by what happened, not by what they scored)."""
    row = stored_run(store, run_id)
    # Shown as it was run, even where an older sitgen placed a robot across the map's edge; a
    # run kept as a summary is re-simulated.
    whole = whole_run(store, row)
    if whole is None or whole.trajectory is None:
        return None
    situation, trajectory = whole.situation, whole.trajectory
    events = [json.loads(line) for line in whole.events_jsonl.splitlines()]
    breakdown = json.loads(
        store.db.execute("SELECT breakdown FROM runs WHERE id = ?", (run_id,)).fetchone()[0]
    )
    reason = store.db.execute("SELECT reason FROM runs WHERE id = ?", (run_id,)).fetchone()[0]
    sim = row["run_spec"].get("sim", {})
    dt_s = float(sim.get("dt_s", 0.1))
    laser = {"fov_deg": 180.0, "beams": 181, "range_m": 10.0, "offset_x_m": 0.0}
    laser.update({k: v for k, v in sim.get("laser", {}).items() if k in laser})
    save_situation_figure(situation, out / f"run-{run_id}.png", trajectory, events, dt_s)
    grid = situation.grid
    data = {
        "run": run_id,
        "dt_s": dt_s,
        "map": {
            "rows": int(grid.occupied.shape[0]),
            "cols": int(grid.occupied.shape[1]),
            "res": grid.resolution,
            "cells": base64.b64encode(grid.occupied.astype(np.uint8).tobytes()).decode(),
        },
        "robots": [{"id": r.id, "role": r.role, "body": r.body} for r in situation.robots],
        "laser": laser,
        "trajectory": base64.b64encode(trajectory.astype("<f4").tobytes()).decode(),
    }
    script = "window.SITGEN_RUN = " + json.dumps(data, separators=(",", ":")) + ";\n"
    end_s = (len(trajectory) - 1) * dt_s
    body = (
        [f"<h1>Run {run_id}</h1>"]
        if blind
        else [f"<p><a href='index.html'>← all runs</a></p><h1>Run {run_id} (rank {rank})</h1>"]
    )
    score = "" if blind else f"score <b>{row['score']:.1f}</b>, "
    body.append(
        f"<p>{score}outcome <b>{row['outcome']}</b> "
        f"({html.escape(reason)}),"
        f" {end_s:.1f} s, controller <code>{html.escape(row['controller'])}</code>,"
        f" {len(situation.robots) - 1} peers, situation seed {row['situation_seed']}</p>"
    )
    failure = row["failure"]
    deciding = frozenset(
        i for i in (failure or {}).get("events", []) if isinstance(i, int) and 0 <= i < len(events)
    )
    body.append(_failure_section(failure, events, distinct, run_id))
    if failure is not None and not blind:
        body.append(_run_robustness(store.robustness([run_id]).get(run_id)))
    if not blind:
        body.append(_why_this_rank(breakdown, row["score"]))
    body.append("<h2>Replay</h2><p class='controls'><button id='play'>play</button>")
    body.append("speed <select id='speed'>")
    body += [
        f"<option value='{s}'{' selected' if s == 1 else ''}>{s}×</option>"
        for s in (1, 2, 5, 10, 20, 50)
    ]
    body.append(
        "</select><input id='scrub' type='range' min='0' value='0' step='1'> "
        "<span id='time'>0.0 s</span></p><canvas id='replay'></canvas>"
    )
    body.append(
        "<p>Agent red, peers blue; the agent's laser rays drawn from the map and poses.</p>"
    )
    body.append("<h2>Timeline</h2>" + _timeline_svg(events, end_s, deciding))
    body.append("<h2>Situation</h2>")
    body.append(
        f"<img class='figure' src='run-{run_id}.png' alt='situation figure of run {run_id}'>"
    )
    body.append(
        "<p>Starts are squares, goals circles, the agent filled, peers hollow; thin lines the "
        "driven paths; ✕ collision, ○ unsafe proximity, ◇ loitering, ■ timeout.</p>"
    )
    body.append("<h2>Event log</h2><pre id='events'>")
    body.append(
        "\n".join(
            f"<mark id='event-{i}' title='decided the failure class'>{html.escape(line)}</mark>"
            if i in deciding
            else html.escape(line)
            for i, line in enumerate(_event_line(e) for e in events)
        )
        + "</pre>"
    )
    if deciding:
        body.append("<p>Marked: the events that decided the failure class.</p>")
    if blind:
        scripts = f"<script src='run-{run_id}.js'></script>{RUN_SCRIPT}"
        return _page(f"sitgen run {run_id}", "".join(body), scripts), script
    body.append(_minimal_section(store, run_id, out))
    body.append(
        f"<h2>Rerun</h2><p><code>sitgen rerun {html.escape(db_name)} {run_id}</code> regenerates "
        "the situation from its spec and seed, runs it again and confirms the same event log."
        "</p>"
    )
    scripts = f"<script src='run-{run_id}.js'></script>{RUN_SCRIPT}"
    return _page(f"sitgen run {run_id}", "".join(body), scripts), script


def _why_this_rank(breakdown: dict[str, Any], score: float) -> str:
    """The score's breakdown by event kind, and the points of the run's failure class where
    the scoring gives some (the rest of the score)."""
    body = ["<h2>Why this rank</h2><table id='breakdown'>"]
    body.append("<tr><th>event</th><th>count</th><th>seconds</th><th>points</th></tr>")
    ordered = sorted(breakdown.items(), key=lambda kv: -kv[1]["points"])
    for kind, line in ordered:
        body.append(
            f"<tr><td>{kind}</td><td class='num'>{line['count']}</td>"
            f"<td class='num'>{line['seconds']:.1f}</td>"
            f"<td class='num'>{line['points']:.1f}</td></tr>"
        )
    class_points = score - sum(line["points"] for line in breakdown.values())
    if abs(class_points) > 1e-6 * max(1.0, abs(score)):
        body.append(
            "<tr><td>its failure class</td><td></td><td></td>"
            f"<td class='num'>{class_points:.1f}</td></tr>"
        )
    body.append(f"</table><p>{html.escape(main_events(breakdown)) or 'no scored events'}</p>")
    return "".join(body)


def _minimal_section(store: Store, run_id: int, out: Path) -> str:
    """The run's shrink, if the store keeps one: what shrank, the minimal situation's figure
    (with its run), and the files and command that rerun it."""
    shrunk = store.shrink(run_id)
    if shrunk is None:
        return ""

    name = f"run-{run_id}-min"
    minimal = Situation(shrunk["situation"])
    minimal.save(out / f"{name}.json")
    (out / f"{name}.run.json").write_text(json.dumps(shrunk["run_spec"], indent=2) + "\n")
    record = run(minimal, seed=shrunk["run_seed"], spec=shrunk["run_spec"])
    dt_s = float(shrunk["run_spec"].get("sim", {}).get("dt_s", 0.1))
    save_situation_figure(minimal, out / f"{name}.png", record.trajectory, record.events, dt_s)
    a, b = shrunk["before"], shrunk["after"]
    rows = [
        ("peers", a["peers"], b["peers"]),
        ("obstacle cells", a["obstacle_cells"], b["obstacle_cells"]),
        ("route length", f"{a['route_length_m']:.1f} m", f"{b['route_length_m']:.1f} m"),
        (
            "time to failure",
            f"{a['time_to_failure_s']:.1f} s",
            f"{b['time_to_failure_s']:.1f} s",
        ),
        ("map", "{:g} × {:g} m".format(*a["map_m"]), "{:g} × {:g} m".format(*b["map_m"])),
    ]
    table = "".join(
        f"<tr><td>{what}</td><td class='num'>{x}</td><td class='num'>{y}</td></tr>"
        for what, x, y in rows
    )
    command = f"sitgen run {name}.json --spec {name}.run.json --seed {shrunk['run_seed']}"
    return (
        f"<section id='minimal'><h2>Minimal repro</h2><p>The smallest situation found that "
        f"still fails as <b>{html.escape(shrunk['failure_class'])}</b> with the same controller "
        f"and run spec ({shrunk['probes']} probes, docs/shrink.md):</p>"
        f"<table><tr><th></th><th>before</th><th>after</th></tr>{table}</table>"
        f"<img class='figure' src='{name}.png' alt='minimal situation of run {run_id}'>"
        f"<p><a href='{name}.json'>{name}.json</a>, <a href='{name}.run.json'>{name}.run.json"
        f"</a>; in this folder: <code>{html.escape(command)}</code></p></section>"
    )


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


def _run_robustness(measured: dict[str, Any] | None) -> str:
    """A run page's robustness paragraph: robust or knife-edge, with every copy's class."""
    if measured is None:
        return (
            "<p id='robustness' data-robust=''>Robustness: not measured "
            "(<code>sitgen robustness DB RUN</code> reruns it under perturbation).</p>"
        )
    recurs, reruns = measured["recurs"], measured["reruns"]
    word = verdict(recurs, reruns)
    copies = "".join(
        f"<li>copy {k}: <code>{html.escape(c or 'no failure')}</code></li>"
        for k, c in enumerate(measured["classes"], 1)
    )
    return (
        f"<p id='robustness' class='{word}' data-robust='{str(word == 'robust').lower()}' "
        f"data-recurs='{recurs}' data-reruns='{reruns}'>Robustness: <b>{word}</b>, its class "
        f"recurs in {recurs} of {reruns} reruns under perturbations a real robot would not "
        "notice (laser noise, starts jittered by a centimetre and half a degree).</p>"
        f"<details><summary>each rerun's class</summary><ul id='rerun-classes'>{copies}</ul>"
        "</details>"
    )


FEATURE_WORDS = {
    "count": ("deciding events", "{}"),
    "start_s": ("the first began at", "{:.1f} s"),
    "seconds": ("they lasted, in all", "{:.1f} s"),
    "bearing": ("the other party came from the", "{}"),
    "agent_mean_speed_m_s": ("the agent's mean speed", "{:.2f} m/s"),
    "closing_speed_m_s": ("closing speed", "{:.2f} m/s"),
}
"""How a failure's features read on a run page: words, and the value's format."""


def _failure_section(
    failure: dict[str, Any] | None,
    events: list[dict[str, Any]],
    distinct: DistinctFailure | None,
    run_id: int,
) -> str:
    """The run's failure class in words and why: its sentence, the features of its deciding
    events, and those events of the log by position."""
    body = ["<h2>Failure class</h2>"]
    if failure is None:
        body.append(
            "<p id='failure' data-class=''>Failure: <b>no failure</b> (no scored event put this "
            "run in a failure class).</p>"
        )
        return "".join(body)
    key = str(failure.get("class", ""))
    sentence = str(failure.get("description") or key)
    body.append(
        f"<p id='failure' data-class='{html.escape(key)}'>Failure: <b>{html.escape(sentence)}</b>"
        f" (class <code>{html.escape(key)}</code>).</p>"
    )
    if distinct is not None:
        role = (
            "its representative"
            if distinct.representative == run_id
            else f"represented by <a href='run-{distinct.representative}.html'>run "
            f"{distinct.representative}</a>"
        )
        body.append(
            f"<p id='distinct-failure' data-key='{html.escape(distinct.key)}'>One of "
            f"{distinct.runs} runs of the distinct failure “{html.escape(distinct.description)}”"
            f", {role}.</p>"
        )
    features = failure.get("features") or {}
    if features:
        body.append("<table id='failure-features'>")
        order = list(FEATURE_WORDS)
        for name, value in sorted(
            features.items(), key=lambda kv: (order.index(kv[0]) if kv[0] in order else 99, kv[0])
        ):
            words, fmt = FEATURE_WORDS.get(name, (name.replace("_", " "), "{}"))
            try:
                shown = fmt.format(value)
            except (TypeError, ValueError):
                shown = str(value)
            body.append(f"<tr><td>{html.escape(words)}</td><td>{html.escape(shown)}</td></tr>")
        body.append("</table>")
    positions = [
        i for i in failure.get("events", []) if isinstance(i, int) and 0 <= i < len(events)
    ]
    if positions:
        body.append("<p>Decided by these events of the log (by position; click to seek):</p>")
        body.append("<pre id='failure-events'>")
        body.append(
            "\n".join(
                f"<span data-event='{i}' data-seek='{events[i]['start_s']}'>"
                f"{html.escape(f'#{i:<4}' + _event_line(events[i]))}</span>"
                for i in positions
            )
        )
        body.append("</pre>")
    else:
        body.append("<p>No events of the log are named as deciding it.</p>")
    return "".join(body)


def _event_line(e: dict[str, Any]) -> str:
    end = f"–{e['end_s']:.1f}" if e["end_s"] is not None else ""
    other = f" with {e['other']}" if e["other"] is not None else ""
    scored = "" if e["scored"] else " (not scored)"
    return f"{e['start_s']:7.1f}{end} s  robot {e['robot']}  {e['kind']}{other}{scored}"


def write_report(
    db: str | Path,
    out: str | Path,
    top: int = 50,
    weights: Weights | None = None,
    weights_name: str = "",
) -> list[Path]:
    """Write the report of campaign store ``db`` into ``out``; returns the pages written. The
    ``top`` runs get a page, and so does every distinct failure's representative. With
    ``weights`` (read from ``weights_name``) every score is rescored by them."""
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
