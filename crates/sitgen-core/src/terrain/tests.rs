use proptest::prelude::*;

use super::*;
use crate::grid::regions::{label_regions, Connectivity, Regions};
use crate::rng::{stream, ChoiceSource};
use crate::spec::from_toml_str;
use crate::test_data::shared;

fn preset(name: &str) -> TerrainSpec {
    from_toml_str(&format!("[terrain]\npreset = \"{name}\"\n"))
        .unwrap()
        .terrain
}

fn generate_seeded(spec: &TerrainSpec, seed: u64) -> Terrain {
    generate(spec, &mut ChoiceSource::stream(seed, stream::TERRAIN)).unwrap()
}

fn target_of(spec: &TerrainSpec) -> (f64, f64) {
    spec.filters
        .iter()
        .find_map(|f| match f {
            FilterSpec::Coverage(c) => Some((c.target, c.tolerance)),
            _ => None,
        })
        .expect("every preset has a coverage constraint")
}

#[test]
fn perlin_equals_the_reference_bit_for_bit_at_every_listed_point() {
    let Some(data) = shared("") else {
        eprintln!("SKIPPED: ../shared/data not found (set SITGEN_SHARED_DATA); Perlin reference table not checked");
        return;
    };
    let text =
        std::fs::read_to_string(data.join("perlin/perlin_improved_noise_values.tsv")).unwrap();
    let mut checked = 0;
    for line in text.lines().skip(1) {
        let cols: Vec<&str> = line.split('\t').collect();
        let [x, y, z, value]: [f64; 4] = [0, 1, 2, 3].map(|i| cols[i].parse().unwrap());
        let got = noise::perlin(x, y, z);
        assert_eq!(
            got.to_bits(),
            value.to_bits(),
            "noise({x}, {y}, {z}) = {got:e}, reference {value:e}"
        );
        checked += 1;
    }
    assert_eq!(checked, 535);
}

#[test]
fn every_preset_is_deterministic_and_seed_dependent() {
    for name in presets::NAMES {
        let spec = preset(name);
        let a = generate_seeded(&spec, 11);
        let b = generate_seeded(&spec, 11);
        let c = generate_seeded(&spec, 12);
        assert_eq!(a, b, "{name}: same seed, same map");
        assert_ne!(a.map.grid, c.map.grid, "{name}: another seed, another map");
    }
}

#[test]
fn the_terrain_stream_alone_decides_the_map() {
    let spec = preset("caves");
    let mut recording = ChoiceSource::stream(5, stream::TERRAIN);
    recording.start_recording();
    let live = generate(&spec, &mut recording).unwrap();
    let mut replay = ChoiceSource::replay(recording.recorded().unwrap().to_vec());
    assert_eq!(generate(&spec, &mut replay).unwrap(), live);
}

#[test]
fn presets_meet_their_coverage_over_many_seeds() {
    for name in presets::NAMES {
        let spec = preset(name);
        let (target, tolerance) = target_of(&spec);
        for seed in 0..100 {
            let t = generate_seeded(&spec, seed);
            let got = t.map.grid.coverage();
            assert!(
                (got - target).abs() <= tolerance,
                "{name} seed {seed}: coverage {got}, target {target} ± {tolerance}"
            );
            assert_eq!(t.stages.last().unwrap().coverage, Some(got));
        }
    }
}

fn free_regions(grid: &OccupancyGrid) -> usize {
    let free: Vec<bool> = grid.cells.iter().map(|&c| !c).collect();
    label_regions(&free, grid.rows, grid.cols, Connectivity::Eight)
        .sizes
        .len()
}

#[test]
fn keep_largest_free_region_presets_have_one_free_region() {
    for name in ["caves", "indoor", "maze"] {
        for seed in 0..20 {
            let t = generate_seeded(&preset(name), seed);
            assert_eq!(free_regions(&t.map.grid), 1, "{name} seed {seed}");
        }
    }
}

fn occupancy(rows: usize, cols: usize, bits: &[bool]) -> OccupancyGrid {
    OccupancyGrid {
        rows,
        cols,
        cells: bits[..rows * cols].to_vec(),
    }
}

fn apply(filter: FilterSpec, grid: &OccupancyGrid, res: f64) -> OccupancyGrid {
    match filter
        .as_filter()
        .apply(Layer::Occupancy(grid.clone()), res)
    {
        Layer::Occupancy(g) => g,
        Layer::Field(_) => panic!("an occupancy filter returned a field"),
    }
}

