//! Bindings of `sitgen_core::control::fault`: the catalogue of seeded faults.

use pyo3::prelude::*;
use pyo3::types::PyDict;
use sitgen_core::control::fault::CATALOGUE;

/// Every seeded fault, in catalogue order: dicts with `id`, `controllers`, `changes`,
/// `stands_for` and `exposed_by` (None for a fault not bound to a circumstance).
#[pyfunction]
fn fault_catalogue(py: Python<'_>) -> PyResult<Vec<Bound<'_, PyDict>>> {
    CATALOGUE
        .iter()
        .map(|info| {
            let d = PyDict::new(py);
            d.set_item("id", info.id)?;
            d.set_item("controllers", info.controllers.to_vec())?;
            d.set_item("changes", info.changes)?;
            d.set_item("stands_for", info.stands_for)?;
            d.set_item("exposed_by", info.exposed_by)?;
            Ok(d)
        })
        .collect()
}

pub(crate) fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_function(wrap_pyfunction!(fault_catalogue, m)?)?;
    Ok(())
}
