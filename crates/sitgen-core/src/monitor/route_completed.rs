//! # `route_completed` event
//!
//! **What it detects.** A robot reaching the last waypoint of its route, having reached every
//! one before it in order (see [`waypoint_reached`](super::waypoint_reached)). Instant, once
//! per run. The agent completing its route ends the run with outcome `completed`. Details:
//! `waypoints` (how many), `driven_m` (path length driven from the start, metres).
//!
//! **Why it matters.** The mission succeeded; with its time and driven length, how efficiently.
//!
//! **Parameters.** `monitor.waypoint_radius_m` (see `waypoint_reached`).
//!
//! **Example.** `   96.2 s  agent    completed route, 5 waypoints, 43.20 m driven`
//!
//! **Source.** Arnold & Alexander (2013) §3 ("route completion").

use serde_json::json;

use super::{details, Event, EventKind, Log};

/// Log that robot `robot` completed its route of `waypoints` at `step` after driving `driven_m`.
pub(super) fn record(log: &mut Log, step: u64, robot: u32, waypoints: usize, driven_m: f64) {
    log.open(
        EventKind::RouteCompleted,
        step,
        robot,
        None,
        details([
            ("waypoints", json!(waypoints)),
            ("driven_m", json!(driven_m)),
        ]),
    );
}

/// The text of a route-completed event.
pub(super) fn describe(e: &Event) -> String {
    format!(
        "completed route, {} waypoints, {:.2} m driven",
        e.detail_f64("waypoints"),
        e.detail_f64("driven_m")
    )
}
