"""The report index's sections for what a store holds besides its runs: a fault evaluation's
kills, a search's archive and curves, a diff's verdicts with A's run beside B's, and the
situation coverage of the runs. Each is one HTML fragment of ``index.html``
(:mod:`sitgen.presentation.report` puts them together), linking the run pages it names.
"""

from __future__ import annotations

import html
import math

from sitgen.generation.diff import NEW
from sitgen.generation.diff_report import DiffReport, Pair, controller_label
from sitgen.generation.diff_report import summary_lines as diff_summary_lines
from sitgen.generation.fault_report import (
    FaultReport,
    fault_status,
    summary_lines,
)
from sitgen.generation.search import SearchReplay
from sitgen.generation.search.archive import elite_grid
from sitgen.store import Store
from sitgen.triage.coverage import RunCoverage, dimensions, stored, summarise


def faults_section(report: FaultReport, pages: set[int]) -> str:
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


def diff_section(report: DiffReport, pages: set[int], classes_of: dict[int, str | None]) -> str:
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


def search_section(search: SearchReplay, pages: set[int]) -> str:
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


def coverage_section(store: Store, pages: set[int]) -> str:
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
