//! # `snd` controller: Smoothed Nearness-Diagram navigation
//!
//! **What it does.** Drives to one goal, the robot's last waypoint, avoiding what its laser
//! sees, by Durham & Bullo's Smoothed Nearness-Diagram as Player's `snd` driver computes it
//! (`reference/algorithms.md` §1.4), step for step: the scan becomes a full circle of N
//! sectors (unseen directions free), a nearness diagram, gaps where the range jumps by more
//! than `min_gap_width`, valleys between gaps whose opening passes a corner-clearance test,
//! the valley whose rising gap lies nearest the goal, a target sector (the goal itself when
//! its corridor is clear, else beside the corner at a safe angle, or mid-valley when narrow),
//! a deviation that blends every obstacle within the safety distance into one push, and a
//! command: turn rate proportional to the heading error, speed falling with clearance,
//! heading error and nearness to the goal. Within `goal_position_tol` of the goal it turns on
//! the spot to the goal heading, then stops for good. It never reverses. Other waypoints and
//! the route's `at_end` are ignored: [`SndFollow`](super::SndFollow) drives routes.
//!
//! **Why.** The navigator under test in Arnold & Alexander (2013). Faithful to the driver so
//! that the weaknesses they found (slowing near any obstacle, unseen obstacles taken as free
//! space, valley oscillation, no backing up) are reproduced rather than fixed.
//!
//! **Parameters.** Player's names; angles in degrees as Player's cfg files write them; R is
//! `robot_radius`. Ranges are checked as (0, upper].
//! - `robot_radius` (m, default: the body's enclosing radius about its rotation centre, about
//!   0.438 m for the Pioneer 3-AT, taken at reset; in (0, 10]): the circle SND keeps clear.
//!   Player's default 0.25 m does not enclose the Pioneer's footprint, so its corners would
//!   touch obstacles before the "obstacle inside radius" stop fires.
//! - `min_gap_width` (m, default 2R, in (0, 100]): range jump that makes a gap.
//! - `obstacle_avoid_dist` (m, default 4R, in (0, 100]): largest safety distance Ds_max.
//! - `max_speed` (m/s, default 0.5, in (0, 10]).
//! - `max_turn_rate_deg_s` (degrees/s, default 60, in (0, 3600]): ω_max. Player 3.0.2's
//!   effective default (1.0472 rad/s); Player ≥ 3.1's code returns 60 *radians*/s by a unit
//!   bug (§1.2), which makes turning bang-bang: set 3437.75 to reproduce it.
//! - `goal_position_tol` (m, default R/2, in (0, 100]).
//! - `goal_angle_tol_deg` (degrees, default 30, in (0, 360]): 3.0.2's effective value; a value
//!   of 180 or more never corrects the heading, as Player ≥ 3.1's 30-radian default does.
//! - `max_range_m` (m, default: the laser's, `sim.laser.range_m`, read from each observation as
//!   Player reads it from the laser's data; in (0, 1000]): a reading at or beyond it (the laser
//!   reads exactly `range_m` when nothing is hit) is "no return": free space. Setting it
//!   overrides the laser's; a value below the laser's range makes SND take distant walls for
//!   free space, one above it makes every empty beam an obstacle at that range.
//!
//! Sitgen specifics: SND runs synchronously, once per observation, on the current scan and pose
//! (no 100 ms wall-clock thread, no decimation), so a run is deterministic. The angular
//! resolution is the observation's beam spacing, (last bearing − first) / (beams − 1): sitgen
//! casts beams at exactly that spacing, so there is no Stage `fov/samples` compression
//! (§1.3). N = C-round(2π/res + 0.5) with 2π/res first rounded to 9 decimals, so that the
//! floating-point 1° spacing gives 360.5 → 361 sectors, as Player does for 1°, not 360.4999…
//! → 360. The goal heading is the bearing of the route's last leg (previous waypoint, or the
//! start, to the last): sitgen's routes carry no headings, and arriving along the leg is the
//! natural final heading. Fewer than two beams, beams more than 1 rad apart, or a scan wider
//! than N sectors give no usable scan: the robot stops (Player refuses to start).
//!
//! Known behaviour, reproduced on purpose: next to an obstacle that only the ±90° edge beams
//! see (a doorpost as the robot leaves a doorway, a rock it is passing), turning a little
//! hides it, the other side's obstacle alone then swings S_ao (a weighted *mean* of m·δ) by
//! ≈ m·90°, |θ| > 30° stops the robot, and each 0.1 s turn overshoots the narrow band of
//! headings where both are seen: it can turn to and fro on the spot indefinitely. Indoor
//! doorways and maze corridors trigger it often (see the tests).
//!
//! **Source.** J. Durham & F. Bullo, "Smooth Nearness-Diagram Navigation", IROS 2008; Player
//! `server/drivers/position/snd/gap_nd_nav.cc` (J. Durham, L. Invernizzi), as restated in
//! `reference/algorithms.md` §1 with its integer semantics (§1.6).

use std::collections::BTreeMap;
use std::f64::consts::{FRAC_PI_2, FRAC_PI_4, FRAC_PI_6, PI, TAU};

use super::fault::Fault;
use super::{check_known, Command, Controller};
use crate::error::{join, SpecError};
use crate::sim::Observation;
use crate::situation::{Pose, Robot};

