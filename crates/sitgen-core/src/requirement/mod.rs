//! Requirements: a safety engineer's own judgement of a run, in Signal Temporal Logic.
//!
//! A requirement is a name and a formula in rtamt's STL syntax ([`parse`]) over the monitor's
//! signals ([`crate::monitor::signals`]). After a run its robustness is computed offline over
//! the run's discrete-time signals, as rtamt's discrete-time offline monitor computes it
//! ([`robustness`]): the formula's value at sample 0. Below 0 the requirement is violated.
//! The verdict keeps the robustness, when the violation began and the interval that decided
//! it (see [`Verdict`]).
//!
//! Why in the core: evaluating beside the run costs a few per cent of it, where rtamt's
//! pure-Python evaluation costs as much as the run; rtamt stays the tests' oracle.

pub mod parse;
pub mod robustness;

use schemars::JsonSchema;
use serde::{Deserialize, Serialize, Serializer};

use crate::error::{join, SpecError};
use crate::monitor::signals;
use robustness::Instr;

/// Names a requirement may not take besides sitgen's failure classes and event kinds: a
/// requirement's failures are listed among those, and a name must say whose they are.
const RESERVED: [&str; 4] = ["requirement", "score", "outcome", "failure"];

/// One requirement.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct RequirementSpec {
    /// Its name: letters, digits, `_` and `-`, 1 to 64 of them, starting with a letter.
    pub name: String,
    /// The formula, in rtamt's STL syntax over the signals (docs/requirements.md); bounds in
    /// seconds unless a unit says otherwise, each a whole number of `sim.dt_s` steps.
    pub formula: String,
    /// How much a violation weighs against the others when runs are ranked, in (0, 1000].
    /// Default 1.
    #[serde(default = "default_weight")]
    pub weight: f64,
}

fn default_weight() -> f64 {
    1.0
}

/// A requirement ready to evaluate: its code and the signals it reads.
#[derive(Debug, Clone)]
pub struct Compiled {
    /// Its name.
    pub name: String,
    /// Its weight.
    pub weight: f64,
    code: Vec<Instr>,
    /// Which signals it reads, by index.
    pub reads: [bool; 8],
}

impl RequirementSpec {
    /// Check the name and weight and compile the formula for samples `dt_s` apart; errors
    /// name `path` and, for the formula, the column.
    pub fn compile(&self, path: &str, dt_s: f64) -> Result<Compiled, SpecError> {
        let name_ok = !self.name.is_empty()
            && self.name.len() <= 64
            && self.name.starts_with(|c: char| c.is_ascii_alphabetic())
            && self
                .name
                .chars()
                .all(|c| c.is_ascii_alphanumeric() || c == '_' || c == '-');
        if !name_ok {
            return Err(SpecError::new(
                join(path, "name"),
                format!(
                    "{:?} is not a requirement name: 1 to 64 letters, digits, _ or -, starting with a letter",
                    self.name
                ),
            ));
        }
        if RESERVED.contains(&self.name.as_str())
            || crate::failure::FailureClass::from_key(&self.name).is_some()
            || crate::monitor::EventKind::from_name(&self.name).is_some()
        {
            return Err(SpecError::new(
                join(path, "name"),
                format!(
                    "{:?} is the name of one of sitgen's own classes; choose another",
                    self.name
                ),
            ));
        }
        SpecError::check_positive(&join(path, "weight"), self.weight, 1000.0)?;
        let code =
            parse::compile(&self.formula, &signals::index, &signals::NAMES, dt_s).map_err(|e| {
                SpecError::new(
                    join(path, "formula"),
                    format!("column {}: {}", e.column, e.message),
                )
            })?;
        let mut reads = [false; 8];
        for i in &code {
            if let Instr::Signal(s) = i {
                reads[*s] = true;
            }
        }
        Ok(Compiled {
            name: self.name.clone(),
            weight: self.weight,
            code,
            reads,
        })
    }
}

/// Check a run's requirements: each compiles, and no two share a name.
pub fn compile_all(
    specs: &[RequirementSpec],
    path: &str,
    dt_s: f64,
) -> Result<Vec<Compiled>, SpecError> {
    let mut out: Vec<Compiled> = Vec::with_capacity(specs.len());
    for (i, r) in specs.iter().enumerate() {
        let here = format!("{path}[{i}]");
        let c = r.compile(&here, dt_s)?;
        if out.iter().any(|o| o.name == c.name) {
            return Err(SpecError::new(
                join(&here, "name"),
                format!("two requirements are called {:?}", c.name),
            ));
        }
        out.push(c);
    }
    Ok(out)
}

/// A requirement's verdict on one run.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Verdict {
    /// The requirement.
    pub name: String,
    /// Its robustness at sample 0 (±∞ written `"inf"`/`"-inf"`); `null` when `error` says why
    /// there is none.
    #[serde(
        serialize_with = "number_or_infinity",
        deserialize_with = "read_number"
    )]
    pub robustness: Option<f64>,
    /// Whether it was violated (robustness below 0).
    pub violated: bool,
    /// When the violation began, seconds: for `always[a:b] φ` (or untimed) the first sample
    /// of its window where φ's robustness is below 0; for `eventually[a:b] φ` the window's
    /// end (when it was decided); otherwise 0.
    pub first_violation_s: Option<f64>,
    /// The interval that decided it, seconds: for `always`, the stretch of φ below 0 around
    /// its worst sample; for `eventually`, its whole window; otherwise [0, 0].
    pub interval_s: Option<[f64; 2]>,
    /// The requirement's weight.
    pub weight: f64,
    /// Why there is no robustness: the formula's value is undefined (NaN) at some sample.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub error: Option<String>,
}

