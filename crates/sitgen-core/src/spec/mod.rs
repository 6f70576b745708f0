//! The situation spec: what a user writes (TOML) to describe the situations to generate.
//!
//! Reading a spec is three steps, each with errors that name the field path:
//! 1. **parse** the TOML (or a JSON object from Python) into a generic value tree;
//! 2. **resolve** presets: a `terrain.preset` names a built-in partial spec, and the user's
//!    fields are laid over it ([`merge`]);
//! 3. **deserialize** into the typed structs (unknown fields rejected) and **validate** ranges
//!    and the filter chain.
//!
//! The typed structs are the single source of truth: the JSON Schema in `schema/` is generated
//! from them, and every field's doc comment gives its unit, default and allowed range.

// Spec errors live below every stage (`crate::error`), so that terrain and mission, which this
// module composes, need nothing of it; they are named here too, where users look for them.
pub use crate::error::{join, SpecError};

use std::path::Path;

use schemars::JsonSchema;
use serde::{Deserialize, Serialize};

use crate::mission::MissionSpec;
use crate::terrain::{presets, TerrainSpec};

/// A situation spec: how to generate one kind of situation. Later pipeline stages (mission,
/// run) add their own sections.
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct SituationSpec {
    /// How to generate the terrain map.
    #[serde(default)]
    pub terrain: TerrainSpec,
    /// How to place robots and give them routes.
    #[serde(default)]
    pub mission: MissionSpec,
}

impl SituationSpec {
    /// Check every range and the filter chain; the error names the first bad field.
    pub fn validate(&self) -> Result<(), SpecError> {
        self.terrain.validate("terrain")?;
        self.mission.validate("mission")?;
        crate::control::check(&self.mission.agent_controller, "mission.agent_controller")?;
        let peer = &self.mission.peer_controller;
        crate::control::check_peer(&peer.name, "mission.peer_controller")?;
        crate::control::check(peer, "mission.peer_controller")?;
        for (i, peer) in self.mission.peer_controllers.iter().enumerate() {
            let path = format!("mission.peer_controllers[{i}]");
            crate::control::check_peer(&peer.name, &path)?;
            crate::control::check(peer, &path)?;
        }
        Ok(())
    }
}

/// Parse, resolve and validate a spec from TOML text.
pub fn from_toml_str(text: &str) -> Result<SituationSpec, SpecError> {
    let value: toml::Table = text.parse().map_err(|e: toml::de::Error| {
        let at = e
            .span()
            .map(|s| {
                let (line, col) = line_col(text, s.start);
                format!(" at line {line}, column {col}")
            })
            .unwrap_or_default();
        SpecError::new("", format!("TOML syntax error{at}: {}", e.message().trim()))
    })?;
    from_table(value)
}

/// Parse, resolve and validate a spec from a JSON object (how Python passes a dict).
pub fn from_json_str(text: &str) -> Result<SituationSpec, SpecError> {
    let value: toml::Value = serde_json::from_str(text)
        .map_err(|e| SpecError::new("", format!("not a spec object: {e}")))?;
    match value {
        toml::Value::Table(t) => from_table(t),
        other => Err(SpecError::new(
            "",
            format!("expected a table of sections, found {}", other.type_str()),
        )),
    }
}

/// Read a spec file. Relative paths inside it (image sources) are taken relative to the file.
pub fn from_file(path: &Path) -> Result<SituationSpec, SpecError> {
    let text = std::fs::read_to_string(path)
        .map_err(|e| SpecError::new("", format!("cannot read spec {}: {e}", path.display())))?;
    let mut spec = from_toml_str(&text)?;
    if let Some(dir) = path.parent() {
        spec.terrain.source.resolve_paths(dir);
    }
    Ok(spec)
}

/// Resolve presets in a generic value tree, then deserialize and validate it.
pub fn from_table(mut table: toml::Table) -> Result<SituationSpec, SpecError> {
    if let Some(toml::Value::Table(terrain)) = table.get_mut("terrain") {
        resolve_preset(terrain, "terrain", presets::lookup)?;
    }
    let spec: SituationSpec =
        serde_path_to_error::deserialize(toml::Value::Table(table)).map_err(SpecError::from)?;
    spec.validate()?;
    Ok(spec)
}

/// Replace `section` by its preset (named in its `preset` field) with the section's own
/// fields laid over it.
fn resolve_preset(
    section: &mut toml::Table,
    path: &str,
    lookup: fn(&str) -> Option<toml::Table>,
) -> Result<(), SpecError> {
    let name = match section.get("preset") {
        None => return Ok(()),
        Some(toml::Value::String(name)) => name.clone(),
        Some(other) => {
            return Err(SpecError::new(
                join(path, "preset"),
                format!("expected a preset name, found {}", other.type_str()),
            ))
        }
    };
    let Some(mut base) = lookup(&name) else {
        return Err(SpecError::new(
            join(path, "preset"),
            format!(
                "unknown preset `{name}`; expected one of {}",
                presets::NAMES.join(", ")
            ),
        ));
    };
    merge(&mut base, std::mem::take(section));
    *section = base;
    Ok(())
}

/// Lay `over` onto `base`, key by key. Tables merge recursively, except that a table whose
/// `kind` differs from the base's replaces it whole (its fields belong to another kind);
/// arrays and scalars replace.
pub fn merge(base: &mut toml::Table, over: toml::Table) {
    for (key, value) in over {
        match (base.get_mut(&key), value) {
            (Some(toml::Value::Table(b)), toml::Value::Table(o)) if same_kind(b, &o) => {
                merge(b, o);
            }
            (_, value) => {
                base.insert(key, value);
            }
        }
    }
}

fn same_kind(a: &toml::Table, b: &toml::Table) -> bool {
    match b.get("kind") {
        None => true,
        Some(k) => a.get("kind") == Some(k),
    }
}

/// 1-based line and column of byte offset `at` in `text`.
fn line_col(text: &str, at: usize) -> (usize, usize) {
    let before = &text[..at.min(text.len())];
    let line = before.matches('\n').count() + 1;
    let col = before.chars().rev().take_while(|&c| c != '\n').count() + 1;
    (line, col)
}

/// The JSON Schema of [`SituationSpec`], pretty-printed, as checked in under `schema/`.
pub fn json_schema() -> String {
    let schema = schemars::schema_for!(SituationSpec);
    let mut text = serde_json::to_string_pretty(&schema).expect("a schema serialises");
    text.push('\n');
    text
}

#[cfg(test)]
mod tests;
