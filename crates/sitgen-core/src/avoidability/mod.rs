//! # Avoidability: could the agent have escaped its collision with a robot?
//!
//! **What it does.** For the agent's first collision with another robot in a run, searches the
//! agent's admissible manoeuvres for an *escape*: commands within the robot's limits (the
//! simulator's top speed, turn rate and accelerations, forwards or backwards) that touch
//! nothing — no wall, no robot — from a moment on until `after_s` past the collision and, past
//! that, until the robot it hit is no longer closing in on it (so that stopping in a peer's
//! path is no escape: the peer comes on), at most to the time limit. The search starts from
//! two moments:
//! 1. **the sighting**: the first scan of the spell in which the agent's laser saw the robot
//!    it hit up to contact (a robot lost for less than [`SIGHTING_GAP_S`] is the same spell),
//!    where the agent could first have known of this approach;
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
//! `at_rest` says whether the agent stood still when struck (no point of its footprint moving
//! faster than 5 cm/s): Fraichard's *passive motion safety* (if a collision happens, the robot
//! is at rest) held, and the collision is the other robot's doing — though, when an escape
//! exists from the sighting, standing in the robot's path was the controller's choice.
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
use crate::run::{Branch, Run, RunSpec};
use crate::sim::Contact;
use crate::situation::Situation;

#[cfg(test)]
mod tests;

/// How long past the collision an escape must stay clear, seconds: long enough for a robot at
/// a Pioneer's 0.5 m/s to pass its own length several times over.
pub const AFTER_S: f64 = 5.0;

/// A robot is at rest when no point of its footprint moves faster than this, m/s: the
/// monitor's own threshold for a robot closing in ([`crate::monitor::attribution::MOVING_M_S`],
/// a twentieth of a Pioneer's top speed), so that a robot creeping round on the spot at a few
/// thousandths of a radian a second counts as standing, as the failure classes have it.
const AT_REST_M_S: f64 = crate::monitor::attribution::MOVING_M_S;

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

/// What [`judge`] found.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Judgement {
    /// The robot hit.
    pub robot: u32,
    /// When contact began, seconds.
    pub collision_s: f64,
    /// When the spell in which the agent's laser saw it up to contact began, seconds
    /// (`None`: not seen in the [`SIGHTING_GAP_S`] before contact).
    pub sighted_s: Option<f64>,
    /// The agent's speed in the step of contact, m/s.
    pub speed_m_s: f64,
    /// Its turn rate then, rad/s.
    pub turn_rate_rad_s: f64,
    /// Whether the agent stood still when struck: no point of its footprint moving faster
    /// than 5 cm/s (passive motion safety held).
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
        let (a, o) = (
            &b.world().robots()[agent].pose,
            &b.world().robots()[hit].pose,
        );
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

/// How long the agent's laser may lose a robot without its sighting ending, seconds: a robot
/// glimpsed, hidden for a moment behind a corner and seen again is one approach.
pub const SIGHTING_GAP_S: f64 = 1.0;

/// A spell of the agent's laser seeing one robot: when it began, when it last saw it, and the
/// run branched where the spell began.
struct Spell {
    began: u64,
    last: u64,
    branch: Branch,
}

/// Judge the agent's collision with a robot that began at `collision_s` (its failure's
/// deciding event; `None`: its first) in the run of `situation` under `spec` with noise from
/// `seed` (the run made again, deterministic; `None` if the run has none): search
/// for an escape from the first scan of the spell in which the agent's laser saw that robot
/// before contact (spells broken by [`SIGHTING_GAP_S`] unseen), and from the start, each
/// until `after_s` past the collision and the robot hit no longer closing in (or the time
/// limit). The agent's and every peer's controller must be built in; an external agent's is
/// an error naming it ([`judge_recorded`] judges such a run from its recorded path).
pub fn judge(
    situation: &Situation,
    spec: &RunSpec,
    seed: u64,
    after_s: f64,
    collision_s: Option<f64>,
) -> Result<Option<Judgement>, SpecError> {
    SpecError::check_positive("after_s", after_s, 3600.0)?;
    let run = Run::new(situation, spec, seed)?;
    if run.agent_is_external() {
        return Err(SpecError::new(
            "run.controller.name",
            "the agent's controller is external: judge its run from its recorded path",
        ));
    }
    let until = collision_s.map(|t| (t / spec.sim.dt_s).round() as u64);
    judge_run(run, spec, after_s, until, None)
}

