//! # Avoidability: could the agent have escaped its collision with a robot?
//!
//! **What it does.** For the agent's first collision with another robot in a run, searches the
//! agent's admissible manoeuvres for an *escape*: commands within the robot's limits (the
//! simulator's top speed, turn rate and accelerations, forwards or backwards) that touch
//! nothing — no wall, no robot — from a moment on until `after_s` past the collision and, past
//! that, until the robot it hit is no longer closing in on it (so that stopping in a peer's
//! path is no escape: the peer comes on), at most to the time limit. The search starts from
//! two moments:
//! 1. **the first sighting**: the first scan of the agent's laser that saw the robot it hit,
//!    where the agent could first have known of it;
//! 2. **the start**: as if the agent had known every peer's path from the start (a perfect
//!    sensor).
//!
//! Each manoeuvre is tried in a branch of the run ([`crate::run::Branch`]): the world and every
//! peer's controller copied where they stood at that moment and stepped on by the simulator
//! itself, so a peer that avoids nothing drives the same path it drove in the run, and past the
//! collision carries on along its route as it would have had the agent not been there. The
//! verdict:
//! - [`Verdict::Avoidable`]: an escape exists from the first sighting — the controller's own
//!   mistake; the first escape found is the *witness*;
//! - [`Verdict::UnavoidableWithThisSensor`]: none from the sighting (or the robot was never
//!   seen before contact), one from the start: a sensor that saw further, wider or through
//!   obstacles might have saved it;
//! - [`Verdict::Unavoidable`]: none even from the start.
//!
//! `at_rest` says whether the agent stood still when struck: Fraichard's *passive motion
//! safety* (if a collision happens, the robot is at rest) held, and the collision is the other
//! robot's doing.
//!
//! **Why.** A peer that avoids nothing can drive into an agent from its blind side, and no
//! controller could have helped it; ranking such collisions beside the controller's own
//! mistakes hides the mistakes. The paper leaves telling them apart to an engineer studying
//! each accident run.
//!
//! **Parameters.** `after_s` (seconds, default [`AFTER_S`]): how long past the collision an
//! escape must stay clear. The manoeuvres tried ([`manoeuvres`], in order, the first that
//! escapes is the witness): stop; hold one command of a 5 × 5 grid over speed
//! {−1, −½, 0, ½, 1} × top speed and turn rate {−1, −½, 0, ½, 1} × top turn rate; the same
//! commands for 0.5, 1, 2 or 4 s, then stop; turn on the spot at ±½ or ±1 × top turn rate for
//! 0.5, 1 or 2 s, then drive straight at ±top speed — 1 + 24 + 96 + 24 = 145 manoeuvres at most,
//! each segment whole control periods.
//!
//! **Source.** Th. Fraichard, "A short paper about motion safety", ICRA 2007 (safety criteria;
//! passive safety); S. Bouraine, Th. Fraichard, H. Salhi, "Provably safe navigation for mobile
//! robots with limited field-of-views in dynamic environments", Autonomous Robots 32(3), 2012
//! (what a limited field of view makes unavoidable).

use serde::Serialize;

use crate::error::SpecError;
use crate::monitor::{Event, EventKind, Party};
use crate::run::{Branch, Run, RunSpec};
use crate::situation::Situation;

#[cfg(test)]
mod tests;

/// How long past the collision an escape must stay clear, seconds: long enough for a robot at
/// a Pioneer's 0.5 m/s to pass its own length several times over.
pub const AFTER_S: f64 = 5.0;

/// Speeds below this, m/s (and turn rates below this, rad/s), are standing still: a robot
/// the simulator has at (0, 0) reads exactly 0.
const AT_REST: f64 = 1e-6;

/// Whether the collision could have been escaped, and from when.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Verdict {
    /// An escape exists from the agent's first sighting of the robot.
    Avoidable,
    /// None from the first sighting (or never seen before contact); one from the start.
    UnavoidableWithThisSensor,
    /// None even from the start.
    Unavoidable,
}

impl Verdict {
    /// The verdict's name, as stored and printed.
    pub fn name(self) -> &'static str {
        match self {
            Verdict::Avoidable => "avoidable",
            Verdict::UnavoidableWithThisSensor => "unavoidable_with_this_sensor",
            Verdict::Unavoidable => "unavoidable",
        }
    }
}

/// One constant command of a manoeuvre.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct Segment {
    /// Speed, m/s (negative: backwards).
    pub v_m_s: f64,
    /// Turn rate, rad/s (counter-clockwise).
    pub w_rad_s: f64,
    /// How long it is held, seconds.
    pub duration_s: f64,
}

