//! sitgen-core: the pure-Rust core of sitgen.
//!
//! Everything that runs per cell, per ray or per step lives here. The crate has no Python
//! bindings, prints nothing, reads no clock and owns no global random state: every random
//! choice comes from a [`rng::ChoiceSource`] handed in by the caller, so a result is a pure
//! function of its inputs (spec, seed) and byte-identical on any machine and thread count.
//!
//! Pipeline stages, one module each: [`spec`] (situation spec, TOML, presets, validation),
//! [`rng`] (named seed streams, recordable choices), [`grid`] (scalar fields and occupancy
//! grids), [`terrain`] (sources and the filter chain), [`interchange`] (map files in and out),
//! [`mission`] (placement and routes), [`situation`] (the situation file), [`sim`] (the
//! simulator), [`control`] (controllers), [`monitor`] (events), [`scoring`] (penalties),
//! [`failure`] (failure classes), [`requirement`] (the user's requirements in STL), [`coverage`] (situation coverage), [`run`] (one situation
//! driven to its end), [`avoidability`] (whether a collision could have been escaped) and [`crosscheck`] (the same situation run by Stage, compared).

pub mod avoidability;
pub mod control;
pub mod coverage;
pub mod crosscheck;
pub mod error;
pub mod failure;
pub mod geometry;
pub mod grid;
pub mod interchange;
pub mod mission;
pub mod monitor;
pub mod parallel;
pub mod requirement;
pub mod rng;
pub mod run;
pub mod scoring;
pub mod shrink;
pub mod sim;
pub mod situation;
pub mod spec;
pub mod terrain;

#[cfg(test)]
mod test_data;

/// The version of sitgen that produced a result, recorded in provenance.
pub const VERSION: &str = env!("CARGO_PKG_VERSION");
