//! # Seeded faults
//!
//! **What it does.** A catalogue of named defects that can be switched on in the built-in
//! controllers with a controller spec's `fault` field (`[run.controller] name = "snd_follow"`,
//! `fault = "mirrored_scan"`). Each stands for a class of bug real navigation code has. With no
//! fault a controller is exactly itself: every seam below is a no-op for `None`.
//!
//! **Why.** Run scores say how bad a run looked, not how good a way of generating situations is
//! at finding bugs. The proportion of known faults a strategy finds at a budget (its kill rate)
//! does (Arnold & Alexander 2013, §6, after Nguyen et al.); `sitgen faults` measures it and
//! `docs/faults.md` gives the kill rule.
//!
//! **Where a fault acts.** In one of three seams, each named here so that the catalogue and
//! every place it reaches into a controller can be found from this file:
//! - *observation*: [`wrap`] puts the controller behind [`Seeded`], which changes what it is
//!   given to see (`mirrored_scan`, `stale_scan`, `narrow_fov`);
//! - *parameters*: the controller's resolved parameters are changed once, at reset
//!   ([`switch_m`], [`own_radius_m`], and SND's own `SndParams::under_fault` in `snd.rs`,
//!   which keeps this file free of any controller's types);
//! - *logic*: one changed line in the algorithm, at a `Seeded fault` comment that names it
//!   (`snd.rs`, `vo.rs`, `dwa.rs`), tested with [`Fault::is`].
//!
//! **Parameters.** `fault`: a fault id from [`CATALOGUE`] that lists the controller; default
//! none.
//!
//! **Source.** The bug classes follow Nguyen et al.'s use of seeded faults to compare test
//! generators; the SND faults follow its steps in `reference/algorithms.md` §1 (one of them,
//! `turn_rate_in_radians`, is Player ≥ 3.1's own unit bug, §1.2).

use std::f64::consts::{FRAC_PI_4, PI};

use super::{Command, Controller};
use crate::error::{join, SpecError};
use crate::mission::{AtEnd, ControllerSpec};
use crate::sim::{wrap_angle, Observation};
use crate::situation::Robot;

/// A seeded fault.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum Fault {
    /// SND: beams one sector off in the full circle.
    SectorOffByOne,
    /// Scan read in reverse order.
    MirroredScan,
    /// SND: turn rate read as radians per second.
    TurnRateInRadians,
    /// SND: Ds_max halved.
    SafetyDistanceHalved,
    /// SND: the goal-corridor test always passes.
    CorridorTestSkipped,
    /// SND: no stop for an obstacle inside the robot radius.
    InsideRadiusStopRemoved,
    /// The previous step's scan.
    StaleScan,
    /// A 90° field of view.
    NarrowFov,
    /// Waypoints reached at four times the switching distance.
    SwitchDistanceTooLarge,
    /// SND: the smooth deviation's sign flipped.
    DeviationSignFlipped,
    /// SND: speed without the clearance factor.
    SpeedIgnoresClearance,
    /// SND: Player's default 0.25 m robot radius.
    PlayerDefaultRadius,
    /// SND: the valley corner test at half its clearance.
    CornerClearanceHalved,
    /// VO: peers taken as standing still.
    VoStaticPeers,
    /// VO: its own radius left out.
    VoPointRobot,
    /// DWA: braking without the control period.
    DwaNoBrakingMargin,
    /// DWA: the robot a point.
    DwaPointRobot,
    /// Headings within 3° of ±π read as ±177°.
    HeadingWrapNearPi,
    /// Every command a stop once a 16-bit tick count has wrapped (524.288 s).
    WatchdogOverflow,
    /// Tracks past the third dropped with their laser returns.
    TrackDroppedInCrowd,
    /// SND: a goal behind taken as its mirror image ahead.
    GoalBehindReflected,
    /// SND: range jumps of 1.15–1.25 m not taken as gaps.
    GapBandMissed,
    /// A `loop` route ends after its first lap.
    LoopIndexNotReset,
    /// SND: readings at exactly the maximum range taken as obstacles.
    MaxRangeAsObstacle,
    /// Readings under 0.3 m reported as no return.
    MinRangeDropout,
    /// The tenth waypoint of a route of sixteen or more skipped.
    LongRouteWaypointSkipped,
    /// The heading read through a gyro 1 % off in scale.
    GyroScaleError,
}

