//! Bindings of `sitgen_core::failure`: the failure class of a stored event log, every class it
//! shows, and the list of classes.

use pyo3::exceptions::PyValueError;
use pyo3::prelude::*;
use sitgen_core::failure::{self, classes, classify, FailureClass};
use sitgen_core::monitor::Event;

/// Parse an event log given as JSON Lines; a line that is not an event is an error naming its
/// line number.
fn parse_events(events_jsonl: &str) -> PyResult<Vec<Event>> {
    let mut events = Vec::new();
    for (i, line) in events_jsonl.lines().enumerate() {
        if line.trim().is_empty() {
            continue;
        }
        let e: Event = serde_json::from_str(line)
            .map_err(|e| PyValueError::new_err(format!("event line {}: {e}", i + 1)))?;
        events.push(e);
    }
    Ok(events)
}

/// The failure (JSON: class, description, events, features) of an event log given as JSON
/// Lines, whose agent is robot `agent`; `None` if it has no scored failure.
#[pyfunction]
#[pyo3(signature = (events_jsonl, agent=0))]
fn classify_events(events_jsonl: &str, agent: u32) -> PyResult<Option<String>> {
    let events = parse_events(events_jsonl)?;
    Ok(classify(&events, agent).map(|f| serde_json::to_string(&f).expect("failures serialize")))
}

/// The keys of every failure class an event log (JSON Lines) shows, most severe first.
#[pyfunction]
#[pyo3(signature = (events_jsonl, agent=0))]
fn event_classes(events_jsonl: &str, agent: u32) -> PyResult<Vec<&'static str>> {
    let events = parse_events(events_jsonl)?;
    Ok(classes(&events, agent)
        .into_iter()
        .map(|c| c.key())
        .collect())
}

/// (key, seconds) of the first time each failure class an event log (JSON Lines) shows was
/// seen, most severe first: what a shrink keeps to (`sitgen_core::failure::first_seen`).
#[pyfunction]
#[pyo3(signature = (events_jsonl, agent=0))]
fn first_seen(events_jsonl: &str, agent: u32) -> PyResult<Vec<(&'static str, f64)>> {
    let events = parse_events(events_jsonl)?;
    Ok(failure::first_seen(&events, agent)
        .into_iter()
        .map(|(c, s)| (c.key(), s))
        .collect())
}

/// Every failure class as (key, description), most severe first.
#[pyfunction]
fn failure_classes() -> Vec<(&'static str, &'static str)> {
    FailureClass::ALL
        .iter()
        .map(|c| (c.key(), c.description()))
        .collect()
}

pub(crate) fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_function(wrap_pyfunction!(classify_events, m)?)?;
    m.add_function(wrap_pyfunction!(event_classes, m)?)?;
    m.add_function(wrap_pyfunction!(failure_classes, m)?)?;
    m.add_function(wrap_pyfunction!(first_seen, m)?)?;
    Ok(())
}
