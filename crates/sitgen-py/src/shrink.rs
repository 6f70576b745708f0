//! Bindings of `sitgen_core::shrink`: candidates built and probed in Rust, in batches across
//! threads without the GIL.

use numpy::PyReadonlyArray2;
use pyo3::prelude::*;
use pyo3::types::PyDict;
use sitgen_core::grid::Map;
use sitgen_core::run::{par_map, RunSpec};
use sitgen_core::shrink::{self, Probe};
use sitgen_core::situation::{Robot, Situation};

use crate::interchange::to_map;
use crate::SpecError;

fn read(json: &str) -> PyResult<Situation> {
    Situation::from_json(json).map_err(|e| SpecError::new_err(e.to_string()))
}

fn run_spec(json: &str) -> PyResult<RunSpec> {
    RunSpec::from_json(json, "run").map_err(|e| SpecError::new_err(e.to_string()))
}

/// A situation shrunk from `original`: the map `occupied` (bool array, row 0 at the top) at
/// `resolution_m` and the robots `robots_json` (a JSON list, as in a situation file). Not
/// checked: the probes do that.
#[pyfunction]
fn shrunk_situation(
    original: &str,
    occupied: PyReadonlyArray2<'_, bool>,
    resolution_m: f64,
    robots_json: &str,
) -> PyResult<String> {
    let (original, map, robots) = edit(original, &occupied, resolution_m, robots_json)?;
    Ok(original.shrunk(&map, robots).to_json())
}

/// The parts of an edited situation: the original, the new map and the new robots.
fn edit(
    original: &str,
    occupied: &PyReadonlyArray2<'_, bool>,
    resolution_m: f64,
    robots_json: &str,
) -> PyResult<(Situation, Map, Vec<Robot>)> {
    let robots: Vec<Robot> = serde_json::from_str(robots_json)
        .map_err(|e| SpecError::new_err(format!("robots: {e}")))?;
    Ok((read(original)?, to_map(occupied, resolution_m)?, robots))
}

/// A situation a situation operator made from `original` (as [`shrunk_situation`], marked
/// `mutated_from` in its provenance). Not checked: the search checks it (`shrink_check`).
#[pyfunction]
fn mutated_situation(
    original: &str,
    occupied: PyReadonlyArray2<'_, bool>,
    resolution_m: f64,
    robots_json: &str,
) -> PyResult<String> {
    let (original, map, robots) = edit(original, &occupied, resolution_m, robots_json)?;
    Ok(original.mutated(&map, robots).to_json())
}

/// The margin peer legs of candidates shrunk from `original` keep (metres), or `None`.
#[pyfunction]
fn shrink_leg_margin(original: &str) -> PyResult<Option<f64>> {
    Ok(shrink::leg_margin(&read(original)?))
}

/// Probe every candidate (situation JSON) with the run spec `run_json` and sensor seed
/// `seed` on `threads` threads. One dict per candidate, in order: `ok`; then `problem` (why
/// it was skipped), or `class` (key or None), `first_s` ([key, seconds] for every class its
/// events show, most severe first, then `requirement:NAME` for each requirement violated),
/// `time_s`, `outcome`.
#[pyfunction]
#[pyo3(signature = (candidates, run_json, seed, leg_margin_m, threads))]
fn shrink_probes<'py>(
    py: Python<'py>,
    candidates: Vec<String>,
    run_json: &str,
    seed: u64,
    leg_margin_m: Option<f64>,
    threads: usize,
) -> PyResult<Vec<Bound<'py, PyDict>>> {
    let spec = run_spec(run_json)?;
    let probes = py.detach(|| {
        par_map(&candidates, threads, |json| {
            let s = Situation::from_json(json).map_err(|e| e.to_string())?;
            shrink::probe(&s, &spec, seed, leg_margin_m)
        })
    });
    probes.into_iter().map(|p| probe_dict(py, p)).collect()
}

fn probe_dict(py: Python<'_>, probe: Result<Probe, String>) -> PyResult<Bound<'_, PyDict>> {
    let d = PyDict::new(py);
    match probe {
        Ok(p) => {
            d.set_item("ok", true)?;
            d.set_item("class", p.class.map(|c| c.key()))?;
            // A violated requirement shows as its class, `requirement:NAME`, after sitgen's own.
            let first: Vec<(String, f64)> = p
                .first_s
                .iter()
                .map(|(c, s)| (c.key().to_string(), *s))
                .chain(
                    p.violated
                        .iter()
                        .map(|(n, s)| (format!("requirement:{n}"), *s)),
                )
                .collect();
            d.set_item("first_s", first)?;
            d.set_item("time_s", p.time_s)?;
            let outcome = serde_json::to_value(&p.outcome).expect("outcomes serialize");
            d.set_item("outcome", outcome.as_str())?;
        }
        Err(problem) => {
            d.set_item("ok", false)?;
            d.set_item("problem", problem)?;
        }
    }
    Ok(d)
}

/// Why `candidate` (situation JSON) cannot be probed (a shrink's validity checks: a valid
/// situation, every robot starting clear, peer legs keeping `leg_margin_m`), or `None`: the
/// check a probe makes first, for probes run outside the core (user controllers).
#[pyfunction]
#[pyo3(signature = (candidate, leg_margin_m))]
fn shrink_check(candidate: &str, leg_margin_m: Option<f64>) -> Option<String> {
    match Situation::from_json(candidate) {
        Ok(s) => shrink::check(&s, leg_margin_m).err(),
        Err(e) => Some(e.to_string()),
    }
}

/// The robots of `situation` as they stand `t_s` seconds into its run with `run_json` and
/// sensor seed `seed` (JSON list): each at its pose with the rest of its route.
#[pyfunction]
fn robots_at(
    py: Python<'_>,
    situation: &str,
    run_json: &str,
    seed: u64,
    t_s: f64,
) -> PyResult<String> {
    let s = read(situation)?;
    let spec = run_spec(run_json)?;
    let robots = py
        .detach(|| shrink::robots_at(&s, &spec, seed, t_s))
        .map_err(SpecError::new_err)?;
    Ok(serde_json::to_string(&robots).expect("robots serialize"))
}

pub(crate) fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_function(wrap_pyfunction!(shrunk_situation, m)?)?;
    m.add_function(wrap_pyfunction!(mutated_situation, m)?)?;
    m.add_function(wrap_pyfunction!(shrink_leg_margin, m)?)?;
    m.add_function(wrap_pyfunction!(shrink_probes, m)?)?;
    m.add_function(wrap_pyfunction!(robots_at, m)?)?;
    m.add_function(wrap_pyfunction!(shrink_check, m)?)?;
    Ok(())
}