/// SND's parameters in SI units (m, m/s, rad/s, rad), every default resolved.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SndParams {
    /// R, metres.
    pub robot_radius: f64,
    /// Range jump that makes a gap, metres.
    pub min_gap_width: f64,
    /// Ds_max, metres.
    pub obstacle_avoid_dist: f64,
    /// v_max, m/s.
    pub max_speed: f64,
    /// ω_max, rad/s.
    pub max_turn_rate: f64,
    /// Metres.
    pub goal_position_tol: f64,
    /// Radians.
    pub goal_angle_tol: f64,
    /// A seeded fault switched on (`fault.rs`); `None`: SND as Player has it.
    pub fault: Option<Fault>,
}

impl SndParams {
    /// Player's defaults (3.0.2 angles) for robot radius `r`.
    pub fn with_radius(r: f64) -> Self {
        Self {
            robot_radius: r,
            min_gap_width: 2.0 * r,
            obstacle_avoid_dist: 4.0 * r,
            max_speed: 0.5,
            max_turn_rate: 60f64.to_radians(),
            goal_position_tol: r / 2.0,
            goal_angle_tol: 30f64.to_radians(),
            fault: None,
        }
    }

    /// These parameters under seeded fault `fault` (`fault.rs`'s parameter seam, kept here so
    /// that the catalogue needs none of SND's types): some faults change a parameter once, at
    /// reset, and every fault is remembered for the logic seams.
    pub fn under_fault(mut self, fault: Option<Fault>) -> Self {
        match fault {
            Some(Fault::TurnRateInRadians) => self.max_turn_rate = self.max_turn_rate.to_degrees(),
            Some(Fault::SafetyDistanceHalved) => self.obstacle_avoid_dist /= 2.0,
            Some(Fault::PlayerDefaultRadius) => {
                self = SndParams {
                    max_speed: self.max_speed,
                    max_turn_rate: self.max_turn_rate,
                    goal_angle_tol: self.goal_angle_tol,
                    ..SndParams::with_radius(PLAYER_ROBOT_RADIUS_M)
                }
            }
            _ => {}
        }
        self.fault = fault;
        self
    }
}

/// Player's `snd` default `robot_radius`, metres (`player_default_radius` puts it in place of
/// the body's).
const PLAYER_ROBOT_RADIUS_M: f64 = 0.25;

/// SND's parameter names, as specs write them.
pub const SND_PARAMS: &[&str] = &[
    "robot_radius",
    "min_gap_width",
    "obstacle_avoid_dist",
    "max_speed",
    "max_turn_rate_deg_s",
    "goal_position_tol",
    "goal_angle_tol_deg",
    "max_range_m",
];

/// Parameters as a spec gives them: those defaulting to multiples of R wait for the body,
/// which is known only at reset.
#[derive(Debug, Clone, PartialEq)]
pub struct SndConfig {
    robot_radius: Option<f64>,
    min_gap_width: Option<f64>,
    obstacle_avoid_dist: Option<f64>,
    max_speed: f64,
    max_turn_rate: f64,
    goal_position_tol: Option<f64>,
    goal_angle_tol: f64,
    max_range_m: Option<f64>,
}

/// Parameter `name` in (0, hi] if given.
fn optional(
    params: &BTreeMap<String, f64>,
    path: &str,
    name: &str,
    hi: f64,
) -> Result<Option<f64>, SpecError> {
    params
        .get(name)
        .map(|&v| SpecError::check_positive(&join(path, name), v, hi).map(|()| v))
        .transpose()
}

impl SndConfig {
    /// Read SND's parameters from `params` (others are left to the caller to check).
    pub fn read(params: &BTreeMap<String, f64>, path: &str) -> Result<Self, SpecError> {
        Ok(Self {
            robot_radius: optional(params, path, "robot_radius", 10.0)?,
            min_gap_width: optional(params, path, "min_gap_width", 100.0)?,
            obstacle_avoid_dist: optional(params, path, "obstacle_avoid_dist", 100.0)?,
            max_speed: super::param(params, path, "max_speed", 0.5, 10.0)?,
            max_turn_rate: super::param(params, path, "max_turn_rate_deg_s", 60.0, 3600.0)?
                .to_radians(),
            goal_position_tol: optional(params, path, "goal_position_tol", 100.0)?,
            goal_angle_tol: super::param(params, path, "goal_angle_tol_deg", 30.0, 360.0)?
                .to_radians(),
            max_range_m: optional(params, path, "max_range_m", 1000.0)?,
        })
    }

    /// The parameters for a body whose enclosing radius is `body_radius` metres.
    pub fn resolve(&self, body_radius: f64) -> SndParams {
        let r = self.robot_radius.unwrap_or(body_radius);
        let defaults = SndParams::with_radius(r);
        SndParams {
            robot_radius: r,
            min_gap_width: self.min_gap_width.unwrap_or(defaults.min_gap_width),
            obstacle_avoid_dist: self
                .obstacle_avoid_dist
                .unwrap_or(defaults.obstacle_avoid_dist),
            max_speed: self.max_speed,
            max_turn_rate: self.max_turn_rate,
            goal_position_tol: self.goal_position_tol.unwrap_or(defaults.goal_position_tol),
            goal_angle_tol: self.goal_angle_tol,
            fault: None,
        }
    }

