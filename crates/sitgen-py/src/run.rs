//! Bindings of `sitgen_core::run`: one run, stepped from Python (for Python and external
//! controllers) or driven to its end in Rust without the GIL.

use std::sync::{Mutex, MutexGuard};

use numpy::{PyArray1, PyArrayMethods};
use pyo3::exceptions::PyValueError;
use pyo3::prelude::*;
use pyo3::types::{PyBytes, PyDict, PyTuple};
use sitgen_core::control;
use sitgen_core::mission::ControllerSpec;
use sitgen_core::monitor::{self, EventKind};
use sitgen_core::run::{profile, protocol, Run, RunRecord, RunSpec};
use sitgen_core::scoring;
use sitgen_core::sim::Observation;
use sitgen_core::situation::Situation;

use crate::sim::observation_dict;
use crate::watchdog::Watchdog;
use crate::SpecError;

fn spec_error(e: impl ToString) -> PyErr {
    SpecError::new_err(e.to_string())
}

/// A run of a situation (JSON) under a run spec (JSON, `{}` for the defaults), with sensor
/// noise drawn from `seed`.
#[pyclass(name = "Run", module = "sitgen._core")]
pub struct PyRun {
    /// Behind a mutex because Python objects must be shareable between threads, and a
    /// controller's state is only ever used by one step at a time.
    run: Option<Mutex<Run>>,
    /// The external peers' controllers (`set_peers`): each called, as `drive`'s `act` is,
    /// whenever its peer decides, before every step this run takes.
    peers: Vec<(u32, Py<PyAny>)>,
    /// An external peer no controller has been given for yet: the run may not step (the peer
    /// would stand still unseen).
    unserved: Option<u32>,
}

fn finished() -> PyErr {
    PyValueError::new_err("the run has been finished")
}

impl PyRun {
    fn live(&self) -> PyResult<MutexGuard<'_, Run>> {
        let run = self.run.as_ref().ok_or_else(finished)?;
        Ok(run.lock().unwrap_or_else(|e| e.into_inner()))
    }

    /// Refuse to step while an external peer has no controller.
    fn served(&self) -> PyResult<()> {
        match self.unserved {
            Some(id) => Err(PyValueError::new_err(format!(
                "robot {id}'s controller is external: give it with set_peers before stepping"
            ))),
            None => Ok(()),
        }
    }

    fn live_mut(&mut self) -> PyResult<&mut Run> {
        let run = self.run.as_mut().ok_or_else(finished)?;
        Ok(run.get_mut().unwrap_or_else(|e| e.into_inner()))
    }

    /// `drive`'s loop, the peers' controllers given.
    fn drive_with(
        &mut self,
        py: Python<'_>,
        act: &Bound<'_, PyAny>,
        watchdog: Option<Watchdog>,
        line: bool,
        peers: &[(u32, Py<PyAny>)],
    ) -> PyResult<()> {
        let run = self.live_mut()?;
        if !run.agent_is_external() {
            return Err(PyValueError::new_err(
                "the agent's controller is built in: run it to its end",
            ));
        }
        loop {
            let command = if run.agent_acts_now() {
                let reached = run.agent_waypoints_reached();
                let o = run.agent_observation();
                let watched = watchdog.as_ref().map(Watchdog::watch);
                let reply = if line {
                    let message = protocol::observation_line(&o, reached);
                    act.call1((PyBytes::new(py, message.as_bytes()), o.time_s))
                } else {
                    act.call1(observation_args(py, o, reached)?)
                };
                drop(watched);
                Some(reply?.extract::<(f64, f64)>()?)
            } else {
                None
            };
            if step_all(py, run, peers, command)? {
                return Ok(());
            }
        }
    }
}

/// The commands of the external peers that decide on `run`'s coming step, each asked of its
/// controller in `peers` (every external peer's, `set_peers` sees to it) with its observation.
fn peer_commands(
    py: Python<'_>,
    run: &mut Run,
    peers: &[(u32, Py<PyAny>)],
) -> PyResult<Vec<(u32, (f64, f64))>> {
    let mut commands = Vec::new();
    for (id, act) in peers {
        if !run.acts_now(*id) {
            continue;
        }
        let reached = run.waypoints_reached(*id);
        let o = run.observation(*id);
        let reply = act.bind(py).call1(observation_args(py, o, reached)?)?;
        commands.push((*id, reply.extract::<(f64, f64)>()?));
    }
    Ok(commands)
}

