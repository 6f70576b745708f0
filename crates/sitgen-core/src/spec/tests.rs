use super::*;
use crate::terrain::{FilterSpec, SourceSpec};

fn error_of(text: &str) -> String {
    from_toml_str(text).unwrap_err().to_string()
}

#[test]
fn an_empty_spec_is_rejected_because_noise_needs_a_threshold() {
    assert_eq!(
        error_of(""),
        "terrain.filters: the chain ends with a scalar field from the perlin source; add a threshold or coverage filter"
    );
}

#[test]
fn a_full_spec_reads_with_defaults_filled() {
    let spec = from_toml_str(
        r#"
        [terrain]
        width_m = 20
        [terrain.source]
        kind = "perlin"
        octaves = 3
        [[terrain.filters]]
        kind = "pixelise"
        [[terrain.filters]]
        kind = "coverage"
        target = 0.3
        "#,
    )
    .unwrap();
    assert_eq!(spec.terrain.width_m, Some(20.0));
    assert_eq!(spec.terrain.resolution_m, 0.1);
    let SourceSpec::Perlin(p) = &spec.terrain.source else {
        panic!("perlin expected")
    };
    assert_eq!((p.octaves, p.persistence, p.lacunarity), (3, 0.5, 2.0));
    assert!(matches!(&spec.terrain.filters[1], FilterSpec::Coverage(c) if c.tolerance == 0.01));
}

#[test]
fn out_of_range_values_name_the_field_path() {
    let text = r#"
        [terrain]
        [[terrain.filters]]
        kind = "pixelise"
        [[terrain.filters]]
        kind = "invert"
        [[terrain.filters]]
        kind = "coverage"
        target = 1.7
    "#;
    assert_eq!(
        error_of(text),
        "terrain.filters[2].target: 1.7 is not in [0, 1]"
    );
}

#[test]
fn unknown_fields_are_rejected_inside_tagged_items() {
    let text = r#"
        [[terrain.filters]]
        kind = "coverage"
        target = 0.2
        tolerence = 0.1
    "#;
    let e = error_of(text);
    assert!(
        e == "terrain.filters[0].tolerence: unknown field `tolerence`, expected `target` or `tolerance`",
        "{e}"
    );
}

#[test]
fn unknown_top_level_and_terrain_fields_are_rejected() {
    assert_eq!(
        error_of("[terrian]\n"),
        "terrian: unknown field `terrian`, expected `terrain` or `mission`"
    );
    let e = error_of("[terrain]\nsize = 3\n");
    assert!(
        e.starts_with("terrain.size: unknown field `size`, expected one of"),
        "{e}"
    );
}

#[test]
fn wrong_types_name_the_field() {
    let text = r#"
        [terrain.source]
        kind = "perlin"
        octaves = "six"
    "#;
    let e = error_of(text);
    assert!(
        e.starts_with("terrain.source.octaves: invalid type: string \"six\""),
        "{e}"
    );
    let e = error_of("[terrain]\nresolution_m = \"fine\"\n");
    assert!(e.starts_with("terrain.resolution_m: invalid type"), "{e}");
}

#[test]
fn unknown_kinds_and_presets_list_what_is_allowed() {
    let e = error_of("[[terrain.filters]]\nkind = \"blur\"\n");
    assert_eq!(
        e,
        "terrain.filters[0].kind: unknown filter `blur`; expected one of pixelise, threshold, coverage, dilate, erode, invert, border, remove_islands, keep_largest_free_region"
    );
    let e = error_of("[terrain.source]\nkind = \"fractal\"\n");
    assert!(
        e.starts_with("terrain.source.kind: unknown source `fractal`"),
        "{e}"
    );
    let e = error_of("[terrain]\npreset = \"moon\"\n");
    assert_eq!(
        e,
        "terrain.preset: unknown preset `moon`; expected one of open_field, rocky_desert, caves, urban, indoor, maze"
    );
    let e = error_of("[[terrain.filters]]\ntarget = 0.2\n");
    assert!(e.starts_with("terrain.filters[0].kind: missing"), "{e}");
}

#[test]
fn filters_that_need_a_grid_say_what_to_put_before_them() {
    let e = error_of("[[terrain.filters]]\nkind = \"dilate\"\n");
    assert_eq!(
        e,
        "terrain.filters[0].kind: dilate needs an occupancy grid but gets a scalar field; put threshold or coverage before it"
    );
    let text = r#"
        [terrain.source]
        kind = "caves"
        [[terrain.filters]]
        kind = "threshold"
    "#;
    assert!(error_of(text).starts_with("terrain.filters[0].kind: threshold needs a scalar field"));
}

#[test]
fn syntax_errors_give_a_line_and_column() {
    let e = error_of("[terrain]\nwidth_m = = 3\n");
    assert!(e.starts_with("TOML syntax error at line 2, column"), "{e}");
    assert!(!e.contains('\n'), "one line: {e}");
}

#[test]
fn too_many_cells_are_rejected_before_generating() {
    let e = error_of("[terrain]\npreset = \"caves\"\nwidth_m = 5000\nheight_m = 5000\n");
    assert!(
        e.starts_with("terrain.resolution_m: 5000 m × 5000 m"),
        "{e}"
    );
}

#[test]
fn a_preset_is_overridden_field_by_field() {
    let spec = from_toml_str(
        r#"
        [terrain]
        preset = "caves"
        width_m = 25.0
        [terrain.source]
        fill = 0.5
        "#,
    )
    .unwrap();
    let base = from_toml_str("[terrain]\npreset = \"caves\"\n").unwrap();
    assert_eq!(spec.terrain.width_m, Some(25.0));
    assert_eq!(spec.terrain.filters, base.terrain.filters);
    let (SourceSpec::Caves(c), SourceSpec::Caves(b)) = (&spec.terrain.source, &base.terrain.source)
    else {
        panic!("caves expected")
    };
    assert_eq!(c.fill, 0.5);
    assert_eq!(c.smooth_passes, b.smooth_passes);
}

#[test]
fn a_source_of_another_kind_replaces_the_preset_source_whole() {
    let spec = from_toml_str(
        r#"
        [terrain]
        preset = "caves"
        [terrain.source]
        kind = "maze"
        "#,
    )
    .unwrap();
    assert!(matches!(spec.terrain.source, SourceSpec::Maze(_)));
}

#[test]
fn every_preset_is_valid() {
    for name in presets::NAMES {
        let spec = from_toml_str(&format!("[terrain]\npreset = \"{name}\"\n"));
        assert!(spec.is_ok(), "{name}: {spec:?}");
    }
}

#[test]
fn json_input_reads_like_toml() {
    let from_json = from_json_str(r#"{"terrain": {"preset": "maze", "width_m": 12}}"#).unwrap();
    let from_toml = from_toml_str("[terrain]\npreset = \"maze\"\nwidth_m = 12\n").unwrap();
    assert_eq!(from_json, from_toml);
    assert!(from_json_str("[1]")
        .unwrap_err()
        .to_string()
        .contains("expected a table"));
}

#[test]
fn a_resolved_spec_round_trips_through_json() {
    let spec = from_toml_str("[terrain]\npreset = \"urban\"\n").unwrap();
    let json = serde_json::to_string(&spec).unwrap();
    assert_eq!(from_json_str(&json).unwrap(), spec);
}

/// The checked-in schema must equal the one generated from the types.
#[test]
fn the_checked_in_schema_matches_the_types() {
    crate::test_data::assert_schema_checked_in("situation-spec.schema.json", &json_schema());
}