    /// The maximum range the spec sets, metres; `None`: the laser's, from each observation.
    pub fn max_range_m(&self) -> Option<f64> {
        self.max_range_m
    }
}

/// A goal as Player's `GoTo(x, y, heading)` gives it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Goal {
    /// x, metres.
    pub x_m: f64,
    /// y, metres.
    pub y_m: f64,
    /// Heading to end in, radians.
    pub heading_rad: f64,
}

/// A gap: a range discontinuity, located on its far (free) side.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Gap {
    /// Sector, in [0, N).
    pub sector: i64,
    /// Range of the obstacle corner that makes it, metres.
    pub dist: f64,
    /// +1: the corner is on the gap's left (CCW); −1: on its right.
    pub side: i64,
}

/// A valley: free sectors from a rising gap (inclusive) toward another gap (exclusive).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Valley {
    /// The gap the robot heads past.
    pub rising: Gap,
    /// The gap at the valley's other end.
    pub other: Gap,
    /// Direction from the rising gap into the valley: +1 CCW, −1 CW.
    pub dir: i64,
}

impl Valley {
    /// Whether sector `s` lies in the valley.
    pub fn contains(&self, s: i64, n: i64) -> bool {
        let r = self.rising.sector;
        sectors_between_directed(r, s, n, self.dir)
            < sectors_between_directed(r, self.other.sector, n, self.dir)
    }

    /// Width W in sectors: from the rising gap to the first sector inside the valley nearer
    /// than the corner, or to the other gap.
    pub fn width(&self, full: &[f64]) -> i64 {
        let n = full.len() as i64;
        let r = self.rising.sector;
        // Walking k sectors in from the rising gap; k < the other gap's distance is "inside".
        let end = sectors_between_directed(r, self.other.sector, n, self.dir);
        let mut k = 1;
        while k < end && full[wrap(r + self.dir * k, n) as usize] >= self.rising.dist {
            k += 1;
        }
        // Player returns Δ→(r, r + d·k), which is k except for a one-sector circle.
        wrap(k, n)
    }
}

/// The trigonometry of one sector geometry (N sectors `res` apart), computed once and reused
/// while the scan geometry stays the same: the corner and corridor tests would otherwise take
/// a sine and a cosine per sector per cycle.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct SectorTable {
    /// N.
    pub n: i64,
    /// Radians per sector.
    pub res: f64,
    /// (cos, sin) of each sector's bearing res·(s − ⌊N/2⌋).
    dirs: Vec<(f64, f64)>,
    /// (sin, cos) of k·res for k in 0..=N/4.
    offsets: Vec<(f64, f64)>,
}

impl SectorTable {
    /// The table for resolution `res`.
    pub fn new(res: f64) -> Self {
        let n = sector_count(res);
        Self {
            n,
            res,
            dirs: (0..n)
                .map(|s| {
                    let a = res * (s - n / 2) as f64;
                    (a.cos(), a.sin())
                })
                .collect(),
            offsets: (0..=n / 4)
                .map(|k| {
                    let phi = k as f64 * res;
                    (phi.sin(), phi.cos())
                })
                .collect(),
        }
    }
}

/// Which branch decided the command.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum SndCase {
    /// No usable scan (fewer than two beams, beams over 1 rad apart, or more beams than
    /// sectors): stop.
    #[default]
    NoScan,
    /// Step 1: at the goal, heading within tolerance: stop until a new goal.
    Reached,
    /// Step 1: at the goal, turning on the spot toward the goal heading.
    Aligning,
    /// Step 7 case A: something inside the robot radius: straight on at speed 0.
    InsideRadius,
    /// Step 7 case B: no valley, the goal corridor is clear: head for the goal.
    NoValleyGoalClear,
    /// Step 7 case B: no valley, the corridor is blocked: spin clockwise on the spot.
    NoValleySpin,
    /// Step 7 case C: follow the best valley.
    Valley,
}

/// One cycle's command and every intermediate quantity, for tests and inspection. Fields
/// after `d_goal` hold their step's value when the cycle reached that step, else their
/// defaults (empty, 0, `None`).
#[derive(Debug, Clone, Default, PartialEq)]
pub struct SndDecision {
    /// (v m/s, ω rad/s).
    pub command: Command,
    /// Which branch decided it.
    pub case: SndCase,
    /// N, sectors on the full circle.
    pub sectors: i64,
    /// Sector trigonometry, kept between cycles.
    pub table: SectorTable,
    /// Angular resolution, radians per sector.
    pub res: f64,
    /// Distance to the goal, floored at 0.01 m (step 0).
    pub d_goal: f64,
    /// s_g (step 0); may equal N.
    pub goal_sector: i64,
    /// `D[s]`, the full-circle ranges, metres.
    pub full: Vec<f64>,
    /// `PND[s]` (step 2).
    pub pnd: Vec<f64>,
    /// Nearest return, metres (step 2).
    pub d_min: f64,
    /// Safety distance Ds, metres (step 3).
    pub ds: f64,
    /// Gaps after merging, in list order (step 4).
    pub gaps: Vec<Gap>,
    /// Valleys, in list order (step 5).
    pub valleys: Vec<Valley>,
    /// Index of the chosen valley in `valleys` (step 6).
    pub best: Option<usize>,
    /// Valley width W, sectors (case C).
    pub valley_width: Option<i64>,
    /// s_srd, the safe rising discontinuity (case C).
    pub s_srd: Option<i64>,
    /// s_mid, mid-valley (case C).
    pub s_mid: Option<i64>,
    /// s_t, the target sector (case C; equals `s_theta` in cases A and B).
    pub s_t: i64,
    /// S_ao, the smooth deviation, sectors (step 8; 0 outside case C).
    pub s_ao: f64,
    /// s_θ, the heading sector.
    pub s_theta: i64,
    /// θ = res·(s_θ − N/2.0), radians, before clamping (step 9).
    pub theta: f64,
}

