//! Run profiles: named partial run specs (TOML files in `profiles/`) that a run spec lays its
//! own fields over, as terrain presets are for terrain. `paper` reproduces the setting of
//! Arnold & Alexander's case study line by line with its source (docs/profiles.md); `default`
//! is sitgen's own defaults, named so that a campaign can say which one it ran under.

use crate::error::{join, SpecError};

/// Profile names, in the order they are listed to users.
pub const NAMES: &[&str] = &["default", "paper"];

/// The TOML text of profile `name`, comments and sources included.
pub fn text(name: &str) -> Option<&'static str> {
    Some(match name {
        "default" => include_str!("profiles/default.toml"),
        "paper" => include_str!("profiles/paper.toml"),
        _ => return None,
    })
}

/// Profile `name` as a JSON object.
pub fn lookup(name: &str) -> Option<serde_json::Value> {
    let table: toml::Table = text(name)?
        .parse()
        .expect("built-in profiles are valid TOML");
    Some(serde_json::to_value(table).expect("TOML tables are JSON objects"))
}

/// Lay `spec` (a run spec as JSON) over the profile its `profile` field names, if any; the
/// field stays, so the resolved spec says what it was made from. `path` names the spec.
pub fn resolve(spec: &mut serde_json::Value, path: &str) -> Result<(), SpecError> {
    let field = join(path, "profile");
    let name = match spec.get("profile") {
        None | Some(serde_json::Value::Null) => return Ok(()),
        Some(serde_json::Value::String(name)) => name.clone(),
        Some(other) => {
            return Err(SpecError::new(
                field,
                format!("expected a profile name, found {other}"),
            ))
        }
    };
    let mut base = lookup(&name).ok_or_else(|| {
        SpecError::new(
            &field,
            format!(
                "unknown profile `{name}`; expected one of {}",
                NAMES.join(", ")
            ),
        )
    })?;
    merge(&mut base, std::mem::take(spec));
    *spec = base;
    Ok(())
}

/// Lay `over` onto `base`: objects merge key by key, except that a controller that names
/// another controller replaces the profile's whole (its parameters belong to the other one);
/// everything else replaces.
fn merge(base: &mut serde_json::Value, over: serde_json::Value) {
    match (base, over) {
        (serde_json::Value::Object(b), serde_json::Value::Object(o)) => {
            for (key, value) in o {
                match b.get_mut(&key) {
                    Some(slot) if !names_another(slot, &value) => merge(slot, value),
                    _ => {
                        b.insert(key, value);
                    }
                }
            }
        }
        (base, over) => *base = over,
    }
}

fn names_another(base: &serde_json::Value, over: &serde_json::Value) -> bool {
    match (base.get("name"), over.get("name")) {
        (Some(a), Some(b)) => a != b,
        _ => false,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::run::RunSpec;

    #[test]
    fn every_profile_resolves_to_a_valid_run_spec() {
        for name in NAMES {
            let spec = RunSpec::from_json(&format!(r#"{{"profile": "{name}"}}"#), "run").unwrap();
            assert_eq!(spec.profile.as_deref(), Some(*name));
        }
        let default = RunSpec::from_json(r#"{"profile": "default"}"#, "run").unwrap();
        assert_eq!(
            RunSpec {
                profile: None,
                ..default
            },
            RunSpec::default()
        );
    }

    #[test]
    fn a_specs_own_fields_lie_over_its_profile() {
        let spec = RunSpec::from_json(
            r#"{"profile": "paper", "time_limit_s": 60, "sim": {"laser": {"range_m": 8}},
                "controller": {"name": "snd_follow", "params": {"robot_radius": 0.4}}}"#,
            "run",
        )
        .unwrap();
        assert_eq!(spec.time_limit_s, 60.0);
        assert_eq!(spec.sim.laser.range_m, 8.0);
        assert_eq!(spec.sim.laser.beams, 180);
        let c = spec.controller.unwrap();
        assert_eq!(c.control_period_s, Some(0.5));
        assert_eq!(c.params["robot_radius"], 0.4);
        assert_eq!(c.params["max_turn_rate_deg_s"], 60.0);
        // Another controller replaces the profile's, parameters and period with it.
        let spec = RunSpec::from_json(
            r#"{"profile": "paper", "controller": {"name": "vo"}}"#,
            "run",
        )
        .unwrap();
        let c = spec.controller.unwrap();
        assert!(c.params.is_empty() && c.control_period_s.is_none());
    }

    #[test]
    fn an_unknown_profile_is_named() {
        let e = RunSpec::from_json(r#"{"profile": "stage"}"#, "run").unwrap_err();
        assert_eq!(
            e.to_string(),
            "run.profile: unknown profile `stage`; expected one of default, paper"
        );
        let e = RunSpec::from_json(r#"{"profile": 3}"#, "run").unwrap_err();
        assert_eq!(
            e.to_string(),
            "run.profile: expected a profile name, found 3"
        );
    }
}
