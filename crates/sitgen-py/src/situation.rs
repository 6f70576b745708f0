//! Bindings of `sitgen_core::situation` and its exports (`interchange::{stage, ros}`).

use std::path::PathBuf;

use numpy::{PyArray1, PyArrayMethods};
use pyo3::exceptions::PyOSError;
use pyo3::prelude::*;
use sitgen_core::interchange::{ros, stage};
use sitgen_core::situation::{self, Situation};

use crate::{spec::parse, GenerationFailed, SpecError};

fn read(json: &str) -> PyResult<Situation> {
    Situation::from_json(json).map_err(|e| SpecError::new_err(e.to_string()))
}

fn spec_error(e: sitgen_core::error::SpecError) -> PyErr {
    SpecError::new_err(e.to_string())
}

/// Generate the situation of a spec with master seed `seed`; returns its JSON.
#[pyfunction]
fn generate_situation(py: Python<'_>, kind: &str, text: &str, seed: u64) -> PyResult<String> {
    let spec = parse(kind, text)?;
    let (s, _) = py
        .detach(|| situation::generate(&spec, seed))
        .map_err(|e| GenerationFailed::new_err(e.to_string()))?;
    sitgen_core::sim::check_start(&s)
        .map_err(|e| GenerationFailed::new_err(format!("placement: {e}")))?;
    Ok(s.to_json())
}

/// Check a situation's JSON (the error names the field): its fields and routes, with
/// `check_start` where its robots start, with `verify_hash` its content hash. Returns it
/// re-serialised.
#[pyfunction]
#[pyo3(signature = (json, verify_hash = false, check_start = true))]
fn check_situation(json: &str, verify_hash: bool, check_start: bool) -> PyResult<String> {
    let s = read(json)?;
    if check_start {
        sitgen_core::sim::check_start(&s).map_err(spec_error)?;
    }
    if verify_hash {
        s.check_content_hash().map_err(spec_error)?;
    }
    Ok(s.to_json())
}

/// The content hash the situation's map and robots give now.
#[pyfunction]
fn situation_content_hash(json: &str) -> PyResult<String> {
    Ok(read(json)?.content_hash())
}

/// The situation's map: (occupied bool array, row 0 = top; resolution in metres).
#[pyfunction]
fn situation_map<'py>(py: Python<'py>, json: &str) -> PyResult<(Bound<'py, PyAny>, f64)> {
    let map = read(json)?
        .map
        .decode()
        .map_err(|e| SpecError::new_err(e.to_string()))?;
    let g = map.grid;
    let occupied = PyArray1::from_vec(py, g.cells).reshape([g.rows, g.cols])?;
    Ok((occupied.into_any(), map.resolution_m))
}

/// Write the situation, run as the run spec (JSON, checked) says, as a Stage world into
/// `dir`; returns the files written.
#[pyfunction]
fn export_stage(json: &str, run_json: &str, dir: PathBuf) -> PyResult<Vec<PathBuf>> {
    let run = sitgen_core::run::RunSpec::from_json(run_json, "run").map_err(spec_error)?;
    stage::write_stage(&read(json)?, &run, &dir).map_err(PyOSError::new_err)
}

/// Write the situation's map as ROS map_server files into `dir`; returns the files written.
#[pyfunction]
fn export_ros(json: &str, dir: PathBuf) -> PyResult<Vec<PathBuf>> {
    ros::write_ros(&read(json)?, &dir).map_err(PyOSError::new_err)
}

/// The JSON Schema of a situation file.
#[pyfunction]
fn situation_json_schema() -> String {
    situation::json_schema()
}

/// The situation's descriptors (docs/explain.md) as JSON.
#[pyfunction]
fn situation_descriptors(json: &str) -> PyResult<String> {
    let s = read(json)?;
    Ok(serde_json::to_string(&situation::descriptors::describe(&s, None)).expect("serializes"))
}

pub(crate) fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_function(wrap_pyfunction!(situation_descriptors, m)?)?;
    m.add_function(wrap_pyfunction!(generate_situation, m)?)?;
    m.add_function(wrap_pyfunction!(check_situation, m)?)?;
    m.add_function(wrap_pyfunction!(situation_content_hash, m)?)?;
    m.add_function(wrap_pyfunction!(situation_map, m)?)?;
    m.add_function(wrap_pyfunction!(export_stage, m)?)?;
    m.add_function(wrap_pyfunction!(export_ros, m)?)?;
    m.add_function(wrap_pyfunction!(situation_json_schema, m)?)?;
    Ok(())
}
