//! # `follow` controller
//!
//! **What it does.** Pure pursuit along the route (the polyline start → waypoints). Each step it
//! takes the *lookahead point*: the point farthest along the path (the leg into the waypoint it
//! heads for, and the leg after it) at `lookahead_m` from the robot, or the end of the path when
//! all of it is nearer. With that point at (x, y) in the robot frame and d its distance, it drives
//! the circular arc through it: curvature κ = 2·y/d², ω = v·κ at v = `speed_m_s`; when |ω| would
//! exceed `turn_rate_deg_s` it slows down instead of widening the arc. A lookahead point behind
//! (bearing beyond ±90°) is not pursued on an arc: the robot turns on the spot towards it. A
//! point past the corner that lies behind is not taken at all: a hairpin (or the turn back at the
//! end of a `reverse` route) cannot be cut, so the robot drives to the corner first. It avoids
//! nothing and never reverses. At the end of the route it stops, walks the route back, or
//! loops, as the route says (the shared [`RouteFollower`]).
//!
//! **Why.** The baseline that shows what a situation does to a robot that only tracks its path:
//! any collision `follow` has and an avoiding controller does not is avoidance at work. Pure
//! pursuit, rather than aiming at the waypoint, keeps the robot on the legs the planner chose and
//! rounds corners smoothly.
//!
//! **Parameters.**
//! - `lookahead_m` (metres, default 1.0, in (0, 100]): lookahead distance L.
//! - `speed_m_s` (m/s, default 0.5, in (0, 10]): cruising speed.
//! - `turn_rate_deg_s` (degrees per second, default 90, in (0, 3600]): largest turn rate
//!   commanded (the simulator's default limit).
//! - `switch_m` (metres, default 0.3, in (0, 10]): distance at which a waypoint counts as reached.
//!
//! **Source.** Coulter, "Implementation of the Pure Pursuit Path Tracking Algorithm",
//! CMU-RI-TR-92-01 (1992), from memory: lookahead point on the path at distance L, arc of
//! curvature 2·y/L² through it. Waypoint switching: Arnold & Alexander (2013) §4.1, via
//! `route.rs`. Besides switching within `switch_m`, the route moves on to the next leg once the
//! robot is nearer that leg than the one it is on and within L of the corner, which is pure
//! pursuit's own progress along the path (it cuts corners, so it may never come within
//! `switch_m` of one).

use crate::geometry::segment::nearest_point;
use std::collections::BTreeMap;

use super::route::RouteFollower;
use super::{param, Command, Controller};
use crate::error::SpecError;
use crate::sim::Observation;
use crate::situation::Robot;

type Point = (f64, f64);

/// The `follow` controller.
#[derive(Debug, Clone)]
pub struct Follow {
    lookahead_m: f64,
    speed_m_s: f64,
    turn_rate: f64,
    switch_m: f64,
    route: Option<RouteFollower>,
    /// The leg being driven: (the point headed for before the last switch, the point headed
    /// for now).
    leg: (Point, Point),
}

impl Follow {
    /// Build from named parameters; `path` names them in errors.
    pub fn from_params(params: &BTreeMap<String, f64>, path: &str) -> Result<Self, SpecError> {
        let known = ["lookahead_m", "speed_m_s", "turn_rate_deg_s", "switch_m"];
        super::check_known(params, &known, path)?;
        Ok(Self {
            lookahead_m: param(params, path, "lookahead_m", 1.0, 100.0)?,
            speed_m_s: param(params, path, "speed_m_s", 0.5, 10.0)?,
            turn_rate: param(params, path, "turn_rate_deg_s", 90.0, 3600.0)?.to_radians(),
            switch_m: param(params, path, "switch_m", 0.3, 10.0)?,
            route: None,
            leg: ((0.0, 0.0), (0.0, 0.0)),
        })
    }
}

/// Keep `leg` (from, to) the leg being driven: when the route heads for a new point, the leg
/// now starts where the last one ended.
fn note_target(leg: &mut (Point, Point), target: Point) {
    if target != leg.1 {
        *leg = (leg.1, target);
    }
}

/// The route point after `next`: what the route would head for once `next` is reached. Asking
/// a copy of the follower from `next` itself switches past it, so at_end (stop, reverse, loop)
/// is decided in one place, `route.rs`.
fn point_after(route: &RouteFollower, next: Point) -> Option<Point> {
    route.clone().target(next)
}

/// Distance from `p` to the segment a–b.
fn distance_to_leg(p: Point, a: Point, b: Point) -> f64 {
    let q = nearest_point(p, a, b);
    (q.0 - p.0).hypot(q.1 - p.1)
}

/// Where the circle of radius `l` about `p` leaves the segment a–b going from a to b: the
/// larger intersection parameter, if it lies on the segment.
fn circle_exit(p: Point, a: Point, b: Point, l: f64) -> Option<Point> {
    let (dx, dy) = (b.0 - a.0, b.1 - a.1);
    let (fx, fy) = (a.0 - p.0, a.1 - p.1);
    let qa = dx * dx + dy * dy;
    if qa <= 0.0 {
        return None;
    }
    let qb = 2.0 * (fx * dx + fy * dy);
    let qc = fx * fx + fy * fy - l * l;
    let discriminant = qb * qb - 4.0 * qa * qc;
    if discriminant < 0.0 {
        return None;
    }
    let t = (-qb + discriminant.sqrt()) / (2.0 * qa);
    (0.0..=1.0)
        .contains(&t)
        .then_some((a.0 + t * dx, a.1 + t * dy))
}

