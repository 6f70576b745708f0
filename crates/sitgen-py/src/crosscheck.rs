//! Bindings of `sitgen_core::crosscheck` and of `sitgen_core::run::serve` (the controllers
//! Stage's plugin speaks to).

use pyo3::exceptions::PyValueError;
use pyo3::prelude::*;
use sitgen_core::crosscheck;
use sitgen_core::run::serve::Served;
use sitgen_core::run::RunSpec;
use sitgen_core::situation::Situation;

use crate::SpecError;

fn parts(situation_json: &str, run_json: &str) -> PyResult<(Situation, RunSpec)> {
    let situation =
        Situation::from_json(situation_json).map_err(|e| SpecError::new_err(e.to_string()))?;
    let run = RunSpec::from_json(run_json, "run").map_err(|e| SpecError::new_err(e.to_string()))?;
    Ok((situation, run))
}

/// Robot `robot`'s built-in controller in a run of the situation under the run spec (JSON),
/// answering controller-protocol messages.
#[pyclass(name = "ServedController", module = "sitgen._core", unsendable)]
struct PyServed(Served);

#[pymethods]
impl PyServed {
    #[new]
    fn new(situation_json: &str, run_json: &str, robot: u32) -> PyResult<Self> {
        let (situation, run) = parts(situation_json, run_json)?;
        Served::new(&situation, &run, robot)
            .map(Self)
            .map_err(|e| SpecError::new_err(e.to_string()))
    }

    /// The reply line to one message line; None after `end`. ValueError for a bad message.
    fn answer(&mut self, line: &str) -> PyResult<Option<String>> {
        self.0.answer(line).map_err(PyValueError::new_err)
    }
}

/// Run the situation under the run spec in sitgen and compare it with the Stage plugin's log
/// (JSON Lines); returns the report as JSON. ValueError names a bad log line.
#[pyfunction]
fn crosscheck_stage(
    py: Python<'_>,
    situation_json: &str,
    run_json: &str,
    log: &str,
) -> PyResult<String> {
    let (situation, run) = parts(situation_json, run_json)?;
    let report = py
        .detach(|| {
            let steps = crosscheck::read_log(log, situation.robots.len())?;
            crosscheck::compare(&situation, &run, &steps)
        })
        .map_err(PyValueError::new_err)?;
    Ok(serde_json::to_string(&report).expect("reports serialise"))
}

pub(crate) fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_class::<PyServed>()?;
    m.add_function(wrap_pyfunction!(crosscheck_stage, m)?)?;
    Ok(())
}
