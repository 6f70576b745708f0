//! # Situation coverage observer
//!
//! **What it does.** Watches a run, beside the monitor, and marks which cells of the
//! *interaction space* the agent exercised with its peers: interaction type × closest footprint
//! clearance × terrain context × agent speed ([`DIMENSIONS`], 7 × 4 × 5 × 4 = 560 cells). An
//! *encounter* is a stretch of steps in which a peer's footprint is within [`ENCOUNTER_M`] of
//! the agent's. Its interaction type is read once (how the peer came into range, and whether
//! the agent's laser had seen it by the time it was close); every step of it marks the cell of
//! (that type, the clearance then, the terrain round the agent then, the agent's speed then).
//! Everything is measured from the world's poses, the map and the agent's laser, never from the
//! generator's parameters or a controller's state, so a cell is marked only when the situation
//! really happened.
//!
//! **Why.** The paper (§2) asks how complete a set of situations is: "situation coverage",
//! composed from pairwise interactions between entity types, and leaves it open (Alexander,
//! Hawkins & Rae, YCS-2015-496, later made it precise). A campaign of a thousand runs that never
//! met a peer in a doorway has not tested the doorway, however high its scores.
//!
//! **Parameters.** Fixed, so that coverage is comparable across campaigns (docs/coverage.md
//! gives each bin's reason): [`ENCOUNTER_M`] 2 m, [`HIDDEN_M`] 1 m, the clearance bins'
//! edges 0.5 and 1 m (0.5 m is the monitor's default unsafe proximity), the speed bins' edges
//! 0.05, 0.2 and 0.4 m/s, and the terrain fan ([`CONTEXT_RAYS`] rays to [`CONTEXT_RANGE_M`]).
//! The speed window is the monitor's `attribution_window_s` (default 1 s), so the speed a cell
//! names is the speed a failure's features report.
//!
//! **Source.** Arnold & Alexander (2013) §2; Alexander, Hawkins & Rae, "Situation coverage – a
//! coverage criterion for testing autonomous robots" (York YCS-2015-496); Tahir & Alexander
//! (situation-coverage testing in CARLA) for interaction types as a coverage dimension.

use std::collections::{BTreeSet, VecDeque};
use std::f64::consts::{FRAC_PI_2, FRAC_PI_4, TAU};

use serde::Serialize;

use crate::failure::Failure;
use crate::monitor::attribution::{mean_speed_m_s, MOVING_M_S};
use crate::monitor::{Event, Frame, Party};
use crate::sim::{wrap_angle, Contact, World};
use crate::situation::Pose;

#[cfg(test)]
mod tests;

/// Footprint clearance under which a peer and the agent are in an encounter, metres: closing
/// at both robots' top speed (1.6 m/s) this is about a second and a quarter from contact, the
/// horizon in which avoidance has to act.
pub const ENCOUNTER_M: f64 = 2.0;
/// Clearance by which the agent's laser must have seen a peer for it not to count as hidden,
/// metres: half the encounter distance, under a second from contact at a Pioneer's top speed.
pub const HIDDEN_M: f64 = 1.0;
/// Rays of the terrain fan round the agent (one every 10°).
pub const CONTEXT_RAYS: usize = 36;
/// How far the terrain fan looks, metres.
pub const CONTEXT_RANGE_M: f64 = 4.0;
/// Chord through the agent (wall to wall) at most this wide is a corridor, metres: two robots
/// can pass in it, but not swerve round each other.
pub const CORRIDOR_M: f64 = 2.5;
/// Room beyond two robots' widths under which a passage is a gap (metres): in it there is no
/// room for two robots side by side with 10 cm between them and the walls.
pub const GAP_SLACK_M: f64 = 0.3;
/// A ray at least this long leaves the agent's surroundings; a dead end has one such opening
/// at most [`DEAD_END_ARC_DEG`] wide, metres.
pub const OPEN_RAY_M: f64 = 2.0;
/// Widest single opening of a dead end, degrees.
pub const DEAD_END_ARC_DEG: f64 = 120.0;
/// A wall edge ahead at most this far with ground at least [`CORNER_JUMP_M`] farther behind it
/// makes a blind corner, metres.
pub const CORNER_M: f64 = 1.2;
/// Depth behind a blind corner's edge, metres.
pub const CORNER_JUMP_M: f64 = 1.5;

