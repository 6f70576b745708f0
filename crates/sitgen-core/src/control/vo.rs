//! # `vo` controller
//!
//! **What it does.** Velocity Obstacles, non-reciprocal, with a time horizon. Each step:
//! 1. *Obstacles.* Every robot the laser sees (a track: position and velocity) is a disc of
//!    radius `other_radius_m` moving at its velocity; every laser return that is not on a
//!    tracked robot (not within `other_radius_m` + 5 cm of one) is a static disc of radius 0.
//!    The robot is a disc of its body's enclosing radius. Returns too far away to be reached
//!    within the horizon are dropped.
//! 2. *Velocity obstacles.* For each obstacle, the truncated velocity obstacle VO^τ: the robot
//!    velocities that bring the discs into contact within `horizon_s`, assuming the obstacle keeps
//!    its velocity. It is tested through the time to collision (a velocity is inside VO^τ when
//!    that time is at most τ). A return already inside the robot's disc (the disc is larger than
//!    the rectangular body, so this happens beside walls without contact) counts only against
//!    velocities that approach it.
//! 3. *Reachable velocities.* Holonomic candidates in the robot frame: the preferred velocity
//!    itself, then a fixed polar grid of 9 headings evenly over ± `turn_rate_deg_s` ×
//!    `reach_s` (±45° by default: the heading change the robot can make in that time) × speeds
//!    `speed_m_s` × {1, ¾, ½, ¼}, and standing still. Nothing faster than `speed_m_s`, nothing
//!    backwards.
//! 4. *Selection.* The preferred velocity points at the waypoint headed for (the shared
//!    [`RouteFollower`]) at `speed_m_s`. Among candidates outside every VO it takes the one
//!    nearest the preferred velocity; when every candidate is inside some VO, the one with the
//!    largest time to collision, then the nearest to the preferred velocity, then the first in
//!    the order above.
//! 5. *Differential drive.* The chosen velocity u, at angle e from the heading, becomes
//!    v = ‖u‖·cos e (never negative, as |e| ≤ 90°), ω = `turn_gain`·e capped at `turn_rate_deg_s`.
//!    Standing still turns on the spot towards the preferred velocity, which moves no part of the
//!    robot's disc and so is free of collision in the model.
//!
//! **Why.** A classic velocity-space avoider with a known failure mode in this setting: it
//! treats the peers as passive and extrapolates them at constant velocity, approximates both
//! robots by discs, and has no plan beyond the horizon (local minima, dead ends; see
//! `reference/algorithms.md` §3.1). A baseline for what sitgen should find.
//!
//! **Parameters.**
//! - `speed_m_s` (m/s, default 0.5, in (0, 10]): preferred and largest speed.
//! - `horizon_s` (seconds, default 3, in (0, 60]): time horizon τ of the truncated VOs.
//! - `other_radius_m` (metres, default: the robot's own enclosing radius, 0.438 m for the
//!   Pioneer 3-AT, in (0, 10]): radius assumed for every other robot, whose size the agent cannot
//!   know from a track.
//! - `turn_gain` (1/s, default 2, in (0, 100]): k in ω = k·e.
//! - `turn_rate_deg_s` (degrees per second, default 90, in (0, 3600]): largest turn rate.
//! - `reach_s` (seconds, default 0.5, in (0, 10]): the window over which a heading change counts
//!   as reachable; the candidate headings span ± `turn_rate_deg_s` × `reach_s`, capped at ±90°.
//! - `switch_m` (metres, default 0.3, in (0, 10]): distance at which a waypoint counts as reached.
//!
//! **Source.** Fiorini & Shiller, "Motion planning in dynamic environments using velocity
//! obstacles", IJRR 17(7), 1998 (from memory; `reference/algorithms.md` §3.1): collision cone,
//! VO = v_B ⊕ CC, truncation by a time horizon, reachable avoidance velocities, the "closest to
//! the goal velocity" heuristic, largest time to collision when none is free.

