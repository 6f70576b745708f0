//! Mission planning: the second stage of the pipeline, after Arnold & Alexander (2013) §3.
//!
//! 1. *Place robots*: from the exact distance transform of the map (its edge counting as a wall,
//!    as it does to the simulator), every cell whose centre is
//!    farther from every obstacle than the body's enclosing radius plus `clearance_m` (plus half
//!    a cell diagonal, as an obstacle cell is a square, not a point) can hold a robot in any
//!    heading without touching anything. Robots are drawn uniformly from those cells, the agent
//!    first (from those in the largest region of the dilated map that A* can cross, so that
//!    its goals are mostly reachable); cells too close to a placed robot are removed before
//!    the next draw.
//! 2. *Plan the agent's route*: the map is dilated by `plan_margin_m` (the paper's dilation, which
//!    keeps routes off obstacle edges). Goals are drawn uniformly from free cells of the dilated
//!    map and planned with A* from the previous goal; an unreachable goal is discarded and
//!    another drawn, up to `goal_attempts` times. Goals are appended until the route is at least
//!    `min_route_length_m` long. Each leg is simplified with Ramer–Douglas–Peucker at
//!    `rdp_epsilon_m`, so the simplified route may cross obstacles: the agent must avoid them.
//! 3. *Give peers routes*: legs are straight segments that are clear on the dilated map, so a
//!    peer that drives straight at its waypoints never needs to plan. In `random` mode each leg
//!    goes a random way to a random point of the second half of the clear stretch that way
//!    (the longest of 8 such draws, so that peers in cluttered maps travel rather than
//!    shuffle); in `crossing` mode each leg is aimed through a random point of the agent's
//!    route and beyond it, so their paths cross (a random leg if 50 aims find no clear line).

pub mod astar;
pub mod rdp;
mod routes;

pub use routes::{check_peer_legs, continue_agent_route, generate};

use schemars::JsonSchema;
use serde::{Deserialize, Serialize};

use crate::error::{join, SpecError};
use crate::geometry::Body;

/// How peers' legs are chosen.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize, JsonSchema)]
#[serde(rename_all = "snake_case")]
pub enum PeerMode {
    /// Each leg ends at a random free point (Arnold & Alexander's peers).
    #[default]
    Random,
    /// Each leg crosses the agent's route.
    Crossing,
}

/// What a robot does at the end of its route.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize, JsonSchema)]
#[serde(rename_all = "snake_case")]
pub enum AtEnd {
    /// Stop at the last waypoint.
    #[default]
    Stop,
    /// Drive the route back to the start, and again, back and forth.
    Reverse,
    /// Drive from the last waypoint to the first and round again.
    Loop,
}

/// A controller and its parameters.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct ControllerSpec {
    /// Controller name (`snd_follow`, `straight`, `follow`, `vo`, `dwa`, `python:…`, `cmd:…`, `ros2:…`).
    pub name: String,
    /// Parameters by name, in the controller's documented units. Default: none.
    #[serde(default)]
    pub params: std::collections::BTreeMap<String, f64>,
    /// A seeded fault to switch on in a built-in controller (`docs/faults.md`); default none,
    /// the controller as it is.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub fault: Option<String>,
    /// Simulated seconds between the controller's decisions, a whole number of simulator
    /// steps, in (0, 3600]: it observes and commands every k-th step, and its command stays in
    /// force between (a controller slower than the simulator, as Player's SND thread was under
    /// a Stage running faster than real time). Default: every step.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub control_period_s: Option<f64>,
    /// What the controller is given of the other robots and the walls (docs/controller-protocol.md,
    /// "Perception"); default [`Perception::Sensed`].
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub perception: Option<Perception>,
    /// A `ros2:` node only: start the node once per worker process and reset it between runs
    /// (a new clock, initial pose, route and goal, and its reset service called where it offers
    /// one) instead of starting it for every run (docs/ros2.md, "One node across runs").
    /// Default false.
    #[serde(default, skip_serializing_if = "std::ops::Not::not")]
    pub keep_alive: bool,
    /// A user controller only: the processor time it may spend deciding one step, seconds of
    /// CPU, in (0, 600] (its process's; a wall-clock backstop of ten times this, at most 20 s
    /// more and at least 2 s, ends one that waits instead: docs/controller-protocol.md,
    /// "Deadlines"). Default 1 s (10 s for `navground:`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub step_timeout_s: Option<f64>,
}