/// What stands in for an agent whose controller is outside the core: the poses its run
/// recorded (`[step][robot][3]`, flat) and its first collision with a robot as the monitor
/// recorded it (the step contact began, the robot).
#[derive(Debug, Clone, Copy)]
pub struct Recorded<'a> {
    /// Every robot's pose at the start and after every step.
    pub trajectory: &'a [f64],
    /// The step contact began.
    pub collision_step: u64,
    /// The robot hit.
    pub robot: u32,
}

/// [`judge`] for a run whose agent's controller is outside the core (a `python:` class, a
/// program, a ROS 2 node): the agent is driven along its recorded path (each decision the
/// command that takes it from where it stands to where the record has it a control period
/// later: the exact inverse of the simulator's motion), every peer by its own controller, and
/// the collision is the recorded one. An error if the replayed agent strays from its record
/// by more than a millimetre before contact (a record of another run, or of a peer that
/// reacted differently).
pub fn judge_recorded(
    situation: &Situation,
    spec: &RunSpec,
    seed: u64,
    after_s: f64,
    recorded: &Recorded<'_>,
) -> Result<Judgement, SpecError> {
    SpecError::check_positive("after_s", after_s, 3600.0)?;
    let mut run = Run::new(situation, spec, seed)?;
    run.hand_over_agent();
    let n = situation.robots.len();
    let steps = recorded.trajectory.len() / (3 * n.max(1));
    if recorded.collision_step as usize >= steps || recorded.robot as usize >= n {
        return Err(SpecError::new(
            "trajectory",
            format!(
                "{steps} recorded steps of {n} robots do not reach a collision with robot {} at \
                 step {}",
                recorded.robot, recorded.collision_step
            ),
        ));
    }
    judge_run(run, spec, after_s, None, Some(recorded))
        .map(|j| j.expect("a recorded collision is judged"))
}

/// The search of [`judge`] on `run` at its start, for the contact that begins at step `until`
/// (`None`: the first with a robot); `recorded` drives an external agent.
fn judge_run(
    mut run: Run,
    spec: &RunSpec,
    after_s: f64,
    until: Option<u64>,
    recorded: Option<&Recorded<'_>>,
) -> Result<Option<Judgement>, SpecError> {
    let branch = |run: &Run| {
        run.branch()
            .map_err(|e| SpecError::new("situation.robots", e))
    };
    let dt = spec.sim.dt_s;
    let gap = (SIGHTING_GAP_S / dt).round() as u64;
    let from_start = branch(&run)?;
    let agent = run.agent();
    let n = run.world().robots().len();
    let period = run.agent_period();
    let mut spells: Vec<Option<Spell>> = (0..n).map(|_| None).collect();
    let hit = loop {
        if run.ended() {
            return Ok(None);
        }
        let step = run.world().steps();
        if let Some(r) = recorded {
            if step == r.collision_step {
                break r.robot;
            }
            if step > 0 && straying(run.world(), agent, r, step) > STRAY_M {
                return Err(SpecError::new(
                    "trajectory",
                    format!(
                        "the agent's recorded path does not replay: {:.4} m off its record at \
                         {:.1} s",
                        straying(run.world(), agent, r, step),
                        step as f64 * dt
                    ),
                ));
            }
        }
        for id in run.agent_sees() {
            match &mut spells[id as usize] {
                Some(s) if s.last + gap >= step => s.last = step,
                spell => {
                    *spell = Some(Spell {
                        began: step,
                        last: step,
                        branch: branch(&run)?,
                    })
                }
            }
        }
        let command = recorded.map(|r| {
            let ahead = (step + period).min(r.collision_step);
            let at = &run.world().robots()[agent as usize].pose;
            velocity_between(at, pose_at(r, n, agent, ahead), (ahead - step) as f64 * dt)
        });
        // Between the agent's decisions the run keeps its last command, as it did.
        run.step(command);
        // Of robots touched in one step, one the agent had not seen is judged: its contact is
        // the more severe class, the one a failure is decided by.
        let now = run.world().steps();
        if recorded.is_some() {
            // The record says where its contact begins (checked at the top of the loop).
            continue;
        }
        let touched = touched_robots(run.world(), agent);
        let unseen = |id: &&u32| {
            spells[**id as usize]
                .as_ref()
                .is_none_or(|s| s.last + gap < now)
        };
        let touched = touched.iter().find(unseen).or(touched.first()).copied();
        match until {
            Some(k) if now == k => {
                break touched.ok_or_else(|| {
                    SpecError::new(
                        "collision_s",
                        format!(
                            "the run made again has no contact of the agent with a robot at \
                             {:.1} s (a run of another sitgen version?)",
                            k as f64 * dt
                        ),
                    )
                })?;
            }
            None if touched.is_some() => break touched.expect("matched"),
            _ => {}
        }
    };
    let collision = run.world().steps();
    let me = &run.world().robots()[agent as usize];
    let (v, w) = me.velocity;
    let reach = (me.body.origin_x_m.abs() + me.body.length_m / 2.0).hypot(me.body.width_m / 2.0);
    // Seen within the gap before contact, as the monitor's `visible` reads its window (the
    // scan that drove the step of contact is one step before it).
    let sighting = spells[hit as usize]
        .take()
        .filter(|s| s.last + gap >= collision);
    let limit = (spec.time_limit_s / dt - 1e-9).ceil() as u64;
    let horizon = Horizon {
        robot: hit,
        min_step: (collision + (after_s / dt).round() as u64).min(limit),
        limit_step: limit,
    };
    let w_max = spec.sim.max_turn_rate_deg_s.to_radians();
    let tried = manoeuvres(spec.sim.max_speed_m_s, w_max, dt, period);
    let mut count = 0;
    let mut found = None;
    if let Some(s) = &sighting {
        let (escape, k) = search(&s.branch, &horizon, &tried);
        count += k;
        found = escape.map(|e| (Verdict::Avoidable, e));
    }
    if found.is_none() {
        let (escape, k) = search(&from_start, &horizon, &tried);
        count += k;
        found = escape.map(|e| (Verdict::UnavoidableWithThisSensor, e));
    }
    let (verdict, witness) = match found {
        Some((verdict, e)) => (verdict, Some(e)),
        None => (Verdict::Unavoidable, None),
    };
    Ok(Some(Judgement {
        robot: hit,
        collision_s: collision as f64 * dt,
        sighted_s: sighting.map(|s| s.began as f64 * dt),
        speed_m_s: v,
        turn_rate_rad_s: w,
        at_rest: v.abs() + w.abs() * reach < AT_REST_M_S,
        verdict,
        witness,
        tried: count,
    }))
}