/// One dimension of the interaction space.
#[derive(Debug, Clone, Copy, Serialize)]
pub struct Dimension {
    /// Its name.
    pub name: &'static str,
    /// Its values (bins), in order.
    pub values: &'static [&'static str],
}

/// Agent–peer interaction types.
pub const INTERACTIONS: [&str; 7] = [
    "head_on",
    "crossing_left",
    "crossing_right",
    "overtaking",
    "from_behind",
    "hidden",
    "stopped",
];
/// Closest footprint clearance: contact (a move refused between them), under 0.5 m, under 1 m,
/// under 2 m.
pub const CLEARANCES: [&str; 4] = ["contact", "under_0.5m", "under_1m", "under_2m"];
/// Terrain round the agent.
pub const CONTEXTS: [&str; 5] = ["open", "corridor", "gap", "dead_end", "blind_corner"];
/// The agent's speed: under 0.05 m/s, under 0.2, under 0.4, 0.4 and over.
pub const SPEEDS: [&str; 4] = ["stopped", "slow", "cruising", "fast"];

/// The interaction space, dimension by dimension.
pub const DIMENSIONS: [Dimension; 4] = [
    Dimension {
        name: "interaction",
        values: &INTERACTIONS,
    },
    Dimension {
        name: "clearance",
        values: &CLEARANCES,
    },
    Dimension {
        name: "context",
        values: &CONTEXTS,
    },
    Dimension {
        name: "speed",
        values: &SPEEDS,
    },
];

const HEAD_ON: u8 = 0;
const CROSSING_LEFT: u8 = 1;
const CROSSING_RIGHT: u8 = 2;
const OVERTAKING: u8 = 3;
const FROM_BEHIND: u8 = 4;
const HIDDEN: u8 = 5;
const STOPPED: u8 = 6;

const OPEN: u8 = 0;
const CORRIDOR: u8 = 1;
const GAP: u8 = 2;
const DEAD_END: u8 = 3;
const BLIND_CORNER: u8 = 4;

/// Cells in the interaction space.
pub fn cell_count() -> usize {
    DIMENSIONS.iter().map(|d| d.values.len()).product()
}

/// A cell of the interaction space: one value per dimension, by index.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub struct Cell {
    /// Index into [`INTERACTIONS`].
    pub interaction: u8,
    /// Index into [`CLEARANCES`].
    pub clearance: u8,
    /// Index into [`CONTEXTS`].
    pub context: u8,
    /// Index into [`SPEEDS`].
    pub speed: u8,
}

impl Cell {
    /// Its key: the four values joined by `/`, e.g. `head_on/under_0.5m/corridor/slow`.
    pub fn key(&self) -> String {
        format!(
            "{}/{}/{}/{}",
            INTERACTIONS[self.interaction as usize],
            CLEARANCES[self.clearance as usize],
            CONTEXTS[self.context as usize],
            SPEEDS[self.speed as usize]
        )
    }
}

/// What a run covered.
#[derive(Debug, Clone, Default, PartialEq, Serialize)]
pub struct CoverageRecord {
    /// Keys of the cells exercised, in cell order.
    pub cells: Vec<String>,
    /// Encounters between the agent and a peer.
    pub encounters: u32,
    /// The cell the run's failure began in: the cell of the agent and the other party at the
    /// start of the first event that decided it, when that party is a peer in an encounter.
    pub failure_cell: Option<String>,
    /// Where the run's failure began, for every failure (a peer's part in it or not): the
    /// agent's terrain context (`open`, `corridor`, …) and pose (x m, y m, heading rad) at
    /// the start of the first event that decided it.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub failure_at: Option<FailurePlace>,
}

/// The agent's terrain context and pose where a failure began.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct FailurePlace {
    /// The terrain context's name ([`CONTEXTS`]).
    pub context: String,
    /// (x m, y m, heading rad).
    pub pose: [f64; 3],
}

/// The state of the agent and one peer at a step of an encounter, less the interaction type.
#[derive(Debug, Clone, Copy)]
struct Moment {
    clearance: u8,
    context: u8,
    speed: u8,
}

