//! Bindings for campaigns: many situations generated and run in Rust, across threads, without
//! the GIL.

use pyo3::prelude::*;
use pyo3::types::{PyBytes, PyDict};
use sitgen_core::run::{pack_trajectory, run_batch, Job, RunSpec};
use sitgen_core::spec;

/// Parse one job; errors name the job and the field.
fn job(
    index: usize,
    (spec_json, situation_seed, run_json, run_seed): &JobTuple,
) -> Result<Job, String> {
    let situation = spec::from_json_str(spec_json).map_err(|e| format!("job {index}: {e}"))?;
    let run = RunSpec::from_json(run_json, "run").map_err(|e| format!("job {index}: {e}"))?;
    Ok(Job {
        situation,
        situation_seed: *situation_seed,
        run,
        run_seed: *run_seed,
    })
}

type JobTuple = (String, u64, String, u64);

/// Generate and run `jobs` — (situation spec JSON, situation seed, run spec JSON, run seed) —
/// on `threads` threads. Returns one dict per job, in order: `ok`; then `error`, or
/// `situation` (JSON), `record` (JSON), `events_jsonl`, `trajectory` (zlib f32 bytes),
/// `robots`.
#[pyfunction]
fn run_jobs<'py>(
    py: Python<'py>,
    jobs: Vec<JobTuple>,
    threads: usize,
) -> PyResult<Vec<Bound<'py, PyDict>>> {
    let parsed: Vec<Result<Job, String>> =
        jobs.iter().enumerate().map(|(i, j)| job(i, j)).collect();
    let good: Vec<Job> = parsed
        .iter()
        .filter_map(|j| j.as_ref().ok().cloned())
        .collect();
    let results = py.detach(|| {
        run_batch(&good, threads)
            .into_iter()
            .map(|r| {
                r.map(|(s, rec)| {
                    let packed = pack_trajectory(&rec.trajectory);
                    let record = serde_json::to_string(&rec).expect("records serialize");
                    (s.to_json(), record, rec.events_jsonl(), packed, rec.robots)
                })
            })
            .collect::<Vec<_>>()
    });
    let mut results = results.into_iter();
    let mut out = Vec::with_capacity(jobs.len());
    for p in parsed {
        let d = PyDict::new(py);
        let result = match p {
            Err(e) => Err(e),
            Ok(_) => results.next().expect("one result per good job"),
        };
        match result {
            Ok((situation, record, events, trajectory, robots)) => {
                d.set_item("ok", true)?;
                d.set_item("situation", situation)?;
                d.set_item("record", record)?;
                d.set_item("events_jsonl", events)?;
                d.set_item("trajectory", PyBytes::new(py, &trajectory))?;
                d.set_item("robots", robots)?;
            }
            Err(e) => {
                d.set_item("ok", false)?;
                d.set_item("error", e)?;
            }
        }
        out.push(d);
    }
    Ok(out)
}

pub(crate) fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_function(wrap_pyfunction!(run_jobs, m)?)?;
    Ok(())
}