/// What a controller perceives of the world beyond its own state.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize, JsonSchema)]
#[serde(rename_all = "snake_case")]
pub enum Perception {
    /// What the robot's sensors give, as on a deployed robot: the laser scan, and as tracks the
    /// robots the scan sees now.
    #[default]
    Sensed,
    /// What a simulator knows: the scan, and as tracks every other robot's true position and
    /// velocity, seen or not; a user controller is also given the map's walls as line
    /// segments when it starts.
    Exact,
}

impl ControllerSpec {
    /// The controller `name` with its defaults.
    pub fn named(name: &str) -> Self {
        Self {
            name: name.into(),
            params: Default::default(),
            fault: None,
            control_period_s: None,
            perception: None,
            keep_alive: false,
            step_timeout_s: None,
        }
    }
}

/// How to place robots and give them routes.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct MissionSpec {
    /// Seed of the mission's draws (placement, routes, peers' choices). Default: the
    /// situation's seed. A search sets it to place the same robots on a changed map.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub seed: Option<u64>,
    /// Body of every robot. Default: Pioneer 3-AT.
    #[serde(default)]
    pub body: Body,
    /// Fewest peer robots, in [0, 20]. Default 0.
    #[serde(default)]
    pub peers_min: u32,
    /// Most peer robots, in [peers_min, 20]; the count is drawn uniformly. Default 5.
    #[serde(default = "default_peers_max")]
    pub peers_max: u32,
    /// Free space kept around every robot's footprint at the start, metres, in [0, 10].
    /// Default 0.1.
    #[serde(default = "default_clearance_m")]
    pub clearance_m: f64,
    /// Dilation of the map for route planning, metres, in [0, enclosing radius + clearance_m].
    /// Default 0.4.
    #[serde(default = "default_plan_margin_m")]
    pub plan_margin_m: f64,
    /// Shortest acceptable agent route (planned length), metres, in [0, 100000]. Default 20.
    #[serde(default = "default_min_route_length_m")]
    pub min_route_length_m: f64,
    /// Ramer–Douglas–Peucker tolerance for the agent's route, metres, in [0, 1000]. Default 0.5.
    #[serde(default = "default_rdp_epsilon_m")]
    pub rdp_epsilon_m: f64,
    /// Goals drawn for one leg before generation fails, in [1, 100000]. Default 200.
    #[serde(default = "default_goal_attempts")]
    pub goal_attempts: u32,
    /// `random` or `crossing`. Default `random`.
    #[serde(default)]
    pub peer_mode: PeerMode,
    /// Legs of each peer's route, in [1, 100]. Default 3.
    #[serde(default = "default_peer_legs")]
    pub peer_legs: u32,
    /// What peers do at the end of their route: `stop`, `reverse` or `loop`. Default `loop`.
    #[serde(default = "default_peer_at_end")]
    pub peer_at_end: AtEnd,
    /// The agent's controller. Default `snd_follow`.
    #[serde(default = "default_agent_controller")]
    pub agent_controller: ControllerSpec,
    /// The peers' controller. Default `straight`.
    #[serde(default = "default_peer_controller")]
    pub peer_controller: ControllerSpec,
    /// Controllers the peers are drawn from, each peer its own (uniformly, after every route
    /// is planned), in place of `peer_controller`: a crowd that mixes behaviours. Default
    /// empty: every peer runs `peer_controller`.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub peer_controllers: Vec<ControllerSpec>,
}