/// The pure-pursuit lookahead point on the path `legs` (in order) from `p`: the farthest
/// point along the path at distance `l`; the path's end when all of it lies within `l`; the
/// nearest point of the first leg when the whole path is farther than `l` (the quickest way back).
fn lookahead_point(p: Point, legs: &[(Point, Point)], l: f64) -> Point {
    if let Some(exit) = legs
        .iter()
        .rev()
        .find_map(|&(a, b)| circle_exit(p, a, b, l))
    {
        return exit;
    }
    let end = legs[legs.len() - 1].1;
    if (end.0 - p.0).hypot(end.1 - p.1) <= l {
        return end;
    }
    nearest_point(p, legs[0].0, legs[0].1)
}

impl Follow {
    /// The arc through `goal` (robot frame), or a turn on the spot when it lies behind.
    fn pursue(&self, goal: Point) -> Command {
        let (x, y) = goal;
        let d2 = x * x + y * y;
        if d2 < 1e-18 {
            return (0.0, 0.0);
        }
        if x < 0.0 {
            // Behind: an arc through it would be a wide loop; turn towards it instead (left when
            // it lies dead behind, so the choice is deterministic).
            let side = if y < 0.0 { -1.0 } else { 1.0 };
            return (0.0, side * self.turn_rate);
        }
        let curvature = 2.0 * y / d2;
        let v = if curvature.abs() * self.speed_m_s > self.turn_rate {
            self.turn_rate / curvature.abs()
        } else {
            self.speed_m_s
        };
        (v, v * curvature)
    }
}

impl Controller for Follow {
    fn senses(&self) -> bool {
        false
    }

    fn route(&self) -> Option<&RouteFollower> {
        self.route.as_ref()
    }

    fn reset(&mut self, robot: &Robot) {
        let start = (robot.start.x_m, robot.start.y_m);
        self.leg = (start, start);
        self.route = Some(RouteFollower::new(robot, self.switch_m));
    }

