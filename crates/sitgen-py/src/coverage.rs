//! Bindings of `sitgen_core::coverage`: the interaction space's dimensions (each run's cells come
//! with its record).

use pyo3::prelude::*;
use sitgen_core::coverage::DIMENSIONS;

/// The interaction space as (dimension name, its values in order).
#[pyfunction]
fn coverage_dimensions() -> Vec<(&'static str, Vec<&'static str>)> {
    DIMENSIONS
        .iter()
        .map(|d| (d.name, d.values.to_vec()))
        .collect()
}

pub(crate) fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_function(wrap_pyfunction!(coverage_dimensions, m)?)?;
    Ok(())
}