/// C's `round` (half away from zero), as an integer.
fn c_round(x: f64) -> i64 {
    x.round() as i64
}

/// Sector `s` taken onto [0, n) (Player's `getIndex`). Arguments are almost always within one
/// turn of the range, which spares the integer division.
#[inline]
fn wrap(s: i64, n: i64) -> i64 {
    if s >= n {
        if s < 2 * n {
            s - n
        } else {
            s.rem_euclid(n)
        }
    } else if s < 0 {
        if s >= -n {
            s + n
        } else {
            s.rem_euclid(n)
        }
    } else {
        s
    }
}

/// An angle in [−π, π], as Player's `normalize` computes it.
fn normalize(a: f64) -> f64 {
    a.sin().atan2(a.cos())
}

/// Δ(a, b): signed shortest sector count from `a` to `b`, positive CCW. A raw difference of
/// exactly ±⌊n/2⌋ comes back as ∓(n − ⌊n/2⌋), the long way round for odd n, as Player's
/// `getSectorsBetween` does.
pub fn sectors_between(a: i64, b: i64, n: i64) -> i64 {
    let d = wrap(b, n) - wrap(a, n);
    if d.abs() < n / 2 {
        d
    } else {
        -d.signum() * (n - d.abs())
    }
}

/// Δ→(a, b, dir): sectors from `a` to `b` going in direction `dir` (±1), in [0, n).
pub fn sectors_between_directed(a: i64, b: i64, n: i64, dir: i64) -> i64 {
    wrap(dir * (wrap(b, n) - wrap(a, n)), n)
}

/// N for angular resolution `res`: C-round(2π/res + 0.5). The ratio is rounded to 9
/// decimals first so that a resolution meant to divide the circle exactly (1°: 360) gives the
/// same N whichever way floating point rounded it.
pub fn sector_count(res: f64) -> i64 {
    let ratio = ((TAU / res) * 1e9).round() / 1e9;
    c_round(ratio + 0.5)
}

/// Step 0: the distance to the goal (floored at 0.01 m) and the goal sector s_g.
/// Beyond 1000 m Player's "direction mode" takes the goal heading as a bearing.
pub fn goal_sector(pose: &Pose, goal: &Goal, n: i64, res: f64) -> (f64, i64) {
    let (dx, dy) = (goal.x_m - pose.x_m, goal.y_m - pose.y_m);
    let d = dx.hypot(dy).max(0.01);
    let bearing = if d < 1000.0 {
        normalize((dy / d).atan2(dx / d) - pose.heading_rad)
    } else {
        normalize(goal.heading_rad)
    };
    (d, c_round(n as f64 / 2.0 + bearing / res))
}

/// Step 1: within `goal_position_tol`, stop if the heading is within tolerance, else turn on
/// the spot by the *unwrapped* difference (so possibly the long way round), as Player does.
/// `None` when the goal is not yet reached.
pub fn goal_reached(
    pose: &Pose,
    goal: &Goal,
    d_goal: f64,
    p: &SndParams,
) -> Option<(SndCase, Command)> {
    if d_goal >= p.goal_position_tol {
        return None;
    }
    let goal_heading = normalize(goal.heading_rad);
    if normalize(pose.heading_rad - goal_heading).abs() < p.goal_angle_tol {
        Some((SndCase::Reached, (0.0, 0.0)))
    } else {
        let w = ((goal_heading - pose.heading_rad) / 3.0).clamp(-p.max_turn_rate, p.max_turn_rate);
        Some((SndCase::Aligning, (0.0, w)))
    }
}

/// The full circle `D[s] = r[s − N/2 + L/2]` where that is a beam, else `max_range` (unseen
/// directions are free). Readings at or beyond `max_range`, or NaN, read `max_range` (no
/// return); negative ones read 0.
pub fn full_circle(ranges: &[f64], n: i64, max_range: f64, full: &mut Vec<f64>) {
    let first = (n / 2 - ranges.len() as i64 / 2) as usize;
    full.clear();
    full.resize(first, max_range);
    full.extend(ranges.iter().map(|&r| {
        if r < max_range {
            r.max(0.0)
        } else {
            // Also NaN and infinity: no return.
            max_range
        }
    }));
    full.resize(n as usize, max_range);
}

/// Step 2: `PND[s]` = 0 for no return, else max_range + 2R − `D[s]`; returns d_min, the nearest
/// return (`max_range` if none).
pub fn nearness_diagram(full: &[f64], max_range: f64, r: f64, pnd: &mut Vec<f64>) -> f64 {
    pnd.clear();
    let mut d_min = max_range;
    pnd.extend(full.iter().map(|&d| {
        if d >= max_range {
            0.0
        } else {
            d_min = d_min.min(d);
            max_range + 2.0 * r - d
        }
    }));
    d_min
}