/// A fault's entry in the catalogue.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FaultInfo {
    /// The fault.
    pub fault: Fault,
    /// Its id, as specs write it.
    pub id: &'static str,
    /// The built-in controllers it can be switched on in.
    pub controllers: &'static [&'static str],
    /// What it changes.
    pub changes: &'static str,
    /// The real bug class it stands for.
    pub stands_for: &'static str,
    /// The kind of situation that exposes it, for a fault that shows only in particular
    /// circumstances; None for one that can show wherever its controller avoids anything.
    pub exposed_by: Option<&'static str>,
}

const SND: &[&str] = &["snd", "snd_follow"];
const LASER: &[&str] = &["snd", "snd_follow", "vo", "dwa"];
const ROUTE: &[&str] = &["snd_follow", "vo", "dwa"];

/// Every fault, in a fixed order (ids are stable; the order is the one reports list them in).
/// The last ten show only in particular circumstances (a heading, a time, a crowd, a route's
/// shape, a range): they tell generation strategies apart where the first ones do not.
pub const CATALOGUE: [FaultInfo; 27] = [
    FaultInfo {
        fault: Fault::SectorOffByOne,
        id: "sector_off_by_one",
        controllers: SND,
        changes: "every beam lands one sector counter-clockwise of its own in SND's full circle",
        stands_for: "off-by-one in an index mapping",
        exposed_by: None,
    },
    FaultInfo {
        fault: Fault::MirroredScan,
        id: "mirrored_scan",
        controllers: LASER,
        changes:
            "the scan's ranges are read in reverse order: what lies right is taken to lie left",
        stands_for: "a frame or handedness convention mismatch between a driver and its user",
        exposed_by: None,
    },
    FaultInfo {
        fault: Fault::TurnRateInRadians,
        id: "turn_rate_in_radians",
        controllers: SND,
        changes: "max_turn_rate_deg_s is taken as radians per second (60 becomes 3438°/s)",
        stands_for: "a unit mix-up (Player ≥ 3.1's SND has this very bug)",
        exposed_by: None,
    },
    FaultInfo {
        fault: Fault::SafetyDistanceHalved,
        id: "safety_distance_halved",
        controllers: SND,
        changes: "Ds_max (obstacle_avoid_dist) is halved: SND deviates later and slows less near \
                  obstacles",
        stands_for: "a wrong constant or a parameter tuned for another robot",
        exposed_by: None,
    },
    FaultInfo {
        fault: Fault::CorridorTestSkipped,
        id: "corridor_test_skipped",
        controllers: SND,
        changes: "the goal-corridor test always passes: SND heads for the goal whenever it lies \
                  ahead, however blocked the way",
        stands_for: "a missing check (a guard deleted or short-circuited)",
        exposed_by: None,
    },
    FaultInfo {
        fault: Fault::InsideRadiusStopRemoved,
        id: "inside_radius_stop_removed",
        controllers: SND,
        changes: "step 7's stop for an obstacle inside the robot radius is gone: SND steers on by \
                  valleys",
        stands_for: "a removed safety interlock",
        exposed_by: None,
    },
    FaultInfo {
        fault: Fault::StaleScan,
        id: "stale_scan",
        controllers: LASER,
        changes: "the controller acts on the previous step's scan and tracks with the current pose",
        stands_for: "stale sensor data (a buffering or threading bug, latency not accounted for)",
        exposed_by: None,
    },
    FaultInfo {
        fault: Fault::NarrowFov,
        id: "narrow_fov",
        controllers: LASER,
        changes: "beams and tracks more than 45° off the heading are dropped: a 90° laser in \
                  place of 180°",
        stands_for: "a sensor misconfigured (the driver's field of view narrower than the device)",
        exposed_by: None,
    },
    FaultInfo {
        fault: Fault::SwitchDistanceTooLarge,
        id: "switch_distance_too_large",
        controllers: ROUTE,
        changes: "a waypoint counts as reached at four times the switching distance: corners are \
                  cut",
        stands_for: "a mis-tuned arrival tolerance",
        exposed_by: None,
    },
    FaultInfo {
        fault: Fault::DeviationSignFlipped,
        id: "deviation_sign_flipped",
        controllers: SND,
        changes: "the smooth deviation S_ao pushes toward nearby obstacles instead of away",
        stands_for: "a sign error",
        exposed_by: None,
    },
    FaultInfo {
        fault: Fault::SpeedIgnoresClearance,
        id: "speed_ignores_clearance",
        controllers: SND,
        changes: "the speed law drops its clearance factor: full speed up to obstacles",
        stands_for: "a missing term in a control law",
        exposed_by: None,
    },
    FaultInfo {
        fault: Fault::PlayerDefaultRadius,
        id: "player_default_radius",
        controllers: SND,
        changes: "R is Player's default 0.25 m, not the body's enclosing radius (0.438 m for the \
                  Pioneer 3-AT), and the gap and safety distances that default to multiples of \
                  R follow it",
        stands_for: "a configuration default that does not fit the robot",
        exposed_by: None,
    },
    FaultInfo {
        fault: Fault::CornerClearanceHalved,
        id: "corner_clearance_halved",
        controllers: SND,
        changes: "the valley corner test asks for 1.1 R instead of 2.2 R: SND heads for openings \
                  its body cannot pass",
        stands_for: "a wrong constant",
        exposed_by: None,
    },
    FaultInfo {
        fault: Fault::VoStaticPeers,
        id: "vo_static_peers",
        controllers: &["vo"],
        changes: "tracked robots' velocities are taken as zero: peers are treated as standing \
                  obstacles",
        stands_for: "an input not wired through (the velocity estimate dropped)",
        exposed_by: None,
    },
    FaultInfo {
        fault: Fault::VoPointRobot,
        id: "vo_point_robot",
        controllers: &["vo"],
        changes: "the robot's own radius is left out of every velocity obstacle",
        stands_for: "the robot's footprint ignored (the Minkowski sum omitted)",
        exposed_by: None,
    },
    FaultInfo {
        fault: Fault::DwaNoBrakingMargin,
        id: "dwa_no_braking_margin",
        controllers: &["dwa"],
        changes: "admissibility forgets that a command holds for a control period: the whole \
                  clearance counts as braking distance",
        stands_for: "a discrete-time effect ignored in a safety bound",
        exposed_by: None,
    },
    FaultInfo {
        fault: Fault::DwaPointRobot,
        id: "dwa_point_robot",
        controllers: &["dwa"],
        changes: "the robot is a point: its disc has radius 0, so arcs are cleared for its centre \
                  only",
        stands_for: "the robot's footprint ignored",
        exposed_by: None,
    },
    FaultInfo {
        fault: Fault::HeadingWrapNearPi,
        id: "heading_wrap_near_pi",
        controllers: LASER,
        changes: "headings within 3° of ±180° are read as ±177°: driving due west, the robot \
                  believes it is a few degrees off its course",
        stands_for: "an angle-wrap error at ±π (a yaw taken through a saturating conversion)",
        exposed_by: Some("driving within 3° of due west (a route leg heading west)"),
    },
    FaultInfo {
        fault: Fault::WatchdogOverflow,
        id: "watchdog_overflow",
        controllers: LASER,
        changes: "once a 16-bit count of 8 ms ticks has wrapped (524.288 s), every scan looks \
                  stale to the watchdog and every command is a stop",
        stands_for: "a counter or timer that overflows after minutes of running",
        exposed_by: Some("a run that lasts more than 524 s"),
    },
    FaultInfo {
        fault: Fault::TrackDroppedInCrowd,
        id: "track_dropped_in_crowd",
        controllers: LASER,
        changes: "with four or more robots in view, those past the first three (by id) are \
                  dropped, and their laser returns removed as clutter",
        stands_for: "a fixed-size track table overflowing in a crowd",
        exposed_by: Some("four or more robots in view at once"),
    },
    FaultInfo {
        fault: Fault::GoalBehindReflected,
        id: "goal_behind_reflected",
        controllers: &["snd_follow"],
        changes: "a waypoint more than 170° off the heading is taken as its mirror image ahead: \
                  the robot drives away from a goal right behind it",
        stands_for: "a wrong branch for goals behind the robot (an acos where an atan2 belongs)",
        exposed_by: Some("a waypoint more than 170° off the heading (a route that doubles back)"),
    },
    FaultInfo {
        fault: Fault::GapBandMissed,
        id: "gap_band_missed",
        controllers: SND,
        changes: "range jumps between 1.15 and 1.25 m are not taken as gaps, so openings \
                  behind such a step are not seen",
        stands_for: "a gap test wrong only for one band of widths (a missing bin of a table)",
        exposed_by: Some("a range step of 1.15-1.25 m between neighbouring beams at an opening"),
    },
    FaultInfo {
        fault: Fault::LoopIndexNotReset,
        id: "loop_index_not_reset",
        controllers: ROUTE,
        changes: "a loop route's waypoint index is not reset after the first lap: the robot \
                  stops at the last waypoint",
        stands_for: "a loop counter not reset (state that only a second pass exercises)",
        exposed_by: Some("a loop route driven past its first lap"),
    },
    FaultInfo {
        fault: Fault::MaxRangeAsObstacle,
        id: "max_range_as_obstacle",
        controllers: SND,
        changes: "readings at exactly the laser's maximum range are taken as obstacles there \
                  (<= where < belongs)",
        stands_for: "a no-return sentinel not filtered (an off-by-one comparison)",
        exposed_by: Some("open space with beams out to the laser's maximum range"),
    },
    FaultInfo {
        fault: Fault::MinRangeDropout,
        id: "min_range_dropout",
        controllers: &["snd", "snd_follow", "dwa"],
        changes: "readings under 0.3 m are reported as no return: whatever nearly touches \
                  the robot vanishes",
        stands_for: "a driver's too-close status mapped to no return",
        exposed_by: Some("something within 0.3 m of the laser: 5 cm from a Pioneer's side"),
    },
    FaultInfo {
        fault: Fault::LongRouteWaypointSkipped,
        id: "long_route_waypoint_skipped",
        controllers: ROUTE,
        changes: "on routes of sixteen or more waypoints the tenth is skipped: the robot cuts \
                  from the ninth to the eleventh",
        stands_for: "an index incremented twice on one path through the code",
        exposed_by: Some("a route of sixteen or more waypoints whose tenth matters"),
    },
    FaultInfo {
        fault: Fault::GyroScaleError,
        id: "gyro_scale_error",
        controllers: LASER,
        changes: "the heading is the start heading plus 1.01 times the turn since: a net \
                  turn of 360° leaves it 3.6° off",
        stands_for: "a sensor scale factor off by a per cent (an uncalibrated gyro)",
        exposed_by: Some("turning through a large net angle (loops, long winding routes)"),
    },
];

