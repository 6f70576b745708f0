//! Attribution: who moved into whom, from where, how fast, and whether the agent could have
//! known. Not an event kind: the facts that `collision` and `unsafe_proximity` events between
//! the agent and another party carry in their details, measured from the world's poses and the
//! agent's laser (never from a controller), so that failure classes can tell a robot that drove
//! into something from one that was struck.
//!
//! Details added to an event that concerns the agent, at the step it started:
//! - `initiator`: who moved into whom. `"agent"` (the agent drove into it), `"other"` (the
//!   other party drove into the agent), `"both"` (both closed in). A party *closes in* when its
//!   own displacement over the `attribution_window_s` before, projected on the line from it to
//!   the other, exceeds [`MOVING_M_S`]. When neither did (contact while turning on the spot),
//!   the robot whose move was refused is the initiator (in a near miss, where no move was
//!   refused, the one that came nearer). Walls never move: always `"agent"`.
//! - `agent_approach_m_s`, `other_approach_m_s`: those projected speeds (m/s, positive =
//!   toward the other), and `closing_speed_m_s`: how fast the distance between the two centres
//!   fell over the window (robots only).
//! - `agent_mean_speed_m_s`: the agent's mean speed over the window (path length / time), what
//!   it actually did; `speed_m_s` beside it is its commanded speed at that step.
//! - `bearing`: where the other robot's centre lay from the agent's heading: `front` (within
//!   45°), `left`, `right` (45°–135°) or `rear`; `bearing_deg` the angle, counter-clockwise.
//! - `seen`: whether the agent's laser had seen the other robot before; `seen_before_s`: how
//!   long before the event it first saw it, `last_seen_before_s`: how long before it last saw
//!   it (one step, 0.1 s, when the scan that drove the step of the event saw it); both `null`
//!   when never seen.
//!
//! **Parameters.** `monitor.attribution_window_s` (seconds, default 1): long enough to see
//! where a robot was heading (ten steps), short enough that it is the last approach, not the
//! route before it.

use std::collections::{BTreeMap, VecDeque};

use serde_json::{json, Value};

use super::{seconds, Frame, Party};

/// Speed along the line to the other party above which a robot is closing in, m/s: 5 cm/s, a
/// twentieth of a Pioneer's top speed, above the creep of a robot turning on the spot.
pub const MOVING_M_S: f64 = 0.05;

/// Mean speed along consecutive positions `dt_s` apart: path length over time (0 for fewer
/// than two), what a robot actually did rather than what it was commanded.
pub fn mean_speed_m_s(positions: impl IntoIterator<Item = (f64, f64)>, dt_s: f64) -> f64 {
    let (mut path, mut steps, mut last) = (0.0, 0usize, None::<(f64, f64)>);
    for p in positions {
        if let Some((x, y)) = last {
            path += (p.0 - x).hypot(p.1 - y);
            steps += 1;
        }
        last = Some(p);
    }
    if steps == 0 {
        0.0
    } else {
        path / (steps as f64 * dt_s)
    }
}

/// Recent poses of every robot and what the agent's laser has seen.
#[derive(Debug)]
pub(super) struct Attribution {
    agent: u32,
    dt_s: f64,
    window_steps: usize,
    /// (x, y, heading) of every robot for the last `window_steps + 1` frames, oldest first.
    history: VecDeque<Vec<(f64, f64, f64)>>,
    first_seen: Vec<Option<u64>>,
    last_seen: Vec<Option<u64>>,
}

impl Attribution {
    pub(super) fn new(robots: usize, agent: u32, window_steps: u64, dt_s: f64) -> Self {
        Self {
            agent,
            dt_s,
            window_steps: window_steps.max(1) as usize,
            history: VecDeque::new(),
            first_seen: vec![None; robots],
            last_seen: vec![None; robots],
        }
    }

