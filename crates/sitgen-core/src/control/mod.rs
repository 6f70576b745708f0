//! Controllers: what drives each robot. A controller sees only an [`Observation`] (its laser,
//! own pose and velocity, stall flag, time, and the robots its laser sees) plus its own route,
//! given at reset; it returns a command (v m/s, ω rad/s). It never sees the map.
//!
//! Built in: `straight` (the peers'), `snd` (Smoothed Nearness-Diagram to the last waypoint),
//! `snd_follow` (the paper's agent: a route follower driving SND), and the baselines `follow`
//! (pure pursuit), `vo` (Velocity Obstacles) and `dwa` (Dynamic Window Approach). User
//! controllers (`python:`, `cmd:`) are driven from the Python layer (`sitgen.run`).

mod dwa;
pub mod fault;
mod follow;
pub mod route;
pub mod snd;
mod snd_follow;
mod straight;
mod vo;

use std::collections::BTreeMap;

pub use dwa::Dwa;
pub use follow::Follow;
pub use snd::Snd;
pub use snd_follow::SndFollow;
pub use straight::Straight;
pub use vo::Vo;

use crate::error::{join, SpecError};
use crate::mission::ControllerSpec;
use crate::sim::Observation;
use crate::situation::Robot;

/// A velocity command: (v m/s, ω rad/s).
pub type Command = (f64, f64);

/// What every controller implements.
pub trait Controller: Send + BoxedClone {
    /// Start a run as `robot` (its route, body and behaviour at the end of the route).
    fn reset(&mut self, robot: &Robot);
    /// The command for this step.
    fn act(&mut self, obs: &Observation) -> Command;
    /// Where the controller is on its route, for controllers that follow one (so that a run
    /// can be restarted part-way with the rest of each route); `None` for those that do not.
    fn route(&self) -> Option<&route::RouteFollower> {
        None
    }
    /// Whether it reads the laser: a peer whose controller does is fitted with one (the
    /// agent always carries it).
    fn senses(&self) -> bool {
        true
    }
}

/// A controller copied with its state, mid-run: a run branches from a step with every
/// built-in controller where it stands ([`crate::avoidability`]). Every `Clone` controller has
/// it.
pub trait BoxedClone {
    /// A copy of this controller, state and all.
    fn boxed_clone(&self) -> Box<dyn Controller>;
}

impl<T: Controller + Clone + 'static> BoxedClone for T {
    fn boxed_clone(&self) -> Box<dyn Controller> {
        Box::new(self.clone())
    }
}

impl Clone for Box<dyn Controller> {
    fn clone(&self) -> Self {
        self.boxed_clone()
    }
}

/// Names of the built-in controllers.
pub const BUILT_IN: &[&str] = &["straight", "snd", "snd_follow", "follow", "vo", "dwa"];

/// The built-in controller a spec names, with its seeded fault if it names one; `path` names
/// the spec in errors.
pub fn build(spec: &ControllerSpec, path: &str) -> Result<Box<dyn Controller>, SpecError> {
    if !BUILT_IN.contains(&spec.name.as_str()) {
        return Err(SpecError::new(
            join(path, "name"),
            format!(
                "unknown controller `{}`; built in: {}",
                spec.name,
                BUILT_IN.join(", ")
            ),
        ));
    }
    let f = fault::of(spec, path)?;
    let params_path = join(path, "params");
    let (params, p) = (&spec.params, params_path.as_str());
    // The parameter and logic seams are the controller's own; the observation seam wraps it.
    let controller: Box<dyn Controller> = match spec.name.as_str() {
        "straight" => Box::new(Straight::from_params(params, p)?),
        "snd" => Box::new(Snd::from_params(params, p)?.with_fault(f)),
        "snd_follow" => Box::new(SndFollow::from_params(params, p)?.with_fault(f)),
        "follow" => Box::new(Follow::from_params(params, p)?),
        "vo" => Box::new(Vo::from_params(params, p)?.with_fault(f)),
        "dwa" => Box::new(Dwa::from_params(params, p)?.with_fault(f)),
        other => unreachable!("`{other}` is built in but not built"),
    };
    Ok(fault::wrap(controller, f))
}

/// How many simulator steps of `dt_s` seconds lie between a controller's decisions: its
/// `control_period_s` as a whole number of steps (1 when it has none). A period that is not a
/// whole number of steps is refused rather than rounded, so the rate a spec asks for is the rate
/// it gets; `path` names the spec in errors.
pub fn period_steps(spec: &ControllerSpec, dt_s: f64, path: &str) -> Result<u64, SpecError> {
    let Some(period) = spec.control_period_s else {
        return Ok(1);
    };
    let field = join(path, "control_period_s");
    SpecError::check_positive(&field, period, 3600.0)?;
    let steps = (period / dt_s).round();
    if steps < 1.0 || (steps * dt_s - period).abs() > 1e-6 * period {
        return Err(SpecError::new(
            field,
            format!("{period} s is not a whole number of {dt_s} s simulator steps"),
        ));
    }
    Ok(steps as u64)
}