    fn act(&mut self, obs: &Observation) -> Command {
        let here = (obs.pose.x_m, obs.pose.y_m);
        let Some(route) = self.route.as_mut() else {
            return (0.0, 0.0);
        };
        let Some(mut next) = route.target(here) else {
            return (0.0, 0.0);
        };
        note_target(&mut self.leg, next);
        let mut after = point_after(route, next);
        if let Some(a) = after {
            // Past the corner when nearer the next leg than this one, with the corner inside
            // the lookahead circle (so that a route folding back on itself cannot switch early).
            let near_corner = (next.0 - here.0).hypot(next.1 - here.1) <= self.lookahead_m;
            if near_corner
                && distance_to_leg(here, next, a) < distance_to_leg(here, self.leg.0, next)
            {
                // Handing the route the corner itself makes it switch past it.
                if let Some(n) = route.target(next) {
                    note_target(&mut self.leg, n);
                    next = n;
                    after = point_after(route, next);
                }
            }
        }
        let (s, c) = obs.pose.heading_rad.sin_cos();
        let to_robot = |p: Point| {
            let (dx, dy) = (p.0 - here.0, p.1 - here.1);
            (c * dx + s * dy, -s * dx + c * dy)
        };
        let mut goal = to_robot(lookahead_point(here, &[self.leg], self.lookahead_m));
        if let Some(a) = after {
            // Past the corner only when that point lies ahead: a hairpin (or the turn back of a
            // `reverse` route) cannot be cut, so the robot drives to the corner first.
            let beyond = to_robot(lookahead_point(
                here,
                &[self.leg, (next, a)],
                self.lookahead_m,
            ));
            if beyond.0 >= 0.0 {
                goal = beyond;
            }
        }
        self.pursue(goal)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::control::tests::run_situation;
    use crate::geometry::Body;
    use crate::grid::{Map, OccupancyGrid};
    use crate::mission::{AtEnd, ControllerSpec};
    use crate::situation::{Pose, Role, Situation};
    use crate::spec::SituationSpec;

    fn agent(waypoints: &[[f64; 2]], at_end: AtEnd) -> Robot {
        Robot {
            id: 0,
            role: Role::Agent,
            body: Body::default(),
            start: Pose {
                x_m: 3.0,
                y_m: 3.0,
                heading_rad: 0.0,
            },
            waypoints: waypoints.to_vec(),
            controller: ControllerSpec {
                name: "follow".into(),
                params: Default::default(),
                fault: None,
                control_period_s: None,
                perception: None,
                keep_alive: false,
                step_timeout_s: None,
            },
            at_end,
        }
    }

    fn open_field(robot: Robot) -> Situation {
        let map = Map {
            grid: OccupancyGrid::filled(200, 200, false),
            resolution_m: 0.1,
        };
        Situation::new(&map, vec![robot], SituationSpec::default(), 0)
    }

    fn follow() -> ControllerSpec {
        ControllerSpec {
            name: "follow".into(),
            params: Default::default(),
            fault: None,
            control_period_s: None,
            perception: None,
            keep_alive: false,
            step_timeout_s: None,
        }
    }

    /// The error building `follow` with `params`, as text.
    fn build_error(params: &[(&str, f64)]) -> String {
        crate::control::tests::build_error("follow", params, "c")
    }

    #[test]
    fn parameter_errors_are_named() {
        let e = build_error(&[("lookahead", 1.0)]);
        assert!(
            e.starts_with("c.params.lookahead: unknown parameter"),
            "{e}"
        );
        assert_eq!(
            build_error(&[("lookahead_m", 0.0)]),
            "c.params.lookahead_m: 0 is not in (0, 100]"
        );
        let e = build_error(&[("turn_rate_deg_s", f64::NAN)]);
        assert!(e.starts_with("c.params.turn_rate_deg_s: "), "{e}");
    }

    /// Distance from `p` to the polyline through `points`.
    fn off_path(p: Point, points: &[Point]) -> f64 {
        points
            .windows(2)
            .map(|w| distance_to_leg(p, w[0], w[1]))
            .fold(f64::INFINITY, f64::min)
    }

    #[test]
    fn follows_a_multi_waypoint_route_to_the_end_stops_and_never_reverses() {
        // A zig-zag with a right-angle corner, a sharp turn back, and a long leg.
        let waypoints = [[10.0, 3.0], [10.0, 9.0], [4.0, 12.0], [16.0, 16.0]];
        let s = open_field(agent(&waypoints, AtEnd::Stop));
        let mut path = vec![(3.0, 3.0)];
        path.extend(waypoints.iter().map(|w| (w[0], w[1])));
        let mut worst_off_path: f64 = 0.0;
        let mut reversed = false;
        let mut corners_passed = 0;
        let world = run_situation(&s, &follow(), 2000, |w| {
            let r = &w.robots()[0];
            let p = (r.pose.x_m, r.pose.y_m);
            worst_off_path = worst_off_path.max(off_path(p, &path));
            reversed |= r.command.0 < 0.0;
            if corners_passed < 3 {
                let c = path[corners_passed + 1];
                if (p.0 - c.0).hypot(p.1 - c.1) < 1.0 {
                    corners_passed += 1;
                }
            }
            false
        });
        let r = &world.robots()[0];
        let end = (16.0, 16.0);
        let d = (r.pose.x_m - end.0).hypot(r.pose.y_m - end.1);
        assert!(d <= 0.3 + 0.05 + 1e-9, "ended {d} m from the last waypoint");
        assert_eq!(r.command, (0.0, 0.0), "stopped at the end");
        assert!(!reversed, "never reverses");
        assert_eq!(corners_passed, 3, "went round every corner");
        // Corner cutting is bounded by the lookahead distance.
        assert!(
            worst_off_path < 1.0,
            "strayed {worst_off_path} m off the path"
        );
    }

    #[test]
    fn reverse_walks_the_route_back() {
        let s = open_field(agent(&[[10.0, 3.0], [10.0, 9.0]], AtEnd::Reverse));
        let mut back_at_start = false;
        let mut reached_end = false;
        run_situation(&s, &follow(), 1500, |w| {
            let p = &w.robots()[0].pose;
            reached_end |= (p.x_m - 10.0).hypot(p.y_m - 9.0) < 0.35;
            back_at_start |= reached_end && (p.x_m - 3.0).hypot(p.y_m - 3.0) < 0.35;
            back_at_start
        });
        assert!(reached_end && back_at_start);
    }

    #[test]
    fn the_lookahead_point_is_on_the_next_leg_near_a_corner() {
        let legs = [((0.0, 0.0), (4.0, 0.0)), ((4.0, 0.0), (4.0, 4.0))];
        let g = lookahead_point((3.5, 0.0), &legs, 1.0);
        assert!((g.0 - 4.0).abs() < 1e-12 && (g.1 - 0.866_025_403_784_438_6).abs() < 1e-9);
        // Far off the path: back to its nearest point.
        assert_eq!(lookahead_point((2.0, 5.0), &legs[..1], 1.0), (2.0, 0.0));
        // All of it within reach: its end.
        assert_eq!(lookahead_point((3.9, 0.0), &legs[..1], 1.0), (4.0, 0.0));
    }

    #[test]
    fn a_point_behind_is_turned_to_on_the_spot_and_sharp_arcs_are_slowed() {
        let f = Follow::from_params(&BTreeMap::new(), "c").unwrap();
        assert_eq!(f.pursue((-1.0, -0.1)), (0.0, -f.turn_rate));
        let (v, w) = f.pursue((0.1, 0.5));
        assert!(v < f.speed_m_s && (w - f.turn_rate).abs() < 1e-12);
        let (v, w) = f.pursue((1.0, 0.0));
        assert_eq!((v, w), (0.5, 0.0));
    }
}
