//! Bindings of `sitgen_core::spec`.

use std::path::PathBuf;

use pyo3::prelude::*;
use sitgen_core::spec::{self, SituationSpec};
use sitgen_core::terrain::presets;

use crate::SpecError;

/// Read a spec given as `kind` = "toml" (text), "json" (text of an object) or "file" (path).
pub(crate) fn parse(kind: &str, text: &str) -> PyResult<SituationSpec> {
    let parsed = match kind {
        "toml" => spec::from_toml_str(text),
        "json" => spec::from_json_str(text),
        "file" => spec::from_file(&PathBuf::from(text)),
        other => {
            return Err(pyo3::exceptions::PyValueError::new_err(format!(
                "spec kind must be toml, json or file, not {other}"
            )))
        }
    };
    parsed.map_err(|e| SpecError::new_err(e.to_string()))
}

/// The resolved spec (presets applied, defaults filled) as JSON.
#[pyfunction]
fn resolve_spec(kind: &str, text: &str) -> PyResult<String> {
    let spec = parse(kind, text)?;
    Ok(serde_json::to_string(&spec).expect("a spec serialises"))
}

/// The JSON Schema of the situation spec.
#[pyfunction]
fn spec_json_schema() -> String {
    spec::json_schema()
}

/// Names of the built-in terrain presets.
#[pyfunction]
fn preset_names() -> Vec<&'static str> {
    presets::NAMES.to_vec()
}

/// The TOML text of a built-in terrain preset.
#[pyfunction]
fn preset_text(name: &str) -> PyResult<&'static str> {
    presets::text(name).ok_or_else(|| {
        SpecError::new_err(format!(
            "terrain.preset: unknown preset `{name}`; expected one of {}",
            presets::NAMES.join(", ")
        ))
    })
}

pub(crate) fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_function(wrap_pyfunction!(resolve_spec, m)?)?;
    m.add_function(wrap_pyfunction!(spec_json_schema, m)?)?;
    m.add_function(wrap_pyfunction!(preset_names, m)?)?;
    m.add_function(wrap_pyfunction!(preset_text, m)?)?;
    Ok(())
}
