//! Bindings of `sitgen_core::run::episodes`: a batch of externally driven runs stepped in one
//! call without the GIL, observations and results as numpy arrays (for `sitgen.gym`).

use std::sync::{Mutex, MutexGuard};

use numpy::{PyArray1, PyArrayMethods, PyReadonlyArray2};
use pyo3::exceptions::PyValueError;
use pyo3::prelude::*;
use pyo3::types::{PyDict, PyList};
use sitgen_core::run::episodes::{EpisodeObservation, Episodes};
use sitgen_core::run::RunSpec;
use sitgen_core::situation::Situation;

use crate::SpecError;

fn spec_error(e: impl ToString) -> PyErr {
    SpecError::new_err(e.to_string())
}

/// `n` episode slots under a run spec (JSON), stepped on `threads` threads (0: every core).
#[pyclass(name = "Episodes", module = "sitgen._core")]
pub struct PyEpisodes {
    /// Behind a mutex because Python objects must be shareable between threads; one call uses
    /// the episodes at a time.
    episodes: Mutex<Episodes>,
    beams: usize,
}

impl PyEpisodes {
    /// Observation arrays for every slot (zeros for empty ones) into `out`.
    fn fill_observations<'py>(
        &self,
        py: Python<'py>,
        seen: &[Option<EpisodeObservation>],
        out: &Bound<'py, PyDict>,
    ) -> PyResult<()> {
        let n = seen.len();
        let mut ranges = vec![0f32; n * self.beams];
        let mut goal = vec![0f32; n * 2];
        let mut velocity = vec![0f32; n * 2];
        for (i, o) in seen.iter().enumerate() {
            let Some(o) = o else { continue };
            for (j, r) in o.observation.ranges.iter().enumerate().take(self.beams) {
                ranges[i * self.beams + j] = *r as f32;
            }
            goal[2 * i] = o.goal.0 as f32;
            goal[2 * i + 1] = o.goal.1 as f32;
            velocity[2 * i] = o.observation.velocity.0 as f32;
            velocity[2 * i + 1] = o.observation.velocity.1 as f32;
        }
        out.set_item(
            "ranges",
            PyArray1::from_vec(py, ranges).reshape([n, self.beams])?,
        )?;
        out.set_item("goal", PyArray1::from_vec(py, goal).reshape([n, 2])?)?;
        out.set_item(
            "velocity",
            PyArray1::from_vec(py, velocity).reshape([n, 2])?,
        )?;
        Ok(())
    }

    fn lock(&self) -> MutexGuard<'_, Episodes> {
        self.episodes.lock().unwrap_or_else(|e| e.into_inner())
    }

    fn slot(&self, i: usize) -> PyResult<usize> {
        let n = self.lock().len();
        if i < n {
            Ok(i)
        } else {
            Err(PyValueError::new_err(format!("no slot {i}: there are {n}")))
        }
    }
}

#[pymethods]
impl PyEpisodes {
    #[new]
    #[pyo3(signature = (spec_json, n, threads=0))]
    fn new(spec_json: &str, n: usize, threads: usize) -> PyResult<Self> {
        let spec = RunSpec::from_json(spec_json, "run").map_err(spec_error)?;
        let threads = match threads {
            0 => std::thread::available_parallelism().map_or(1, |t| t.get()),
            t => t,
        };
        let episodes = Episodes::new(&spec, n, threads).map_err(spec_error)?;
        let beams = episodes.spec().sim.laser.beams as usize;
        Ok(Self {
            episodes: Mutex::new(episodes),
            beams,
        })
    }

    /// The run spec every episode runs under, resolved (JSON).
    #[getter]
    fn spec_json(&self) -> PyResult<String> {
        serde_json::to_string(self.lock().spec()).map_err(|e| PyValueError::new_err(e.to_string()))
    }

    /// Simulator steps per decision.
    #[getter]
    fn steps_per_decision(&self) -> u64 {
        self.lock().steps_per_decision()
    }

    /// Start slot `i` on a situation (JSON), sensor noise from `seed`.
    fn reset(&mut self, i: usize, situation_json: &str, seed: u64) -> PyResult<()> {
        let i = self.slot(i)?;
        let situation = Situation::from_json(situation_json).map_err(spec_error)?;
        self.lock().reset(i, &situation, seed).map_err(spec_error)
    }

    /// Every slot's observation: `ranges` (n × beams), `goal` (n × 2, agent frame), `velocity`
    /// (n × 2), float32.
    fn observe<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        let seen: Vec<_> = {
            let mut episodes = self.lock();
            (0..episodes.len()).map(|i| episodes.observe(i)).collect()
        };
        let out = PyDict::new(py);
        self.fill_observations(py, &seen, &out)?;
        Ok(out)
    }

    /// One decision per slot (`commands`: n × 2, v m/s and ω rad/s), without the GIL. Returns
    /// the observations (as `observe`), `progress_m` and `penalty` (n, float64), `outcome`
    /// (n: None, "completed", "timeout" or "error") and `events` (n lists of event JSON).
    fn step<'py>(
        &mut self,
        py: Python<'py>,
        commands: PyReadonlyArray2<'py, f64>,
    ) -> PyResult<Bound<'py, PyDict>> {
        let array = commands.as_array();
        let n = self.lock().len();
        if array.shape() != [n, 2] {
            return Err(PyValueError::new_err(format!(
                "commands: expected shape ({n}, 2), found {:?}",
                array.shape()
            )));
        }
        let commands: Vec<(f64, f64)> = array.rows().into_iter().map(|r| (r[0], r[1])).collect();
        let episodes = self.episodes.get_mut().unwrap_or_else(|e| e.into_inner());
        let steps = py.detach(|| episodes.step(&commands));
        let seen: Vec<_> = steps
            .iter()
            .map(|s| s.as_ref().map(|s| s.observation.clone()))
            .collect();
        let out = PyDict::new(py);
        self.fill_observations(py, &seen, &out)?;
        let field = |f: fn(&sitgen_core::run::episodes::EpisodeStep) -> f64| {
            steps
                .iter()
                .map(|s| s.as_ref().map_or(0.0, f))
                .collect::<Vec<_>>()
        };
        out.set_item(
            "progress_m",
            PyArray1::from_vec(py, field(|s| s.progress_m)),
        )?;
        out.set_item("penalty", PyArray1::from_vec(py, field(|s| s.penalty)))?;
        let outcomes = PyList::empty(py);
        let events = PyList::empty(py);
        for s in &steps {
            let outcome = s.as_ref().and_then(|s| s.ended.as_ref()).map(|o| {
                serde_json::to_value(o)
                    .ok()
                    .and_then(|v| v.as_str().map(str::to_string))
                    .unwrap_or_default()
            });
            outcomes.append(outcome)?;
            let started: Vec<String> = s
                .as_ref()
                .map(|s| s.events.iter().map(|e| e.to_json()).collect())
                .unwrap_or_default();
            events.append(started)?;
        }
        out.set_item("outcome", outcomes)?;
        out.set_item("events", events)?;
        Ok(out)
    }

    /// End slot `i`'s run and empty it: the run's record as JSON, None for an empty slot.
    fn finish(&mut self, i: usize) -> PyResult<Option<String>> {
        let i = self.slot(i)?;
        self.lock()
            .finish(i)
            .map(|r| serde_json::to_string(&r).map_err(|e| PyValueError::new_err(e.to_string())))
            .transpose()
    }
}

pub(crate) fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_class::<PyEpisodes>()?;
    Ok(())
}
