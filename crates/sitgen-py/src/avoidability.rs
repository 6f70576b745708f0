//! Bindings of `sitgen_core::avoidability`: whether the agent could have escaped its first
//! collision with a robot, for a batch of runs on a thread pool.

use pyo3::prelude::*;
use sitgen_core::avoidability;
use sitgen_core::run::{par_map, RunSpec};
use sitgen_core::situation::Situation;

/// One run to judge: its situation and run spec (JSON), its sensor seed, and when the contact
/// to judge began (`None`: the agent's first with a robot).
type Job = (String, String, u64, Option<f64>);

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

/// One run whose agent's controller is outside the core, judged from its record: its
/// situation and run spec (JSON), sensor seed, every robot's poses (flat, `[step][robot][3]`),
/// and the step and robot of its first collision with a robot as its event log has it.
type RecordedJob = (String, String, u64, Vec<f64>, u64, u32);

/// [`judge_avoidability`] for runs whose agent's controller is outside the core
/// ([`avoidability::judge_recorded`]): one JSON object a job, `{"judgement": {...}}` or
/// `{"error": message}`.
#[pyfunction]
fn judge_avoidability_recorded(
    py: Python<'_>,
    jobs: Vec<RecordedJob>,
    after_s: f64,
    threads: usize,
) -> Vec<String> {
    py.detach(|| {
        par_map(
            &jobs,
            threads,
            |(situation, spec, seed, trajectory, step, robot)| {
                let judged = Situation::from_json(situation)
                    .map_err(|e| e.to_string())
                    .and_then(|s| {
                        let spec = RunSpec::from_json(spec, "run").map_err(|e| e.to_string())?;
                        let recorded = avoidability::Recorded {
                            trajectory,
                            collision_step: *step,
                            robot: *robot,
                        };
                        avoidability::judge_recorded(&s, &spec, *seed, after_s, &recorded)
                            .map_err(|e| e.to_string())
                    });
                match judged {
                    Ok(j) => serde_json::json!({ "judgement": j }),
                    Err(e) => serde_json::json!({ "error": e }),
                }
                .to_string()
            },
        )
    })
}

fn judge(
    (situation, spec, seed, collision_s): &Job,
    after_s: f64,
) -> Result<Option<avoidability::Judgement>, String> {
    let situation = Situation::from_json(situation).map_err(|e| e.to_string())?;
    let spec = RunSpec::from_json(spec, "run").map_err(|e| e.to_string())?;
    avoidability::judge(&situation, &spec, *seed, after_s, *collision_s).map_err(|e| e.to_string())
}

pub(crate) fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_function(wrap_pyfunction!(judge_avoidability, m)?)?;
    m.add_function(wrap_pyfunction!(judge_avoidability_recorded, m)?)
}
