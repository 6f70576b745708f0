//! Bindings of `sitgen_core::terrain`.

use numpy::{PyArray1, PyArrayMethods};
use pyo3::prelude::*;
use pyo3::types::PyDict;
use sitgen_core::rng::{stream, ChoiceSource};
use sitgen_core::terrain;

use crate::{spec::parse, GenerationFailed};

/// Improved Perlin noise (Perlin 2002) at (x, y, z), bit for bit the reference.
#[pyfunction]
#[pyo3(signature = (x, y, z=0.0))]
fn perlin(x: f64, y: f64, z: f64) -> f64 {
    terrain::noise::perlin(x, y, z)
}

/// Generate the terrain of a spec (see `spec.parse` for `kind`) with master seed `seed`.
/// Returns a dict: occupied (bool array, row 0 = top), resolution_m, attempts, stages (JSON),
/// spec (JSON).
#[pyfunction]
fn generate_terrain<'py>(
    py: Python<'py>,
    kind: &str,
    text: &str,
    seed: u64,
) -> PyResult<Bound<'py, PyDict>> {
    let spec = parse(kind, text)?;
    let generated = py
        .detach(|| {
            let mut choices = ChoiceSource::stream(seed, stream::TERRAIN);
            terrain::generate(&spec.terrain, &mut choices)
        })
        .map_err(|e| GenerationFailed::new_err(e.to_string()))?;
    let grid = generated.map.grid;
    let occupied = PyArray1::from_vec(py, grid.cells).reshape([grid.rows, grid.cols])?;
    let out = PyDict::new(py);
    out.set_item("occupied", occupied)?;
    out.set_item("resolution_m", generated.map.resolution_m)?;
    out.set_item("attempts", generated.attempts)?;
    out.set_item(
        "stages",
        serde_json::to_string(&generated.stages).expect("reports serialise"),
    )?;
    out.set_item(
        "spec",
        serde_json::to_string(&spec).expect("a spec serialises"),
    )?;
    Ok(out)
}

pub(crate) fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_function(wrap_pyfunction!(perlin, m)?)?;
    m.add_function(wrap_pyfunction!(generate_terrain, m)?)?;
    Ok(())
}
