//! Helpers shared by the crate's tests: the reference data beside the repository and the
//! checked-in schema files.

use std::path::PathBuf;

/// `../shared/data` beside the repository (or `$SITGEN_SHARED_DATA`) joined with `rel`, if it
/// exists; tests that need it print why they skip when it does not.
pub fn shared(rel: &str) -> Option<PathBuf> {
    let path = std::env::var_os("SITGEN_SHARED_DATA")
        .map(PathBuf::from)
        .unwrap_or_else(|| PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../../shared/data"))
        .join(rel);
    path.exists().then_some(path)
}

/// Assert that `schema/<file>` equals `generated`; with `SITGEN_BLESS=1` rewrite it first.
pub fn assert_schema_checked_in(file: &str, generated: &str) {
    let path = PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("../../schema")
        .join(file);
    if std::env::var_os("SITGEN_BLESS").is_some() {
        std::fs::write(&path, generated).unwrap();
    }
    let checked_in = std::fs::read_to_string(&path).unwrap_or_default();
    assert!(
        checked_in == generated,
        "schema/{file} is out of date; run `SITGEN_BLESS=1 cargo test -p sitgen-core schema` and commit it"
    );
}