/// Step 3: Ds = clamp(5·(d_min − R), 0, Ds_max).
pub fn safety_distance(d_min: f64, r: f64, ds_max: f64) -> f64 {
    (5.0 * (d_min - r)).clamp(0.0, ds_max)
}

/// Range jumps seeded fault `gap_band_missed` does not take as gaps, metres.
const MISSED_GAP_BAND: std::ops::RangeInclusive<f64> = 1.15..=1.25;

/// Step 4: the gaps in increasing sector order, forced gaps at the edges of a scan narrower
/// than the circle, then merged ([`merge_gaps`]). `beams` is L; `fault` is SND's seeded
/// fault, if any.
pub fn find_gaps(
    full: &[f64],
    pnd: &[f64],
    beams: usize,
    min_gap_width: f64,
    fault: Option<Fault>,
    gaps: &mut Vec<Gap>,
) {
    gaps.clear();
    let n = full.len() as i64;
    let l = beams as i64;
    let first = n / 2 - l / 2;
    let partial = l < n;
    if partial {
        gaps.push(Gap {
            sector: wrap(first - 1, n),
            dist: full[first as usize],
            side: 1,
        });
    }
    for s in first + 1..first + l {
        let (s, u) = (s as usize, s as usize - 1);
        let delta = pnd[s] - pnd[u];
        // Seeded fault `gap_band_missed`.
        if Fault::GapBandMissed.is(fault) && MISSED_GAP_BAND.contains(&delta.abs()) {
            continue;
        }
        if delta > min_gap_width {
            gaps.push(Gap {
                sector: u as i64,
                dist: full[s],
                side: 1,
            });
        } else if delta < -min_gap_width {
            gaps.push(Gap {
                sector: s as i64,
                dist: full[u],
                side: -1,
            });
        }
    }
    if partial {
        let after = first + l;
        gaps.push(Gap {
            sector: wrap(after, n),
            dist: full[wrap(after - 1, n) as usize],
            side: -1,
        });
    }
    merge_gaps(gaps, n);
}

/// Step 4.4: one walk along the list, each gap compared with the next (cyclically): two gaps
/// in adjacent sectors on the same side become one, the first kept for side +1, one at the
/// second's sector (with the first's corner distance) for side −1. As in Player, the walk
/// moves on past a merged pair, so a run of three merges only once.
pub fn merge_gaps(gaps: &mut Vec<Gap>, n: i64) {
    let mut k = 0;
    while k < gaps.len() {
        let next = if k + 1 < gaps.len() { k + 1 } else { 0 };
        let (a, b) = (gaps[k], gaps[next]);
        if next != k && a.sector == wrap(b.sector - 1, n) && a.side == b.side {
            if a.side < 0 {
                gaps[k].sector = b.sector;
            }
            gaps.remove(next);
            if next == 0 {
                // The list's head went: the current gap is still the last one, so the walk ends.
                break;
            }
        }
        k += 1;
    }
}

/// The corner-clearance test of step 5: the corner point of `gap` must be at least 2.2R from
/// every return in the next N/4 − 1 sectors into the valley (direction `dir`).
pub fn rising_gap_is_safe(
    gap: &Gap,
    dir: i64,
    full: &[f64],
    table: &SectorTable,
    max_range: f64,
    r: f64,
) -> bool {
    let n = table.n;
    let point = |s: i64, d: f64| {
        let (c, s) = table.dirs[s as usize];
        (d * c, d * s)
    };
    let corner = point(gap.sector, gap.dist);
    // Squared distances: the same test as Player's sqrt(…) < 2.2R but for exact ties.
    let clearance2 = (2.2 * r) * (2.2 * r);
    (1..n / 4).all(|i| {
        let s = wrap(gap.sector + dir * i, n);
        let d = full[s as usize];
        if d < max_range - 0.01 {
            let q = point(s, d);
            let (dx, dy) = (corner.0 - q.0, corner.1 - q.1);
            dx * dx + dy * dy >= clearance2
        } else {
            true
        }
    })
}

/// Step 5: the valleys between cyclically consecutive gaps, each kept only if its rising gap
/// passes [`rising_gap_is_safe`].
pub fn find_valleys(
    gaps: &[Gap],
    full: &[f64],
    goal_sector: i64,
    table: &SectorTable,
    max_range: f64,
    r: f64,
    valleys: &mut Vec<Valley>,
) {
    valleys.clear();
    let n = table.n;
    for (k, &a) in gaps.iter().enumerate() {
        let b = gaps[(k + 1) % gaps.len()];
        let candidate = match (a.side, b.side) {
            (-1, 1) => {
                // Both rising: the one nearer the goal, the right one on a tie.
                let to_a = sectors_between(a.sector, goal_sector, n).abs();
                let to_b = sectors_between(b.sector, goal_sector, n).abs();
                if to_a <= to_b {
                    (a, b, 1)
                } else {
                    (b, a, -1)
                }
            }
            (-1, _) => (a, b, 1),
            (_, 1) => (b, a, -1),
            _ => continue,
        };
        let (rising, other, dir) = candidate;
        if rising_gap_is_safe(&rising, dir, full, table, max_range, r) {
            valleys.push(Valley { rising, other, dir });
        }
    }
}