/// How far a replayed agent may stray from its record before contact, metres: a stored
/// record keeps poses as float32 (a few micrometres at 100 m), so a millimetre is another run.
const STRAY_M: f64 = 1e-3;

/// Robot `id`'s recorded pose at `step`.
fn pose_at(r: &Recorded<'_>, robots: usize, id: u32, step: u64) -> [f64; 3] {
    let k = (step as usize * robots + id as usize) * 3;
    [r.trajectory[k], r.trajectory[k + 1], r.trajectory[k + 2]]
}

/// How far the agent stands from its recorded pose at `step`, metres.
fn straying(world: &crate::sim::World, agent: u32, r: &Recorded<'_>, step: u64) -> f64 {
    let at = &world.robots()[agent as usize].pose;
    let want = pose_at(r, world.robots().len(), agent, step);
    (at.x_m - want[0]).hypot(at.y_m - want[1])
}

/// The constant (v, ω) that takes a robot from `from` to `to` in `t` seconds: the exact
/// inverse of [`crate::sim::integrate`] (the chord of an arc of turn Δθ is 2 |v/ω| sin(|Δθ|/2),
/// along the heading halfway through the turn).
pub fn velocity_between(from: &crate::situation::Pose, to: [f64; 3], t: f64) -> (f64, f64) {
    if t <= 0.0 {
        return (0.0, 0.0);
    }
    let turn = crate::sim::wrap_angle(to[2] - from.heading_rad);
    let (dx, dy) = (to[0] - from.x_m, to[1] - from.y_m);
    let chord = dx.hypot(dy);
    let mid = from.heading_rad + turn / 2.0;
    let sign = if dx * mid.cos() + dy * mid.sin() < 0.0 {
        -1.0
    } else {
        1.0
    };
    let v = if turn.abs() < 1e-12 {
        chord / t
    } else {
        chord * turn.abs() / (2.0 * (turn.abs() / 2.0).sin() * t)
    };
    (sign * v, turn / t)
}

/// The robots the agent touched in the step the world just took, in id order: a move of the
/// agent's refused by one, or its move refused by the agent.
fn touched_robots(world: &crate::sim::World, agent: u32) -> Vec<u32> {
    let robots = world.robots();
    let me = &robots[agent as usize];
    let moved = |r: &crate::sim::RobotState| r.stalled && r.velocity != (0.0, 0.0);
    robots
        .iter()
        .filter(|r| r.id != agent)
        .filter(|r| {
            (moved(r) && r.contacts.contains(&Contact::Robot(agent)))
                || (moved(me) && me.contacts.contains(&Contact::Robot(r.id)))
        })
        .map(|r| r.id)
        .collect()
}
