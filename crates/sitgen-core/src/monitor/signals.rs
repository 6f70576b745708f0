//! # Requirement signals
//!
//! **What they are.** One value a sample of what the agent did, for requirements in STL
//! ([`crate::requirement`]) to be judged on. Sample 0 is the start; sample k is the world
//! after step k, at k · `sim.dt_s` seconds. Every signal is a function of the recorded poses
//! (the trajectory), the robots' bodies, the map and the agent's laser sightings, never of a
//! controller, so an outside tool recomputes it from a stored run (docs/requirements.md):
//! - `speed`: the agent's signed forward speed over the step that led to the sample, m/s:
//!   the length of its displacement over `dt_s`, negative when it moved against its heading
//!   halfway through the step; 0 at sample 0.
//! - `turn_rate`: its heading's change over that step (wrapped to (−π, π]) over `dt_s`,
//!   rad/s, positive counter-clockwise; 0 at sample 0.
//! - `peer_distance`: centre to centre (the poses' points) to the nearest peer, m.
//! - `peer_clearance`: footprint to footprint to the nearest peer by that measure, m; 0 in
//!   contact.
//! - `obstacle_clearance`: the agent's footprint to the nearest occupied cell or the map's
//!   edge, m; 0 in contact. Exact up to [`OBSTACLE_CLEARANCE_CAP_M`]; it reads that cap when
//!   nothing is nearer.
//! - `goal_distance`: the agent's centre to the last waypoint of its route, m.
//! - `closing_speed`: how fast the nearest peer's centre distance shrinks, m/s: that peer's
//!   distance at the previous sample less its distance now, over `dt_s` (positive when
//!   closing); 0 at sample 0.
//! - `peer_seen`: 1 when the nearest peer was hit first by a beam of the scan the agent's
//!   laser took at the start of the step that led to the sample, else 0; 0 at sample 0.
//!
//! With no peer, `peer_distance` and `peer_clearance` read +∞ (a requirement about peers
//! holds), `closing_speed` and `peer_seen` 0.
//!
//! **Why.** A safety engineer's requirements are about these quantities ("never closer than
//! 0.4 m to a person while faster than 0.3 m/s"); the monitor's events are sitgen's own
//! yardstick, these are the user's.
//!
//! **Parameters.** None: the names are fixed. Only the signals a run's requirements name are
//! computed.
//!
//! **Source.** sitgen's own; the set follows the quantities of the paper's events (Arnold &
//! Alexander 2013, §3) and of the safety requirements of mobile-robot standards (ISO 13482's
//! speed and separation).

use crate::geometry::Body;
use crate::sim::{footprint, wrap_angle, Aid, World};
use crate::situation::Pose;

/// The signals' names, in index order.
pub const NAMES: [&str; 8] = [
    "speed",
    "turn_rate",
    "peer_distance",
    "peer_clearance",
    "obstacle_clearance",
    "goal_distance",
    "closing_speed",
    "peer_seen",
];

/// Each signal's index in [`NAMES`].
pub const SPEED: usize = 0;
/// `turn_rate`.
pub const TURN_RATE: usize = 1;
/// `peer_distance`.
pub const PEER_DISTANCE: usize = 2;
/// `peer_clearance`.
pub const PEER_CLEARANCE: usize = 3;
/// `obstacle_clearance`.
pub const OBSTACLE_CLEARANCE: usize = 4;
/// `goal_distance`.
pub const GOAL_DISTANCE: usize = 5;
/// `closing_speed`.
pub const CLOSING_SPEED: usize = 6;
/// `peer_seen`.
pub const PEER_SEEN: usize = 7;

/// Largest value `obstacle_clearance` reads, metres: an exact clearance costs a search of the
/// cells within it every sample (about 3 % of a run at 2 m, 6 % at 5 m).
pub const OBSTACLE_CLEARANCE_CAP_M: f64 = 2.0;

/// The index of the signal called `name`.
pub fn index(name: &str) -> Option<usize> {
    NAMES.iter().position(|n| *n == name)
}

/// What a run recorded that the signals are computed from.
pub struct Recorded<'a> {
    /// Poses of every robot at every sample, flat `[sample][robot][3]`.
    pub trajectory: &'a [f64],
    /// Robots a sample.
    pub robots: usize,
    /// The agent's id.
    pub agent: usize,
    /// Every robot's body, by id.
    pub bodies: Vec<Body>,
    /// The agent's goal: its route's last waypoint (its start if it has none).
    pub goal: (f64, f64),
    /// For each sample, the robots the agent's scan before its step saw (empty at sample 0).
    pub seen: &'a [Vec<u32>],
    /// The world (its map, for `obstacle_clearance`).
    pub world: &'a World,
}