fn number_or_infinity<S: Serializer>(v: &Option<f64>, s: S) -> Result<S::Ok, S::Error> {
    match v {
        None => s.serialize_none(),
        Some(x) if x.is_finite() => s.serialize_f64(*x),
        Some(x) if *x > 0.0 => s.serialize_str("inf"),
        Some(_) => s.serialize_str("-inf"),
    }
}

fn read_number<'de, D: serde::Deserializer<'de>>(d: D) -> Result<Option<f64>, D::Error> {
    Ok(match serde_json::Value::deserialize(d)? {
        serde_json::Value::Number(n) => n.as_f64(),
        serde_json::Value::String(s) if s == "inf" => Some(f64::INFINITY),
        serde_json::Value::String(s) if s == "-inf" => Some(f64::NEG_INFINITY),
        _ => None,
    })
}

/// Seconds of sample `k`, rounded to the nanosecond as the event log's times are.
fn seconds(k: usize, dt_s: f64) -> f64 {
    (k as f64 * dt_s * 1e9).round() / 1e9
}

impl Compiled {
    /// The robustness signal over `signals` (indexed as [`signals::NAMES`], `n` samples).
    pub fn robustness_signal(&self, signals: &[Vec<f64>], n: usize) -> Vec<f64> {
        let views: Vec<&[f64]> = signals.iter().map(Vec::as_slice).collect();
        robustness::evaluate(&self.code, &views, n).0
    }

    /// The verdict over `signals` (`n` samples, `dt_s` apart).
    pub fn verdict(&self, signals: &[Vec<f64>], n: usize, dt_s: f64) -> Verdict {
        let views: Vec<&[f64]> = signals.iter().map(Vec::as_slice).collect();
        let (rho, operand) = robustness::evaluate(&self.code, &views, n);
        let mut v = Verdict {
            name: self.name.clone(),
            robustness: None,
            violated: false,
            first_violation_s: None,
            interval_s: None,
            weight: self.weight,
            error: None,
        };
        if n == 0 {
            v.error = Some("the run has no samples".into());
            return v;
        }
        let value = rho[0];
        if value.is_nan() {
            // Where an operand first went undefined is where a user looks for the cause.
            let at = views
                .iter()
                .zip(&self.reads)
                .filter(|(_, r)| **r)
                .filter_map(|(s, _)| s.iter().position(|x| x.is_nan()))
                .min();
            v.error = Some(match at {
                Some(k) => format!("a signal is undefined (NaN) at {} s", seconds(k, dt_s)),
                None => "its value is undefined (NaN): a 0/0, or sqrt or pow of a negative number?"
                    .into(),
            });
            return v;
        }
        v.robustness = Some(value);
        v.violated = value < 0.0;
        if v.violated {
            let top = *self.code.last().expect("code is never empty");
            let (first, interval) = explain(top, operand.as_deref(), n);
            v.first_violation_s = Some(seconds(first, dt_s));
            v.interval_s = Some([seconds(interval.0, dt_s), seconds(interval.1, dt_s)]);
        }
        v
    }
}

/// When a violation at sample 0 began and the interval that decided it, in samples, for the
/// top instruction `top` with first operand's signal `operand`.
fn explain(top: Instr, operand: Option<&[f64]>, n: usize) -> (usize, (usize, usize)) {
    let last = n - 1;
    match (top, operand) {
        (Instr::Always(w), Some(phi)) => {
            let (a, b) = w.map_or((0, last), |w| (w.begin.min(last), w.end.min(last)));
            let window = &phi[a..=b];
            let first = a + window.iter().position(|x| *x < 0.0).unwrap_or(0);
            let worst = a + window
                .iter()
                .enumerate()
                .fold(
                    (0, f64::INFINITY),
                    |best, (i, x)| if *x < best.1 { (i, *x) } else { best },
                )
                .0;
            let mut start = worst;
            while start > a && phi[start - 1] < 0.0 {
                start -= 1;
            }
            let mut end = worst;
            while end < b && phi[end + 1] < 0.0 {
                end += 1;
            }
            (first, (start, end))
        }
        (Instr::Eventually(w), Some(_)) => {
            let (a, b) = w.map_or((0, last), |w| (w.begin.min(last), w.end.min(last)));
            (b, (a, b))
        }
        _ => (0, (0, 0)),
    }
}

/// Every requirement's verdict on a run whose signals are `signals`.
pub fn verdicts(compiled: &[Compiled], signals: &[Vec<f64>], n: usize, dt_s: f64) -> Vec<Verdict> {
    compiled
        .iter()
        .map(|c| c.verdict(signals, n, dt_s))
        .collect()
}

/// Which signals any of `compiled` reads.
pub fn reads(compiled: &[Compiled]) -> [bool; 8] {
    let mut out = [false; 8];
    for c in compiled {
        for (o, r) in out.iter_mut().zip(c.reads) {
            *o |= r;
        }
    }
    out
}

#[cfg(test)]
mod tests;
