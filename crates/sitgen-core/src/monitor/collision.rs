//! # `collision` event
//!
//! **What it detects.** A stall (Stage's): a robot's move was refused because its footprint
//! would have overlapped an occupied cell, the map's edge, or another robot. One event per pair
//! (robot and wall, or two robots), lasting from the first stalled step while the contact lasts.
//! A robot struck while standing still is in the collision too: a peer that drives into the
//! stationary agent gives an agent collision with that peer. Details:
//! - `speed_m_s`: the robot's speed (|v|, m/s) when the contact began; for a pair of robots
//!   also `other_speed_m_s`;
//! - `blocked`: the ids whose moves were refused while it lasted (who drove into whom);
//! - `visible`: whether the other party was visible to the agent's laser in the
//!   `visibility_window_s` before contact (for pairs with the agent: the other robot was among
//!   the robots some beam hit first; for the agent against a wall: the agent was moving in a
//!   direction its laser covers, since walls do not move — so backing or turning on the spot
//!   into a wall with a 180° laser is not visible); `null` where the agent is not involved;
//! - where the agent is involved, the [`super::attribution`] facts at contact: `initiator`
//!   (whether the agent drove into the other party or was struck), `agent_mean_speed_m_s` over
//!   the second before, and for a robot `bearing`, `closing_speed_m_s`, approach speeds and
//!   `seen` / `seen_before_s` / `last_seen_before_s`.
//!
//! **Why it matters.** Contact is the accident sitgen exists to find. Whether the agent could
//! have seen the other party separates perception faults (the paper's run 207: a robot
//! outside the field of view) from control faults (run 231: seen, and still hit).
//!
//! **Parameters.** `monitor.visibility_window_s` (seconds, default 1);
//! `monitor.merge_gap_s` (seconds, default 1): a contact broken for less than this and resumed
//! continues the same collision.
//!
//! **Example.** `   12.3 s  agent    collision with peer 2 at 0.00 m/s (struck from the rear; not visible 1 s before), 4.1 s`
//!
//! **Source.** Arnold & Alexander (2013) §3 ("stalls … produced by Stage when the robot collides
//! with terrain or another robot"); Stage's stall semantics, `reference/algorithms.md` §2.3.

use serde_json::{json, Value};

use super::attribution::Attribution;
use super::{details, party_name, Event, EventKind, Frame, Lasting, Log, Party};
use crate::sim::Contact;

/// Who is in contact: (lower robot id, the other party).
type Key = (u32, Party);

#[derive(Debug)]
pub(super) struct Detector {
    agent: u32,
    window_steps: u64,
    window_s: f64,
    /// Whether the laser covers the direction behind the robot (a 360° laser).
    sees_behind: bool,
    lasting: Lasting<Key>,
}

impl Detector {
    pub(super) fn new(
        agent: u32,
        window_s: f64,
        fov_deg: f64,
        dt_s: f64,
        merge_steps: u64,
    ) -> Self {
        Self {
            agent,
            window_steps: super::steps(window_s, dt_s),
            window_s,
            sees_behind: fov_deg >= 360.0,
            lasting: Lasting::new(merge_steps),
        }
    }

    pub(super) fn observe(&mut self, frame: &Frame<'_>, seen: &Attribution, log: &mut Log) {
        let mut active: Vec<(Key, u32)> = Vec::new();
        for r in frame.robots().iter().filter(|r| r.stalled) {
            for c in &r.contacts {
                let key = match *c {
                    Contact::Wall => (r.id, Party::Wall),
                    Contact::Robot(o) => (r.id.min(o), Party::Robot(r.id.max(o))),
                };
                active.push((key, r.id));
            }
        }
        active.sort();
        let keys: Vec<Key> = active.iter().map(|a| a.0).collect();
        self.lasting.update(&keys, frame.step, log);
        for (i, &key) in keys.iter().enumerate() {
            if i > 0 && keys[i - 1] == key {
                continue;
            }
            let blocked: Vec<u32> = active.iter().filter(|a| a.0 == key).map(|a| a.1).collect();
            if let Some(&index) = self.lasting.open.get(&key) {
                // Who pushed may change while the contact lasts (a head-on pair both push).
                let mut all: Vec<u32> =
                    serde_json::from_value(log.events[index].details["blocked"].clone())
                        .unwrap_or_default();
                if blocked.iter().any(|b| !all.contains(b)) {
                    all.extend(blocked);
                    all.sort_unstable();
                    all.dedup();
                    log.set(index, "blocked", json!(all));
                }
                continue;
            }
            let index = log.open(
                EventKind::Collision,
                frame.step,
                key.0,
                Some(key.1),
                self.describe_contact(frame, seen, key, &blocked),
            );
            self.lasting.open.insert(key, index);
        }
    }

    fn describe_contact(
        &self,
        frame: &Frame<'_>,
        seen: &Attribution,
        (robot, other): Key,
        blocked: &[u32],
    ) -> std::collections::BTreeMap<String, Value> {
        let speed = |id: u32| frame.robots()[id as usize].velocity.0.abs();
        let visible = match other {
            Party::Wall if robot == self.agent => {
                let v = frame.robots()[robot as usize].velocity.0;
                Value::Bool(v > 0.0 || self.sees_behind)
            }
            Party::Robot(o) if robot == self.agent || o == self.agent => {
                let id = if robot == self.agent { o } else { robot };
                Value::Bool(seen.seen_within(id, self.window_steps, frame.step))
            }
            _ => Value::Null,
        };
        let mut d = details([
            ("speed_m_s", json!(speed(robot))),
            ("blocked", json!(blocked)),
            ("visible", visible),
        ]);
        if !d["visible"].is_null() {
            d.insert("visibility_window_s".into(), json!(self.window_s));
        }
        if let Party::Robot(o) = other {
            d.insert("other_speed_m_s".into(), json!(speed(o)));
        }
        // The pair is keyed by the lower id; attribution is told the party that is not the agent.
        if robot == self.agent {
            d.extend(seen.details(frame, other, blocked));
        } else if other == Party::Robot(self.agent) {
            d.extend(seen.details(frame, Party::Robot(robot), blocked));
        }
        d
    }

    pub(super) fn finish(&mut self, step: u64, log: &mut Log) {
        self.lasting.close_all(step, log);
    }
}

/// The text of a collision event.
pub(super) fn describe(e: &Event, agent: u32) -> String {
    let window = e.detail_f64("visibility_window_s");
    let visible = match e.details.get("visible").and_then(Value::as_bool) {
        Some(true) => format!("visible {window} s before"),
        Some(false) => format!("not visible {window} s before"),
        None => String::new(),
    };
    let side = e
        .details
        .get("bearing")
        .and_then(Value::as_str)
        .map(|b| format!(" from the {b}"))
        .unwrap_or_default();
    let who = match e.details.get("initiator").and_then(Value::as_str) {
        Some("agent") => format!("drove into it{side}"),
        Some("other") => format!("struck{side}"),
        Some("both") => format!("both closing{side}"),
        _ => String::new(),
    };
    let facts: Vec<String> = [who, visible]
        .into_iter()
        .filter(|f| !f.is_empty())
        .collect();
    let facts = if facts.is_empty() {
        String::new()
    } else {
        format!(" ({})", facts.join("; "))
    };
    format!(
        "collision with {} at {:.2} m/s{facts}",
        party_name(e.other, agent),
        e.detail_f64("speed_m_s")
    )
}