/// An encounter between the agent and one peer.
#[derive(Debug)]
struct Encounter {
    peer: u32,
    start_step: u64,
    /// How the peer came into range (any type but `hidden`).
    approach: u8,
    /// Whether the agent's laser has seen the peer during the encounter.
    seen: bool,
    /// Decided when the clearance first falls under [`HIDDEN_M`].
    hidden: Option<bool>,
    /// One per step from `start_step`.
    moments: Vec<Moment>,
}

impl Encounter {
    fn interaction(&self) -> u8 {
        match (self.approach, self.hidden) {
            (FROM_BEHIND, _) => FROM_BEHIND,
            (_, Some(true)) => HIDDEN,
            (approach, _) => approach,
        }
    }

    fn cell(&self, m: &Moment) -> Cell {
        Cell {
            interaction: self.interaction(),
            clearance: m.clearance,
            context: m.context,
            speed: m.speed,
        }
    }
}

/// The coverage observer of one run.
#[derive(Debug)]
pub struct Observer {
    agent: usize,
    dt_s: f64,
    half_fov: f64,
    gap_m: f64,
    window_steps: usize,
    /// (x, y) of every robot for the last `window_steps + 1` frames, oldest first.
    history: VecDeque<Vec<(f64, f64)>>,
    /// Each robot's open encounter (an index into `encounters`).
    open: Vec<Option<usize>>,
    encounters: Vec<Encounter>,
    reach: Vec<f64>,
    /// The last terrain context read and the agent's pose then: an agent pinned for minutes
    /// against a peer needs the fan cast once, not every step.
    context_at: Option<(Pose, u8)>,
}

impl Observer {
    /// An observer of a run starting in `world`, whose agent is robot `agent`; speeds and
    /// approaches are measured over `window_s` (the monitor's attribution window).
    pub fn new(world: &World, agent: u32, window_s: f64) -> Self {
        let dt_s = world.spec().dt_s;
        let robots = world.robots();
        let mut observer = Self {
            agent: agent as usize,
            dt_s,
            half_fov: world.spec().laser.fov_deg.to_radians() / 2.0,
            gap_m: 2.0 * robots[agent as usize].body.width_m + GAP_SLACK_M,
            window_steps: ((window_s / dt_s - 1e-9).ceil() as usize).max(1),
            history: VecDeque::new(),
            open: vec![None; robots.len()],
            encounters: Vec::new(),
            reach: robots.iter().map(|r| r.body.enclosing_radius()).collect(),
            context_at: None,
        };
        observer.remember(world);
        observer
    }

    fn remember(&mut self, world: &World) {
        let mut row = if self.history.len() > self.window_steps {
            self.history.pop_front().expect("non-empty")
        } else {
            Vec::new()
        };
        row.clear();
        row.extend(world.robots().iter().map(|r| (r.pose.x_m, r.pose.y_m)));
        self.history.push_back(row);
    }

    /// Watch the world after a step.
    pub fn observe(&mut self, frame: &Frame<'_>) {
        self.remember(frame.world);
        let robots = frame.robots();
        let a = &robots[self.agent];
        let footprint = a.footprint();
        let mut moment_base: Option<(u8, u8)> = None;
        for (i, p) in robots.iter().enumerate() {
            if i == self.agent {
                continue;
            }
            let (dx, dy) = (p.pose.x_m - a.pose.x_m, p.pose.y_m - a.pose.y_m);
            let apart = self.reach[i] + self.reach[self.agent] + ENCOUNTER_M;
            let clearance = if dx * dx + dy * dy >= apart * apart {
                f64::INFINITY
            } else {
                footprint.distance(&p.footprint())
            };
            if clearance >= ENCOUNTER_M {
                self.open[i] = None;
                continue;
            }
            let index = match self.open[i] {
                Some(index) => index,
                None => {
                    self.encounters.push(Encounter {
                        peer: i as u32,
                        start_step: frame.step,
                        approach: self.approach(frame.world, i),
                        seen: false,
                        hidden: None,
                        moments: Vec::new(),
                    });
                    self.open[i] = Some(self.encounters.len() - 1);
                    self.encounters.len() - 1
                }
            };
            let (context, speed) = match moment_base {
                Some(m) => m,
                None => *moment_base.insert((self.context(frame.world), self.agent_speed_bin())),
            };
            let touching = a.contacts.contains(&Contact::Robot(i as u32))
                || p.contacts.contains(&Contact::Robot(self.agent as u32));
            let bearing = wrap_angle(dy.atan2(dx) - a.pose.heading_rad);
            let half_fov = self.half_fov;
            let e = &mut self.encounters[index];
            e.seen |= frame.seen_by_agent.contains(&(i as u32));
            if e.hidden.is_none() && clearance < HIDDEN_M {
                // Hidden: in the laser's field of view by now, yet not seen on the way in.
                e.hidden = Some(!e.seen && bearing.abs() <= half_fov);
            }
            e.moments.push(Moment {
                clearance: clearance_bin(clearance, touching),
                context,
                speed,
            });
        }
    }

