//! # `oscillation` event
//!
//! **What it detects.** A robot that has not finished its route and that turns to and fro
//! while going nowhere: within the last `oscillation_window_s` (a full window, so not in a
//! run's first seconds) its turn direction reversed at
//! least `oscillation_reversals` times and every position lay in a box whose diagonal (the
//! *extent*) is below `oscillation_distance_m`. The turn direction of a step is the sign of the
//! heading change the world actually made (never the command), counted only when it turns
//! faster than `oscillation_turn_rate_deg_s`, so a robot driving straight with small
//! corrections does not reverse. The event starts at the first reversal of the window that
//! first qualified and ends at the last reversal (or where the robot got away, when the extent
//! grew past the threshold); a pause shorter than `merge_gap_s` continues it. Details: `reversals` (counted while it lasted), `window_s`,
//! `extent_m` (the largest extent of a window while it lasted), `nearest` (`"wall"`, a robot
//! id, or `null` when nothing was within 2 m) and `nearest_m` (the smallest footprint
//! clearance to it while it lasted). `nearest` decides the event's class, so it is written as
//! it changes, while the event lasts: a perturbed copy watching for an oscillation class past
//! its horizon reads the class it would stop with.
//!
//! **Why it matters.** Dithering between two ways round an obstacle is the known failure of
//! gap-based avoidance (the paper's run 219: SND "oscillated between trying to pass to the left
//! and trying to pass to the right"), and of reciprocal Velocity Obstacles. Beside a person it
//! is unpredictable motion; anywhere it is a mission that does not progress. `loitering` alone
//! cannot tell it from waiting.
//!
//! **Parameters.** `monitor.oscillation_window_s` (seconds, default 10), `oscillation_reversals`
//! (count, default 4: two full left–right cycles, more than a single hesitation),
//! `oscillation_distance_m` (metres, default 0.5: loitering's pace, 5 cm/s, over the window)
//! and `oscillation_turn_rate_deg_s` (degrees per second, default 5: far above the drift of a
//! robot holding a heading, far below SND's turns of tens of degrees per second);
//! `monitor.merge_gap_s` (seconds, default 1).
//!
//! **Example.** `   31.4 s  agent    oscillation: 6 turn reversals within 0.42 m, nearest peer 1 at 0.12 m, 8.3 s`
//!
//! **Source.** Arnold & Alexander (2013) §5 (run 219); Minguez & Montano (2004) on the
//! oscillations of nearness-diagram navigation in narrow places; van den Berg et al. (2008) on
//! reciprocal oscillation of Velocity Obstacles.

use std::collections::VecDeque;

use serde_json::{json, Value};

use super::loitering::Window;
use super::{details, party_name, Event, EventKind, Frame, Log, Party};
use crate::sim::{wrap_angle, RobotState};

/// How far the nearest party is looked for, metres.
pub const NEAR_M: f64 = 2.0;

/// One robot's turning so far.
#[derive(Debug)]
struct Turning {
    heading: f64,
    /// The last non-zero turn direction (+1 left, −1 right), 0 before the first turn.
    direction: i8,
    /// Steps at which the direction reversed, within the window.
    reversals: VecDeque<u64>,
    window: Window,
    open: Option<Open>,
    last_end: u64,
}

/// An oscillation in progress.
#[derive(Debug)]
struct Open {
    /// Its index in the log.
    index: usize,
    began: u64,
    reversals: u64,
    largest_extent: f64,
    /// The nearest party so far and its clearance, metres.
    nearest: Option<(Party, f64)>,
    /// Since when it has not been oscillating, and where it ended then.
    pause: Option<(u64, u64)>,
}

impl Open {
    /// End the event at `end`, writing what it saw (once, not every step it lasted).
    fn close(self, end: u64, log: &mut Log) {
        let (party, metres) = match self.nearest {
            Some((party, m)) => (json!(party), json!(m)),
            None => (Value::Null, Value::Null),
        };
        log.set(self.index, "reversals", json!(self.reversals));
        log.set(self.index, "extent_m", json!(self.largest_extent));
        log.set(self.index, "nearest", party);
        log.set(self.index, "nearest_m", metres);
        log.close(self.index, end);
    }
}

#[derive(Debug)]
pub(super) struct Detector {
    distance_m: f64,
    reversals: usize,
    window_s: f64,
    window_steps: u64,
    min_turn_rad: f64,
    merge_steps: u64,
    robots: Vec<Turning>,
}

/// The oscillation thresholds (from `MonitorSpec`).
pub(super) struct Thresholds {
    pub window_s: f64,
    pub reversals: u32,
    pub distance_m: f64,
    pub turn_rate_deg_s: f64,
    /// Pauses shorter than this many steps continue the same event.
    pub merge_steps: u64,
}

impl Detector {
    pub(super) fn new(robots: &[RobotState], t: &Thresholds, dt_s: f64) -> Self {
        let window_steps = super::steps(t.window_s, dt_s).max(1);
        let robots = robots
            .iter()
            .map(|r| {
                let mut window = Window::default();
                window.extent(0, (r.pose.x_m, r.pose.y_m), 0);
                Turning {
                    heading: r.pose.heading_rad,
                    direction: 0,
                    reversals: VecDeque::new(),
                    window,
                    open: None,
                    last_end: 0,
                }
            })
            .collect();
        Self {
            distance_m: t.distance_m,
            reversals: t.reversals as usize,
            window_s: t.window_s,
            window_steps,
            min_turn_rad: t.turn_rate_deg_s.to_radians() * dt_s,
            merge_steps: t.merge_steps,
            robots,
        }
    }