/// One step of `run`: the agent's `command` with the external peers' (see `peer_commands`).
fn step_all(
    py: Python<'_>,
    run: &mut Run,
    peers: &[(u32, Py<PyAny>)],
    command: Option<(f64, f64)>,
) -> PyResult<bool> {
    let mut commands = peer_commands(py, run, peers)?;
    commands.extend(command.map(|c| (run.agent(), c)));
    Ok(run.step_with(&commands))
}

/// The peers of `run` whose controllers are external, by id.
fn external_peers(run: &Run) -> Vec<u32> {
    let agent = run.agent();
    run.external()
        .into_iter()
        .filter(|&id| id != agent)
        .collect()
}

#[pymethods]
impl PyRun {
    #[new]
    #[pyo3(signature = (situation_json, spec_json="{}", seed=0))]
    fn new(situation_json: &str, spec_json: &str, seed: u64) -> PyResult<Self> {
        let situation = Situation::from_json(situation_json).map_err(spec_error)?;
        let spec = RunSpec::from_json(spec_json, "run").map_err(spec_error)?;
        let run = Run::new(&situation, &spec, seed).map_err(spec_error)?;
        let unserved = external_peers(&run).first().copied();
        Ok(Self {
            run: Some(Mutex::new(run)),
            unserved,
            peers: Vec::new(),
        })
    }

    /// Whether the agent's commands must come from Python.
    #[getter]
    fn agent_is_external(&self) -> PyResult<bool> {
        Ok(self.live()?.agent_is_external())
    }

    /// The peers whose commands must come from Python (`python:`, `navground:`), by id.
    #[getter]
    fn external_peers(&self) -> PyResult<Vec<u32>> {
        Ok(external_peers(&*self.live()?))
    }

    /// The external peers' controllers, by id: each is called as `drive`'s `act` is (the
    /// observation's parts, `waypoints_reached` as the monitor counts the peer's first pass),
    /// whenever its peer decides, before each `step` and each step of `drive` and
    /// `run_to_end`. An exception from one stops the step and propagates.
    fn set_peers(&mut self, peers: Bound<'_, PyDict>) -> PyResult<()> {
        let external = self.external_peers()?;
        let mut given = Vec::new();
        for (id, act) in peers.iter() {
            let id: u32 = id.extract()?;
            if !external.contains(&id) {
                return Err(PyValueError::new_err(format!(
                    "robot {id} is not a peer with an external controller"
                )));
            }
            given.push((id, act.unbind()));
        }
        given.sort_by_key(|(id, _)| *id);
        self.unserved = external
            .into_iter()
            .find(|id| given.binary_search_by_key(id, |(who, _)| *who).is_err());
        self.peers = given;
        Ok(())
    }

    /// The agent's id.
    #[getter]
    fn agent(&self) -> PyResult<u32> {
        Ok(self.live()?.agent())
    }

    /// Whether the agent's controller decides on the coming step (every `control_period_s`);
    /// on other steps its last command stays in force and `step` ignores the one given.
    #[getter]
    fn agent_acts(&self) -> PyResult<bool> {
        Ok(self.live()?.agent_acts_now())
    }

    /// Whether the run has ended.
    #[getter]
    fn ended(&self) -> PyResult<bool> {
        Ok(self.live()?.ended())
    }