use std::collections::BTreeMap;

use super::fault::{self, Fault};
use super::route::RouteFollower;
use super::{param, Command, Controller};
use crate::error::SpecError;
use crate::sim::Observation;
use crate::situation::Robot;

type Vector = (f64, f64);

/// Laser returns this much farther than `other_radius_m` from a track still belong to it: ranges
/// are rounded to the laser's step and a corner of the other body may lie just outside the disc.
const TRACK_GATE_MARGIN_M: f64 = 0.05;
/// Candidate headings on the polar grid (odd, so that straight ahead is one).
const HEADINGS: usize = 9;
/// Candidate speeds as fractions of `speed_m_s`.
const SPEED_FRACTIONS: [f64; 4] = [1.0, 0.75, 0.5, 0.25];

/// A disc obstacle in the robot frame: centre, velocity, and the sum of its radius and the
/// robot's (the robot is then a point).
#[derive(Debug, Clone, Copy, PartialEq)]
struct Obstacle {
    centre: Vector,
    velocity: Vector,
    combined_radius: f64,
}

/// The `vo` controller.
#[derive(Debug, Clone)]
pub struct Vo {
    speed_m_s: f64,
    horizon_s: f64,
    other_radius_m: Option<f64>,
    turn_gain: f64,
    turn_rate: f64,
    switch_m: f64,
    /// The fixed polar grid (robot frame), in selection order, standing still last.
    grid: Vec<Vector>,
    /// Largest heading change a candidate may ask for, radians.
    reach: f64,
    own_radius_m: f64,
    fault: Option<Fault>,
    route: Option<RouteFollower>,
    /// Per-step buffers, kept to spare allocations.
    obstacles: Vec<Obstacle>,
    candidates: Vec<Vector>,
}

impl Vo {
    /// Build from named parameters; `path` names them in errors.
    pub fn from_params(params: &BTreeMap<String, f64>, path: &str) -> Result<Self, SpecError> {
        let known = [
            "speed_m_s",
            "horizon_s",
            "other_radius_m",
            "turn_gain",
            "turn_rate_deg_s",
            "reach_s",
            "switch_m",
        ];
        super::check_known(params, &known, path)?;
        let other_radius_m = match params.contains_key("other_radius_m") {
            true => Some(param(params, path, "other_radius_m", 1.0, 10.0)?),
            false => None,
        };
        let speed_m_s = param(params, path, "speed_m_s", 0.5, 10.0)?;
        let turn_rate = param(params, path, "turn_rate_deg_s", 90.0, 3600.0)?.to_radians();
        let reach_s = param(params, path, "reach_s", 0.5, 10.0)?;
        let reach = (turn_rate * reach_s).min(std::f64::consts::FRAC_PI_2);
        Ok(Self {
            speed_m_s,
            horizon_s: param(params, path, "horizon_s", 3.0, 60.0)?,
            other_radius_m,
            turn_gain: param(params, path, "turn_gain", 2.0, 100.0)?,
            turn_rate,
            switch_m: param(params, path, "switch_m", 0.3, 10.0)?,
            grid: reachable_velocities(speed_m_s, reach),
            reach,
            own_radius_m: 0.0,
            fault: None,
            route: None,
            obstacles: Vec::new(),
            candidates: Vec::new(),
        })
    }
}

impl Vo {
    /// This controller with seeded fault `fault` switched on (from the next reset).
    pub fn with_fault(mut self, fault: Option<Fault>) -> Self {
        self.fault = fault;
        self
    }
}

/// The fixed candidate grid in the robot frame: for each speed (fastest first), headings from
/// straight ahead outwards, left before right; then standing still.
fn reachable_velocities(speed_m_s: f64, reach: f64) -> Vec<Vector> {
    let half = HEADINGS / 2;
    let step = reach / half as f64;
    let mut grid = Vec::with_capacity(HEADINGS * SPEED_FRACTIONS.len() + 1);
    for fraction in SPEED_FRACTIONS {
        let s = speed_m_s * fraction;
        grid.push((s, 0.0));
        for k in 1..=half {
            for side in [1.0, -1.0] {
                let (sin, cos) = (side * step * k as f64).sin_cos();
                grid.push((s * cos, s * sin));
            }
        }
    }
    grid.push((0.0, 0.0));
    grid
}