    /// How peer `i` came into range, from the agent's heading and the peer's displacement
    /// over the window.
    fn approach(&self, world: &World, i: usize) -> u8 {
        let a = &world.robots()[self.agent].pose;
        let now = self.history.back().expect("remembered")[i];
        let then = self.history.front().expect("remembered")[i];
        let bearing = wrap_angle((now.1 - a.y_m).atan2(now.0 - a.x_m) - a.heading_rad);
        if bearing.abs() > FRAC_PI_2 {
            return FROM_BEHIND;
        }
        let span_s = (self.history.len() - 1) as f64 * self.dt_s;
        let (mx, my) = (now.0 - then.0, now.1 - then.1);
        if span_s <= 0.0 || mx.hypot(my) / span_s < MOVING_M_S {
            return STOPPED;
        }
        // The peer's course relative to the agent's heading: opposite, alike, or across (a peer
        // heading to the agent's right comes from its left).
        let course = wrap_angle(my.atan2(mx) - a.heading_rad);
        match course.abs() {
            c if c >= 3.0 * FRAC_PI_4 => HEAD_ON,
            c if c <= FRAC_PI_4 => OVERTAKING,
            _ if course < 0.0 => CROSSING_LEFT,
            _ => CROSSING_RIGHT,
        }
    }

    /// The terrain round the agent now ([`terrain_context`]; the map never changes, so the
    /// same pose gives the same context).
    fn context(&mut self, world: &World) -> u8 {
        let pose = world.robots()[self.agent].pose;
        match self.context_at {
            Some((at, context)) if at == pose => context,
            _ => {
                let context = terrain_context(world, self.agent, self.gap_m);
                self.context_at = Some((pose, context));
                context
            }
        }
    }

    /// The agent's mean speed over the window (path length over time).
    fn agent_speed_bin(&self) -> u8 {
        let a = self.agent;
        match mean_speed_m_s(self.history.iter().map(|p| p[a]), self.dt_s) {
            s if s < MOVING_M_S => 0,
            s if s < 0.2 => 1,
            s if s < 0.4 => 2,
            _ => 3,
        }
    }

    /// What the run covered; `events` and `failure` are its log and failure, for the cell the
    /// failure began in.
    /// `world` is the run's world and `trajectory` its poses (every robot, every step, flat),
    /// for where the failure began.
    pub fn finish(
        self,
        events: &[Event],
        failure: Option<&Failure>,
        world: &World,
        trajectory: &[f64],
    ) -> CoverageRecord {
        let failure_at = failure.and_then(|f| {
            let e = &events[*f.events.first()?];
            let robots = world.robots().len();
            let step = (e.start_s / self.dt_s).round() as usize;
            let at = (step * robots + self.agent) * 3;
            let p = trajectory.get(at..at + 3)?;
            let pose = Pose {
                x_m: p[0],
                y_m: p[1],
                heading_rad: p[2],
            };
            let context = terrain_context_at(world, &pose, self.gap_m);
            Some(FailurePlace {
                context: CONTEXTS[context as usize].to_string(),
                pose: [p[0], p[1], p[2]],
            })
        });
        let mut cells = BTreeSet::new();
        for e in &self.encounters {
            cells.extend(e.moments.iter().map(|m| e.cell(m)));
        }
        let failure_cell = failure.and_then(|f| {
            let e = &events[*f.events.first()?];
            let peer = [Some(Party::Robot(e.robot)), e.other]
                .into_iter()
                .find_map(|p| match p {
                    Some(Party::Robot(id)) if id as usize != self.agent => Some(id),
                    _ => None,
                })?;
            let step = (e.start_s / self.dt_s).round() as u64;
            self.encounters.iter().find_map(|enc| {
                let k = step.checked_sub(enc.start_step)? as usize;
                (enc.peer == peer && k < enc.moments.len()).then(|| enc.cell(&enc.moments[k]).key())
            })
        });
        CoverageRecord {
            cells: cells.iter().map(Cell::key).collect(),
            encounters: self.encounters.len() as u32,
            failure_cell,
            failure_at,
        }
    }
}