/// An escape: the agent's commands from `from_s` to `until_s`, and where they take it.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Witness {
    /// When the manoeuvre starts, simulated seconds (the sighting, or 0).
    pub from_s: f64,
    /// Until when it is shown clear, seconds.
    pub until_s: f64,
    /// The commands, in order, covering `from_s` to `until_s`.
    pub segments: Vec<Segment>,
    /// The agent's pose (x, y, heading) at `from_s` and after every step to `until_s`.
    pub path: Vec<[f64; 3]>,
}

/// The collision judged.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Collision {
    /// The step at which contact began (the event's start).
    pub step: u64,
    /// The robot hit.
    pub robot: u32,
    /// The step of the agent's first scan that saw it, if any did before contact.
    pub sighted_step: Option<u64>,
}

/// What [`judge`] found.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Judgement {
    /// The robot hit.
    pub robot: u32,
    /// When contact began, seconds.
    pub collision_s: f64,
    /// When the agent's laser first saw it, seconds (`None`: not before contact).
    pub sighted_s: Option<f64>,
    /// Whether the agent stood still when struck (passive motion safety held).
    pub at_rest: bool,
    /// The verdict.
    pub verdict: Verdict,
    /// The first escape found: from the sighting when avoidable, from the start when
    /// unavoidable with this sensor; none when unavoidable.
    pub witness: Option<Witness>,
    /// Manoeuvres tried, both searches together.
    pub tried: usize,
}

/// A manoeuvre as the search steps it: (steps, v, ω) segments, the last held to the horizon.
type Manoeuvre = Vec<(u64, f64, f64)>;

/// The manoeuvres tried, in order (see the module's parameters), for a robot of top speed
/// `v_max` m/s and top turn rate `w_max` rad/s deciding every `period` steps of `dt` seconds.
pub fn manoeuvres(v_max: f64, w_max: f64, dt: f64, period: u64) -> Vec<Manoeuvre> {
    let steps = |s: f64| (((s / dt) / period as f64).round() as u64).max(1) * period;
    let levels = [1.0, 0.5, -0.5, -1.0];
    let mut commands = vec![(0.0, 0.0)];
    for v in [1.0, 0.5, 0.0, -0.5, -1.0] {
        for w in [0.0, 0.5, -0.5, 1.0, -1.0] {
            if (v, w) != (0.0, 0.0) {
                commands.push((v * v_max, w * w_max));
            }
        }
    }
    let mut out: Vec<Manoeuvre> = commands.iter().map(|&(v, w)| vec![(0, v, w)]).collect();
    for s in [0.5, 1.0, 2.0, 4.0] {
        for &(v, w) in &commands[1..] {
            out.push(vec![(steps(s), v, w), (0, 0.0, 0.0)]);
        }
    }
    for s in [0.5, 1.0, 2.0] {
        for w in levels {
            for v in [1.0, -1.0] {
                out.push(vec![(steps(s), 0.0, w * w_max), (0, v * v_max, 0.0)]);
            }
        }
    }
    out
}

/// How far an escape must stay clear: past `min_step` (the collision plus `after_s`), until
/// the robot hit is no longer closing in on the agent (its centre's distance not falling over
/// a step), at most to `limit_step` (the run's time limit).
#[derive(Debug, Clone, Copy)]
pub struct Horizon {
    /// The robot hit.
    pub robot: u32,
    /// The earliest step an escape may end.
    pub min_step: u64,
    /// The latest.
    pub limit_step: u64,
}

/// The first of `manoeuvres` that takes the agent of `branch` past `horizon` touching
/// nothing, with the poses it passes; and how many were tried.
pub fn search(
    branch: &Branch,
    horizon: &Horizon,
    manoeuvres: &[Manoeuvre],
) -> (Option<Witness>, usize) {
    let dt = branch.world().spec().dt_s;
    let from = branch.world().steps();
    for (i, m) in manoeuvres.iter().enumerate() {
        if let Some(path) = escapes(branch.clone(), horizon, m) {
            let total = (path.len() - 1) as u64;
            let mut left = total;
            let segments = m
                .iter()
                .enumerate()
                .map(|(k, &(n, v, w))| {
                    let n = if k + 1 == m.len() { left } else { n.min(left) };
                    left -= n;
                    Segment {
                        v_m_s: v,
                        w_rad_s: w,
                        duration_s: n as f64 * dt,
                    }
                })
                .filter(|s| s.duration_s > 0.0)
                .collect();
            let witness = Witness {
                from_s: from as f64 * dt,
                until_s: (from + total) as f64 * dt,
                segments,
                path,
            };
            return (Some(witness), i + 1);
        }
    }
    (None, manoeuvres.len())
}