impl Fault {
    /// Its catalogue entry.
    pub fn info(self) -> &'static FaultInfo {
        CATALOGUE
            .iter()
            .find(|i| i.fault == self)
            .expect("every fault is in the catalogue")
    }

    /// Its id.
    pub fn id(self) -> &'static str {
        self.info().id
    }

    /// The fault with id `id`.
    pub fn from_id(id: &str) -> Option<Self> {
        CATALOGUE.iter().find(|i| i.id == id).map(|i| i.fault)
    }

    /// Whether `fault` (a controller's, possibly none) is this one: the test at every logic
    /// seam.
    pub fn is(self, fault: Option<Fault>) -> bool {
        fault == Some(self)
    }
}

/// The ids of the faults controller `name` has, in catalogue order.
pub fn faults_of(name: &str) -> Vec<&'static str> {
    CATALOGUE
        .iter()
        .filter(|i| i.controllers.contains(&name))
        .map(|i| i.id)
        .collect()
}

/// The fault a controller spec switches on, checked against its controller; `path` names the
/// spec in errors.
pub fn of(spec: &ControllerSpec, path: &str) -> Result<Option<Fault>, SpecError> {
    let Some(id) = spec.fault.as_deref() else {
        return Ok(None);
    };
    let field = join(path, "fault");
    let Some(fault) = Fault::from_id(id) else {
        let ids: Vec<&str> = CATALOGUE.iter().map(|i| i.id).collect();
        return Err(SpecError::new(
            field,
            format!("unknown fault `{id}`; expected one of {}", ids.join(", ")),
        ));
    };
    if !fault.info().controllers.contains(&spec.name.as_str()) {
        let own = faults_of(&spec.name);
        let has = if own.is_empty() {
            "it has none".to_string()
        } else {
            format!("its faults: {}", own.join(", "))
        };
        return Err(SpecError::new(
            field,
            format!(
                "`{id}` is not a fault of controller `{}` ({has}); `{id}` is one of {}'s",
                spec.name,
                fault.info().controllers.join(", ")
            ),
        ));
    }
    Ok(Some(fault))
}

