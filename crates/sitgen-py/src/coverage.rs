//! Bindings of `sitgen_core::coverage`: the interaction space's dimensions (each run's cells come
//! with its record).

use pyo3::prelude::*;
use sitgen_core::coverage::{agent_context_at, DIMENSIONS};
use sitgen_core::sim::{SimSpec, World};
use sitgen_core::situation::{Pose, Role, Situation};

use crate::SpecError;

/// The interaction space as (dimension name, its values in order).
#[pyfunction]
fn coverage_dimensions() -> Vec<(&'static str, Vec<&'static str>)> {
    DIMENSIONS
        .iter()
        .map(|d| (d.name, d.values.to_vec()))
        .collect()
}

/// The terrain context its agent would be in standing at (`x_m`, `y_m`, `heading_rad`) in
/// `situation` (JSON): what its run's coverage would record there.
#[pyfunction]
fn agent_context(situation: &str, x_m: f64, y_m: f64, heading_rad: f64) -> PyResult<&'static str> {
    let s = Situation::from_json(situation).map_err(|e| SpecError::new_err(e.to_string()))?;
    let world =
        World::new(&s, SimSpec::default(), 0).map_err(|e| SpecError::new_err(e.to_string()))?;
    let agent = s
        .robots
        .iter()
        .position(|r| r.role == Role::Agent)
        .unwrap_or(0) as u32;
    let pose = Pose {
        x_m,
        y_m,
        heading_rad,
    };
    Ok(agent_context_at(&world, agent, &pose))
}

pub(crate) fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_function(wrap_pyfunction!(coverage_dimensions, m)?)?;
    m.add_function(wrap_pyfunction!(agent_context, m)?)?;
    Ok(())
}