    /// What the agent senses now, plus `waypoints_reached` (as the monitor counts them).
    fn observe_agent<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        let mut run = self.live()?;
        let d = observation_dict(py, run.agent_observation())?;
        d.set_item("waypoints_reached", run.agent_waypoints_reached())?;
        Ok(d)
    }

    /// One step with the agent's command (ignored for a built-in agent); returns whether the
    /// run has ended.
    #[pyo3(signature = (command=None))]
    fn step(&mut self, py: Python<'_>, command: Option<(f64, f64)>) -> PyResult<bool> {
        self.served()?;
        let peers = std::mem::take(&mut self.peers);
        let ended = step_all(py, self.live_mut()?, &peers, command);
        self.peers = peers;
        ended
    }

    /// Every robot of `situation_json` (the run's situation) as it stands now: at its pose
    /// with the rest of its route (JSON list, as in a situation file).
    fn robots_now(&self, situation_json: &str) -> PyResult<String> {
        let situation = Situation::from_json(situation_json).map_err(spec_error)?;
        let robots = self.live()?.robots_now(&situation);
        Ok(serde_json::to_string(&robots).expect("robots serialize"))
    }

    /// Step the run to its end with an agent controller called from here: whenever the agent
    /// decides, `act` returns its command (v m/s, ω rad/s). It is called as
    /// `act(ranges, pose, velocity, stalled, time_s, tracks, waypoints_reached)`, `ranges` a
    /// fresh numpy array each call (one copy of the scan, never a Python float per beam) and
    /// `tracks` a tuple of dicts (`id`, `position`, `velocity`); or, with `line`, as
    /// `act(message, time_s)`, `message` the controller protocol's observation line (bytes),
    /// for a program. An exception from `act` stops the run where it is and propagates (the
    /// caller ends the run with its reason). `limits`: (cpu_s, wall_s, kill_grace_s) of each
    /// call — the calling thread gets SIGALRM after `wall_s` of wall clock, and with a
    /// `kill_grace_s` this process is killed that long past either limit (see `watchdog`; for
    /// disposable processes only); None: calls are not watched.
    #[pyo3(signature = (act, limits=None, line=false))]
    fn drive(
        &mut self,
        py: Python<'_>,
        act: &Bound<'_, PyAny>,
        limits: Option<(f64, f64, Option<f64>)>,
        line: bool,
    ) -> PyResult<()> {
        self.served()?;
        let watchdog = limits.map(|(cpu_s, wall_s, grace_s)| Watchdog::new(cpu_s, wall_s, grace_s));
        let peers = std::mem::take(&mut self.peers);
        let driven = self.drive_with(py, act, watchdog, line, &peers);
        self.peers = peers;
        driven
    }

    /// End the run with outcome `error` for `reason`.
    fn fail(&mut self, reason: String) -> PyResult<()> {
        self.live_mut()?.fail(reason);
        Ok(())
    }

    /// Step a run of built-in controllers to its end, without the GIL (with external peers,
    /// stepped here calling them).
    fn run_to_end(&mut self, py: Python<'_>) -> PyResult<()> {
        self.served()?;
        let peers = std::mem::take(&mut self.peers);
        let run = self.live_mut()?;
        if run.agent_is_external() {
            return Err(PyValueError::new_err(
                "the agent's controller is external: step the run from Python",
            ));
        }
        let ended = if run.any_external() {
            loop {
                match step_all(py, run, &peers, None) {
                    Ok(false) => continue,
                    done => break done.map(|_| ()),
                }
            }
        } else {
            py.detach(|| run.run_to_end());
            Ok(())
        };
        self.peers = peers;
        ended
    }

    /// End the run; returns the record (see `record_dict`).
    fn finish<'py>(&mut self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        let run = self
            .run
            .take()
            .ok_or_else(finished)?
            .into_inner()
            .unwrap_or_else(|e| e.into_inner());
        let agent = run.agent();
        record_dict(py, run.finish(), agent)
    }
}

type ObservationArgs<'py> = (
    Bound<'py, PyArray1<f64>>,
    (f64, f64, f64),
    (f64, f64),
    bool,
    f64,
    Bound<'py, PyTuple>,
    usize,
);