    /// Note the poses of a frame (call once per frame, before the detectors).
    pub(super) fn observe(&mut self, frame: &Frame<'_>) {
        // The agent's scan was taken at the start of this step, one step before the frame.
        let scan_step = frame.step.saturating_sub(1);
        for &id in frame.seen_by_agent {
            self.first_seen[id as usize].get_or_insert(scan_step);
            self.last_seen[id as usize] = Some(scan_step);
        }
        // The oldest row is reused for the newest: no allocation per step.
        let mut row = if self.history.len() > self.window_steps {
            self.history.pop_front().expect("non-empty")
        } else {
            Vec::with_capacity(frame.robots().len())
        };
        row.clear();
        row.extend(
            frame
                .robots()
                .iter()
                .map(|r| (r.pose.x_m, r.pose.y_m, r.pose.heading_rad)),
        );
        self.history.push_back(row);
    }

    /// Whether the agent's laser saw robot `id` within `window_steps` before `step`.
    pub(super) fn seen_within(&self, id: u32, window_steps: u64, step: u64) -> bool {
        self.last_seen[id as usize].is_some_and(|s| s + window_steps >= step)
    }

    /// The attribution details of an event between the agent and `other` starting at this
    /// frame; `blocked`: the robots whose move was refused at this step (collisions).
    pub(super) fn details(
        &self,
        frame: &Frame<'_>,
        other: Party,
        blocked: &[u32],
    ) -> BTreeMap<String, Value> {
        let a = self.agent as usize;
        let now = self.history.back().expect("observed before detectors");
        let then = self.history.front().expect("observed before detectors");
        let span_s = (self.history.len() - 1) as f64 * self.dt_s;
        let per_s = |d: f64| if span_s > 0.0 { d / span_s } else { 0.0 };
        let speed = mean_speed_m_s(self.history.iter().map(|p| (p[a].0, p[a].1)), self.dt_s);
        let mut d = BTreeMap::new();
        d.insert("agent_mean_speed_m_s".into(), json!(speed));
        let Party::Robot(o) = other else {
            d.insert("initiator".into(), json!("agent"));
            return d;
        };
        let o = o as usize;
        let (ax, ay, heading) = now[a];
        let (ox, oy) = (now[o].0, now[o].1);
        let gap = (ox - ax).hypot(oy - ay).max(1e-12);
        let u = ((ox - ax) / gap, (oy - ay) / gap);
        let toward = |i: usize, sign: f64| {
            sign * per_s((now[i].0 - then[i].0) * u.0 + (now[i].1 - then[i].1) * u.1)
        };
        let agent_approach = toward(a, 1.0);
        let other_approach = toward(o, -1.0);
        let gap_then = (then[o].0 - then[a].0).hypot(then[o].1 - then[a].1);
        let initiator = match (agent_approach > MOVING_M_S, other_approach > MOVING_M_S) {
            (true, true) => "both",
            (true, false) => "agent",
            (false, true) => "other",
            (false, false) if blocked.contains(&self.agent) => "agent",
            (false, false) if !blocked.is_empty() => "other",
            // A near miss refuses no move: the one that came nearer did it.
            (false, false) if agent_approach >= other_approach => "agent",
            (false, false) => "other",
        };
        let bearing_deg = crate::sim::wrap_angle((oy - ay).atan2(ox - ax) - heading).to_degrees();
        let side = match bearing_deg.abs() {
            b if b <= 45.0 => "front",
            b if b >= 135.0 => "rear",
            _ if bearing_deg > 0.0 => "left",
            _ => "right",
        };
        let ago = |s: Option<u64>| match s {
            Some(s) => json!(seconds(frame.step - s.min(frame.step), self.dt_s)),
            None => Value::Null,
        };
        d.insert("initiator".into(), json!(initiator));
        d.insert("agent_approach_m_s".into(), json!(agent_approach));
        d.insert("other_approach_m_s".into(), json!(other_approach));
        d.insert("closing_speed_m_s".into(), json!(per_s(gap_then - gap)));
        d.insert("bearing".into(), json!(side));
        d.insert("bearing_deg".into(), json!(bearing_deg));
        d.insert("seen".into(), json!(self.first_seen[o].is_some()));
        d.insert("seen_before_s".into(), ago(self.first_seen[o]));
        d.insert("last_seen_before_s".into(), ago(self.last_seen[o]));
        d
    }
}
