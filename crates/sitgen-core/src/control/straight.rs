//! # `straight` controller
//!
//! **What it does.** Drives at the next waypoint as the crow flies: turns toward it at
//! `turn_gain` × heading error (capped by the simulator's turn-rate limit) and drives forward
//! at `speed_m_s` × cos(error) while the error is within `drive_within_deg`, else turns on the
//! spot. It avoids nothing and never reverses.
//!
//! **Why.** The paper's peer robots: moving obstacles with collision avoidance disabled, on
//! routes that need no planning, so that encounters come from the situation and not from a
//! second controller's choices.
//!
//! **Parameters.**
//! - `speed_m_s` (m/s, default 0.5, in (0, 10]): cruising speed.
//! - `turn_gain` (1/s, default 1.5, in (0, 100]): turn rate per radian of heading error.
//! - `drive_within_deg` (degrees, default 45, in (0, 90]): heading error above which it only turns.
//! - `switch_m` (metres, default 0.3, in (0, 10]): distance at which a waypoint counts as reached.
//! - `start_s` (seconds, default 0, in [0, 3600]): it stands at its start until the run's clock
//!   reaches this, then sets off. A peer's departure can be delayed so that an encounter happens
//!   later at the same place (the search's situation operators time peers this way).
//!
//! **Source.** Arnold & Alexander (2013) §4.1 ("dumb robots … collision avoidance disabled");
//! Stage's position-mode controller turns first and drives when nearly aligned (§2.2).

use std::collections::BTreeMap;

use super::route::RouteFollower;
use super::{param, Command, Controller};
use crate::error::SpecError;
use crate::sim::{wrap_angle, Observation};
use crate::situation::Robot;

/// The `straight` controller.
#[derive(Debug, Clone)]
pub struct Straight {
    speed_m_s: f64,
    turn_gain: f64,
    drive_within: f64,
    switch_m: f64,
    start_s: f64,
    route: Option<RouteFollower>,
}

impl Straight {
    /// Build from named parameters; `path` names them in errors.
    pub fn from_params(params: &BTreeMap<String, f64>, path: &str) -> Result<Self, SpecError> {
        let known = [
            "speed_m_s",
            "turn_gain",
            "drive_within_deg",
            "switch_m",
            "start_s",
        ];
        super::check_known(params, &known, path)?;
        let start_s = params.get("start_s").copied().unwrap_or(0.0);
        SpecError::check_in(&crate::error::join(path, "start_s"), start_s, 0.0, 3600.0)?;
        Ok(Self {
            speed_m_s: param(params, path, "speed_m_s", 0.5, 10.0)?,
            turn_gain: param(params, path, "turn_gain", 1.5, 100.0)?,
            drive_within: param(params, path, "drive_within_deg", 45.0, 90.0)?.to_radians(),
            switch_m: param(params, path, "switch_m", 0.3, 10.0)?,
            start_s,
            route: None,
        })
    }
}

impl Controller for Straight {
    fn senses(&self) -> bool {
        false
    }

    fn route(&self) -> Option<&RouteFollower> {
        self.route.as_ref()
    }

    fn reset(&mut self, robot: &Robot) {
        self.route = Some(RouteFollower::new(robot, self.switch_m));
    }

    fn act(&mut self, obs: &Observation) -> Command {
        let Some(route) = self.route.as_mut() else {
            return (0.0, 0.0);
        };
        if obs.time_s < self.start_s {
            return (0.0, 0.0);
        }
        let here = (obs.pose.x_m, obs.pose.y_m);
        let Some(target) = route.target(here) else {
            return (0.0, 0.0);
        };
        let bearing = (target.1 - here.1).atan2(target.0 - here.0);
        let error = wrap_angle(bearing - obs.pose.heading_rad);
        let v = if error.abs() <= self.drive_within {
            self.speed_m_s * error.cos()
        } else {
            0.0
        };
        (v, self.turn_gain * error)
    }
}