/// Step 6: the valley whose rising gap is nearest the goal sector. Pass 1 skips a valley
/// holding sector 0 (straight behind, unseen) unless the laser covers the circle; pass 2
/// (narrower lasers only) lets any valley replace a best that is missing or more than
/// N/4 + 1 sectors off. Ties keep the first.
pub fn choose_valley(
    valleys: &[Valley],
    goal_sector: i64,
    n: i64,
    full_scan: bool,
) -> Option<usize> {
    let cost = |v: &Valley| sectors_between(v.rising.sector, goal_sector, n).abs();
    let mut best = None;
    let mut best_cost = n;
    for (i, v) in valleys.iter().enumerate() {
        if (full_scan || !v.contains(0, n)) && cost(v) < best_cost {
            best = Some(i);
            best_cost = cost(v);
        }
    }
    if !full_scan {
        for (i, v) in valleys.iter().enumerate() {
            if (best.is_none() || best_cost > 1 + n / 4) && cost(v) < best_cost {
                best = Some(i);
                best_cost = cost(v);
            }
        }
    }
    best
}

/// The goal-corridor (filter) test toward sector `c0`: no return inside the rectangle
/// [0, `length`] × [−`half_width`, `half_width`] along `c0`; sectors more than N/4 away are not
/// checked. A `length` ≤ 0 always passes.
pub fn corridor_clear(
    c0: i64,
    half_width: f64,
    length: f64,
    full: &[f64],
    table: &SectorTable,
) -> bool {
    let n = table.n;
    // The sectors within N/4 of c0 (Δ has no half-circle quirk that near), k sectors off.
    (-(n / 4)..=n / 4).all(|off| {
        let d = full[wrap(c0 + off, n) as usize];
        let (sin, cos) = table.offsets[off.unsigned_abs() as usize];
        d >= (half_width / sin).min(length / cos)
    })
}

/// What step 7 decided.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Target {
    /// The branch.
    pub case: SndCase,
    /// s_t (case C), or s_θ directly (cases A and B).
    pub sector: i64,
    /// W, s_srd and s_mid (case C).
    pub valley: Option<(i64, i64, i64)>,
}

/// Step 7: the target sector. `d_goal` is the unfloored goal distance; `beams` is L.
#[allow(clippy::too_many_arguments)]
pub fn target_sector(
    best: Option<&Valley>,
    full: &[f64],
    d_min: f64,
    goal_sector: i64,
    d_goal: f64,
    table: &SectorTable,
    max_range: f64,
    beams: usize,
    p: &SndParams,
) -> Target {
    let (n, res) = (table.n, table.res);
    let l = beams as i64;
    let r = p.robot_radius;
    let corridor = (max_range - r).min(d_goal - r);
    let goal_clear = |c0| {
        // Seeded fault `corridor_test_skipped`.
        Fault::CorridorTestSkipped.is(p.fault) || corridor_clear(c0, r, corridor, full, table)
    };
    // Seeded fault `inside_radius_stop_removed`.
    if d_min < r && !Fault::InsideRadiusStopRemoved.is(p.fault) {
        return Target {
            case: SndCase::InsideRadius,
            sector: n / 2,
            valley: None,
        };
    }
    let Some(v) = best else {
        let clear = goal_clear(goal_sector);
        return Target {
            case: if clear {
                SndCase::NoValleyGoalClear
            } else {
                SndCase::NoValleySpin
            },
            sector: if clear { goal_sector } else { 0 },
            valley: None,
        };
    };
    let (s_r, dir, corner) = (v.rising.sector, v.dir, v.rising.dist);
    let width = v.width(full);
    let reach = p.obstacle_avoid_dist + r;
    let k = if corner < reach {
        n / 4
    } else {
        c_round((reach / corner).clamp(-1.0, 1.0).asin() / res)
    };
    // Player's cap (a hack, its comment says): at most a third of the scan's beams.
    let k = k.min(l / 3);
    let s_srd = wrap(s_r + dir * k, n);
    let s_mid = wrap(s_r + dir * (width / 2 - 1), n);
    let goal_in_front = sectors_between(goal_sector, n / 2, n).abs() < (n / 4).min(l / 2);
    let s_t = if goal_in_front && goal_clear(goal_sector) {
        goal_sector
    } else if sectors_between(s_r, s_mid, n).abs() < sectors_between(s_r, s_srd, n).abs() {
        s_mid
    } else {
        s_srd
    };
    Target {
        case: SndCase::Valley,
        sector: s_t,
        valley: Some((width, s_srd, s_mid)),
    }
}