proptest! {
    #[test]
    fn keep_largest_free_region_leaves_exactly_one(rows in 1usize..30, cols in 1usize..30,
            bits in prop::collection::vec(prop::bool::weighted(0.45), 900)) {
        let g = occupancy(rows, cols, &bits);
        let out = apply(FilterSpec::KeepLargestFreeRegion(filters::KeepLargestFreeRegion {}), &g, 0.1);
        let had_free = g.cells.iter().any(|&c| !c);
        prop_assert_eq!(free_regions(&out), usize::from(had_free));
        // Only fills: every cell occupied before is still occupied.
        prop_assert!(g.cells.iter().zip(&out.cells).all(|(&a, &b)| !a || b));
    }

    #[test]
    fn dilate_then_erode_never_shrinks_and_dilate_never_loses(rows in 1usize..25, cols in 1usize..25,
            bits in prop::collection::vec(prop::bool::weighted(0.2), 625), r in 0.0f64..0.5) {
        let g = occupancy(rows, cols, &bits);
        let d = apply(FilterSpec::Dilate(filters::Dilate { radius_m: r }), &g, 0.1);
        prop_assert!(g.cells.iter().zip(&d.cells).all(|(&a, &b)| !a || b));
        let closed = apply(FilterSpec::Erode(filters::Erode { radius_m: r }), &d, 0.1);
        // A closing contains the original.
        prop_assert!(g.cells.iter().zip(&closed.cells).all(|(&a, &b)| !a || b));
    }

    #[test]
    fn remove_islands_removes_exactly_the_small_obstacles(rows in 1usize..25, cols in 1usize..25,
            bits in prop::collection::vec(prop::bool::weighted(0.3), 625), min_cells in 0usize..8) {
        let g = occupancy(rows, cols, &bits);
        let area = min_cells as f64 * 0.01;
        let out = apply(FilterSpec::RemoveIslands(filters::RemoveIslands { min_area_m2: area - 1e-9 }), &g, 0.1);
        let regions = label_regions(&g.cells, rows, cols, Connectivity::Eight);
        for (i, label) in regions.label.iter().enumerate() {
            let kept = *label != Regions::NONE && regions.sizes[*label as usize] >= min_cells;
            prop_assert_eq!(out.cells[i], kept);
        }
    }
}

#[test]
fn dilate_grows_a_cell_into_a_disc() {
    let mut g = OccupancyGrid::filled(21, 21, false);
    g.set(10, 10, true);
    let d = apply(
        FilterSpec::Dilate(filters::Dilate { radius_m: 0.5 }),
        &g,
        0.1,
    );
    // Lattice points within distance 5 of the origin: Gauss's circle problem N(5) = 81.
    assert_eq!(d.occupied_count(), 81);
    let e = apply(FilterSpec::Erode(filters::Erode { radius_m: 0.5 }), &d, 0.1);
    assert_eq!(e, g);
}

#[test]
fn border_walls_every_edge_and_invert_swaps() {
    let g = OccupancyGrid::filled(10, 8, false);
    let b = apply(
        FilterSpec::Border(filters::Border { width_m: 0.2 }),
        &g,
        0.1,
    );
    assert_eq!(b.occupied_count(), 10 * 8 - 6 * 4);
    assert!(
        b.get(0, 3) && b.get(9, 3) && b.get(4, 0) && b.get(4, 7) && b.get(1, 1) && !b.get(2, 2)
    );
    let i = apply(FilterSpec::Invert(filters::Invert {}), &b, 0.1);
    assert_eq!(i.occupied_count(), 6 * 4);
}

