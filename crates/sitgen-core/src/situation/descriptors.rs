//! # Situation descriptors
//!
//! **What it does.** Describes a situation by numbers computed from the situation alone,
//! before any run: the agent's route (length, turns, how close it passes walls), the map's
//! occupied share, the peers and how their routes cross the agent's, and how close a peer
//! comes when every robot drives its route at its nominal speed. Each is defined in
//! `docs/explain.md` precisely enough to recompute from a situation file (the tests do).
//!
//! **Why.** A rule learnt from them (`sitgen explain`) names something a generator can aim at
//! (`sitgen campaign --where`), and a campaign stores them with each situation, so that
//! explaining ten thousand runs needs no situation generated again.
//!
//! **Parameters.** The nominal speeds: the agent [`AGENT_SPEED_M_S`]; a peer its controller's
//! `speed_m_s`, else [`PEER_SPEED_M_S`]; the nominal drive sampled every [`SAMPLE_S`]; a
//! quantity without a subject (no crossing, no peer, no obstacle) reads [`NONE`].
//!
//! **Source.** The descriptors of situation-coverage work (Alexander, Hawkins & Rae 2015: the
//! situation's elements and their relations) made numeric for CART (Breiman et al. 1984).

use serde::Serialize;

use super::Situation;
use crate::geometry::segment::nearest_point;
use crate::mission::AtEnd;

/// The agent's nominal speed, m/s.
pub const AGENT_SPEED_M_S: f64 = 0.4;
/// A peer's nominal speed where its controller names none, m/s.
pub const PEER_SPEED_M_S: f64 = 0.5;
/// Time step of the nominal drive, seconds.
pub const SAMPLE_S: f64 = 0.1;
/// What a distance or time reads without a subject.
pub const NONE: f64 = 1000.0;
/// A corner of the route turns by more than this, degrees.
const TURN_DEG: f64 = 30.0;

/// A situation's descriptors (docs/explain.md).
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Descriptors {
    pub route_length_m: f64,
    pub route_turns: u32,
    pub route_clearance_m: f64,
    pub obstacle_share: f64,
    pub peers: u32,
    pub crossing_peers: u32,
    pub crossing_angle_deg: f64,
    pub conflict_gap_s: f64,
    pub nearest_peer_start_m: f64,
    pub nominal_closest_m: f64,
    pub nominal_closest_bearing_deg: f64,
    pub nominal_closest_clearance_m: f64,
    pub terrain: String,
}

type Point = (f64, f64);

/// A polyline with its cumulative lengths.
struct Polyline {
    points: Vec<Point>,
    cumulative: Vec<f64>,
}

impl Polyline {
    fn new(points: Vec<Point>) -> Self {
        let mut cumulative = vec![0.0];
        for w in points.windows(2) {
            let last = *cumulative.last().expect("one");
            cumulative.push(last + dist(w[0], w[1]));
        }
        Self { points, cumulative }
    }

    fn length(&self) -> f64 {
        *self.cumulative.last().expect("one")
    }

    /// The point at distance `s` along it (clamped to its ends), and its leg's heading.
    fn at(&self, s: f64) -> (Point, f64) {
        let n = self.points.len();
        if n < 2 || self.length() <= 0.0 {
            return (self.points[0], 0.0);
        }
        let s = s.clamp(0.0, self.length());
        // The leg: the last breakpoint at or before s, not the final one.
        let leg = self
            .cumulative
            .partition_point(|&c| c <= s)
            .saturating_sub(1)
            .min(n - 2);
        let (a, b) = (self.points[leg], self.points[leg + 1]);
        let span = self.cumulative[leg + 1] - self.cumulative[leg];
        let f = if span > 0.0 {
            (s - self.cumulative[leg]) / span
        } else {
            0.0
        };
        let heading = (b.1 - a.1).atan2(b.0 - a.0);
        ((a.0 + f * (b.0 - a.0), a.1 + f * (b.1 - a.1)), heading)
    }
}

fn dist(a: Point, b: Point) -> f64 {
    (b.0 - a.0).hypot(b.1 - a.1)
}

fn route_of(r: &super::Robot) -> Vec<Point> {
    std::iter::once((r.start.x_m, r.start.y_m))
        .chain(r.waypoints.iter().map(|w| (w[0], w[1])))
        .collect()
}

