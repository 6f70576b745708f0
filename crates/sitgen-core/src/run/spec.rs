//! The run spec: how to run a situation (simulator, monitor, scoring, time limit, the agent's
//! controller, a perturbed copy's perturbation), checked field by field.

use schemars::JsonSchema;
use serde::{Deserialize, Serialize};

use super::{profile, Perturbation, MAX_STEPS};
use crate::control;
use crate::error::{join, SpecError};
use crate::mission::ControllerSpec;
use crate::monitor::MonitorSpec;
use crate::requirement::{self, RequirementSpec};
use crate::scoring::ScoringSpec;
use crate::sim::SimSpec;
use crate::situation::Situation;

/// How to run a situation.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct RunSpec {
    /// A named run profile laid under this spec's own fields (docs/profiles.md): `default`
    /// (sitgen's defaults) or `paper` (Arnold & Alexander's Player/Stage setting). Default:
    /// none, sitgen's defaults.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub profile: Option<String>,
    /// The agent's controller; default: the one the situation names (`snd_follow` unless its
    /// mission said otherwise). `python:module:Class` and `cmd:program args` are run by the
    /// Python layer.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub controller: Option<ControllerSpec>,
    /// Simulated seconds after which an unfinished run stops with a timeout, in (0, 86400].
    /// Default 600.
    #[serde(default = "default_time_limit_s")]
    pub time_limit_s: f64,
    /// The simulator.
    #[serde(default)]
    pub sim: SimSpec,
    /// The monitor's thresholds.
    #[serde(default)]
    pub monitor: MonitorSpec,
    /// Penalties.
    #[serde(default)]
    pub scoring: ScoringSpec,
    /// Run a perturbed copy of the situation instead of the situation itself: sensor noise
    /// and start offsets a real robot would not notice ([`perturb`]). Default none.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub perturbation: Option<Perturbation>,
    /// Watch the run only until its failure is decided, as a perturbed copy is watched (its
    /// `horizon_s` and `watch_for`, [`perturb`]), without perturbing it: what a shrink's probe
    /// asks. Default none: to the time limit.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub watch: Option<Watch>,
    /// The user's requirements, in STL over the monitor's signals (docs/requirements.md);
    /// each run's record carries their verdicts. Written `[[requirement]]`. Default none.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub requirement: Vec<RequirementSpec>,
    /// Record every requirement signal of the run in its record, not only those its
    /// requirements read (what `sitgen export` asks of a run made again). Default false.
    #[serde(default, skip_serializing_if = "std::ops::Not::not")]
    pub signals: bool,
}

/// How far a run is watched: to `horizon_s` simulated seconds, and past it only until it has
/// shown `watch_for` or a more severe class (then to its time limit).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct Watch {
    /// Simulated seconds, in (0, 86400].
    pub horizon_s: f64,
    /// A failure class; default none: stop at the horizon.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub watch_for: Option<crate::failure::FailureClass>,
}

fn default_time_limit_s() -> f64 {
    600.0
}

impl Default for RunSpec {
    fn default() -> Self {
        Self {
            profile: None,
            controller: None,
            time_limit_s: default_time_limit_s(),
            sim: SimSpec::default(),
            monitor: MonitorSpec::default(),
            scoring: ScoringSpec::default(),
            perturbation: None,
            watch: None,
            requirement: Vec::new(),
            signals: false,
        }
    }
}

impl RunSpec {
    /// Check every field; `path` names the section in errors.
    pub fn validate(&self, path: &str) -> Result<(), SpecError> {
        SpecError::check_positive(&join(path, "time_limit_s"), self.time_limit_s, 86_400.0)?;
        self.sim.validate(&join(path, "sim"))?;
        let steps = (self.time_limit_s / self.sim.dt_s).ceil();
        if steps > MAX_STEPS {
            return Err(SpecError::new(
                join(path, "sim.dt_s"),
                format!(
                    "{} s at {} s per step is {steps:.0} steps; a run may take at most {MAX_STEPS:.0}",
                    self.time_limit_s, self.sim.dt_s
                ),
            ));
        }
        if let Some(c) = &self.controller {
            let path = join(path, "controller");
            control::check(c, &path)?;
            control::period_steps(c, self.sim.dt_s, &path)?;
        }
        if let Some(p) = &self.perturbation {
            p.validate(&join(path, "perturbation"))?;
        }
        if let Some(w) = &self.watch {
            SpecError::check_positive(&join(path, "watch.horizon_s"), w.horizon_s, 86_400.0)?;
        }
        self.monitor.validate(&join(path, "monitor"))?;
        requirement::compile_all(&self.requirement, &join(path, "requirement"), self.sim.dt_s)?;
        self.scoring.validate(&join(path, "scoring"))
    }

    /// The simulator settings and sensor-noise seed of a run with seed `seed`: the spec's own,
    /// or its perturbed copy's.
    /// How far the run is watched: its `watch`, else its perturbation's horizon, as
    /// (horizon_s, watch_for); None: to the time limit.
    pub(super) fn horizon(&self) -> Option<(f64, Option<crate::failure::FailureClass>)> {
        match (&self.watch, &self.perturbation) {
            (Some(w), _) => Some((w.horizon_s, w.watch_for)),
            (None, Some(p)) => p.horizon_s.map(|h| (h, p.watch_for)),
            (None, None) => None,
        }
    }

    pub(super) fn world_settings(&self, seed: u64) -> (SimSpec, u64) {
        match &self.perturbation {
            Some(p) => (p.sim(&self.sim), p.seed(seed)),
            None => (self.sim.clone(), seed),
        }
    }

    /// Parse and validate a run spec from JSON, its profile (if it names one) laid under its
    /// own fields; errors name the field under `path`.
    pub fn from_json(text: &str, path: &str) -> Result<Self, SpecError> {
        let mut value: serde_json::Value = serde_json::from_str(text)
            .map_err(|e| SpecError::new(path, format!("expected a JSON object: {e}")))?;
        profile::resolve(&mut value, path)?;
        let spec: RunSpec = serde_path_to_error::deserialize(value).map_err(|e| {
            SpecError::new(join(path, &e.path().to_string()), e.inner().to_string())
        })?;
        spec.validate(path)?;
        Ok(spec)
    }
}

pub use crate::control::is_external;

/// The controller robot `id` runs under `run` (the run spec's for the agent, if it names one,
/// else the situation's) and the field that names it.
pub fn controller_spec<'a>(
    situation: &'a Situation,
    run: &'a RunSpec,
    id: u32,
) -> (&'a ControllerSpec, String) {
    let r = &situation.robots[id as usize];
    match &run.controller {
        Some(c) if r.role == crate::situation::Role::Agent => (c, "run.controller".to_string()),
        _ => (&r.controller, format!("robots[{id}].controller")),
    }
}