impl Recorded<'_> {
    fn samples(&self) -> usize {
        self.trajectory.len() / (3 * self.robots.max(1))
    }

    fn pose(&self, k: usize, robot: usize) -> Pose {
        let i = (k * self.robots + robot) * 3;
        Pose {
            x_m: self.trajectory[i],
            y_m: self.trajectory[i + 1],
            heading_rad: self.trajectory[i + 2],
        }
    }

    /// The nearest peer at sample `k` by centre distance, and that distance.
    fn nearest(&self, k: usize) -> Option<(usize, f64)> {
        let a = self.pose(k, self.agent);
        (0..self.robots)
            .filter(|&j| j != self.agent)
            .map(|j| (j, centre_distance(&a, &self.pose(k, j))))
            .fold(None, |best, (j, d)| match best {
                Some((_, bd)) if bd <= d => best,
                _ => Some((j, d)),
            })
    }
}

fn centre_distance(a: &Pose, b: &Pose) -> f64 {
    (a.x_m - b.x_m).hypot(a.y_m - b.y_m)
}

/// The signals `wanted` (by index) over every sample; the others are left empty. The nearest
/// peer, which four signals read, is found once a sample.
pub fn compute(rec: &Recorded<'_>, wanted: &[bool; 8], dt_s: f64) -> Vec<Vec<f64>> {
    let n = rec.samples();
    let about_peers = [PEER_DISTANCE, PEER_CLEARANCE, CLOSING_SPEED, PEER_SEEN];
    let nearest: Vec<Option<(usize, f64)>> = if about_peers.iter().any(|&i| wanted[i]) {
        (0..n).map(|k| rec.nearest(k)).collect()
    } else {
        Vec::new()
    };
    let mut out = vec![Vec::new(); NAMES.len()];
    for (i, signal) in out.iter_mut().enumerate() {
        if i == OBSTACLE_CLEARANCE && wanted[i] {
            *signal = obstacle_clearance(rec);
        } else if wanted[i] {
            *signal = (0..n)
                .map(|k| sample(rec, i, k, dt_s, nearest.get(k).copied().flatten()))
                .collect();
        }
    }
    out
}

/// `obstacle_clearance` at every sample. Each sample's clearance is at most the last one's
/// plus how far any point of the footprint moved (its centre's displacement plus its turn
/// times the footprint's reach): a bound that lets the exact search look only that far.
fn obstacle_clearance(rec: &Recorded<'_>) -> Vec<f64> {
    let edges = rec.world.edge_cells_before();
    let body = &rec.bodies[rec.agent];
    let radius = body.enclosing_radius();
    let mut last: Option<(Pose, f64)> = None;
    (0..rec.samples())
        .map(|k| {
            let pose = rec.pose(k, rec.agent);
            let at_most_m = last.as_ref().map(|(p, d)| {
                let turned = wrap_angle(pose.heading_rad - p.heading_rad).abs();
                d + (pose.x_m - p.x_m).hypot(pose.y_m - p.y_m) + turned * radius
            });
            let aid = Aid {
                edge_cells_before: &edges,
                at_most_m: at_most_m.filter(|b| *b < OBSTACLE_CLEARANCE_CAP_M),
            };
            let found =
                rec.world
                    .wall_clearance_at(body, &pose, OBSTACLE_CLEARANCE_CAP_M, Some(aid));
            last = found.map(|d| (pose, d));
            found.unwrap_or(OBSTACLE_CLEARANCE_CAP_M)
        })
        .collect()
}

/// Signal `i` at sample `k`, whose nearest peer is `nearest`.
fn sample(rec: &Recorded<'_>, i: usize, k: usize, dt_s: f64, nearest: Option<(usize, f64)>) -> f64 {
    let agent = rec.pose(k, rec.agent);
    let before = (k > 0).then(|| rec.pose(k - 1, rec.agent));
    match i {
        SPEED => before.map_or(0.0, |b| {
            let (dx, dy) = (agent.x_m - b.x_m, agent.y_m - b.y_m);
            let mid = b.heading_rad + wrap_angle(agent.heading_rad - b.heading_rad) / 2.0;
            let along = dx * mid.cos() + dy * mid.sin();
            dx.hypot(dy).copysign(if along < 0.0 { -1.0 } else { 1.0 }) / dt_s
        }),
        TURN_RATE => before.map_or(0.0, |b| {
            wrap_angle(agent.heading_rad - b.heading_rad) / dt_s
        }),
        PEER_DISTANCE => nearest.map_or(f64::INFINITY, |(_, d)| d),
        PEER_CLEARANCE => nearest.map_or(f64::INFINITY, |(j, _)| {
            let mine = footprint(&rec.bodies[rec.agent], &agent);
            mine.distance(&footprint(&rec.bodies[j], &rec.pose(k, j)))
        }),
        OBSTACLE_CLEARANCE => unreachable!("obstacle_clearance is computed in turn"),
        GOAL_DISTANCE => (agent.x_m - rec.goal.0).hypot(agent.y_m - rec.goal.1),
        CLOSING_SPEED => match (before, nearest) {
            (Some(b), Some((j, now))) => (centre_distance(&b, &rec.pose(k - 1, j)) - now) / dt_s,
            _ => 0.0,
        },
        PEER_SEEN => match nearest {
            Some((j, _)) if rec.seen.get(k).is_some_and(|s| s.contains(&(j as u32))) => 1.0,
            _ => 0.0,
        },
        _ => unreachable!("NAMES lists every signal"),
    }
}
