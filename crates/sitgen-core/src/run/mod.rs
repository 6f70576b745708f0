//! A run: one situation driven to its end, watched, and scored.
//!
//! Each step, in this order (the paper's Player/Stage loop made synchronous):
//! 1. every robot whose controller decides this step (every `control_period_s`; between, its
//!    last command stays in force) observes the world as the last step left it (the agent, and
//!    each peer whose controller senses, carries the laser; the agent's scans every step, for
//!    the monitor);
//! 2. those controllers act on their observations — the agent's is a built-in controller, or
//!    the command comes from outside (a Python or external controller driven by the Python
//!    layer);
//! 3. a command that is not finite ends the run with outcome `error`;
//! 4. the world steps ([`World::step`]);
//! 5. the monitor watches the new state, the coverage observer marks the cells of the
//!    interaction space it shows ([`crate::coverage`]), and every robot's pose is appended to
//!    the trajectory;
//! 6. the run ends when the monitor sees the agent complete its route (`completed`) or the time
//!    limit is reached (`timeout`, with a timeout event); its scored events give its score and
//!    its failure class ([`crate::failure::classify`]).
//!
//! A run is a pure function of (situation, run spec, seed): no clock, no shared state.

use schemars::JsonSchema;
use serde::{Deserialize, Serialize};

use crate::control::{self, Command, Controller};
use crate::coverage::{CoverageRecord, Observer};
use crate::error::SpecError;
use crate::failure::{self, Failure, FailureClass};
use crate::mission::Perception;
use crate::monitor::{self, signals, Event, Frame, Monitor};
use crate::requirement::{self, Compiled, Verdict};
use crate::scoring::{self, Score, ScoringSpec};
use crate::sim::{Observation, World};
use crate::situation::Situation;

mod branch;
pub mod episodes;
mod jobs;
pub mod perturb;
pub mod profile;
pub mod protocol;
pub mod serve;
mod spec;

pub use branch::Branch;
pub use jobs::{pack_trajectory, par_map, run_batch, run_job, Job, JobResult, JobSituation};
pub use perturb::Perturbation;
pub use spec::{controller_spec, is_external, RunSpec};

/// Most steps a run may take: 10⁷ (a day at 10 ms steps is 8.6 × 10⁶), so that a tiny `dt_s`
/// cannot ask for a run that never ends.
pub const MAX_STEPS: f64 = 1e7;

/// How a run ended.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize, JsonSchema)]
#[serde(rename_all = "snake_case")]
pub enum Outcome {
    /// The agent completed its route.
    Completed,
    /// The time limit came first.
    Timeout,
    /// A perturbed copy's horizon came first: stopped unfinished, without a timeout.
    Stopped,
    /// The agent's controller failed (crashed, hung, or returned garbage).
    Error,
}

/// The result of a run.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct RunRecord {
    /// How it ended.
    pub outcome: Outcome,
    /// Why, for `error` (and a one-line summary otherwise).
    pub reason: String,
    /// Score and breakdown.
    pub score: Score,
    /// The event log, in start order.
    pub events: Vec<Event>,
    /// What went wrong: the failure class of the most severe scored event; `None` if nothing.
    pub failure: Option<Failure>,
    /// The cells of the interaction space the run exercised ([`crate::coverage`]).
    pub coverage: CoverageRecord,
    /// Steps simulated.
    pub steps: u64,
    /// Simulated seconds.
    pub time_s: f64,
    /// Robots, in id order.
    pub robots: usize,
    /// Poses (x, y, heading) of every robot at the start and after every step, flat:
    /// `[step][robot][3]`.
    #[serde(skip)]
    pub trajectory: Vec<f64>,
    /// Each of the run spec's requirements' verdict, in order ([`crate::requirement`]).
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub requirements: Vec<Verdict>,
    /// The requirement signals the requirements read, one value a sample, indexed as
    /// [`monitor::signals::NAMES`] (those not read are empty).
    #[serde(skip)]
    pub signals: Vec<Vec<f64>>,
}

