//! # `timeout` event
//!
//! **What it detects.** The agent's route not completed when the run's time limit is reached.
//! Instant, at the time limit; the run's outcome is then `timeout`. Details: `reached` and `of`
//! (waypoints reached, waypoints on the route).
//!
//! **Why it matters.** A mission failure even without an accident: the robot got stuck, lost
//! its way, or was too slow; together with `loitering` it tells which.
//!
//! **Parameters.** The run's `time_limit_s` (simulated seconds, default 600).
//!
//! **Example.** `  600.0 s  agent    timeout, 2 of 5 waypoints reached`
//!
//! **Source.** Arnold & Alexander (2013) §4.2 (each run was stopped after a fixed time).

use serde_json::json;

use super::{details, Event, EventKind, Log};

/// Log that `robot` timed out at `step` having reached `reached` of `of` waypoints.
pub(super) fn record(log: &mut Log, step: u64, robot: u32, reached: usize, of: usize) {
    log.open(
        EventKind::Timeout,
        step,
        robot,
        None,
        details([("reached", json!(reached)), ("of", json!(of))]),
    );
}

/// The text of a timeout event.
pub(super) fn describe(e: &Event) -> String {
    format!(
        "timeout, {} of {} waypoints reached",
        e.detail_f64("reached"),
        e.detail_f64("of")
    )
}
