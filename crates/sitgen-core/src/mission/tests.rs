use std::path::PathBuf;

use rayon::prelude::*;

use super::astar::PathSearch;
use super::rdp::simplify_indices;
use crate::interchange::movingai::{parse_map, parse_scenarios};

/// `../shared/data` beside the repository, or `$SITGEN_SHARED_DATA`.
fn shared_data() -> Option<PathBuf> {
    let dir = std::env::var_os("SITGEN_SHARED_DATA")
        .map(PathBuf::from)
        .unwrap_or_else(|| PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../../shared/data"));
    dir.is_dir().then_some(dir)
}

#[test]
fn astar_gives_the_movingai_optimal_length_for_every_problem() {
    let Some(data) = shared_data() else {
        eprintln!(
            "SKIPPED: ../shared/data not found (set SITGEN_SHARED_DATA); MovingAI not checked"
        );
        return;
    };
    let scenarios = data.join("movingai/scenarios");
    let mut files: Vec<PathBuf> = std::fs::read_dir(&scenarios)
        .unwrap()
        .flat_map(|set| std::fs::read_dir(set.unwrap().path()).unwrap())
        .map(|f| f.unwrap().path())
        .collect();
    files.sort();
    let mut total = 0;
    for scen in &files {
        let set = scen.parent().unwrap().file_name().unwrap();
        let map_name = scen
            .file_name()
            .unwrap()
            .to_string_lossy()
            .replace(".scen", "");
        let map_path = data.join("movingai/maps").join(set).join(&map_name);
        let grid = parse_map(&std::fs::read_to_string(&map_path).unwrap()).unwrap();
        let problems = parse_scenarios(&std::fs::read_to_string(scen).unwrap()).unwrap();
        let bad: Vec<String> = problems
            .par_iter()
            .map_init(
                || PathSearch::new(&grid.cells, grid.rows, grid.cols),
                |search, p| {
                    (
                        search
                            .shortest_path(p.start, p.goal)
                            .map(|path| path.length),
                        p,
                    )
                },
            )
            .filter_map(|(got, p)| {
                // The files print 6 significant digits (older sets) or 8 decimals: compare
                // within their printed precision plus 1e-6 relative.
                let printed = 5e-6 * p.optimal.max(1.0);
                match got {
                    Some(len) if (len - p.optimal).abs() <= printed + 1e-6 * p.optimal => None,
                    other => Some(format!(
                        "{map_name} {:?}→{:?}: {other:?} vs {}",
                        p.start, p.goal, p.optimal
                    )),
                }
            })
            .collect();
        assert!(bad.is_empty(), "{} wrong, e.g. {}", bad.len(), bad[0]);
        total += problems.len();
    }
    assert_eq!(total, 16_980, "every problem of the six scenario files");
}

#[test]
fn rdp_matches_simplify_js_high_quality_on_every_reference_case() {
    let Some(data) = shared_data() else {
        eprintln!("SKIPPED: ../shared/data not found (set SITGEN_SHARED_DATA); RDP not checked");
        return;
    };
    let inputs: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(data.join("rdp/rdp_inputs.json")).unwrap())
            .unwrap();
    let outputs: serde_json::Value = serde_json::from_str(
        &std::fs::read_to_string(data.join("rdp/rdp_reference_outputs.json")).unwrap(),
    )
    .unwrap();
    let mut checked = 0;
    for result in outputs["results"].as_array().unwrap() {
        let case = result["case"].as_str().unwrap();
        let eps = result["epsilon"].as_f64().unwrap();
        let input = inputs["cases"]
            .as_array()
            .unwrap()
            .iter()
            .find(|c| c["id"] == case)
            .unwrap();
        let points: Vec<(f64, f64)> = input["points"]
            .as_array()
            .unwrap()
            .iter()
            .map(|p| (p[0].as_f64().unwrap(), p[1].as_f64().unwrap()))
            .collect();
        let expected: Vec<usize> =
            serde_json::from_value(result["simplifyjs_1.2.4_highQuality_idx"].clone()).unwrap();
        assert_eq!(
            simplify_indices(&points, eps),
            expected,
            "{case} at ε = {eps}"
        );
        checked += 1;
    }
    assert_eq!(checked, 40);
}
