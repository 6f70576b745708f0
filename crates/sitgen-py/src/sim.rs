//! Bindings of `sitgen_core::sim`: the `World` class.

use numpy::PyArray1;
use pyo3::exceptions::PyValueError;
use pyo3::prelude::*;
use pyo3::types::{PyDict, PyList};
use sitgen_core::sim::{self, Contact, SimSpec};
use sitgen_core::situation::{Role, Situation};

use crate::SpecError;

/// A running world built from a situation (JSON) and simulator settings (JSON, `{}` for the
/// defaults), with sensor noise drawn from `seed`.
#[pyclass(name = "World", module = "sitgen._core")]
pub struct PyWorld {
    world: sim::World,
}

fn role_name(role: Role) -> &'static str {
    match role {
        Role::Agent => "agent",
        Role::Peer => "peer",
    }
}

#[pymethods]
impl PyWorld {
    #[new]
    #[pyo3(signature = (situation_json, sim_json="{}", seed=0))]
    fn new(situation_json: &str, sim_json: &str, seed: u64) -> PyResult<Self> {
        let situation =
            Situation::from_json(situation_json).map_err(|e| SpecError::new_err(e.to_string()))?;
        let mut de = serde_json::Deserializer::from_str(sim_json);
        let spec: SimSpec = serde_path_to_error::deserialize(&mut de)
            .map_err(|e| SpecError::new_err(format!("sim.{}: {}", e.path(), e.inner())))?;
        let world = sim::World::new(&situation, spec, seed)
            .map_err(|e| SpecError::new_err(e.to_string()))?;
        Ok(Self { world })
    }

    /// Simulated time, seconds.
    #[getter]
    fn time(&self) -> f64 {
        self.world.time_s()
    }

    /// Steps taken.
    #[getter]
    fn steps(&self) -> u64 {
        self.world.steps()
    }

    /// Advance one step; `commands` maps robot id to (v m/s, ω rad/s) and replaces latched
    /// commands.
    fn step(&mut self, py: Python<'_>, commands: Vec<(u32, (f64, f64))>) -> PyResult<()> {
        let commands: Vec<(u32, f64, f64)> = commands
            .into_iter()
            .map(|(id, (v, w))| (id, v, w))
            .collect();
        py.detach(|| self.world.step(&commands))
            .map_err(PyValueError::new_err)
    }

    /// Advance `steps` steps with the latched commands, scanning the agent's laser each step as
    /// a controller would (for benchmarks: the whole loop runs without the GIL).
    fn advance(&mut self, py: Python<'_>, steps: u64) -> PyResult<()> {
        py.detach(|| {
            for _ in 0..steps {
                std::hint::black_box(self.world.scan(0));
                self.world.step(&[])?;
            }
            Ok::<(), String>(())
        })
        .map_err(PyValueError::new_err)
    }

    /// Scan the agent's laser `times` times from where it stands, without the GIL, tracing
    /// every beam each time (for the laser benchmark).
    fn scan_repeatedly(&self, py: Python<'_>, times: u64) {
        py.detach(|| {
            for _ in 0..times {
                self.world.forget_scans();
                std::hint::black_box(self.world.scan(0));
            }
        });
    }

    /// What robot `robot_id` senses: ranges and angles (numpy), pose, velocity, stalled, time,
    /// tracks (the robots its laser sees: id, position, velocity).
    fn observe<'py>(&self, py: Python<'py>, robot_id: u32) -> PyResult<Bound<'py, PyDict>> {
        let o = self
            .world
            .observe(robot_id)
            .map_err(PyValueError::new_err)?;
        observation_dict(py, o)
    }

    /// Every robot's state: id, role, pose, velocity, command, stalled, contacts.
    fn state<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyList>> {
        let list = PyList::empty(py);
        for r in self.world.robots() {
            let d = PyDict::new(py);
            d.set_item("id", r.id)?;
            d.set_item("role", role_name(r.role))?;
            d.set_item("pose", (r.pose.x_m, r.pose.y_m, r.pose.heading_rad))?;
            d.set_item("velocity", r.velocity)?;
            d.set_item("command", r.command)?;
            d.set_item("stalled", r.stalled)?;
            let contacts = PyList::empty(py);
            for c in &r.contacts {
                match c {
                    Contact::Wall => contacts.append("wall")?,
                    Contact::Robot(id) => contacts.append(*id)?,
                }
            }
            d.set_item("contacts", contacts)?;
            list.append(d)?;
        }
        Ok(list)
    }
}

/// An observation as the dict Python controllers receive.
pub(crate) fn observation_dict(py: Python<'_>, o: sim::Observation) -> PyResult<Bound<'_, PyDict>> {
    let out = PyDict::new(py);
    out.set_item("ranges", PyArray1::from_vec(py, o.ranges))?;
    out.set_item("angles", PyArray1::from_vec(py, o.angles))?;
    out.set_item("max_range", o.max_range_m)?;
    out.set_item("pose", (o.pose.x_m, o.pose.y_m, o.pose.heading_rad))?;
    out.set_item("velocity", o.velocity)?;
    out.set_item("stalled", o.stalled)?;
    out.set_item("time", o.time_s)?;
    let tracks = PyList::empty(py);
    for t in &o.tracks {
        let d = PyDict::new(py);
        d.set_item("id", t.id)?;
        d.set_item("position", t.position)?;
        d.set_item("velocity", t.velocity)?;
        tracks.append(d)?;
    }
    out.set_item("tracks", tracks)?;
    Ok(out)
}

pub(crate) fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_class::<PyWorld>()?;
    Ok(())
}
