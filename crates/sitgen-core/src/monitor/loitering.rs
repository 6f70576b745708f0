//! # `loitering` event
//!
//! **What it detects.** A robot that has not finished its route and that has stayed within a
//! small area for `loitering_window_s`: every position of the window lies in a box whose
//! diagonal (the window's *extent*) is below `loitering_distance_m`. The event starts where
//! that window began (when the robot stopped getting anywhere), and lasts until the extent of
//! the window is large enough again. Turning on the spot, oscillating between two gaps and
//! pushing against a wall all loiter; driving out to a waypoint and back along the same line
//! does not (net displacement would call that loitering), nor does a robot that has completed
//! its route. Details: `extent_m`, the smallest extent of a window while it lasted.
//!
//! **Why it matters.** A robot that makes no progress is stuck, deadlocked or dithering (the
//! paper's run 219: SND alternating between two gaps); it blocks whoever shares its space and
//! fails its mission.
//!
//! **Parameters.** `monitor.loitering_distance_m` (metres, default 1.0) and
//! `monitor.loitering_window_s` (seconds, default 20): less than 5 cm/s of progress over 20 s,
//! far below any useful pace yet above the crawl of a robot squeezing through a gap, so slow
//! but real progress is not flagged.
//!
//! **Example.** `   40.0 s  agent    loitering within 0.31 m for 20 s, 35.2 s`
//!
//! **Source.** Arnold & Alexander (2013) §3 ("the daemon … can detect loitering").

use std::collections::VecDeque;

use serde_json::json;

use super::{details, Event, EventKind, Frame, Log};
use crate::sim::RobotState;

/// The least (or greatest) of a sliding window of values, in amortised O(1) per step: a
/// deque of (step, value) whose values only get worse toward the back.
#[derive(Debug, Default)]
struct Extreme {
    deque: VecDeque<(u64, f64)>,
}

impl Extreme {
    /// Add `value` at `step` and forget steps before `oldest`; `better(a, b)`: a beats b.
    fn push(&mut self, step: u64, value: f64, oldest: u64, better: fn(f64, f64) -> bool) -> f64 {
        while self.deque.back().is_some_and(|&(_, v)| !better(v, value)) {
            self.deque.pop_back();
        }
        self.deque.push_back((step, value));
        while self.deque.front().is_some_and(|&(s, _)| s < oldest) {
            self.deque.pop_front();
        }
        self.deque.front().expect("just pushed").1
    }
}

fn less(a: f64, b: f64) -> bool {
    a < b
}
fn greater(a: f64, b: f64) -> bool {
    a > b
}

/// The bounding box of one robot's positions over a sliding window (shared with
/// [`super::oscillation`]).
#[derive(Debug, Default)]
pub(super) struct Window {
    min_x: Extreme,
    max_x: Extreme,
    min_y: Extreme,
    max_y: Extreme,
}

impl Window {
    /// Add the position at `step`; returns the diagonal of the box since `oldest`.
    pub(super) fn extent(&mut self, step: u64, (x, y): (f64, f64), oldest: u64) -> f64 {
        let w = self.max_x.push(step, x, oldest, greater) - self.min_x.push(step, x, oldest, less);
        let h = self.max_y.push(step, y, oldest, greater) - self.min_y.push(step, y, oldest, less);
        (w * w + h * h).sqrt()
    }
}

#[derive(Debug)]
pub(super) struct Detector {
    distance_m: f64,
    window_s: f64,
    window_steps: u64,
    windows: Vec<Window>,
    /// Each robot's open event (its index in the log) and the step its last event ended.
    open: Vec<Option<usize>>,
    last_end: Vec<u64>,
}

impl Detector {
    pub(super) fn new(robots: &[RobotState], distance_m: f64, window_s: f64, dt_s: f64) -> Self {
        let window_steps = ((window_s / dt_s) - 1e-9).ceil().max(1.0) as u64;
        let windows = robots
            .iter()
            .map(|r| {
                let mut w = Window::default();
                w.extent(0, (r.pose.x_m, r.pose.y_m), 0);
                w
            })
            .collect();
        Self {
            distance_m,
            window_s,
            window_steps,
            windows,
            open: vec![None; robots.len()],
            last_end: vec![0; robots.len()],
        }
    }

    pub(super) fn observe(&mut self, frame: &Frame<'_>, done: &[bool], log: &mut Log) {
        let full = frame.step >= self.window_steps;
        let oldest = frame.step.saturating_sub(self.window_steps);
        for r in frame.robots() {
            let i = r.id as usize;
            let extent = self.windows[i].extent(frame.step, (r.pose.x_m, r.pose.y_m), oldest);
            let loitering = full && !done[i] && extent < self.distance_m;
            match (self.open[i], loitering) {
                (None, true) => {
                    let began = oldest.max(self.last_end[i]);
                    self.open[i] = Some(log.open(
                        EventKind::Loitering,
                        began,
                        r.id,
                        None,
                        details([
                            ("extent_m", json!(extent)),
                            ("window_s", json!(self.window_s)),
                        ]),
                    ));
                }
                (Some(index), true) => {
                    let least = log.events[index].detail_f64("extent_m").min(extent);
                    log.set(index, "extent_m", json!(least));
                }
                (Some(index), false) => {
                    log.close(index, frame.step);
                    self.last_end[i] = frame.step;
                    self.open[i] = None;
                }
                (None, false) => {}
            }
        }
    }

    pub(super) fn finish(&mut self, step: u64, log: &mut Log) {
        for index in self.open.iter_mut().filter_map(Option::take) {
            log.close(index, step);
        }
    }
}

/// The text of a loitering event.
pub(super) fn describe(e: &Event) -> String {
    format!(
        "loitering within {:.2} m for {} s",
        e.detail_f64("extent_m"),
        e.detail_f64("window_s")
    )
}
