"""The comparison page of ``sitgen compare`` (``DIR/comparison.html``): each controller's
failure rate with its exact 95 % interval drawn as a bar, its distinct failures (robust ones
marked, those no other controller showed listed), time to goal and path efficiency; then the
pairwise exact McNemar tests on the same situations as a matrix a reader scans for the cells
that differ. Each controller's own store reads as any campaign's (``sitgen report``)."""

from __future__ import annotations

import html
from typing import Any

from sitgen.presentation.page import _page

BAR_PX = 300


def comparison_page(result: dict[str, Any], command: str) -> str:
    """The page for a :func:`sitgen.generation.compare.comparison` ``result``, made by
    ``command``."""
    sides = result["controllers"]
    body = [
        "<h1>Controllers compared on the same situations</h1>",
        f"<p>Made by <code>{html.escape(command)}</code>. Failure rate: runs with a failure "
        "class, errors left out, with its exact 95 % (Clopper–Pearson) interval; pairs: the "
        f"exact McNemar test on the situations both ran, a difference below p = {result['alpha']}."
        "</p>",
        "<table id='controllers'><thead><tr><th>controller</th><th>runs</th>"
        "<th>failure rate</th><th></th><th>distinct (robust)</th><th>median time to goal</th>"
        "<th>path efficiency</th><th>only it showed</th></tr></thead><tbody>",
    ]
    for s in sides:
        low, high = s["interval"]
        time = s["median_time_to_goal_s"]
        efficiency = s["median_path_efficiency"]
        body.append(
            f"<tr data-controller='{html.escape(s['label'])}'><td>{html.escape(s['label'])}</td>"
            f"<td>{s['runs']}</td>"
            f"<td>{100 * s['failure_rate']:.1f} % ({100 * low:.1f}–{100 * high:.1f} %)</td>"
            f"<td>{_bar(s['failure_rate'], low, high)}</td>"
            f"<td>{len(s['distinct'])} ({len(s['robust'])})</td>"
            f"<td>{'' if time is None else f'{time:.1f} s'}</td>"
            f"<td>{'' if efficiency is None else f'{efficiency:.2f}'}</td>"
            f"<td>{html.escape(', '.join(s['only']))}</td></tr>"
        )
    body.append("</tbody></table>")
    labels = [s["label"] for s in sides]
    cell = {(p["a"], p["b"]): p for p in result["pairs"]}
    body.append(
        "<h2>Pairs</h2><p>Row against column: the situations where only the row's controller "
        "failed, and where only the column's did; highlighted where the test finds a "
        "difference.</p><table id='pairs'><thead><tr><th></th>"
        + "".join(f"<th>{html.escape(b)}</th>" for b in labels)
        + "</tr></thead><tbody>"
    )
    for a in labels:
        row = [f"<tr><th>{html.escape(a)}</th>"]
        for b in labels:
            p = cell.get((a, b))
            flipped = p is None and (b, a) in cell
            p = p or cell.get((b, a))
            if p is None:
                row.append("<td></td>")
                continue
            mine, theirs = (p["b_only"], p["a_only"]) if flipped else (p["a_only"], p["b_only"])
            differs = p["verdict"] != "no difference"
            row.append(
                f"<td class='{'differs' if differs else 'same'}' "
                f"title='{html.escape(p['verdict'])}, p = {p['p_value']:.3g}'>"
                f"{mine} / {theirs}{' *' if differs else ''}</td>"
            )
        body.append("".join(row) + "</tr>")
    body.append(
        "</tbody></table><p>* the test finds a difference (p below the level).</p>"
        "<style>td.differs{background:#fde2e2;font-weight:bold}</style>"
    )
    body.append("<h2>Each controller's failures</h2><ul>")
    for s in sides:
        body.append(
            f"<li><b>{html.escape(s['label'])}</b>: "
            + (html.escape(", ".join(s["distinct"])) or "none")
            + f" — <code>sitgen failures {html.escape(s['label'])}.db</code>, "
            f"<code>sitgen report {html.escape(s['label'])}.db</code></li>"
        )
    body.append("</ul>")
    return _page("sitgen compare", "".join(body))


def _bar(rate: float, low: float, high: float) -> str:
    """The rate as a dot on its interval, 0–100 % over ``BAR_PX`` pixels."""

    def x(v: float) -> float:
        return 5 + v * BAR_PX

    return (
        f"<svg class='rate' width='{BAR_PX + 10}' height='14' role='img'>"
        f"<line x1='5' y1='7' x2='{BAR_PX + 5}' y2='7' stroke='#ddd'/>"
        f"<line x1='{x(low):.1f}' y1='7' x2='{x(high):.1f}' y2='7' stroke='#555' "
        "stroke-width='3'/>"
        f"<circle cx='{x(rate):.1f}' cy='7' r='4' fill='#c81e1e'/></svg>"
    )