/// The agent's poses if manoeuvre `m` takes it from where `branch` stands past `horizon`
/// touching nothing; `None` at its first contact.
fn escapes(mut branch: Branch, horizon: &Horizon, m: &Manoeuvre) -> Option<Vec<[f64; 3]>> {
    let agent = branch.agent() as usize;
    let hit = horizon.robot as usize;
    let pose = |b: &Branch| {
        let p = &b.world().robots()[agent].pose;
        [p.x_m, p.y_m, p.heading_rad]
    };
    let gap = |b: &Branch| {
        let (a, o) = (&b.world().robots()[agent].pose, &b.world().robots()[hit].pose);
        (a.x_m - o.x_m).hypot(a.y_m - o.y_m)
    };
    let mut path = vec![pose(&branch)];
    let mut last_gap = gap(&branch);
    let (mut segment, mut left) = (0, m[0].0);
    while branch.world().steps() < horizon.limit_step {
        while left == 0 && segment + 1 < m.len() {
            segment += 1;
            left = m[segment].0;
        }
        let (_, v, w) = m[segment];
        left = left.saturating_sub(1);
        if branch.step((v, w)) {
            return None;
        }
        path.push(pose(&branch));
        let now = gap(&branch);
        if branch.world().steps() >= horizon.min_step && now >= last_gap {
            break;
        }
        last_gap = now;
    }
    Some(path)
}

/// The agent's first collision with a robot in `events` (a run's log), as [`judge`] takes it:
/// its step, the robot, and the step of the agent's first scan that saw it (from the event's
/// `seen_before_s`).
pub fn first_robot_collision(events: &[Event], agent: u32, dt_s: f64) -> Option<Collision> {
    let steps = |s: f64| (s / dt_s).round() as u64;
    events
        .iter()
        .filter(|e| e.kind == EventKind::Collision && e.concerns(agent))
        .find_map(|e| {
            let robot = match e.other {
                Some(Party::Robot(id)) if e.robot == agent => id,
                Some(Party::Robot(_)) => e.robot,
                _ => return None,
            };
            let step = steps(e.start_s);
            let sighted_step = e
                .details
                .get("seen_before_s")
                .and_then(serde_json::Value::as_f64)
                .map(|before| step.saturating_sub(steps(before)));
            Some(Collision {
                step,
                robot,
                sighted_step,
            })
        })
}

/// Judge `collision` of the run of `situation` under `spec` with noise from `seed` (the run
/// made again, deterministic): search for an escape from the first sighting, and from the
/// start, each until `after_s` past the collision and the robot hit no longer closing in (or
/// the time limit). The agent's and every
/// peer's controller must be built in; an external one is an error naming it.
pub fn judge(
    situation: &Situation,
    spec: &RunSpec,
    seed: u64,
    collision: &Collision,
    after_s: f64,
) -> Result<Judgement, SpecError> {
    SpecError::check_positive("after_s", after_s, 3600.0)?;
    let mut run = Run::new(situation, spec, seed)?;
    if run.agent_is_external() {
        return Err(SpecError::new(
            "run.controller.name",
            "the agent's controller is external: its run is made again through the Python \
             layer",
        ));
    }
    let branch = |run: &Run| run.branch().map_err(|e| SpecError::new("situation.robots", e));
    let dt = spec.sim.dt_s;
    let limit = (spec.time_limit_s / dt - 1e-9).ceil() as u64;
    let horizon = Horizon {
        robot: collision.robot,
        min_step: (collision.step + (after_s / dt).round() as u64).min(limit),
        limit_step: limit,
    };
    let agent = run.agent() as usize;
    let period = run.agent_period();
    let w_max = spec.sim.max_turn_rate_deg_s.to_radians();
    let tried = manoeuvres(spec.sim.max_speed_m_s, w_max, dt, period);
    let from_start = branch(&run)?;
    let mut from_sighting = None;
    while run.world().steps() < collision.step && !run.ended() {
        if Some(run.world().steps()) == collision.sighted_step {
            from_sighting = Some(branch(&run)?);
        }
        run.step(None);
    }
    let (vx, w) = run.world().robots()[agent].velocity;
    let at_rest = vx.abs() < AT_REST && w.abs() < AT_REST;
    let mut n = 0;
    let mut sighting_escape = None;
    if let Some(b) = &from_sighting {
        let (found, k) = search(b, &horizon, &tried);
        n += k;
        sighting_escape = found;
    }
    let (verdict, witness) = match sighting_escape {
        Some(w) => (Verdict::Avoidable, Some(w)),
        None => {
            let (found, k) = search(&from_start, &horizon, &tried);
            n += k;
            match found {
                Some(w) => (Verdict::UnavoidableWithThisSensor, Some(w)),
                None => (Verdict::Unavoidable, None),
            }
        }
    };
    Ok(Judgement {
        robot: collision.robot,
        collision_s: collision.step as f64 * dt,
        sighted_s: collision.sighted_step.map(|s| s as f64 * dt),
        at_rest,
        verdict,
        witness,
        tried: n,
    })
}