impl RunRecord {
    /// The event log as JSON Lines.
    pub fn events_jsonl(&self) -> String {
        monitor::to_jsonl(&self.events)
    }
}

/// A run in progress.
pub struct Run {
    world: World,
    monitor: Option<Monitor>,
    coverage: Option<Observer>,
    controllers: Vec<Option<Box<dyn Controller>>>,
    /// Steps between each robot's decisions (its controller's `control_period_s`).
    periods: Vec<u64>,
    /// Whether each robot's controller has the exact perception ([`Perception::Exact`]).
    exact: Vec<bool>,
    /// The agent's observation of the world as it stands, once asked for before the step.
    agent_scan: Option<Observation>,
    agent: u32,
    scoring: ScoringSpec,
    limit_steps: u64,
    /// Where a perturbed copy stops unfinished, if before the time limit, and the class it
    /// watches for past it ([`Perturbation`]).
    horizon: Option<(u64, Option<FailureClass>)>,
    /// The agent's worst class so far, as read from the monitor's log at that many changes.
    worst_read: (u64, Option<FailureClass>),
    trajectory: Vec<f64>,
    ended: Option<(Outcome, String)>,
    /// The requirements judged at the end, and what they need recorded on the way.
    requirements: Requirements,
}

/// A run's requirements and the agent's sightings their signals need (kept only when some
/// requirement reads `peer_seen`).
struct Requirements {
    compiled: Vec<Compiled>,
    reads: [bool; 8],
    seen: Vec<Vec<u32>>,
    goal: (f64, f64),
}

impl Run {
    /// Start a run of `situation`; sensor noise is drawn from `seed`. The agent's controller is
    /// built here unless it is external (`python:`/`cmd:`), in which case every step needs
    /// its command from [`Run::step`].
    pub fn new(situation: &Situation, spec: &RunSpec, seed: u64) -> Result<Self, SpecError> {
        spec.validate("run")?;
        let (sim, world_seed) = spec.world_settings(seed);
        let world = World::new(situation, sim, world_seed)?;
        Self::in_world(situation, spec, world)
    }

    /// [`Run::new`] for a situation whose map is given decoded, with its squared distances to
    /// its occupied cells ([`crate::situation::generate_with_distances`] returns both): the
    /// same run, less a decode and a distance transform ([`World::with_distances`]).
    pub fn with_distances(
        situation: &Situation,
        spec: &RunSpec,
        seed: u64,
        map: crate::grid::Map,
        to_occupied: &[f64],
    ) -> Result<Self, SpecError> {
        spec.validate("run")?;
        let (sim, world_seed) = spec.world_settings(seed);
        let world = World::with_distances(situation, map, to_occupied, sim, world_seed)?;
        Self::in_world(situation, spec, world)
    }