    pub(super) fn observe(&mut self, frame: &Frame<'_>, done: &[bool], log: &mut Log) {
        let oldest = frame.step.saturating_sub(self.window_steps);
        for r in frame.robots() {
            let i = r.id as usize;
            let t = &mut self.robots[i];
            let turn = wrap_angle(r.pose.heading_rad - t.heading);
            t.heading = r.pose.heading_rad;
            let direction = if turn > self.min_turn_rad {
                1
            } else if turn < -self.min_turn_rad {
                -1
            } else {
                0
            };
            let reversed = direction != 0 && t.direction == -direction;
            if direction != 0 {
                t.direction = direction;
            }
            if reversed {
                t.reversals.push_back(frame.step);
            }
            while t.reversals.front().is_some_and(|&s| s <= oldest) {
                t.reversals.pop_front();
            }
            let extent = t
                .window
                .extent(frame.step, (r.pose.x_m, r.pose.y_m), oldest);
            // A full window first, as loitering: a robot's first seconds cover too little
            // ground for its extent to mean "going nowhere".
            let oscillating = frame.step >= self.window_steps
                && !done[i]
                && t.reversals.len() >= self.reversals
                && extent < self.distance_m;
            match (t.open.is_some(), oscillating) {
                (false, true) => {
                    let began = t.reversals[0].max(t.last_end);
                    let reversals = t.reversals.len() as u64;
                    let index = log.open(
                        EventKind::Oscillation,
                        began,
                        r.id,
                        None,
                        details([("window_s", json!(self.window_s))]),
                    );
                    t.open = Some(Open {
                        index,
                        began,
                        reversals,
                        largest_extent: extent,
                        nearest: None,
                        pause: None,
                    });
                }
                (true, true) => {
                    let open = t.open.as_mut().expect("open");
                    open.reversals += u64::from(reversed);
                    open.largest_extent = open.largest_extent.max(extent);
                    open.pause = None;
                }
                (true, false) => {
                    let open = t.open.as_mut().expect("open");
                    // Got away (the box grew): it ended now; else at the last reversal. A pause
                    // shorter than the merge gap continues the same oscillation.
                    let end = if extent >= self.distance_m {
                        frame.step
                    } else {
                        t.reversals.back().copied().unwrap_or(frame.step)
                    };
                    let (since, end) = *open.pause.get_or_insert((frame.step, end.max(open.began)));
                    if frame.step - since >= self.merge_steps {
                        t.open.take().expect("open").close(end, log);
                        t.last_end = end;
                    }
                }
                (false, false) => {}
            }
            if let Some(open) = &mut t.open {
                if let Some(n) = nearest_party(frame, i) {
                    if open.nearest.is_none_or(|(_, m)| n.1 < m) {
                        if open.nearest.is_none_or(|(p, _)| p != n.0) {
                            // The party decides the event's class: a reader of the log while
                            // the robot still oscillates (a copy watching for its class) reads
                            // the class the event would close with now.
                            log.decide(open.index, "nearest", json!(n.0));
                        }
                        open.nearest = Some(n);
                    }
                }
            }
        }
    }

    pub(super) fn finish(&mut self, step: u64, log: &mut Log) {
        for t in &mut self.robots {
            if let Some(open) = t.open.take() {
                let last = t.reversals.back().copied().unwrap_or(step);
                let end = open.pause.map_or(last.max(open.began), |(_, end)| end);
                open.close(end, log);
            }
        }
    }
}

/// The nearest robot or wall to robot `i` within [`NEAR_M`], by footprint clearance (a robot
/// before a wall at the same clearance).
fn nearest_party(frame: &Frame<'_>, i: usize) -> Option<(Party, f64)> {
    let r = &frame.robots()[i];
    let me = r.footprint();
    let reach = r.body.enclosing_radius() + NEAR_M;
    let robot = frame
        .robots()
        .iter()
        .filter(|o| {
            let apart = reach + o.body.enclosing_radius();
            o.id as usize != i
                && (o.pose.x_m - r.pose.x_m).powi(2) + (o.pose.y_m - r.pose.y_m).powi(2)
                    < apart * apart
        })
        .map(|o| (Party::Robot(o.id), me.distance(&o.footprint())))
        .filter(|&(_, m)| m <= NEAR_M)
        .min_by(|a, b| a.1.total_cmp(&b.1));
    // Only a wall nearer than the nearest robot matters, which bounds the search.
    let within = robot.map_or(NEAR_M, |(_, m)| m);
    match frame.world.wall_clearance(i, within) {
        Some(m) if robot.is_none_or(|(_, r)| m < r) => Some((Party::Wall, m)),
        _ => robot,
    }
}

/// The text of an oscillation event.
pub(super) fn describe(e: &Event, agent: u32) -> String {
    let nearest = match e.details.get("nearest") {
        Some(Value::String(_)) => Some(Party::Wall),
        Some(v) => v.as_u64().map(|id| Party::Robot(id as u32)),
        None => None,
    };
    let beside = match nearest {
        Some(p) => format!(
            ", nearest {} at {:.2} m",
            party_name(Some(p), agent),
            e.detail_f64("nearest_m")
        ),
        None => String::new(),
    };
    format!(
        "oscillation: {} turn reversals within {:.2} m{beside}",
        e.detail_f64("reversals"),
        e.detail_f64("extent_m")
    )
}
