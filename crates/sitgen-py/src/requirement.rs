//! Bindings of `sitgen_core::requirement`: a requirement checked and evaluated over given
//! signals (what the tests compare with rtamt, and what `sitgen check-requirement` reads).

use pyo3::prelude::*;
use sitgen_core::monitor::signals;
use sitgen_core::requirement::RequirementSpec;

use crate::SpecError;

fn spec_error(e: impl ToString) -> PyErr {
    SpecError::new_err(e.to_string())
}

/// The robustness signal of `formula` over `signals` (name → one value a sample, every
/// signal of the same length; those not given read NaN), samples `dt_s` apart; SpecError
/// naming the column for a formula that does not read.
#[pyfunction]
fn requirement_robustness(
    formula: &str,
    signals: std::collections::HashMap<String, Vec<f64>>,
    dt_s: f64,
) -> PyResult<Vec<f64>> {
    let spec = RequirementSpec {
        name: "r".into(),
        formula: formula.into(),
        weight: 1.0,
    };
    let compiled = spec.compile("formula", dt_s).map_err(spec_error)?;
    let n = signals.values().map(Vec::len).max().unwrap_or(0);
    let mut by_index = vec![vec![f64::NAN; n]; signals::NAMES.len()];
    for (name, values) in signals {
        let Some(i) = signals::index(&name) else {
            return Err(spec_error(sitgen_core::error::SpecError::new(
                "signals",
                format!(
                    "unknown signal {name:?}; the signals are {}",
                    signals::NAMES.join(", ")
                ),
            )));
        };
        if values.len() != n {
            return Err(spec_error(sitgen_core::error::SpecError::new(
                format!("signals.{name}"),
                format!("{} samples where the others have {n}", values.len()),
            )));
        }
        by_index[i] = values;
    }
    Ok(compiled.robustness_signal(&by_index, n))
}

/// The requirement signals' names, in order.
#[pyfunction]
fn requirement_signals() -> Vec<&'static str> {
    signals::NAMES.to_vec()
}

pub fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_function(wrap_pyfunction!(requirement_robustness, m)?)?;
    m.add_function(wrap_pyfunction!(requirement_signals, m)?)?;
    Ok(())
}