/// The obstacles of one observation in the robot frame: tracks as moving discs, the other laser
/// returns within `reach_m` as static points.
fn obstacles(
    obs: &Observation,
    own_radius_m: f64,
    other_radius_m: f64,
    reach_m: f64,
    fault: Option<Fault>,
    out: &mut Vec<Obstacle>,
) {
    out.clear();
    let (s, c) = obs.pose.heading_rad.sin_cos();
    let to_robot = |(x, y): Vector| (c * x + s * y, -s * x + c * y);
    for t in &obs.tracks {
        let centre = to_robot((t.position.0 - obs.pose.x_m, t.position.1 - obs.pose.y_m));
        // Seeded fault `vo_static_peers`.
        let velocity = if Fault::VoStaticPeers.is(fault) {
            (0.0, 0.0)
        } else {
            to_robot(t.velocity)
        };
        out.push(Obstacle {
            centre,
            velocity,
            combined_radius: own_radius_m + other_radius_m,
        });
    }
    let tracks = out.len();
    let gate = other_radius_m + TRACK_GATE_MARGIN_M;
    for (&range, &bearing) in obs.ranges.iter().zip(&obs.angles) {
        if !(range.is_finite() && range < reach_m) {
            continue;
        }
        let (sb, cb) = bearing.sin_cos();
        let p = (range * cb, range * sb);
        let on_track = out[..tracks]
            .iter()
            .any(|t| (p.0 - t.centre.0).hypot(p.1 - t.centre.1) <= gate);
        if !on_track {
            out.push(Obstacle {
                centre: p,
                velocity: (0.0, 0.0),
                combined_radius: own_radius_m,
            });
        }
    }
}

/// Time until the robot (a point at the origin, after growing the obstacle by its radius) moving
/// at `u` meets `o`; infinite if never. Inside the grown disc already, it is 0 for a velocity
/// that approaches the centre and infinite for one that does not, so that a robot whose disc
/// overlaps a wall it is not touching can still move away or along it.
fn time_to_collision(u: Vector, o: &Obstacle) -> f64 {
    let w = (u.0 - o.velocity.0, u.1 - o.velocity.1);
    let d = o.centre;
    let wd = w.0 * d.0 + w.1 * d.1;
    let gap = d.0 * d.0 + d.1 * d.1 - o.combined_radius * o.combined_radius;
    if gap <= 0.0 {
        return if wd > 0.0 { 0.0 } else { f64::INFINITY };
    }
    if wd <= 0.0 {
        return f64::INFINITY;
    }
    let ww = w.0 * w.0 + w.1 * w.1;
    let discriminant = wd * wd - ww * gap;
    if discriminant < 0.0 {
        return f64::INFINITY;
    }
    // The earlier root of ‖t·w − d‖ = R, in the form that does not cancel: positive, since
    // gap > 0 and w·d > 0.
    gap / (wd + discriminant.sqrt())
}

/// Whether velocity `u` lies in the union of the truncated velocity obstacles, with the time to
/// the first collision (infinite if none).
fn velocity_obstacle(u: Vector, obstacles: &[Obstacle], horizon_s: f64) -> (bool, f64) {
    let ttc = obstacles
        .iter()
        .map(|o| time_to_collision(u, o))
        .fold(f64::INFINITY, f64::min);
    (ttc <= horizon_s, ttc)
}