/// What `Run.drive` hands an in-process controller: the observation's parts.
fn observation_args(
    py: Python<'_>,
    o: Observation,
    reached: usize,
) -> PyResult<ObservationArgs<'_>> {
    let tracks = o
        .tracks
        .iter()
        .map(|t| {
            let d = PyDict::new(py);
            d.set_item("id", t.id)?;
            d.set_item("position", t.position)?;
            d.set_item("velocity", t.velocity)?;
            Ok(d)
        })
        .collect::<PyResult<Vec<_>>>()?;
    Ok((
        PyArray1::from_vec(py, o.ranges),
        (o.pose.x_m, o.pose.y_m, o.pose.heading_rad),
        o.velocity,
        o.stalled,
        o.time_s,
        PyTuple::new(py, tracks)?,
        reached,
    ))
}

/// A record as a dict: `record` (JSON: outcome, reason, score, events, steps, time_s, robots),
/// `events_jsonl`, `events_text`, `trajectory` (numpy, steps + 1 × robots × 3), `signals`
/// (the requirement signals the run's requirements read: name → numpy, one value a sample).
fn record_dict(py: Python<'_>, rec: RunRecord, agent: u32) -> PyResult<Bound<'_, PyDict>> {
    let d = PyDict::new(py);
    d.set_item(
        "record",
        serde_json::to_string(&rec).map_err(|e| PyValueError::new_err(e.to_string()))?,
    )?;
    d.set_item("events_jsonl", rec.events_jsonl())?;
    d.set_item("events_text", monitor::to_text(&rec.events, agent))?;
    let signals = PyDict::new(py);
    for (name, values) in monitor::signals::NAMES.iter().zip(&rec.signals) {
        if !values.is_empty() {
            signals.set_item(*name, PyArray1::from_slice(py, values))?;
        }
    }
    d.set_item("signals", signals)?;
    let rows = rec.trajectory.len() / (3 * rec.robots.max(1));
    let trajectory = PyArray1::from_vec(py, rec.trajectory).reshape([rows, rec.robots, 3])?;
    d.set_item("trajectory", trajectory)?;
    Ok(d)
}

/// Check a run spec (JSON); returns it with defaults filled. The error names the field.
#[pyfunction]
fn check_run_spec(spec_json: &str) -> PyResult<String> {
    let spec = RunSpec::from_json(spec_json, "run").map_err(spec_error)?;
    serde_json::to_string(&spec).map_err(|e| PyValueError::new_err(e.to_string()))
}

/// The default penalty of every event kind, as `(kind, start, per_s)`, in the core's order.
#[pyfunction]
fn default_penalties() -> Vec<(&'static str, f64, f64)> {
    EventKind::ALL
        .iter()
        .map(|&k| {
            let p = scoring::default_penalty(k);
            (k.name(), p.start, p.per_s)
        })
        .collect()
}

/// Names of the run profiles.
#[pyfunction]
fn profile_names() -> Vec<&'static str> {
    profile::NAMES.to_vec()
}

/// The TOML text of a run profile, with the source of every line.
#[pyfunction]
fn profile_text(name: &str) -> PyResult<&'static str> {
    profile::text(name).ok_or_else(|| {
        SpecError::new_err(format!(
            "run.profile: unknown profile `{name}`; expected one of {}",
            profile::NAMES.join(", ")
        ))
    })
}

/// Check a controller name as run specs do (`control::check`: a built-in name, or a
/// well-formed `python:`/`cmd:` one); the error names `field`, wherever the name came from.
#[pyfunction]
fn check_controller(name: &str, field: &str) -> PyResult<()> {
    let spec = ControllerSpec {
        name: name.into(),
        params: Default::default(),
        fault: None,
        control_period_s: None,
        perception: None,
        keep_alive: false,
        step_timeout_s: None,
    };
    control::check(&spec, "").map_err(|e| SpecError::new_err(format!("{field}: {}", e.message)))
}

pub(crate) fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_class::<PyRun>()?;
    m.add_function(wrap_pyfunction!(check_run_spec, m)?)?;
    m.add_function(wrap_pyfunction!(default_penalties, m)?)?;
    m.add_function(wrap_pyfunction!(check_controller, m)?)?;
    m.add_function(wrap_pyfunction!(profile_names, m)?)?;
    m.add_function(wrap_pyfunction!(profile_text, m)?)?;
    Ok(())
}