    /// The run of `situation` in `world`, its start (`spec` checked); a perturbed copy's
    /// robots start jittered, drawn from the world's seed (the copy's).
    fn in_world(
        situation: &Situation,
        spec: &RunSpec,
        mut world: World,
    ) -> Result<Self, SpecError> {
        world.check_start()?;
        let copy_seed = world.seed();
        let jittered = spec
            .perturbation
            .as_ref()
            .map(|p| p.jitter_starts(situation, &mut world, copy_seed));
        let situation = jittered.as_ref().unwrap_or(situation);
        let monitor = Monitor::new(situation, &world, &spec.monitor);
        let agent = monitor.agent();
        let coverage = Observer::new(&world, agent, spec.monitor.attribution_window_s);
        let mut controllers = Vec::with_capacity(situation.robots.len());
        let mut periods = Vec::with_capacity(situation.robots.len());
        let mut exact = Vec::with_capacity(situation.robots.len());
        for r in &situation.robots {
            let (controller, path) = controller_spec(situation, spec, r.id);
            periods.push(control::period_steps(controller, spec.sim.dt_s, &path)?);
            exact.push(controller.perception == Some(Perception::Exact));
            if is_external(&controller.name) {
                if r.id != agent {
                    control::check_peer(&controller.name, &path)?;
                    // Its observation is asked for as the agent's is: with a laser.
                    world
                        .fit_laser(r.id)
                        .expect("the situation's robots are the world's");
                }
                controllers.push(None);
                continue;
            }
            let mut c = control::build(controller, &path)?;
            c.reset(r);
            if c.senses() {
                world
                    .fit_laser(r.id)
                    .expect("the situation's robots are the world's");
            }
            controllers.push(Some(c));
        }
        let limit_steps = (spec.time_limit_s / spec.sim.dt_s - 1e-9).ceil() as u64;
        let horizon = spec.horizon().and_then(|(horizon_s, watch_for)| {
            let steps = (horizon_s / spec.sim.dt_s - 1e-9).ceil() as u64;
            (steps < limit_steps).then_some((steps, watch_for))
        });
        let compiled =
            requirement::compile_all(&spec.requirement, "run.requirement", spec.sim.dt_s)?;
        let me = &situation.robots[agent as usize];
        let requirements = Requirements {
            reads: if spec.signals {
                [true; 8]
            } else {
                requirement::reads(&compiled)
            },
            compiled,
            seen: vec![Vec::new()],
            goal: me
                .waypoints
                .last()
                .map_or((me.start.x_m, me.start.y_m), |w| (w[0], w[1])),
        };
        let mut run = Self {
            requirements,
            world,
            monitor: Some(monitor),
            coverage: Some(coverage),
            controllers,
            periods,
            exact,
            agent_scan: None,
            agent,
            scoring: spec.scoring.clone(),
            limit_steps,
            horizon,
            worst_read: (u64::MAX, None),
            trajectory: Vec::new(),
            ended: None,
        };
        run.record_poses();
        Ok(run)
    }

    /// Whether robot `id`'s controller decides on the coming step: every `control_period_s`,
    /// from the first step on; between, its last command stays in force.
    pub fn acts_now(&self, id: u32) -> bool {
        self.world.steps().is_multiple_of(self.periods[id as usize])
    }

    /// Whether the agent's controller decides on the coming step ([`Run::acts_now`]): an
    /// external controller is asked for a command only then.
    pub fn agent_acts_now(&self) -> bool {
        self.acts_now(self.agent)
    }

    /// Whether the agent's commands come from outside.
    pub fn agent_is_external(&self) -> bool {
        self.controllers[self.agent as usize].is_none()
    }

    /// The robots whose commands come from outside (the agent's, peers' `python:` and
    /// `navground:` controllers), in id order.
    pub fn external(&self) -> Vec<u32> {
        (0..self.controllers.len() as u32)
            .filter(|&id| self.controllers[id as usize].is_none())
            .collect()
    }

    /// Whether any robot's commands come from outside: the run is stepped from the Python
    /// layer ([`Run::step_with`]).
    pub fn any_external(&self) -> bool {
        self.controllers.iter().any(Option::is_none)
    }

    /// The world as it stands.
    pub fn world(&self) -> &World {
        &self.world
    }

    /// The agent's id.
    pub fn agent(&self) -> u32 {
        self.agent
    }

    /// What the agent senses now (for an external controller). The scan is kept for the
    /// coming step, which would otherwise cast the same beams again (noise is keyed by step and
    /// robot, so it is the same scan either way).
    pub fn agent_observation(&mut self) -> Observation {
        let obs = self
            .agent_scan
            .get_or_insert_with(|| {
                self.world
                    .observe(self.agent)
                    .expect("the agent is in the world")
            })
            .clone();
        self.perceived(self.agent, obs)
    }

    /// What robot `id` senses now, as its controller is given it (for an external controller;
    /// the agent's is [`Run::agent_observation`]).
    pub fn observation(&mut self, id: u32) -> Observation {
        if id == self.agent {
            return self.agent_observation();
        }
        let obs = self.world.observe(id).expect("ids are the world's");
        self.perceived(id, obs)
    }

    /// How many waypoints of its route robot `id` has reached on its first pass, as the
    /// monitor sees it.
    pub fn waypoints_reached(&self, id: u32) -> usize {
        self.monitor.as_ref().map_or(0, |m| m.waypoints_reached(id))
    }