/// Step 8: S_ao = Σ m³·Δ(s_t, s + N/2) / Σ m², with proximity m = clamp((Ds + R − D)/Ds, 0, 1);
/// 0 when nothing is within R + Ds. At Ds = 0 (d_min exactly R) m is its limit: 1 within R.
pub fn smooth_deviation(full: &[f64], s_t: i64, ds: f64, r: f64) -> f64 {
    let n = full.len() as i64;
    let (mut num, mut den) = (0.0, 0.0);
    for (s, &d) in full.iter().enumerate() {
        let m = if ds > 0.0 {
            // Most sectors are farther than R + Ds: m is 0 there, and the division is spared.
            let near = ds + r - d;
            if near > 0.0 {
                (near / ds).clamp(0.0, 1.0)
            } else {
                0.0
            }
        } else if d <= r {
            1.0
        } else {
            0.0
        };
        if m > 0.0 {
            let away = wrap(s as i64 + n / 2, n);
            let delta = sectors_between(s_t, away, n) as f64;
            num += m * m * m * delta;
            den += m * m;
        }
    }
    if den > 0.0 {
        num / den
    } else {
        0.0
    }
}

/// The heading sector s_θ = round(s_t + S_ao), clamped to [0, N − 1] so that the deviation
/// never flips the turn through "behind".
pub fn heading_sector(s_t: i64, s_ao: f64, n: i64) -> i64 {
    c_round(s_t as f64 + s_ao).clamp(0, n - 1)
}

/// Step 9: (v, ω) and θ for heading sector `s_theta`; `d_goal` unfloored. v is never negative.
pub fn velocity_command(
    s_theta: i64,
    n: i64,
    res: f64,
    d_goal: f64,
    d_min: f64,
    p: &SndParams,
) -> (Command, f64) {
    let theta = res * (s_theta as f64 - n as f64 / 2.0);
    let turn = theta.clamp(-FRAC_PI_2, FRAC_PI_2);
    let w = p.max_turn_rate * 2.0 * turn / PI;
    let aim = turn.clamp(-FRAC_PI_4, FRAC_PI_4);
    let clearance = if Fault::SpeedIgnoresClearance.is(p.fault) {
        // Seeded fault `speed_ignores_clearance`.
        1.0
    } else {
        ((d_min - p.robot_radius) / p.obstacle_avoid_dist).clamp(0.0, 1.0)
    };
    let v = p.max_speed
        * (2.0 * d_goal).clamp(0.0, 1.0)
        * clearance
        * ((FRAC_PI_6 - aim.abs()) / FRAC_PI_6).clamp(0.0, 1.0);
    ((v, w), theta)
}

/// One SND cycle: scan `ranges` (rightmost beam first, `res` radians apart), laser range
/// `max_range`, robot `pose`, `goal`. A pure function of its inputs.
pub fn snd_step(
    p: &SndParams,
    ranges: &[f64],
    res: f64,
    max_range: f64,
    pose: &Pose,
    goal: &Goal,
) -> SndDecision {
    let mut out = SndDecision::default();
    snd_step_into(p, ranges, res, max_range, pose, goal, &mut out);
    out
}

/// [`snd_step`] writing into `out`, whose buffers are reused (no allocation once warm).
pub fn snd_step_into(
    p: &SndParams,
    ranges: &[f64],
    res: f64,
    max_range: f64,
    pose: &Pose,
    goal: &Goal,
    out: &mut SndDecision,
) {
    let mut full = std::mem::take(&mut out.full);
    let mut pnd = std::mem::take(&mut out.pnd);
    let mut gaps = std::mem::take(&mut out.gaps);
    let mut valleys = std::mem::take(&mut out.valleys);
    let table = std::mem::take(&mut out.table);
    full.clear();
    pnd.clear();
    gaps.clear();
    valleys.clear();
    *out = SndDecision {
        full,
        pnd,
        gaps,
        valleys,
        table,
        ..SndDecision::default()
    };

    let beams = ranges.len();
    // Player refuses resolutions outside (0, 1] rad; wider ones would leave N/4 at 0 or 1.
    if beams == 0 || !(res > 0.0 && res <= 1.0) {
        return;
    }
    if out.table.res != res {
        out.table = SectorTable::new(res);
    }
    let n = out.table.n;
    if n < beams as i64 {
        return;
    }
    out.sectors = n;
    out.res = res;

    let (d_goal, s_g) = goal_sector(pose, goal, n, res);
    out.d_goal = d_goal;
    out.goal_sector = s_g;
    if let Some((case, command)) = goal_reached(pose, goal, d_goal, p) {
        out.case = case;
        out.command = command;
        return;
    }

    let r = p.robot_radius;
    full_circle(ranges, n, max_range, &mut out.full);
    if Fault::SectorOffByOne.is(p.fault) {
        // Seeded fault `sector_off_by_one`: D[s] = r[s − N/2 + L/2 − 1].
        out.full.rotate_right(1);
    }
    out.d_min = nearness_diagram(&out.full, max_range, r, &mut out.pnd);
    out.ds = safety_distance(out.d_min, r, p.obstacle_avoid_dist);
    find_gaps(
        &out.full,
        &out.pnd,
        beams,
        p.min_gap_width,
        p.fault,
        &mut out.gaps,
    );
    // Seeded fault `corner_clearance_halved`: the corner test's 2.2R becomes 1.1R.
    let corner_r = if Fault::CornerClearanceHalved.is(p.fault) {
        r / 2.0
    } else {
        r
    };
    find_valleys(
        &out.gaps,
        &out.full,
        s_g,
        &out.table,
        max_range,
        corner_r,
        &mut out.valleys,
    );
    out.best = choose_valley(&out.valleys, s_g, n, beams as i64 >= n);

    // Player recomputes the distance without the 0.01 m floor for the corridor and speed.
    let d_goal_raw = (goal.x_m - pose.x_m).hypot(goal.y_m - pose.y_m);
    let best = out.best.map(|i| &out.valleys[i]);
    let target = target_sector(
        best, &out.full, out.d_min, s_g, d_goal_raw, &out.table, max_range, beams, p,
    );
    out.case = target.case;
    out.s_t = target.sector;
    out.s_theta = target.sector;
    if let Some((width, s_srd, s_mid)) = target.valley {
        out.valley_width = Some(width);
        out.s_srd = Some(s_srd);
        out.s_mid = Some(s_mid);
        out.s_ao = smooth_deviation(&out.full, out.s_t, out.ds, r);
        if Fault::DeviationSignFlipped.is(p.fault) {
            // Seeded fault `deviation_sign_flipped`.
            out.s_ao = -out.s_ao;
        }
        out.s_theta = heading_sector(out.s_t, out.s_ao, n);
    }
    let (command, theta) = velocity_command(out.s_theta, n, res, d_goal_raw, out.d_min, p);
    out.command = command;
    out.theta = theta;
}

