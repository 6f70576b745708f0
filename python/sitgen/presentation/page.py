"""The HTML pages' frame: the report's style sheet and the page every report page is written in."""

from __future__ import annotations

import html

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


def time_axis(left: float, right: float, y: float, span: float, scale: float) -> list[str]:
    """An SVG time axis from ``left`` to ``right`` pixels at height ``y``, six ticks labelled
    in seconds over ``span`` seconds at ``scale`` pixels a second (a run page's timeline and
    its requirements' plots)."""
    parts = [f"<line x1='{left}' y1='{y}' x2='{right}' y2='{y}' stroke='#999'/>"]
    for k in range(6):
        t = span * k / 5
        parts.append(
            f"<text x='{left + t * scale:.1f}' y='{y + 11}' font-size='10' "
            f"text-anchor='middle'>{t:.0f} s</text>"
        )
    return parts