fn clearance_bin(clearance_m: f64, touching: bool) -> u8 {
    match clearance_m {
        _ if touching => 0,
        c if c < 0.5 => 1,
        c if c < 1.0 => 2,
        _ => 3,
    }
}

/// The terrain round robot `i`, from a fan of [`CONTEXT_RAYS`] rays from its pose to the
/// walls (robots ignored), first match wins:
/// - `dead_end`: the rays that reach [`OPEN_RAY_M`] form at most one opening, no wider than
///   [`DEAD_END_ARC_DEG`] (or there is none): one way out;
/// - `gap`: the narrowest chord through the pose, wall to wall, is at most twice the robot's
///   width plus [`GAP_SLACK_M`];
/// - `corridor`: that chord is at most [`CORRIDOR_M`];
/// - `blind_corner`: two neighbouring rays ahead (within 90° of the heading) of which one ends
///   within [`CORNER_M`] and the other reaches [`CORNER_JUMP_M`] farther: a wall edge near
///   the robot with ground behind it that its laser cannot see;
/// - `open`: none of these.
fn terrain_context(world: &World, i: usize, gap_m: f64) -> u8 {
    terrain_context_at(world, &world.robots()[i].pose, gap_m)
}

/// The terrain context (a [`CONTEXTS`] name) the agent of `world` would be in standing at
/// `pose`: what a run's coverage would record there. A search that edits the walls round a
/// failure asks it whether the edit made the context it aimed at.
pub fn agent_context_at(world: &World, agent: u32, pose: &Pose) -> &'static str {
    let gap_m = 2.0 * world.robots()[agent as usize].body.width_m + GAP_SLACK_M;
    CONTEXTS[terrain_context_at(world, pose, gap_m) as usize]
}

/// [`terrain_context`] of a robot standing at `pose` (the walls only are looked at).
fn terrain_context_at(world: &World, pose: &Pose, gap_m: f64) -> u8 {
    let pose = *pose;
    let step = TAU / CONTEXT_RAYS as f64;
    let ranges: Vec<f64> = (0..CONTEXT_RAYS)
        .map(|k| {
            let (s, c) = (pose.heading_rad + k as f64 * step).sin_cos();
            world.wall_range((pose.x_m, pose.y_m), (c, s), CONTEXT_RANGE_M)
        })
        .collect();
    let n = CONTEXT_RAYS;
    let open = |k: usize| ranges[k % n] >= OPEN_RAY_M;
    let open_rays = (0..n).filter(|&k| open(k)).count();
    let openings = (0..n).filter(|&k| open(k) && !open(k + n - 1)).count();
    let one_narrow_opening =
        openings == 1 && open_rays as f64 * step.to_degrees() <= DEAD_END_ARC_DEG;
    if open_rays == 0 || one_narrow_opening {
        return DEAD_END;
    }
    let chord = (0..n / 2)
        .map(|k| ranges[k] + ranges[k + n / 2])
        .fold(f64::INFINITY, f64::min);
    if chord <= gap_m {
        return GAP;
    }
    if chord <= CORRIDOR_M {
        return CORRIDOR;
    }
    // Rays k (bearing k·step) with |bearing| ≤ 90°, paired with the next one round.
    let ahead = |k: usize| {
        let b = wrap_angle(k as f64 * step);
        b.abs() <= FRAC_PI_2 + 1e-9
    };
    let blind = (0..n).any(|k| {
        let j = (k + 1) % n;
        let (near, far) = (ranges[k].min(ranges[j]), ranges[k].max(ranges[j]));
        ahead(k) && ahead(j) && near <= CORNER_M && far - near >= CORNER_JUMP_M
    });
    if blind {
        BLIND_CORNER
    } else {
        OPEN
    }
}
