"""A run's page of the report: its figure, failure class in words, event timeline that seeks
the replay, score breakdown, robustness, minimal repro, and the replay itself (footprints,
laser rays)."""

from __future__ import annotations

import base64
import html
import json
from pathlib import Path
from typing import Any

import numpy as np

from sitgen.presentation.avoidability_plot import avoidability_section
from sitgen.presentation.page import _page, time_axis
from sitgen.presentation.requirement_plot import requirements_section
from sitgen.run import run
from sitgen.store import Store, main_events
from sitgen.triage.failures import DistinctFailure
from sitgen.triage.recall import stored_run, whole_run
from sitgen.triage.robustness import verdict
from sitgen.world.figure import EVENT_COLOURS, save_situation_figure
from sitgen.world.situation import Situation

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
    parts += time_axis(left, width - 10, height - 12, span, scale)
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
    events = [store.stored_json(run_id, "events", line) for line in whole.events_jsonl.splitlines()]
    breakdown = store.stored_json(
        run_id,
        "breakdown",
        store.db.execute("SELECT breakdown FROM runs WHERE id = ?", (run_id,)).fetchone()[0],
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
    cost = store.costs([run_id]).get(run_id)
    if cost is not None and not blind:
        body.append(
            f"<p id='cost' data-wall-s='{cost[0]:.3f}' data-cpu-s='{cost[1]:.3f}'>It cost "
            f"{cost[1]:.2f} s of processor time and {cost[0]:.2f} s of wall time to run "
            "(the machine's figures, not the run's).</p>"
        )
    failure = row["failure"]
    deciding = frozenset(
        i for i in (failure or {}).get("events", []) if isinstance(i, int) and 0 <= i < len(events)
    )
    body.append(_failure_section(failure, events, distinct, run_id))
    if failure is not None and not blind:
        body.append(_run_robustness(store.robustness([run_id]).get(run_id)))
    judged = store.avoidability([run_id]).get(run_id)
    body.append(avoidability_section(judged, situation, trajectory, dt_s))
    if not blind:
        body.append(_why_this_rank(breakdown, row["score"]))
    body.append(requirements_section(store, row))
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
    body.append(_rosbag_section(db_name, run_id, out))
    scripts = f"<script src='run-{run_id}.js'></script>{RUN_SCRIPT}"
    return _page(f"sitgen run {run_id}", "".join(body), scripts), script


def _rosbag_section(db_name: str, run_id: int, out: Path) -> str:
    """Where the run's rosbag2 is (the report writes one for its top runs), or how to get it."""
    bag = f"rosbag2/run-{run_id}"
    if (out / bag / "metadata.yaml").is_file():
        return (
            f"<h2>ROS 2</h2><p>The run as a rosbag2 (MCAP): <a href='{bag}/metadata.yaml'>{bag}"
            f"</a>; <code>ros2 bag play {bag}</code>, or open it in Foxglove or Lichtblick.</p>"
        )
    return (
        f"<h2>ROS 2</h2><p><code>sitgen export {html.escape(db_name)} --run {run_id} --format "
        f"rosbag2 -o run-{run_id}-bag</code> writes the run as a rosbag2 (MCAP) for "
        "<code>ros2 bag play</code>, Foxglove or Lichtblick.</p>"
    )


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