/// The index of the chosen candidate: nearest to `preferred` outside every VO; if there is none,
/// the largest time to collision, then nearest to `preferred`, then first.
fn select(
    candidates: &[Vector],
    preferred: Vector,
    obstacles: &[Obstacle],
    horizon_s: f64,
) -> usize {
    let mut best: Option<(usize, bool, f64, f64)> = None;
    for (i, &u) in candidates.iter().enumerate() {
        let (inside, ttc) = velocity_obstacle(u, obstacles, horizon_s);
        let deviation = (u.0 - preferred.0).hypot(u.1 - preferred.1);
        let better = match best {
            None => true,
            Some((_, b_inside, b_ttc, b_dev)) => match (inside, b_inside) {
                (false, true) => true,
                (true, false) => false,
                (false, false) => deviation < b_dev,
                (true, true) => ttc > b_ttc || (ttc == b_ttc && deviation < b_dev),
            },
        };
        if better {
            best = Some((i, inside, ttc, deviation));
        }
    }
    best.map_or(candidates.len() - 1, |b| b.0)
}

impl Vo {
    /// The command that tracks holonomic velocity `u` (robot frame) with a differential drive.
    fn drive(&self, u: Vector, preferred: Vector) -> Command {
        let cap = |w: f64| w.clamp(-self.turn_rate, self.turn_rate);
        let speed = u.0.hypot(u.1);
        if speed < 1e-12 {
            let towards = if preferred == (0.0, 0.0) {
                0.0
            } else {
                preferred.1.atan2(preferred.0)
            };
            return (0.0, cap(self.turn_gain * towards));
        }
        let e = u.1.atan2(u.0);
        ((speed * e.cos()).max(0.0), cap(self.turn_gain * e))
    }
}

impl Controller for Vo {
    fn route(&self) -> Option<&RouteFollower> {
        self.route.as_ref()
    }

    fn reset(&mut self, robot: &Robot) {
        self.own_radius_m = robot.body.enclosing_radius();
        self.route = Some(RouteFollower::new(
            robot,
            fault::switch_m(self.fault, self.switch_m),
        ));
    }