/// The angular resolution of a scan with `angles` (beam bearings, evenly spaced): the mean
/// spacing, which sitgen's lasers make exact; `None` for fewer than two beams.
pub fn scan_resolution(angles: &[f64]) -> Option<f64> {
    match angles {
        [first, .., last] => Some((last - first) / (angles.len() - 1) as f64),
        _ => None,
    }
}

/// `robot`'s last waypoint as a goal, with the bearing of the route's last leg (from the
/// previous waypoint, or the start) as its heading; `None` without waypoints.
pub(crate) fn final_goal(robot: &Robot) -> Option<Goal> {
    let last = robot.waypoints.last()?;
    let from = match robot.waypoints.len() {
        1 => [robot.start.x_m, robot.start.y_m],
        k => robot.waypoints[k - 2],
    };
    Some(Goal {
        x_m: last[0],
        y_m: last[1],
        heading_rad: (last[1] - from[1]).atan2(last[0] - from[0]),
    })
}

/// The `snd` controller, and SND as a goal-driven navigator for other controllers.
#[derive(Debug, Clone)]
pub struct Snd {
    config: SndConfig,
    fault: Option<Fault>,
    params: Option<SndParams>,
    goal: Option<Goal>,
    /// At the goal with the heading within tolerance: Player blocks until a new goal.
    waiting: bool,
    decision: SndDecision,
}

impl Snd {
    /// Build from named parameters; `path` names them in errors.
    pub fn from_params(params: &BTreeMap<String, f64>, path: &str) -> Result<Self, SpecError> {
        check_known(params, SND_PARAMS, path)?;
        Ok(Self::from_config(SndConfig::read(params, path)?))
    }

    /// A navigator with `config`, no body and no goal yet.
    pub fn from_config(config: SndConfig) -> Self {
        Self {
            config,
            fault: None,
            params: None,
            goal: None,
            waiting: false,
            decision: SndDecision::default(),
        }
    }

    /// Take `robot`'s body (for the defaults depending on R) and forget any goal.
    pub fn start(&mut self, robot: &Robot) {
        let params = self.config.resolve(robot.body.enclosing_radius());
        self.params = Some(params.under_fault(self.fault));
        self.goal = None;
        self.waiting = false;
    }

    /// This navigator with seeded fault `fault` switched on (from the next start).
    pub fn with_fault(mut self, fault: Option<Fault>) -> Self {
        self.fault = fault;
        self
    }

    /// Set a new goal, as Player's `CMD_POS` does: it also wakes a navigator waiting at the
    /// previous goal.
    pub fn set_goal(&mut self, goal: Goal) {
        self.goal = Some(goal);
        self.waiting = false;
    }

    /// The current goal.
    pub fn goal(&self) -> Option<Goal> {
        self.goal
    }

    /// The resolved parameters (after [`Snd::start`]).
    pub fn params(&self) -> Option<&SndParams> {
        self.params.as_ref()
    }

    /// The last cycle's decision.
    pub fn decision(&self) -> &SndDecision {
        &self.decision
    }

    /// One cycle on `obs`: (0, 0) without a goal or a usable scan, or once the goal is reached.
    pub fn drive(&mut self, obs: &Observation) -> Command {
        let (Some(p), Some(goal)) = (self.params, self.goal) else {
            return (0.0, 0.0);
        };
        if self.waiting {
            return (0.0, 0.0);
        }
        let Some(res) = scan_resolution(&obs.angles) else {
            return (0.0, 0.0);
        };
        snd_step_into(
            &p,
            &obs.ranges,
            res,
            self.config.max_range_m.unwrap_or(obs.max_range_m),
            &obs.pose,
            &goal,
            &mut self.decision,
        );
        self.waiting = self.decision.case == SndCase::Reached;
        self.decision.command
    }
}

impl Controller for Snd {
    fn reset(&mut self, robot: &Robot) {
        self.start(robot);
        if let Some(goal) = final_goal(robot) {
            self.set_goal(goal);
        }
    }

    fn act(&mut self, obs: &Observation) -> Command {
        self.drive(obs)
    }
}

#[cfg(test)]
mod tests;