    /// What robot `id`'s controller is given of its observation `obs`: with the exact
    /// perception, every other robot's true state as its tracks in place of those its laser
    /// sees (the monitor still knows which the laser saw).
    fn perceived(&self, id: u32, obs: Observation) -> Observation {
        perceived(&self.world, self.exact[id as usize], id, obs)
    }

    /// How many waypoints of its route the agent has reached, as the monitor sees it (the
    /// index of its current waypoint, for controllers that do not follow the route themselves).
    pub fn agent_waypoints_reached(&self) -> usize {
        self.waypoints_reached(self.agent)
    }

    /// The waypoints the agent has yet to reach, in order, as the monitor counts them.
    pub fn agent_route_ahead(&self) -> Vec<(f64, f64)> {
        self.live_monitor().route_ahead(self.agent)
    }

    /// The penalty points the run has earned so far: every scored event as if it ended now
    /// (those still lasting count up to now). The timeout, decided only at the end, is not in
    /// it.
    pub fn penalty_so_far(&self) -> f64 {
        scoring::points_until(
            self.live_monitor().events_so_far(),
            &self.scoring,
            self.world.time_s(),
            |e| self.scored(e),
        )
    }

    /// Whether an event counts toward the score: the agent's, or any with `score_peers`.
    fn scored(&self, e: &Event) -> bool {
        self.scoring.score_peers || e.concerns(self.agent)
    }

    pub(crate) fn live_monitor(&self) -> &Monitor {
        self.monitor
            .as_ref()
            .expect("the monitor lives until the end")
    }

    /// `situation`'s robots as they stand now (the situation this run was started with): each
    /// at its pose, at rest, with the rest of its route as its controller's route follower
    /// has it (or, for a controller that follows none, the waypoints the monitor has not yet
    /// seen it reach), so that a run of them carries on from here.
    pub fn robots_now(&self, situation: &Situation) -> Vec<crate::situation::Robot> {
        let monitor = self
            .monitor
            .as_ref()
            .expect("the monitor lives until the end");
        situation
            .robots
            .iter()
            .zip(self.world.robots())
            .zip(&self.controllers)
            .map(|((r, state), controller)| {
                let ahead = match controller.as_ref().and_then(|c| c.route()) {
                    Some(route) => route.remaining().into_iter().map(|(x, y)| [x, y]).collect(),
                    None => r.waypoints[monitor.waypoints_reached(r.id).min(r.waypoints.len())..]
                        .to_vec(),
                };
                crate::situation::Robot {
                    start: state.pose,
                    waypoints: ahead,
                    ..r.clone()
                }
            })
            .collect()
    }

    /// How the run ended, once it has.
    pub fn outcome(&self) -> Option<&Outcome> {
        self.ended.as_ref().map(|(outcome, _)| outcome)
    }

    /// Whether the run has ended.
    pub fn ended(&self) -> bool {
        self.ended.is_some()
    }

    /// One step. `agent_command` is the external controller's command (ignored for a built-in
    /// agent, and on steps where the agent does not act: its last command stays in force);
    /// returns whether the run has ended.
    pub fn step(&mut self, agent_command: Option<Command>) -> bool {
        let given: Vec<(u32, Command)> =
            agent_command.map(|c| (self.agent, c)).into_iter().collect();
        self.step_with(&given)
    }

