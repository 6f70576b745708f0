//! Spec errors: one line, naming the field path and what is allowed.

use std::fmt;

/// A spec that cannot be used, with the path of the offending field
/// (`terrain.filters[2].target`) and what was expected there.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct SpecError {
    /// Dotted field path, with `[i]` for list items; empty for the whole spec.
    pub path: String,
    /// What is wrong and what is allowed.
    pub message: String,
}

impl SpecError {
    /// An error at `path`.
    pub fn new(path: impl Into<String>, message: impl Into<String>) -> Self {
        Self {
            path: path.into(),
            message: message.into(),
        }
    }

    /// An error for a value outside [lo, hi].
    pub fn not_in(path: impl Into<String>, value: f64, lo: f64, hi: f64) -> Self {
        Self::new(path, format!("{value} is not in [{lo}, {hi}]"))
    }

    /// Check that `value` lies in [lo, hi] (NaN never does).
    pub fn check_in(path: &str, value: f64, lo: f64, hi: f64) -> Result<(), Self> {
        if value >= lo && value <= hi {
            Ok(())
        } else {
            Err(Self::not_in(path, value, lo, hi))
        }
    }

    /// Check that `value` lies in (0, hi].
    pub fn check_positive(path: &str, value: f64, hi: f64) -> Result<(), Self> {
        if value > 0.0 && value <= hi {
            Ok(())
        } else {
            Err(Self::new(path, format!("{value} is not in (0, {hi}]")))
        }
    }
}

impl fmt::Display for SpecError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let (path, message) = (one_line(&self.path), one_line(&self.message));
        if path.is_empty() {
            write!(f, "{message}")
        } else {
            write!(f, "{path}: {message}")
        }
    }
}

/// `text` with control characters escaped (`\n`, `\u{1b}`): a field name or value quoted from a
/// file may hold them, and an error stays one line.
fn one_line(text: &str) -> std::borrow::Cow<'_, str> {
    if !text.chars().any(char::is_control) {
        return text.into();
    }
    text.chars()
        .flat_map(|c| {
            let escaped: Vec<char> = if c.is_control() {
                c.escape_default().collect()
            } else {
                vec![c]
            };
            escaped
        })
        .collect::<String>()
        .into()
}

impl std::error::Error for SpecError {}

/// Marks a custom serde error message that carries a field path below where it was raised.
/// serde's error type holds only a message, so a tagged item that deserializes its fields
/// itself passes their path up inside the message; [`SpecError::from`] takes it back out.
const NESTED: char = '\u{1f}';

/// Encode `message` at sub-path `path` as a serde custom-error message.
pub(crate) fn nested(path: &str, message: &str) -> String {
    format!("{NESTED}{path}{NESTED}{message}")
}

/// `parent.child`, or `child` at the root; `child` may start with `[` for an index.
pub fn join(parent: &str, child: &str) -> String {
    if parent.is_empty() {
        child.to_string()
    } else if child.is_empty() {
        parent.to_string()
    } else if child.starts_with('[') {
        format!("{parent}{child}")
    } else {
        format!("{parent}.{child}")
    }
}

impl From<serde_path_to_error::Error<toml::de::Error>> for SpecError {
    fn from(e: serde_path_to_error::Error<toml::de::Error>) -> Self {
        let outer = e.path().to_string();
        let outer = if outer == "." { String::new() } else { outer };
        // `message()`, not `to_string()`: the latter appends the key path on another line.
        let text = e.inner().message().trim().to_string();
        match text
            .strip_prefix(NESTED)
            .and_then(|rest| rest.split_once(NESTED))
        {
            Some((inner, message)) => Self::new(join(&outer, inner), message),
            None => Self::new(outer, text),
        }
    }
}

/// Deserialize a kind-tagged item (`kind = "…"` plus that kind's fields) from its table,
/// keeping the path of a bad field inside it. Used by [`kind_tagged!`].
pub(crate) fn tagged_fields<T: serde::de::DeserializeOwned>(
    table: toml::Table,
) -> Result<T, String> {
    serde_path_to_error::deserialize(toml::Value::Table(table)).map_err(|e| {
        let e = SpecError::from(e);
        nested(&e.path, &e.message)
    })
}

/// Implements `Deserialize` for an enum of newtype variants tagged by a `kind` field, so that
/// errors name the field inside the item (serde's own internally tagged enums lose it).
macro_rules! kind_tagged {
    ($enum:ident, $what:literal, { $($name:literal => $variant:ident),* $(,)? }) => {
        impl $enum {
            /// The `kind` names this enum accepts.
            pub const KINDS: &'static [&'static str] = &[$($name),*];

            /// The `kind` name of this item.
            pub fn kind(&self) -> &'static str {
                match self { $(Self::$variant(_) => $name),* }
            }
        }

        impl<'de> serde::Deserialize<'de> for $enum {
            fn deserialize<D: serde::Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
                use serde::de::Error;
                use $crate::error::{nested, tagged_fields};
                let mut table = toml::Table::deserialize(d)?;
                let expected = Self::KINDS.join(", ");
                let kind = match table.remove("kind") {
                    Some(toml::Value::String(s)) => s,
                    Some(other) => {
                        let msg = format!("expected a string, found {}", other.type_str());
                        return Err(D::Error::custom(nested("kind", &msg)));
                    }
                    None => {
                        let msg = format!("missing; expected one of {expected}");
                        return Err(D::Error::custom(nested("kind", &msg)));
                    }
                };
                match kind.as_str() {
                    $($name => tagged_fields(table).map(Self::$variant).map_err(D::Error::custom),)*
                    other => {
                        let msg = format!("unknown {} `{other}`; expected one of {expected}", $what);
                        Err(D::Error::custom(nested("kind", &msg)))
                    }
                }
            }
        }
    };
}
pub(crate) use kind_tagged;

#[cfg(test)]
mod tests {
    use super::SpecError;

    #[test]
    fn an_error_quoting_a_newline_stays_one_line() {
        let e = SpecError::new("robots[0]", "unknown field `\n\t`, expected `id`");
        assert_eq!(
            e.to_string(),
            "robots[0]: unknown field `\\n\\t`, expected `id`"
        );
    }
}