    fn act(&mut self, obs: &Observation) -> Command {
        let here = (obs.pose.x_m, obs.pose.y_m);
        let Some(target) = self.route.as_mut().and_then(|r| r.target(here)) else {
            return (0.0, 0.0);
        };
        let (s, c) = obs.pose.heading_rad.sin_cos();
        let (dx, dy) = (target.0 - here.0, target.1 - here.1);
        let to_goal = (c * dx + s * dy, -s * dx + c * dy);
        let distance = to_goal.0.hypot(to_goal.1);
        let preferred = if distance > 0.0 {
            let k = self.speed_m_s / distance;
            (to_goal.0 * k, to_goal.1 * k)
        } else {
            (0.0, 0.0)
        };
        let other_radius_m = self.other_radius_m.unwrap_or(self.own_radius_m);
        // A static point farther than this cannot be reached within the horizon.
        let reach_m = self.own_radius_m + self.speed_m_s * self.horizon_s;
        // Seeded fault `vo_point_robot`: the discs grown by the other's radius only.
        let grown_by = if Fault::VoPointRobot.is(self.fault) {
            0.0
        } else {
            self.own_radius_m
        };
        obstacles(
            obs,
            grown_by,
            other_radius_m,
            reach_m,
            self.fault,
            &mut self.obstacles,
        );
        self.candidates.clear();
        if preferred.1.atan2(preferred.0).abs() <= self.reach && distance > 0.0 {
            self.candidates.push(preferred);
        }
        self.candidates.extend_from_slice(&self.grid);
        let chosen = select(&self.candidates, preferred, &self.obstacles, self.horizon_s);
        self.drive(self.candidates[chosen], preferred)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::control::tests::run_situation;
    use crate::mission::ControllerSpec;
    use crate::sim::{Contact, Track, World};
    use crate::situation::{Pose, Situation};

    fn robot(id: u32, start: (f64, f64, f64), goal: [f64; 2]) -> Robot {
        crate::test_data::robot(id, start, &[goal], "straight")
    }

    /// A 20 m × 20 m open field: the agent drives east from (4, 10) to (16, 10); a `straight`
    /// peer drives north from (10, 4) to (10, 16) at the same speed, so both reach (10, 10)
    /// together.
    fn crossing() -> Situation {
        let robots = vec![
            robot(0, (4.0, 10.0, 0.0), [16.0, 10.0]),
            robot(1, (10.0, 4.0, std::f64::consts::FRAC_PI_2), [10.0, 16.0]),
        ];
        crate::test_data::situation(200, &[], robots)
    }

    fn named(name: &str) -> ControllerSpec {
        ControllerSpec {
            name: name.into(),
            params: Default::default(),
            fault: None,
            control_period_s: None,
            perception: None,
            keep_alive: false,
            step_timeout_s: None,
        }
    }

    /// The error building `vo` with `params`, as text.
    fn build_error(params: &[(&str, f64)]) -> String {
        crate::control::tests::build_error("vo", params, "c")
    }

    #[test]
    fn parameter_errors_are_named() {
        let e = build_error(&[("radius_m", 1.0)]);
        assert!(e.starts_with("c.params.radius_m: unknown parameter"), "{e}");
        assert_eq!(
            build_error(&[("other_radius_m", -1.0)]),
            "c.params.other_radius_m: -1 is not in (0, 10]"
        );
        assert_eq!(
            build_error(&[("horizon_s", 61.0)]),
            "c.params.horizon_s: 61 is not in (0, 60]"
        );
    }

    /// Smallest distance between two convex polygons that do not overlap (vertex to edge).
    fn polygon_gap(a: &[(f64, f64); 4], b: &[(f64, f64); 4]) -> f64 {
        let to_edges = |p: (f64, f64), q: &[(f64, f64); 4]| {
            (0..4)
                .map(|i| {
                    let (s, e) = (q[i], q[(i + 1) % 4]);
                    let (dx, dy) = (e.0 - s.0, e.1 - s.1);
                    let t = (((p.0 - s.0) * dx + (p.1 - s.1) * dy) / (dx * dx + dy * dy))
                        .clamp(0.0, 1.0);
                    (s.0 + t * dx - p.0).hypot(s.1 + t * dy - p.1)
                })
                .fold(f64::INFINITY, f64::min)
        };
        let ab = a.iter().map(|&p| to_edges(p, b));
        let ba = b.iter().map(|&p| to_edges(p, a));
        ab.chain(ba).fold(f64::INFINITY, f64::min)
    }

    /// Run the crossing with `agent`: (world, whether either robot ever stalled, whether the
    /// robots ever blocked each other, smallest gap between the bodies). Stage semantics: a
    /// blocked move is not made, so a collision shows as a stall with the other robot among the
    /// contacts, never as overlap.
    fn run_crossing(agent: &str) -> (World, bool, bool, f64) {
        let s = crossing();
        let mut stalled = false;
        let mut robot_contact = false;
        let mut gap = f64::INFINITY;
        let world = run_situation(&s, &named(agent), 600, |w| {
            let r = w.robots();
            stalled |= r.iter().any(|r| r.stalled);
            robot_contact |= r
                .iter()
                .any(|r| r.stalled && r.contacts.iter().any(|c| matches!(c, Contact::Robot(_))));
            let corners = |i: usize| {
                let p = r[i].pose;
                r[i].body.corners(p.x_m, p.y_m, p.heading_rad)
            };
            gap = gap.min(polygon_gap(&corners(0), &corners(1)));
            false
        });
        (world, stalled, robot_contact, gap)
    }

    #[test]
    fn a_path_tracker_collides_with_the_crossing_peer() {
        for agent in ["follow", "straight"] {
            let (_, _, robot_contact, gap) = run_crossing(agent);
            assert!(robot_contact, "{agent} never touched the peer");
            assert!(gap < 0.05, "{agent}: closest approach {gap} m");
        }
    }

    #[test]
    fn vo_avoids_the_crossing_peer_and_reaches_its_goal() {
        let (world, stalled, robot_contact, gap) = run_crossing("vo");
        assert!(!stalled && !robot_contact, "a robot stalled");
        assert!(gap > 0.05, "closest approach {gap} m");
        let p = world.robots()[0].pose;
        let d = (p.x_m - 16.0).hypot(p.y_m - 10.0);
        assert!(d <= 0.3 + 0.05 + 1e-9, "ended {d} m from the goal");
        assert_eq!(world.robots()[0].command, (0.0, 0.0));
    }

    fn obstacle(centre: Vector, velocity: Vector, r: f64) -> Obstacle {
        Obstacle {
            centre,
            velocity,
            combined_radius: r,
        }
    }

    #[test]
    fn time_to_collision_is_exact_and_handles_overlap() {
        let o = obstacle((5.0, 0.0), (0.0, 0.0), 1.0);
        assert!((time_to_collision((1.0, 0.0), &o) - 4.0).abs() < 1e-12);
        assert_eq!(time_to_collision((0.0, 1.0), &o), f64::INFINITY);
        assert_eq!(time_to_collision((-1.0, 0.0), &o), f64::INFINITY);
        // Head-on with a moving obstacle: closing at 2 m/s over 4 m.
        let m = obstacle((5.0, 0.0), (-1.0, 0.0), 1.0);
        assert!((time_to_collision((1.0, 0.0), &m) - 2.0).abs() < 1e-12);
        // Already overlapping: only approaching is a collision.
        let inside = obstacle((0.2, 0.3), (0.0, 0.0), 0.5);
        assert_eq!(time_to_collision((1.0, 0.0), &inside), 0.0);
        assert_eq!(time_to_collision((0.0, -1.0), &inside), f64::INFINITY);
    }

    #[test]
    fn the_preferred_velocity_wins_when_free_and_the_longest_ttc_when_none_is() {
        let vo = Vo::from_params(&BTreeMap::new(), "c").unwrap();
        let grid = &vo.grid;
        assert_eq!(grid.len(), HEADINGS * SPEED_FRACTIONS.len() + 1);
        assert_eq!(select(grid, (0.5, 0.0), &[], 3.0), 0);
        // A wall point dead ahead: straight on at speed is in the VO, the choice veers off.
        let wall = [obstacle((1.0, 0.0), (0.0, 0.0), 0.44)];
        let i = select(grid, (0.5, 0.0), &wall, 3.0);
        assert!(grid[i].1 != 0.0, "veers: {:?}", grid[i]);
        // Surrounded by a fast obstacle bearing down: everything is in some VO; the candidate
        // that runs away longest is taken, never NaN.
        let chaser = [
            obstacle((0.0, 0.0), (0.0, 0.0), 0.1),
            obstacle((-0.5, 0.0), (5.0, 0.0), 0.2),
        ];
        let i = select(grid, (0.5, 0.0), &chaser, 3.0);
        assert!(grid[i].0 > 0.0);
    }

    #[test]
    fn an_empty_scan_and_no_tracks_give_a_finite_command() {
        let mut vo = Vo::from_params(&BTreeMap::new(), "c").unwrap();
        vo.reset(&robot(0, (1.0, 1.0, 0.0), [5.0, 1.0]));
        let obs = Observation {
            ranges: Vec::new(),
            angles: Vec::new(),
            max_range_m: 10.0,
            pose: Pose {
                x_m: 1.0,
                y_m: 1.0,
                heading_rad: 3.0,
            },
            velocity: (0.0, 0.0),
            stalled: false,
            time_s: 0.0,
            tracks: Vec::new(),
        };
        let (v, w) = vo.act(&obs);
        assert!(v.is_finite() && w.is_finite() && v >= 0.0);
        // A track exactly on top of the robot.
        let obs = Observation {
            tracks: vec![Track {
                id: 1,
                position: (1.0, 1.0),
                velocity: (0.0, 0.0),
            }],
            ..obs
        };
        let (v, w) = vo.act(&obs);
        assert!(v.is_finite() && w.is_finite());
    }
}