    /// One step, `external` the commands of the external robots that act now, by id (one
    /// missing is (0, 0); those of robots that do not act now, or are built in, are ignored:
    /// a robot's last command stays in force between its decisions). Returns whether the run
    /// has ended.
    pub fn step_with(&mut self, external: &[(u32, Command)]) -> bool {
        if self.ended.is_some() {
            return true;
        }
        let n = self.controllers.len();
        let mut commands = Vec::with_capacity(n);
        let mut seen = Vec::new();
        for id in 0..n as u32 {
            let acts = self.acts_now(id);
            if !acts && id != self.agent {
                continue;
            }
            let given = || {
                external
                    .iter()
                    .find(|(who, _)| *who == id)
                    .map_or((0.0, 0.0), |&(_, c)| c)
            };
            if id != self.agent && self.controllers[id as usize].is_none() {
                // An external peer was observed by its caller; the command is all it needs.
                let command = given();
                if !(command.0.is_finite() && command.1.is_finite()) {
                    return self.not_finite(id, command);
                }
                commands.push((id, command.0, command.1));
                continue;
            }
            // The agent's laser scans every step whether or not its controller acts: what it
            // saw is the monitor's to know.
            let kept = if id == self.agent {
                self.agent_scan.take()
            } else {
                None
            };
            let obs = kept.unwrap_or_else(|| self.world.observe(id).expect("ids are the world's"));
            if id == self.agent {
                seen = obs.tracks.iter().map(|t| t.id).collect();
                if !acts {
                    continue;
                }
            }
            let obs = self.perceived(id, obs);
            let command = match &mut self.controllers[id as usize] {
                Some(c) => c.act(&obs),
                None => given(),
            };
            if !(command.0.is_finite() && command.1.is_finite()) {
                return self.not_finite(id, command);
            }
            commands.push((id, command.0, command.1));
        }
        self.world
            .step(&commands)
            .expect("commands are finite and for known robots");
        self.watch_step(&seen)
    }

    /// End the run in error: robot `id`'s controller gave `command`, which is not finite.
    fn not_finite(&mut self, id: u32, command: Command) -> bool {
        let who = monitor::robot_name(id, self.agent);
        self.fail(format!(
            "{who}'s controller returned a command that is not finite: ({}, {})",
            command.0, command.1
        ))
    }

    /// One step of another simulator's run of the same situation (a replay of its log, e.g.
    /// Stage's through `integrations/stage`): the world is put where that step left it
    /// ([`World::replay`]) and watched, recorded and ended as [`Run::step`] does; `seen` are
    /// the robots the agent's scan before the step saw. Returns whether the run has ended.
    pub fn replay_step(
        &mut self,
        states: &[(crate::situation::Pose, (f64, f64), bool)],
        seen: &[u32],
    ) -> Result<bool, String> {
        if self.ended.is_some() {
            return Ok(true);
        }
        self.world.replay(self.world.steps() + 1, states)?;
        Ok(self.watch_step(seen))
    }

    /// After the world has stepped: record the poses, let the monitor and the coverage
    /// observer watch, and end the run on completion, at the time limit or at a copy's
    /// horizon.
    fn watch_step(&mut self, seen: &[u32]) -> bool {
        self.agent_scan = None;
        self.record_poses();
        if self.requirements.reads[signals::PEER_SEEN] {
            self.requirements.seen.push(seen.to_vec());
        }
        let monitor = self
            .monitor
            .as_mut()
            .expect("the monitor lives until the end");
        let frame = Frame {
            step: self.world.steps(),
            seen_by_agent: seen,
            world: &self.world,
        };
        monitor.observe(&frame);
        self.coverage
            .as_mut()
            .expect("the observer lives until the end")
            .observe(&frame);
        if monitor.route_completed(self.agent) {
            self.ended = Some((Outcome::Completed, "the agent completed its route".into()));
        } else if self.world.steps() >= self.limit_steps {
            self.ended = Some((
                Outcome::Timeout,
                format!("route not completed within {:.1} s", self.world.time_s()),
            ));
        } else if self.past_horizon() {
            self.ended = Some((
                Outcome::Stopped,
                format!(
                    "stopped at the watch's horizon, {:.1} s",
                    self.world.time_s()
                ),
            ));
        }
        self.ended.is_some()
    }