#[test]
fn an_image_source_reads_back_what_was_written() {
    let t = generate_seeded(&preset("maze"), 3);
    let dir = std::env::temp_dir().join(format!("sitgen-image-test-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    for ext in ["png", "pgm"] {
        let path = dir.join(format!("maze.{ext}"));
        crate::interchange::image::write_image(&t.map.grid, &path).unwrap();
        if ext == "pgm" {
            assert!(
                std::fs::read(&path).unwrap().starts_with(b"P5\n"),
                "binary PGM"
            );
        }
        let spec = from_toml_str(&format!(
            "[terrain]\nresolution_m = 0.1\n[terrain.source]\nkind = \"image\"\npath = {:?}\n[[terrain.filters]]\nkind = \"threshold\"\nvalue = 0.5\n",
            path.display().to_string()
        ))
        .unwrap();
        let back = generate_seeded(&spec.terrain, 0);
        assert_eq!(back.map.grid, t.map.grid, "{ext}");
        assert_eq!(back.map.width_m(), t.map.width_m());
    }
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn a_missing_image_fails_generation_with_the_file_named() {
    let spec = from_toml_str(
        "[terrain.source]\nkind = \"image\"\npath = \"/nonexistent/map.png\"\n[[terrain.filters]]\nkind = \"threshold\"\n",
    )
    .unwrap();
    let e = generate(&spec.terrain, &mut ChoiceSource::replay(vec![])).unwrap_err();
    assert_eq!(e.path, "terrain.source");
    assert!(e.reason.contains("/nonexistent/map.png"), "{e}");
}

#[test]
fn an_unreachable_coverage_fails_generation_naming_the_filter() {
    let spec = from_toml_str(
        "[terrain]\nwidth_m = 10\nheight_m = 10\n[[terrain.filters]]\nkind = \"coverage\"\ntarget = 0.05\ntolerance = 0.001\n[[terrain.filters]]\nkind = \"border\"\nwidth_m = 2.0\n",
    )
    .unwrap();
    let e = generate(&spec.terrain, &mut ChoiceSource::stream(1, stream::TERRAIN)).unwrap_err();
    assert_eq!(e.path, "terrain.filters[0]");
    assert!(
        e.reason
            .starts_with("after 8 draws of the source: coverage 0.05 ± 0.001 cannot be reached"),
        "{e}"
    );
}

#[test]
fn the_paper_chain_pixelises_then_meets_coverage_exactly() {
    let spec = from_toml_str(
        "[terrain]\nwidth_m = 30\nheight_m = 20\n[[terrain.filters]]\nkind = \"pixelise\"\nblock_m = 1.0\n[[terrain.filters]]\nkind = \"coverage\"\ntarget = 0.3\ntolerance = 0.01\n",
    )
    .unwrap();
    let t = generate_seeded(&spec.terrain, 9);
    assert_eq!((t.map.grid.rows, t.map.grid.cols), (200, 300));
    // Blocks of 10 × 10 cells: the map is made of whole blocks.
    for r in 0..200 {
        for c in 0..300 {
            assert_eq!(
                t.map.grid.get(r, c),
                t.map.grid.get(r / 10 * 10, c / 10 * 10)
            );
        }
    }
    assert!((t.map.grid.coverage() - 0.3).abs() <= 0.01);
    assert_eq!(t.stages.len(), 3);
    assert!(t.stages[2].threshold.is_some());
}

#[test]
fn an_unreachable_coverage_draws_the_source_again() {
    // Caves whose coverage jumps when a passage closes miss a tight target for some draws;
    // seed 0..200 of the caves preset include such draws, and all must still succeed.
    let spec = preset("caves");
    let retried = (0..200)
        .map(|seed| generate_seeded(&spec, seed).attempts)
        .filter(|&a| a > 1)
        .count();
    assert!(
        retried > 0,
        "no seed needed a second draw; the test no longer tests retries"
    );
}

#[test]
fn a_map_source_keeps_the_file_size_at_the_spec_resolution() {
    let Some(data) = shared("") else {
        eprintln!("SKIPPED: ../shared/data not found; map source not checked");
        return;
    };
    let depot = data.join("rosmaps/nav2_bringup/depot.yaml");
    let spec = from_toml_str(&format!(
        "[terrain]\nresolution_m = 0.1\n[terrain.source]\nkind = \"map\"\npath = {:?}\n",
        depot.display().to_string()
    ))
    .unwrap();
    let t = generate_seeded(&spec.terrain, 0);
    // 604 × 307 cells of 0.05 m → 30.2 m × 15.35 m → 302 × 154 cells of 0.1 m.
    assert_eq!((t.map.grid.cols, t.map.grid.rows), (302, 154));
    assert!(t.map.grid.coverage() > 0.0);
    let e = from_toml_str(&format!(
        "[terrain]\nwidth_m = 3\n[terrain.source]\nkind = \"map\"\npath = {:?}\n",
        depot.display().to_string()
    ))
    .unwrap_err();
    assert_eq!(e.path, "terrain.width_m");
}
