//! # `unsafe_proximity` event
//!
//! **What it detects.** Two robots whose footprints (the oriented rectangles, not enclosing
//! circles) are closer than `unsafe_proximity_m`, contact included. One event per pair, lasting
//! while they stay that close; `robot` is the lower id, so the agent's pairs name the agent.
//! Details: `min_clearance_m`, the smallest clearance reached while it lasted; where the agent
//! is one of the pair, the [`super::attribution`] facts when it began (`initiator`: which of
//! them closed in, `bearing`, speeds, whether the agent's laser had seen the other).
//!
//! **Why it matters.** A near miss is a collision that luck avoided; people near a robot feel
//! unsafe well before contact. The paper scores it from the moment it starts and per second
//! it lasts, so a long tailgate outranks a brief brush.
//!
//! **Parameters.** `monitor.unsafe_proximity_m` (metres, default 0.5: about the Pioneer's width,
//! the clearance a person would keep from a moving robot of that size); `monitor.merge_gap_s`
//! (seconds, default 1): a near miss interrupted for less than this and resumed is one event.
//!
//! **Example.** `    8.0 s  agent    unsafe proximity to peer 1, min clearance 0.12 m, 3.4 s`
//!
//! **Source.** Arnold & Alexander (2013) §3 ("unsafe proximity (between two robots)") and its
//! penalty example (10 points, then 1 per second).

use serde_json::json;

use super::attribution::Attribution;
use super::{details, party_name, Event, EventKind, Frame, Lasting, Log, Party};
use crate::sim::RobotState;

#[derive(Debug)]
pub(super) struct Detector {
    agent: u32,
    threshold_m: f64,
    /// Each robot's enclosing radius, metres (fixed for the run).
    reach: Vec<f64>,
    lasting: Lasting<(u32, u32)>,
    /// Smallest clearance so far of each open pair.
    min_clearance: std::collections::BTreeMap<(u32, u32), f64>,
}

impl Detector {
    pub(super) fn new(
        robots: &[RobotState],
        agent: u32,
        threshold_m: f64,
        merge_steps: u64,
    ) -> Self {
        Self {
            agent,
            threshold_m,
            reach: robots.iter().map(|r| r.body.enclosing_radius()).collect(),
            lasting: Lasting::new(merge_steps),
            min_clearance: Default::default(),
        }
    }

    pub(super) fn observe(&mut self, frame: &Frame<'_>, seen: &Attribution, log: &mut Log) {
        let mut close = Vec::new();
        for (i, a) in frame.robots().iter().enumerate() {
            for b in &frame.robots()[i + 1..] {
                // Enclosing circles farther apart than the threshold settle most pairs.
                let (dx, dy) = (a.pose.x_m - b.pose.x_m, a.pose.y_m - b.pose.y_m);
                let apart =
                    self.reach[a.id as usize] + self.reach[b.id as usize] + self.threshold_m;
                if dx * dx + dy * dy >= apart * apart {
                    continue;
                }
                let clearance = a.footprint().distance(&b.footprint());
                if clearance < self.threshold_m {
                    close.push(((a.id, b.id), clearance));
                }
            }
        }
        let keys: Vec<(u32, u32)> = close.iter().map(|c| c.0).collect();
        for k in self.lasting.update(&keys, frame.step, log) {
            self.min_clearance.remove(&k);
        }
        for (key, clearance) in close {
            let index = match self.lasting.open.get(&key) {
                Some(&i) => i,
                None => {
                    let mut d = details([("min_clearance_m", json!(clearance))]);
                    // Keyed by the lower id; attribution is told the robot that is not the agent.
                    if key.0 == self.agent {
                        d.extend(seen.details(frame, Party::Robot(key.1), &[]));
                    } else if key.1 == self.agent {
                        d.extend(seen.details(frame, Party::Robot(key.0), &[]));
                    }
                    let i = log.open(
                        EventKind::UnsafeProximity,
                        frame.step,
                        key.0,
                        Some(Party::Robot(key.1)),
                        d,
                    );
                    self.lasting.open.insert(key, i);
                    i
                }
            };
            let least = self.min_clearance.entry(key).or_insert(clearance);
            *least = least.min(clearance);
            log.set(index, "min_clearance_m", json!(*least));
        }
    }

    pub(super) fn finish(&mut self, step: u64, log: &mut Log) {
        self.lasting.close_all(step, log);
    }
}

/// The text of an unsafe-proximity event.
pub(super) fn describe(e: &Event, agent: u32) -> String {
    format!(
        "unsafe proximity to {}, min clearance {:.2} m",
        party_name(e.other, agent),
        e.detail_f64("min_clearance_m")
    )
}