    /// Whether a perturbed copy is done: at its horizon, or past it once it has shown the
    /// class it watches for or a more severe one.
    fn past_horizon(&mut self) -> bool {
        let Some((steps, watch_for)) = self.horizon else {
            return false;
        };
        if self.world.steps() < steps {
            return false;
        }
        let Some(class) = watch_for else {
            return true;
        };
        let monitor = self.live_monitor();
        let changes = monitor.log_changes();
        if self.worst_read.0 != changes {
            let worst = failure::worst_so_far(monitor.events_so_far(), self.agent);
            self.worst_read = (changes, worst);
        }
        self.worst_read.1.is_some_and(|so_far| so_far <= class)
    }

    /// End the run with outcome `error` for `reason` (a controller that crashed, hung or sent
    /// garbage); returns true.
    pub fn fail(&mut self, reason: String) -> bool {
        if self.ended.is_none() {
            self.ended = Some((Outcome::Error, reason));
        }
        true
    }

    /// Step a run whose controllers are all built in until it ends.
    pub fn run_to_end(&mut self) {
        while !self.step(None) {}
    }

    /// The record of the run; a run not yet ended is ended here with a timeout.
    pub fn finish(mut self) -> RunRecord {
        let (outcome, reason) = self.ended.take().unwrap_or_else(|| {
            (
                Outcome::Timeout,
                format!("stopped at {:.1} s", self.world.time_s()),
            )
        });
        let agent = self.agent;
        let monitor = self.monitor.take().expect("finished once");
        let events = monitor.finish(self.world.steps(), outcome == Outcome::Timeout, |e| {
            self.scored(e)
        });
        let failure = failure::classify(&events, agent);
        let score = scoring::score(&events, &self.scoring, failure.as_ref());
        let coverage = self.coverage.take().expect("finished once").finish(
            &events,
            failure.as_ref(),
            &self.world,
            &self.trajectory,
        );
        let (requirements, signals) = self.judge_requirements();
        RunRecord {
            requirements,
            signals,
            outcome,
            reason,
            score,
            failure,
            coverage,
            events,
            steps: self.world.steps(),
            time_s: self.world.time_s(),
            robots: self.controllers.len(),
            trajectory: self.trajectory,
        }
    }

    /// The requirements' verdicts on the run as recorded, and the signals they read.
    fn judge_requirements(&self) -> (Vec<Verdict>, Vec<Vec<f64>>) {
        let r = &self.requirements;
        if !r.reads.contains(&true) && r.compiled.is_empty() {
            return (Vec::new(), Vec::new());
        }
        let robots = self.world.robots();
        let recorded = signals::Recorded {
            trajectory: &self.trajectory,
            robots: robots.len(),
            agent: self.agent as usize,
            bodies: robots.iter().map(|s| s.body.clone()).collect(),
            goal: r.goal,
            seen: &r.seen,
            world: &self.world,
        };
        let dt_s = self.world.spec().dt_s;
        let signals = signals::compute(&recorded, &r.reads, dt_s);
        let n = self.trajectory.len() / (3 * robots.len().max(1));
        (
            requirement::verdicts(&r.compiled, &signals, n, dt_s),
            signals,
        )
    }

    fn record_poses(&mut self) {
        for r in self.world.robots() {
            self.trajectory
                .extend([r.pose.x_m, r.pose.y_m, r.pose.heading_rad]);
        }
    }
}

/// What robot `id`'s controller is given of its observation `obs` in `world`: with the exact
/// perception (`exact`), every other robot's true state as its tracks.
fn perceived(world: &World, exact: bool, id: u32, mut obs: Observation) -> Observation {
    if exact {
        obs.tracks = world.true_tracks(id);
    }
    obs
}

/// Run `situation` with built-in controllers to its end.
pub fn run(situation: &Situation, spec: &RunSpec, seed: u64) -> Result<RunRecord, SpecError> {
    run_to_end(Run::new(situation, spec, seed)?)
}

/// Run `r` with built-in controllers to its end.
fn run_to_end(mut r: Run) -> Result<RunRecord, SpecError> {
    if r.any_external() {
        return Err(SpecError::new(
            "run.controller.name",
            "Python and external controllers run through the Python layer (sitgen.run)",
        ));
    }
    r.run_to_end();
    Ok(r.finish())
}

#[cfg(test)]
pub(crate) mod tests;
