//! Named presets: partial terrain specs (TOML files beside this one) that give the paper's
//! range of environments. A spec names one in `terrain.preset` and overrides any field.
//! Every preset ends with a coverage constraint, so its obstacle density is what it says.

/// Preset names, in the order they are listed to users.
pub const NAMES: &[&str] = &[
    "open_field",
    "rocky_desert",
    "caves",
    "urban",
    "indoor",
    "maze",
];

/// The TOML text of preset `name`.
pub fn text(name: &str) -> Option<&'static str> {
    Some(match name {
        "open_field" => include_str!("open_field.toml"),
        "rocky_desert" => include_str!("rocky_desert.toml"),
        "caves" => include_str!("caves.toml"),
        "urban" => include_str!("urban.toml"),
        "indoor" => include_str!("indoor.toml"),
        "maze" => include_str!("maze.toml"),
        _ => return None,
    })
}

/// The terrain table of preset `name`.
pub fn lookup(name: &str) -> Option<toml::Table> {
    text(name).map(|t| t.parse().expect("built-in presets are valid TOML"))
}