/// Parameter seam: the waypoint switching distance under `fault`.
pub fn switch_m(fault: Option<Fault>, switch_m: f64) -> f64 {
    if Fault::SwitchDistanceTooLarge.is(fault) {
        4.0 * switch_m
    } else {
        switch_m
    }
}

/// Parameter seam: the robot's own radius, as a disc-model avoider takes it, under `fault`.
pub fn own_radius_m(fault: Option<Fault>, robot: &Robot) -> f64 {
    if Fault::DwaPointRobot.is(fault) {
        0.0
    } else {
        robot.body.enclosing_radius()
    }
}

/// Half the field of view `narrow_fov` leaves, radians.
const NARROW_HALF_FOV: f64 = FRAC_PI_4;
/// How near ±π a heading `heading_wrap_near_pi` saturates, radians (3°).
const WRAP_BAND: f64 = PI / 60.0;
/// When `watchdog_overflow`'s 16-bit count of 8 ms ticks wraps, seconds.
const WATCHDOG_WRAP_S: f64 = 65_536.0 * 0.008;
/// How far off the heading a waypoint must be for `goal_behind_reflected`, radians (170°).
const BEHIND: f64 = PI * 17.0 / 18.0;
/// Tracks `track_dropped_in_crowd`'s table holds.
const TRACK_TABLE: usize = 3;
/// Returns this near a dropped track's centre are removed with it, metres (a Pioneer's
/// enclosing radius and a margin).
const TRACK_CLUTTER_M: f64 = 0.5;
/// Readings `min_range_dropout` reports as no return, metres.
const DROPOUT_M: f64 = 0.3;
/// `gyro_scale_error`'s scale factor.
const GYRO_SCALE: f64 = 1.01;
/// Waypoints a route needs for `long_route_waypoint_skipped` to skip its tenth.
const LONG_ROUTE: usize = 16;

