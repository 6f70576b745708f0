//! # `circling` event
//!
//! **What it detects.** The agent near the next waypoint of its route (the goal, if that is
//! the last) without reaching it: within `circling_radius_m` of it (and outside
//! `waypoint_radius_m`, or it would have reached it) for one whole turn around it, or for
//! `loitering_window_s` while moving about over at least half `circling_radius_m` there
//! (dithering: the box of its positions there has that diagonal; a robot standing near it,
//! however it jitters or turns on the spot, is stuck, `loitering`, not circling). The event starts when the agent came that near and lasts until
//! it reaches the waypoint or leaves. Details: `waypoint` (its index, 1 = the first after the
//! start), `goal` (whether it is the route's last), `turns` (whole turns the agent made around
//! it, either way), `radius_m` (its mean distance from it while near), `closest_m`.
//!
//! **Why it matters.** The failure a slow or badly tuned planner has most: it orbits a waypoint
//! it cannot turn tightly enough to reach, or dithers beside it, until the time limit. Without
//! this event such a run is a plain timeout, indistinguishable from a robot that never got
//! near; its own class ranks it above one.
//!
//! **Parameters.** `monitor.circling_radius_m` (metres, default 2: four waypoint radii, about
//! the turning circle of a robot at full speed and half its turn rate) and
//! `monitor.loitering_window_s` (seconds, default 20). The agent only.
//!
//! **Example.** `  31.2 s  agent    circling waypoint 3 of 3 (the goal) at 1.2 m, 4 turns, 2.2 s`
//!
//! **Source.** sitgen's own: the monitor's waypoint arrival (Arnold & Alexander 2013, §3)
//! watched for what comes before it.

use std::f64::consts::TAU;

use serde_json::json;

use super::{details, Event, EventKind, Frame, Log};
use crate::sim::wrap_angle;

/// The agent's approach to its current waypoint.
#[derive(Debug, Default)]
struct Near {
    /// The waypoint (index on the route), and the step the agent came near it.
    waypoint: usize,
    since: u64,
    /// Its bearing from the waypoint last step, and the angle it has wound through since.
    bearing: f64,
    wound: f64,
    distance_sum: f64,
    steps: u64,
    closest_m: f64,
    /// The box of its positions while near: x and y, least and most.
    low: (f64, f64),
    high: (f64, f64),
    /// The open event, once it is one.
    event: Option<usize>,
}

#[derive(Debug)]
pub(super) struct Detector {
    agent: u32,
    radius_m: f64,
    window_steps: u64,
    near: Option<Near>,
}

impl Detector {
    pub(super) fn new(agent: u32, radius_m: f64, window_s: f64, dt_s: f64) -> Self {
        Self {
            agent,
            radius_m,
            window_steps: super::steps(window_s, dt_s).max(1),
            near: None,
        }
    }

    /// After a step: `next` is the agent's next waypoint (index, position, whether it is the
    /// goal), None once its route is complete.
    pub(super) fn observe(
        &mut self,
        frame: &Frame<'_>,
        next: Option<(usize, [f64; 2], bool)>,
        log: &mut Log,
    ) {
        let pose = frame.robots()[self.agent as usize].pose;
        let here = next.map(|(index, [x, y], goal)| {
            let (dx, dy) = (pose.x_m - x, pose.y_m - y);
            (index, (dx * dx + dy * dy).sqrt(), dy.atan2(dx), goal)
        });
        match (here, self.near.as_mut()) {
            (Some((index, d, bearing, goal)), Some(near))
                if index == near.waypoint && d <= self.radius_m =>
            {
                near.wound += wrap_angle(bearing - near.bearing);
                near.bearing = bearing;
                near.distance_sum += d;
                near.steps += 1;
                near.closest_m = near.closest_m.min(d);
                near.low = (near.low.0.min(pose.x_m), near.low.1.min(pose.y_m));
                near.high = (near.high.0.max(pose.x_m), near.high.1.max(pose.y_m));
                let (w, h) = (near.high.0 - near.low.0, near.high.1 - near.low.1);
                let turns = (near.wound.abs() / TAU).floor();
                let dithering = frame.step - near.since >= self.window_steps
                    && (w * w + h * h).sqrt() >= 0.5 * self.radius_m;
                let circling = dithering || turns >= 1.0;
                if circling && near.event.is_none() {
                    near.event = Some(log.open(
                        EventKind::Circling,
                        near.since,
                        self.agent,
                        None,
                        details([("waypoint", json!(index)), ("goal", json!(goal))]),
                    ));
                }
                if let Some(event) = near.event {
                    log.set(event, "turns", json!(turns));
                    let mean = near.distance_sum / near.steps as f64;
                    log.set(event, "radius_m", json!((mean * 1e3).round() / 1e3));
                    log.set(
                        event,
                        "closest_m",
                        json!((near.closest_m * 1e3).round() / 1e3),
                    );
                }
            }
            (here, _) => {
                self.finish(frame.step, log);
                self.near = here.filter(|&(_, d, _, _)| d <= self.radius_m).map(
                    |(waypoint, d, bearing, _)| Near {
                        waypoint,
                        since: frame.step,
                        bearing,
                        distance_sum: d,
                        steps: 1,
                        closest_m: d,
                        low: (pose.x_m, pose.y_m),
                        high: (pose.x_m, pose.y_m),
                        ..Near::default()
                    },
                );
            }
        }
    }

    pub(super) fn finish(&mut self, step: u64, log: &mut Log) {
        if let Some(event) = self.near.take().and_then(|n| n.event) {
            log.close(event, step);
        }
    }
}

/// The text of a circling event.
pub(super) fn describe(e: &Event) -> String {
    let goal = if e.details.get("goal") == Some(&json!(true)) {
        " (the goal)"
    } else {
        ""
    };
    format!(
        "circling waypoint {}{goal} at {:.1} m, {} turns",
        e.detail_f64("waypoint"),
        e.detail_f64("radius_m"),
        e.detail_f64("turns")
    )
}
