//! Bindings of `sitgen_core::avoidability`: whether the agent could have escaped its first
//! collision with a robot, for a batch of runs on a thread pool.

use pyo3::prelude::*;
use sitgen_core::avoidability;
use sitgen_core::run::{par_map, RunSpec};
use sitgen_core::situation::Situation;

/// One run to judge: its situation and run spec (JSON) and its sensor seed.
type Job = (String, String, u64);

/// Judge each job's first agent–robot collision ([`avoidability::judge`]), escapes kept clear
/// `after_s` past the collision, on `threads` threads. One JSON object a job, in order:
/// `{"judgement": {...}}`, `{"none": reason}` (no collision of the agent with a robot), or
/// `{"error": message}` (the run could not be made again).
#[pyfunction]
fn judge_avoidability(py: Python<'_>, jobs: Vec<Job>, after_s: f64, threads: usize) -> Vec<String> {
    py.detach(|| {
        par_map(&jobs, threads, |job| {
            let out = match judge(job, after_s) {
                Ok(Some(j)) => serde_json::json!({ "judgement": j }),
                Ok(None) => serde_json::json!({ "none": "no collision of the agent with a robot" }),
                Err(e) => serde_json::json!({ "error": e }),
            };
            out.to_string()
        })
    })
}

fn judge(
    (situation, spec, seed): &Job,
    after_s: f64,
) -> Result<Option<avoidability::Judgement>, String> {
    let situation = Situation::from_json(situation).map_err(|e| e.to_string())?;
    let spec = RunSpec::from_json(spec, "run").map_err(|e| e.to_string())?;
    avoidability::judge(&situation, &spec, *seed, after_s).map_err(|e| e.to_string())
}

pub(crate) fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_function(wrap_pyfunction!(judge_avoidability, m)?)
}
