//! Following a route: which waypoint a robot is heading for, and when it has arrived.
//!
//! A route is the start position followed by the situation's waypoints. The follower heads for
//! one point at a time and switches to the next when within `switch_m` of it; arrival is
//! detected here, by the follower, not by the simulator (as the paper's client did). At the end
//! of the route: `stop` finishes; `reverse` walks the points back to the start and then forward
//! again; `loop` goes from the last waypoint to the first one and round again.

use crate::mission::AtEnd;
use crate::situation::Robot;

/// Where a robot is on its route.
#[derive(Debug, Clone, PartialEq)]
pub struct RouteFollower {
    points: Vec<(f64, f64)>,
    at_end: AtEnd,
    switch_m: f64,
    next: usize,
    forward: bool,
    finished: bool,
}

impl RouteFollower {
    /// A follower at the start of `robot`'s route, switching within `switch_m` metres.
    pub fn new(robot: &Robot, switch_m: f64) -> Self {
        let waypoints: Vec<(f64, f64)> = robot.waypoints.iter().map(|w| (w[0], w[1])).collect();
        Self::through(
            (robot.start.x_m, robot.start.y_m),
            &waypoints,
            robot.at_end,
            switch_m,
        )
    }

    /// A follower at `start` of the route through `waypoints`, ending as `at_end` says.
    pub fn through(
        start: (f64, f64),
        waypoints: &[(f64, f64)],
        at_end: AtEnd,
        switch_m: f64,
    ) -> Self {
        let mut points = vec![start];
        points.extend(waypoints);
        let finished = points.len() < 2;
        Self {
            points,
            at_end,
            switch_m,
            next: 1,
            forward: true,
            finished,
        }
    }

    /// Index into [start, waypoints…] of the point being headed for.
    pub fn next_index(&self) -> usize {
        self.next
    }

    /// The waypoints still ahead, in driving order, for a robot restarted where it stands: a
    /// `stop` or `reverse` route's points from the one headed for to the end of this pass; a
    /// `loop` route's whole cycle rotated to begin at the one headed for (so that its legs
    /// stay the ones it drove). Empty once a `stop` route is complete.
    pub fn remaining(&self) -> Vec<(f64, f64)> {
        if self.finished {
            return Vec::new();
        }
        match (self.forward, self.at_end) {
            (true, AtEnd::Loop) => self.points[self.next..]
                .iter()
                .chain(&self.points[1..self.next])
                .copied()
                .collect(),
            (true, _) => self.points[self.next..].to_vec(),
            (false, _) => self.points[..=self.next].iter().rev().copied().collect(),
        }
    }

    /// Whether a `stop` route is complete.
    pub fn finished(&self) -> bool {
        self.finished
    }

    /// The point to head for from `position`, after switching past every point already within
    /// reach; `None` once a `stop` route is complete.
    pub fn target(&mut self, position: (f64, f64)) -> Option<(f64, f64)> {
        // At most one switch per point per call, so a route whose points all lie within reach
        // cannot spin forever.
        for _ in 0..self.points.len() {
            if self.finished {
                return None;
            }
            let p = self.points[self.next];
            if (p.0 - position.0).hypot(p.1 - position.1) > self.switch_m {
                break;
            }
            self.advance();
        }
        (!self.finished).then(|| self.points[self.next])
    }

    fn advance(&mut self) {
        let last = self.points.len() - 1;
        match (self.forward, self.next, self.at_end) {
            (true, n, _) if n < last => self.next += 1,
            (true, _, AtEnd::Stop) => self.finished = true,
            (true, _, AtEnd::Loop) => self.next = 1,
            (true, _, AtEnd::Reverse) => {
                self.forward = false;
                self.next = last - 1;
            }
            (false, 0, _) => {
                self.forward = true;
                self.next = 1;
            }
            (false, _, _) => self.next -= 1,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geometry::Body;
    use crate::mission::ControllerSpec;
    use crate::situation::{Pose, Role};

    fn route(at_end: AtEnd) -> RouteFollower {
        let robot = Robot {
            id: 1,
            role: Role::Peer,
            body: Body::default(),
            start: Pose {
                x_m: 0.0,
                y_m: 0.0,
                heading_rad: 0.0,
            },
            waypoints: vec![[1.0, 0.0], [2.0, 0.0]],
            controller: ControllerSpec {
                name: "straight".into(),
                params: Default::default(),
                fault: None,
                control_period_s: None,
                perception: None,
                keep_alive: false,
                step_timeout_s: None,
            },
            at_end,
        };
        RouteFollower::new(&robot, 0.1)
    }

    #[test]
    fn remaining_is_the_route_ahead_in_driving_order() {
        let mut r = route(AtEnd::Stop);
        assert_eq!(r.remaining(), vec![(1.0, 0.0), (2.0, 0.0)]);
        r.target((1.0, 0.0));
        assert_eq!(r.remaining(), vec![(2.0, 0.0)]);
        r.target((2.0, 0.0));
        assert!(r.remaining().is_empty());

        let mut r = route(AtEnd::Loop);
        r.target((1.0, 0.0));
        assert_eq!(r.remaining(), vec![(2.0, 0.0), (1.0, 0.0)]);

        let mut r = route(AtEnd::Reverse);
        r.target((1.0, 0.0));
        r.target((2.0, 0.0));
        assert_eq!(r.remaining(), vec![(1.0, 0.0), (0.0, 0.0)]);
    }

    #[test]
    fn stop_finishes_at_the_last_waypoint() {
        let mut r = route(AtEnd::Stop);
        assert_eq!(r.target((0.0, 0.0)), Some((1.0, 0.0)));
        assert_eq!(r.target((1.0, 0.05)), Some((2.0, 0.0)));
        assert_eq!(r.target((2.0, 0.0)), None);
        assert!(r.finished());
    }

    #[test]
    fn reverse_walks_back_to_the_start_and_out_again() {
        let mut r = route(AtEnd::Reverse);
        let visits: Vec<Option<(f64, f64)>> = [(1.0, 0.0), (2.0, 0.0), (1.0, 0.0), (0.0, 0.0)]
            .into_iter()
            .map(|p| r.target(p))
            .collect();
        assert_eq!(
            visits,
            vec![
                Some((2.0, 0.0)),
                Some((1.0, 0.0)),
                Some((0.0, 0.0)),
                Some((1.0, 0.0))
            ]
        );
    }

    #[test]
    fn loop_returns_to_the_first_waypoint() {
        let mut r = route(AtEnd::Loop);
        r.target((1.0, 0.0));
        assert_eq!(r.target((2.0, 0.0)), Some((1.0, 0.0)));
        assert!(!r.finished());
    }
}
