//! Python bindings of sitgen-core: thin wrappers, no logic. File names mirror the core's
//! modules; long calls release the GIL.

mod avoidability;
mod campaign;
mod coverage;
mod cpu_deadline;
mod crosscheck;
mod episodes;
mod failure;
mod fault;
mod interchange;
mod mission;
mod requirement;
mod run;
mod shrink;
mod sim;
mod situation;
mod spec;
mod terrain;
mod watchdog;

use pyo3::prelude::*;

pyo3::create_exception!(
    _core,
    SpecError,
    pyo3::exceptions::PyValueError,
    "A spec that cannot be used; the message names the field path and what is allowed."
);
pyo3::create_exception!(
    _core,
    GenerationFailed,
    pyo3::exceptions::PyRuntimeError,
    "A valid spec that produced no situation; the message names the stage and the reason."
);

#[pymodule]
fn _core(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add("__version__", sitgen_core::VERSION)?;
    m.add("MAX_CELLS", sitgen_core::grid::MAX_CELLS)?;
    m.add("SpecError", m.py().get_type::<SpecError>())?;
    m.add("GenerationFailed", m.py().get_type::<GenerationFailed>())?;
    spec::register(m)?;
    terrain::register(m)?;
    interchange::register(m)?;
    mission::register(m)?;
    situation::register(m)?;
    sim::register(m)?;
    run::register(m)?;
    requirement::register(m)?;
    episodes::register(m)?;
    campaign::register(m)?;
    failure::register(m)?;
    coverage::register(m)?;
    fault::register(m)?;
    shrink::register(m)?;
    avoidability::register(m)?;
    crosscheck::register(m)?;
    watchdog::register(m)?;
    cpu_deadline::register(m)?;
    Ok(())
}