/// Where a robot driving `route` at `speed` is after `t` seconds, as its `at_end` says past
/// the route's end: it stops there, drives it back to the start and again (`reverse`), or
/// drives from its last waypoint to its first and round again (`loop`).
fn driven(route: &Polyline, cycle: Option<&Polyline>, at_end: AtEnd, s: f64) -> Point {
    let total = route.length();
    match at_end {
        _ if total <= 0.0 => route.points[0],
        AtEnd::Stop => route.at(s).0,
        AtEnd::Reverse => {
            let s = s.rem_euclid(2.0 * total);
            route.at(if s > total { 2.0 * total - s } else { s }).0
        }
        AtEnd::Loop => match cycle {
            Some(c) if s > total && c.length() > 0.0 => c.at((s - total).rem_euclid(c.length())).0,
            _ => route.at(s).0,
        },
    }
}

/// Where segments pq and ab cross, as fractions along each.
fn crossing(p: Point, q: Point, a: Point, b: Point) -> Option<(f64, f64)> {
    let r = (q.0 - p.0, q.1 - p.1);
    let s = (b.0 - a.0, b.1 - a.1);
    let denominator = r.0 * s.1 - r.1 * s.0;
    if denominator.abs() < 1e-12 {
        return None;
    }
    let t = ((a.0 - p.0) * s.1 - (a.1 - p.1) * s.0) / denominator;
    let u = ((a.0 - p.0) * r.1 - (a.1 - p.1) * r.0) / denominator;
    ((0.0..=1.0).contains(&t) && (0.0..=1.0).contains(&u)).then_some((t, u))
}

fn angle_deg(from: f64, to: f64) -> f64 {
    crate::sim::wrap_angle(to - from).abs().to_degrees()
}

fn peer_speed(r: &super::Robot) -> f64 {
    r.controller
        .params
        .get("speed_m_s")
        .copied()
        .unwrap_or(PEER_SPEED_M_S)
}

/// The descriptors of `situation`, its map's squared distance from each cell to the nearest
/// occupied cell given (cells², [`crate::grid::distance::squared_distance_to`]) or computed.
pub fn describe(situation: &Situation, to_occupied: Option<&[f64]>) -> Descriptors {
    let map = situation
        .map
        .decode()
        .expect("a checked situation's map decodes");
    let (rows, cols, res) = (map.grid.rows, map.grid.cols, map.resolution_m);
    let any_occupied = map.grid.cells.iter().any(|&c| c);
    let computed;
    let to_occupied = match to_occupied {
        Some(d) => d,
        None => {
            computed = crate::grid::distance::squared_distance_to(&map.grid.cells, rows, cols);
            &computed
        }
    };
    // Distance from the cell under (x, y) to the nearest occupied cell, centre to centre,
    // less half a cell; None off the map.
    let clearance_at = |(x, y): Point| -> Option<f64> {
        let (col, row) = ((x / res) as i64, rows as i64 - 1 - (y / res) as i64);
        ((0..rows as i64).contains(&row) && (0..cols as i64).contains(&col))
            .then(|| to_occupied[row as usize * cols + col as usize].sqrt() * res - res / 2.0)
    };
    let agent = &situation.robots[0];
    let peers = &situation.robots[1..];
    let route = route_of(agent);
    let legs: Vec<(Point, Point)> = route.windows(2).map(|w| (w[0], w[1])).collect();
    let lengths: Vec<f64> = legs.iter().map(|&(a, b)| dist(a, b)).collect();
    let mut least = NONE;
    if any_occupied {
        for (&(a, b), &length) in legs.iter().zip(&lengths) {
            let k = ((length / res) as usize).max(1);
            for i in 0..=k {
                let t = i as f64 / k as f64;
                if let Some(c) = clearance_at((a.0 + t * (b.0 - a.0), a.1 + t * (b.1 - a.1))) {
                    least = least.min(c);
                }
            }
        }
    }
    let turns = route
        .windows(3)
        .filter(|w| {
            let h1 = (w[1].1 - w[0].1).atan2(w[1].0 - w[0].0);
            let h2 = (w[2].1 - w[1].1).atan2(w[2].0 - w[1].0);
            angle_deg(h1, h2) > TURN_DEG
        })
        .count() as u32;
    // Each peer's first crossing along the agent's route: (distance along, angle, time gap).
    let mut crossings: Vec<(f64, f64, f64)> = Vec::new();
    for peer in peers {
        let peer_route = route_of(peer);
        let peer_legs: Vec<(Point, Point)> = peer_route.windows(2).map(|w| (w[0], w[1])).collect();
        let peer_lengths: Vec<f64> = peer_legs.iter().map(|&(a, b)| dist(a, b)).collect();
        let mut first: Option<(f64, f64, f64)> = None;
        for (i, &(p, q)) in legs.iter().enumerate() {
            for (j, &(a, b)) in peer_legs.iter().enumerate() {
                let Some((t, u)) = crossing(p, q, a, b) else {
                    continue;
                };
                let along = lengths[..i].iter().sum::<f64>() + t * lengths[i];
                let peer_along = peer_lengths[..j].iter().sum::<f64>() + u * peer_lengths[j];
                let angle = angle_deg((q.1 - p.1).atan2(q.0 - p.0), (b.1 - a.1).atan2(b.0 - a.0));
                let gap = (along / AGENT_SPEED_M_S - peer_along / peer_speed(peer).max(1e-6)).abs();
                if first.is_none_or(|f| along < f.0) {
                    first = Some((along, angle, gap));
                }
            }
        }
        crossings.extend(first);
    }
    crossings.sort_by(|a, b| a.partial_cmp(b).expect("finite"));
    let nearest = if legs.is_empty() {
        NONE
    } else {
        peers
            .iter()
            .map(|p| {
                legs.iter()
                    .map(|&(a, b)| {
                        let at = (p.start.x_m, p.start.y_m);
                        dist(at, nearest_point(at, a, b))
                    })
                    .fold(f64::INFINITY, f64::min)
            })
            .fold(NONE, f64::min)
    };
    let (closest, bearing, clearance) =
        nominal_closest(situation, &route, any_occupied, clearance_at);
    let terrain = serde_json::to_value(&situation.provenance.spec.terrain).unwrap_or_default();
    let terrain = terrain
        .get("preset")
        .and_then(|p| p.as_str())
        .or_else(|| terrain.pointer("/source/kind").and_then(|k| k.as_str()))
        .unwrap_or("given")
        .to_string();
    Descriptors {
        route_length_m: lengths.iter().sum(),
        route_turns: turns,
        route_clearance_m: least,
        obstacle_share: map.grid.cells.iter().filter(|&&c| c).count() as f64
            / (rows * cols).max(1) as f64,
        peers: peers.len() as u32,
        crossing_peers: crossings.len() as u32,
        crossing_angle_deg: crossings.first().map_or(0.0, |c| c.1),
        conflict_gap_s: crossings.first().map_or(NONE, |c| c.2),
        nearest_peer_start_m: nearest,
        nominal_closest_m: closest,
        nominal_closest_bearing_deg: bearing,
        nominal_closest_clearance_m: clearance,
        terrain,
    }
}

