//! # `loitering` event
//!
//! **What it detects.** A robot that has not finished its route and whose net progress — the
//! straight-line distance between where it is and where it was `loitering_window_s` ago — is
//! below `loitering_distance_m`. The event starts where that window began (when the robot
//! stopped getting anywhere), and lasts until its net progress over the window is enough
//! again. Turning on the spot, oscillating between two gaps and pushing against a wall all
//! loiter; a robot that has completed its route does not. Details: `net_progress_m`, the
//! smallest net progress over a window while it lasted.
//!
//! **Why it matters.** A robot that makes no progress is stuck, deadlocked or dithering (the
//! paper's run 219: SND alternating between two gaps); it blocks whoever shares its space and
//! fails its mission.
//!
//! **Parameters.** `monitor.loitering_distance_m` (metres, default 1.0) and
//! `monitor.loitering_window_s` (seconds, default 20): an average below 5 cm/s over 20 s, far
//! below any useful pace yet above the crawl of a robot squeezing through a gap, so slow but
//! real progress is not flagged.
//!
//! **Example.** `   40.0 s  agent    loitering, 0.31 m net progress in 20 s, 35.2 s`
//!
//! **Source.** Arnold & Alexander (2013) §3 ("the daemon … can detect loitering").

use serde_json::json;

use super::{details, Event, EventKind, Frame, Log};
use crate::sim::RobotState;

#[derive(Debug)]
pub(super) struct Detector {
    distance_m: f64,
    window_s: f64,
    window_steps: usize,
    /// Each robot's positions over the last window (plus now), oldest first, as a ring.
    history: Vec<std::collections::VecDeque<(f64, f64)>>,
    /// Each robot's open event (its index in the log) and the step its last event ended.
    open: Vec<Option<usize>>,
    last_end: Vec<u64>,
}

impl Detector {
    pub(super) fn new(robots: &[RobotState], distance_m: f64, window_s: f64, dt_s: f64) -> Self {
        let window_steps = ((window_s / dt_s) - 1e-9).ceil().max(1.0) as usize;
        let history = robots
            .iter()
            .map(|r| {
                let mut h = std::collections::VecDeque::with_capacity(window_steps + 1);
                h.push_back((r.pose.x_m, r.pose.y_m));
                h
            })
            .collect();
        Self {
            distance_m,
            window_s,
            window_steps,
            history,
            open: vec![None; robots.len()],
            last_end: vec![0; robots.len()],
        }
    }

    pub(super) fn observe(&mut self, frame: &Frame<'_>, completed: &[bool], log: &mut Log) {
        for r in frame.robots {
            let i = r.id as usize;
            let h = &mut self.history[i];
            if h.len() > self.window_steps {
                h.pop_front();
            }
            h.push_back((r.pose.x_m, r.pose.y_m));
            let full = h.len() > self.window_steps;
            let (then, now) = (h[0], h[h.len() - 1]);
            let progress = (now.0 - then.0).hypot(now.1 - then.1);
            let loitering = full && !completed[i] && progress < self.distance_m;
            match (self.open[i], loitering) {
                (None, true) => {
                    let began = (frame.step - self.window_steps as u64).max(self.last_end[i]);
                    self.open[i] = Some(log.open(
                        EventKind::Loitering,
                        began,
                        r.id,
                        None,
                        details([
                            ("net_progress_m", json!(progress)),
                            ("window_s", json!(self.window_s)),
                        ]),
                    ));
                }
                (Some(index), true) => {
                    let least = log.events[index].detail_f64("net_progress_m").min(progress);
                    log.set(index, "net_progress_m", json!(least));
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
        "loitering, {:.2} m net progress in {} s",
        e.detail_f64("net_progress_m"),
        e.detail_f64("window_s")
    )
}
