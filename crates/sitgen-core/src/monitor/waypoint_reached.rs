//! # `waypoint_reached` event
//!
//! **What it detects.** A robot coming within `waypoint_radius_m` of the next waypoint of its
//! route, in order (its rotation centre, measured by the monitor, not reported by the
//! controller). Instant. The monitor follows one pass of the route: after the last waypoint
//! ([`route_completed`](super::route_completed)) it logs no more waypoints, even for robots
//! that loop or reverse. Details: `index` (1 = the first waypoint after the start), `of` (how
//! many), `x_m`, `y_m`.
//!
//! **Why it matters.** Mission progress: which part of the route a run got through before
//! something went wrong, and how long each leg took.
//!
//! **Parameters.** `monitor.waypoint_radius_m` (metres, default 0.5: the `snd_follow`
//! switching distance, so the monitor agrees with the paper's follower about arrival).
//!
//! **Example.** `   21.4 s  agent    reached waypoint 2 of 5 at (12.30, 4.55)`
//!
//! **Source.** Arnold & Alexander (2013) §3 ("waypoint arrival").

use serde_json::json;

use super::{details, route_completed, Event, EventKind, Frame, Log};
use crate::control::route::RouteFollower;
use crate::mission::AtEnd;
use crate::situation::{Robot, Situation};

#[derive(Debug)]
pub(super) struct Detector {
    /// One pass of each robot's route (as a `stop` route, whatever the robot does at its end).
    routes: Vec<RouteFollower>,
    waypoints: Vec<Vec<[f64; 2]>>,
    completed: Vec<bool>,
    /// Whether the robot is meant to stay at its last waypoint once there.
    stops: Vec<bool>,
    /// Completed and meant to stay there: done.
    done: Vec<bool>,
    driven_m: Vec<f64>,
    last: Vec<(f64, f64)>,
}

impl Detector {
    pub(super) fn new(situation: &Situation, radius_m: f64) -> Self {
        let routes = situation
            .robots
            .iter()
            .map(|r| {
                let one_pass = Robot {
                    at_end: AtEnd::Stop,
                    ..r.clone()
                };
                RouteFollower::new(&one_pass, radius_m)
            })
            .collect();
        Self {
            routes,
            waypoints: situation
                .robots
                .iter()
                .map(|r| r.waypoints.clone())
                .collect(),
            completed: situation
                .robots
                .iter()
                .map(|r| r.waypoints.is_empty())
                .collect(),
            stops: situation
                .robots
                .iter()
                .map(|r| r.at_end == AtEnd::Stop)
                .collect(),
            done: situation
                .robots
                .iter()
                .map(|r| r.waypoints.is_empty() && r.at_end == AtEnd::Stop)
                .collect(),
            driven_m: vec![0.0; situation.robots.len()],
            last: situation
                .robots
                .iter()
                .map(|r| (r.start.x_m, r.start.y_m))
                .collect(),
        }
    }

    /// The waypoints robot `i` has yet to reach on its one pass, in order.
    pub(super) fn ahead(&self, i: usize) -> Vec<(f64, f64)> {
        self.routes[i].remaining()
    }

    /// Robot `i`'s next waypoint on its one pass: (its index, 1 = the first after the start;
    /// where it is; whether it is the last), None once the pass is complete.
    pub(super) fn next(&self, i: usize) -> Option<(usize, [f64; 2], bool)> {
        if self.completed[i] {
            return None;
        }
        let index = self.routes[i].next_index();
        let of = self.waypoints[i].len();
        (1..=of)
            .contains(&index)
            .then(|| (index, self.waypoints[i][index - 1], index == of))
    }

    pub(super) fn observe(&mut self, frame: &Frame<'_>, log: &mut Log) {
        for r in frame.robots() {
            let i = r.id as usize;
            let here = (r.pose.x_m, r.pose.y_m);
            let (dx, dy) = (here.0 - self.last[i].0, here.1 - self.last[i].1);
            // sqrt of the sum of squares: libm's hypot is several times slower, and steps of a
            // few centimetres cannot overflow.
            self.driven_m[i] += (dx * dx + dy * dy).sqrt();
            self.last[i] = here;
            if self.completed[i] {
                continue;
            }
            let before = self.routes[i].next_index();
            self.routes[i].target(here);
            let after = if self.routes[i].finished() {
                self.waypoints[i].len() + 1
            } else {
                self.routes[i].next_index()
            };
            let of = self.waypoints[i].len();
            for index in before..after {
                let [x, y] = self.waypoints[i][index - 1];
                log.open(
                    EventKind::WaypointReached,
                    frame.step,
                    r.id,
                    None,
                    details([
                        ("index", json!(index)),
                        ("of", json!(of)),
                        ("x_m", json!(x)),
                        ("y_m", json!(y)),
                    ]),
                );
            }
            if self.routes[i].finished() {
                self.completed[i] = true;
                self.done[i] = self.stops[i];
                route_completed::record(log, frame.step, r.id, of, self.driven_m[i]);
            }
        }
    }

    /// Whether each robot has driven one pass of its route.
    pub(super) fn completed(&self) -> &[bool] {
        &self.completed
    }

    /// Whether each robot is done: its route driven, and it is meant to stop there.
    pub(super) fn done(&self) -> &[bool] {
        &self.done
    }

    /// Waypoints robot `id` has reached.
    pub(super) fn reached(&self, id: u32) -> usize {
        let i = id as usize;
        if self.completed[i] {
            self.waypoints[i].len()
        } else {
            self.routes[i].next_index() - 1
        }
    }

    /// Waypoints on robot `id`'s route.
    pub(super) fn count(&self, id: u32) -> usize {
        self.waypoints[id as usize].len()
    }
}

/// The text of a waypoint event.
pub(super) fn describe(e: &Event) -> String {
    format!(
        "reached waypoint {} of {} at ({:.2}, {:.2})",
        e.detail_f64("index"),
        e.detail_f64("of"),
        e.detail_f64("x_m"),
        e.detail_f64("y_m")
    )
}