/// `nominal_closest_m`, its bearing from the agent's heading, and the clearance where the
/// agent is then.
fn nominal_closest(
    situation: &Situation,
    route: &[Point],
    any_occupied: bool,
    clearance_at: impl Fn(Point) -> Option<f64>,
) -> (f64, f64, f64) {
    let peers = &situation.robots[1..];
    if peers.is_empty() {
        return (NONE, 0.0, NONE);
    }
    let agent = Polyline::new(route.to_vec());
    let samples = ((agent.length() / AGENT_SPEED_M_S + SAMPLE_S / 2.0) / SAMPLE_S).ceil() as usize;
    let drives: Vec<(Polyline, Option<Polyline>, AtEnd, f64)> = peers
        .iter()
        .map(|p| {
            let points = route_of(p);
            let cycle = (p.at_end == AtEnd::Loop && p.waypoints.len() > 1).then(|| {
                let mut c: Vec<Point> = p.waypoints.iter().map(|w| (w[0], w[1])).collect();
                c.insert(0, *points.last().expect("one"));
                Polyline::new(c)
            });
            (Polyline::new(points), cycle, p.at_end, peer_speed(p))
        })
        .collect();
    let mut best = (f64::INFINITY, 0.0, route[0]);
    for k in 0..samples.max(1) {
        let t = k as f64 * SAMPLE_S;
        let (me, heading) = agent.at(t * AGENT_SPEED_M_S);
        for (polyline, cycle, at_end, speed) in &drives {
            let other = driven(polyline, cycle.as_ref(), *at_end, t * speed);
            let gap = dist(me, other);
            if gap < best.0 {
                let bearing = angle_deg(heading, (other.1 - me.1).atan2(other.0 - me.0));
                best = (gap, bearing, me);
            }
        }
    }
    let clearance = if any_occupied {
        clearance_at(best.2).unwrap_or(NONE)
    } else {
        NONE
    };
    (best.0, best.1, clearance)
}