/// Observation seam: `controller` behind [`Seeded`] if `fault` changes what it sees, or the
/// route it is given at reset.
pub fn wrap(controller: Box<dyn Controller>, fault: Option<Fault>) -> Box<dyn Controller> {
    match fault {
        Some(
            f @ (Fault::MirroredScan
            | Fault::StaleScan
            | Fault::NarrowFov
            | Fault::HeadingWrapNearPi
            | Fault::WatchdogOverflow
            | Fault::TrackDroppedInCrowd
            | Fault::GoalBehindReflected
            | Fault::LoopIndexNotReset
            | Fault::MaxRangeAsObstacle
            | Fault::MinRangeDropout
            | Fault::LongRouteWaypointSkipped
            | Fault::GyroScaleError),
        ) => Box::new(Seeded {
            inner: controller,
            fault: f,
            last: None,
            gyro: None,
        }),
        _ => controller,
    }
}

/// A controller given a faulty view of the world.
#[derive(Clone)]
pub struct Seeded {
    inner: Box<dyn Controller>,
    fault: Fault,
    /// The previous observation (`stale_scan`).
    last: Option<Observation>,
    /// The start heading, and the true heading last seen with the turn since (unwrapped),
    /// radians (`gyro_scale_error`).
    gyro: Option<(f64, f64, f64)>,
}

impl Seeded {
    /// The route the controller is given at reset.
    fn route_of(&self, robot: &Robot) -> Robot {
        let mut given = robot.clone();
        match self.fault {
            Fault::LoopIndexNotReset if given.at_end == AtEnd::Loop => given.at_end = AtEnd::Stop,
            Fault::LongRouteWaypointSkipped if given.waypoints.len() >= LONG_ROUTE => {
                given.waypoints.remove(9);
            }
            _ => {}
        }
        given
    }