/// How the names of controllers run outside the core (by the Python layer) start:
/// `python:MODULE:CLASS`, `cmd:PROGRAM …`, `ros2:PROGRAM …` (a ROS 2 node, docs/ros2.md),
/// `navground:BEHAVIOR` (a navground behaviour, docs/navground.md).
pub const EXTERNAL_PREFIXES: [&str; 4] = ["python:", "cmd:", "ros2:", "navground:"];

/// Whether a controller name is run outside the core (by the Python layer).
pub fn is_external(name: &str) -> bool {
    EXTERNAL_PREFIXES.iter().any(|p| name.starts_with(p))
}

/// The external controllers a peer may run: those called in the Python layer's own process
/// (`python:` classes, navground behaviours). A program or a ROS 2 node drives the agent only:
/// one process or node a robot, on one set of topics, is what their protocols have.
pub const PEER_EXTERNAL_PREFIXES: [&str; 2] = ["python:", "navground:"];

/// Check that `name`, the controller of a peer, is one a peer may run; `path` names the
/// controller spec in errors.
pub fn check_peer(name: &str, path: &str) -> Result<(), SpecError> {
    if is_external(name) && !PEER_EXTERNAL_PREFIXES.iter().any(|p| name.starts_with(p)) {
        return Err(SpecError::new(
            join(path, "name"),
            format!(
                "`{name}`: a peer's controller is built in, python: or navground: (a program \
                 or a ROS 2 node drives only the agent)"
            ),
        ));
    }
    Ok(())
}

/// Check a controller spec before any run: a built-in name with known parameters in range, or
/// a well-formed external name (`python:MODULE:CLASS`, `cmd:PROGRAM …`; whether the module or
/// program exists is for the Python layer to check). `path` names the spec in errors.
pub fn check(spec: &ControllerSpec, path: &str) -> Result<(), SpecError> {
    let name_path = join(path, "name");
    if let Some(period) = spec.control_period_s {
        SpecError::check_positive(&join(path, "control_period_s"), period, 3600.0)?;
    }
    if spec.fault.is_some() && is_external(&spec.name) {
        return Err(SpecError::new(
            join(path, "fault"),
            format!(
                "`{}` is not a built-in controller; seeded faults exist only in the built-in \
                 ones (docs/faults.md)",
                spec.name
            ),
        ));
    }
    if let Some(timeout) = spec.step_timeout_s {
        let field = join(path, "step_timeout_s");
        SpecError::check_positive(&field, timeout, 600.0)?;
        if !is_external(&spec.name) {
            return Err(SpecError::new(
                field,
                format!(
                    "`{}` is built in and runs inside the step loop; a step timeout is for a \
                     user's controller (python:, cmd:, ros2:, navground:)",
                    spec.name
                ),
            ));
        }
    }
    if spec.keep_alive && !spec.name.starts_with("ros2:") {
        return Err(SpecError::new(
            join(path, "keep_alive"),
            format!(
                "`{}`: keep_alive is for a ros2: node (one that takes seconds to start); \
                 expected false",
                spec.name
            ),
        ));
    }
    if let Some(target) = spec.name.strip_prefix("python:") {
        let (module, class) = target.rsplit_once(':').unwrap_or_default();
        if module.trim().is_empty() || class.trim().is_empty() {
            return Err(SpecError::new(
                name_path,
                format!("`{}`: expected python:MODULE:CLASS", spec.name),
            ));
        }
    } else if let Some((prefix, command)) = ["cmd:", "ros2:"]
        .iter()
        .find_map(|p| spec.name.strip_prefix(p).map(|c| (p, c)))
    {
        if command.trim().is_empty() {
            return Err(SpecError::new(
                name_path,
                format!("`{prefix}` names no program; expected {prefix}PROGRAM ARGS"),
            ));
        }
    } else if let Some(behavior) = spec.name.strip_prefix("navground:") {
        if behavior.trim().is_empty() || behavior.contains(char::is_whitespace) {
            return Err(SpecError::new(
                name_path,
                format!("`{}`: expected navground:BEHAVIOR (HL, ORCA, …)", spec.name),
            ));
        }
    } else {
        build(spec, path)?;
    }
    Ok(())
}

/// Reject parameters a controller does not have.
fn check_known(
    params: &BTreeMap<String, f64>,
    known: &[&str],
    path: &str,
) -> Result<(), SpecError> {
    match params.keys().find(|k| !known.contains(&k.as_str())) {
        Some(k) => Err(SpecError::new(
            join(path, k),
            format!("unknown parameter; expected one of {}", known.join(", ")),
        )),
        None => Ok(()),
    }
}

/// Parameter `name` in (0, hi], or `default`.
fn param(
    params: &BTreeMap<String, f64>,
    path: &str,
    name: &str,
    default: f64,
    hi: f64,
) -> Result<f64, SpecError> {
    let value = params.get(name).copied().unwrap_or(default);
    SpecError::check_positive(&join(path, name), value, hi)?;
    Ok(value)
}

#[cfg(test)]
pub(crate) mod tests;