fn default_peers_max() -> u32 {
    5
}
fn default_clearance_m() -> f64 {
    0.1
}
fn default_plan_margin_m() -> f64 {
    0.4
}
fn default_min_route_length_m() -> f64 {
    20.0
}
fn default_rdp_epsilon_m() -> f64 {
    0.5
}
fn default_goal_attempts() -> u32 {
    200
}
fn default_peer_legs() -> u32 {
    3
}
fn default_peer_at_end() -> AtEnd {
    AtEnd::Loop
}
fn default_agent_controller() -> ControllerSpec {
    ControllerSpec::named("snd_follow")
}
fn default_peer_controller() -> ControllerSpec {
    ControllerSpec::named("straight")
}

impl Default for MissionSpec {
    fn default() -> Self {
        Self {
            seed: None,
            body: Body::default(),
            peers_min: 0,
            peers_max: default_peers_max(),
            clearance_m: default_clearance_m(),
            plan_margin_m: default_plan_margin_m(),
            min_route_length_m: default_min_route_length_m(),
            rdp_epsilon_m: default_rdp_epsilon_m(),
            goal_attempts: default_goal_attempts(),
            peer_mode: PeerMode::default(),
            peer_legs: default_peer_legs(),
            peer_at_end: default_peer_at_end(),
            agent_controller: default_agent_controller(),
            peer_controller: default_peer_controller(),
            peer_controllers: Vec::new(),
        }
    }
}

fn check_count(path: &str, value: u32, lo: u32, hi: u32) -> Result<(), SpecError> {
    if (lo..=hi).contains(&value) {
        Ok(())
    } else {
        Err(SpecError::new(
            path,
            format!("{value} is not in [{lo}, {hi}]"),
        ))
    }
}

impl MissionSpec {
    /// Check every range; `path` names the section in errors.
    pub fn validate(&self, path: &str) -> Result<(), SpecError> {
        self.body.validate(&join(path, "body"))?;
        check_count(&join(path, "peers_min"), self.peers_min, 0, 20)?;
        check_count(&join(path, "peers_max"), self.peers_max, self.peers_min, 20)?;
        SpecError::check_in(&join(path, "clearance_m"), self.clearance_m, 0.0, 10.0)?;
        let most = self.body.enclosing_radius() + self.clearance_m;
        if !(self.plan_margin_m >= 0.0 && self.plan_margin_m <= most) {
            return Err(SpecError::new(
                join(path, "plan_margin_m"),
                format!(
                    "{} is not in [0, {most:.4}] (the body's enclosing radius plus clearance_m, so that robots start on plannable ground)",
                    self.plan_margin_m
                ),
            ));
        }
        SpecError::check_in(
            &join(path, "min_route_length_m"),
            self.min_route_length_m,
            0.0,
            1e5,
        )?;
        SpecError::check_in(
            &join(path, "rdp_epsilon_m"),
            self.rdp_epsilon_m,
            0.0,
            1000.0,
        )?;
        check_count(&join(path, "goal_attempts"), self.goal_attempts, 1, 100_000)?;
        check_count(&join(path, "peer_legs"), self.peer_legs, 1, 100)?;
        check_count(
            &join(path, "peer_controllers"),
            self.peer_controllers.len() as u32,
            0,
            100,
        )?;
        let listed = self
            .peer_controllers
            .iter()
            .enumerate()
            .map(|(i, c)| (format!("peer_controllers[{i}]"), c));
        for (name, c) in [
            ("agent_controller".to_string(), &self.agent_controller),
            ("peer_controller".to_string(), &self.peer_controller),
        ]
        .into_iter()
        .chain(listed)
        {
            if c.name.trim().is_empty() {
                return Err(SpecError::new(
                    join(&join(path, &name), "name"),
                    "must name a controller",
                ));
            }
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests;