    /// What the controller sees of `obs`.
    fn view(&mut self, obs: &Observation) -> Observation {
        let mut seen = obs.clone();
        match self.fault {
            Fault::MirroredScan => seen.ranges.reverse(),
            Fault::StaleScan => {
                if let Some(last) = self.last.replace(obs.clone()) {
                    seen.ranges = last.ranges;
                    seen.angles = last.angles;
                    seen.tracks = last.tracks;
                }
            }
            Fault::NarrowFov => {
                let keep: Vec<bool> = obs
                    .angles
                    .iter()
                    .map(|a| a.abs() <= NARROW_HALF_FOV + 1e-9)
                    .collect();
                let kept = |v: &[f64]| -> Vec<f64> {
                    v.iter()
                        .zip(&keep)
                        .filter(|(_, &k)| k)
                        .map(|(&x, _)| x)
                        .collect()
                };
                seen.ranges = kept(&obs.ranges);
                seen.angles = kept(&obs.angles);
                let pose = obs.pose;
                seen.tracks.retain(|t| {
                    let bearing =
                        (t.position.1 - pose.y_m).atan2(t.position.0 - pose.x_m) - pose.heading_rad;
                    bearing.sin().atan2(bearing.cos()).abs() <= NARROW_HALF_FOV
                });
            }
            Fault::HeadingWrapNearPi => {
                let h = obs.pose.heading_rad;
                seen.pose.heading_rad = h.clamp(-PI + WRAP_BAND, PI - WRAP_BAND);
            }
            Fault::TrackDroppedInCrowd if obs.tracks.len() > TRACK_TABLE => {
                let dropped = seen.tracks.split_off(TRACK_TABLE);
                let p = obs.pose;
                for (r, a) in seen.ranges.iter_mut().zip(&obs.angles) {
                    let (sin, cos) = (p.heading_rad + a).sin_cos();
                    let hit = (p.x_m + *r * cos, p.y_m + *r * sin);
                    let near = |t: &crate::sim::Track| {
                        (hit.0 - t.position.0).hypot(hit.1 - t.position.1) <= TRACK_CLUTTER_M
                    };
                    if *r < obs.max_range_m && dropped.iter().any(near) {
                        *r = obs.max_range_m;
                    }
                }
            }
            Fault::GoalBehindReflected => {
                let target = self
                    .inner
                    .route()
                    .and_then(|r| r.remaining().first().copied());
                if let Some((x, y)) = target {
                    let p = obs.pose;
                    let b = wrap_angle((y - p.y_m).atan2(x - p.x_m) - p.heading_rad);
                    if b.abs() > BEHIND {
                        // The bearing b seen as its mirror image in the lateral axis,
                        // ±π − b, by turning the heading the controller reads.
                        let mirrored = PI.copysign(b) - b;
                        seen.pose.heading_rad = wrap_angle(p.heading_rad + b - mirrored);
                    }
                }
            }
            Fault::MaxRangeAsObstacle => {
                // The smallest maximum above the true one: a reading of exactly the maximum
                // is then below it, as `<=` would take it.
                seen.max_range_m = obs.max_range_m.next_up();
            }
            Fault::MinRangeDropout => {
                for r in &mut seen.ranges {
                    if *r < DROPOUT_M {
                        *r = obs.max_range_m;
                    }
                }
            }
            Fault::GyroScaleError => {
                let h = obs.pose.heading_rad;
                let (start, last, turned) = self.gyro.unwrap_or((h, h, 0.0));
                let turned = turned + wrap_angle(h - last);
                self.gyro = Some((start, h, turned));
                seen.pose.heading_rad = wrap_angle(start + GYRO_SCALE * turned);
            }
            _ => {}
        }
        seen
    }
}

impl Controller for Seeded {
    fn route(&self) -> Option<&super::route::RouteFollower> {
        self.inner.route()
    }

    fn senses(&self) -> bool {
        self.inner.senses()
    }

    fn reset(&mut self, robot: &Robot) {
        self.last = None;
        self.gyro = None;
        let given = self.route_of(robot);
        self.inner.reset(&given);
    }

    fn act(&mut self, obs: &Observation) -> Command {
        if Fault::WatchdogOverflow.is(Some(self.fault)) && obs.time_s >= WATCHDOG_WRAP_S {
            return (0.0, 0.0);
        }
        let seen = self.view(obs);
        self.inner.act(&seen)
    }
}

#[cfg(test)]
mod tests;
