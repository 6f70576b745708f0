//! Loading maps from files of any supported format.
//!
//! | extension | format | resolution |
//! |---|---|---|
//! | `.yaml`, `.yml` | ROS map_server YAML and the image it names | from the YAML |
//! | `.png`, `.pgm` | an image read with ROS map_server's default thresholds | given |
//! | `.map` | MovingAI grid (`.`, `G`, `S` free) | given |
//!
//! Images follow ROS map_server's trinary rule (`image_loader.cpp`): p is the mean of the
//! colour channels (alpha left out); occupancy is (255 − p) / 255, or p / 255 with `negate`;
//! a cell is occupied above `occupied_thresh`, free below `free_thresh`, otherwise unknown.
//! Unknown cells are occupied unless the caller says free: a robot must not be sent into
//! space nobody has seen. The ROS `origin` (pose of the bottom-left corner in the ROS map
//! frame) is returned beside the map, so positions can be carried between the two frames;
//! sitgen's own frame starts at the map's bottom-left corner.

use std::path::Path;

use serde::Deserialize;

use crate::grid::{Map, OccupancyGrid};

use super::movingai;

/// How unknown cells of a ROS map are read.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Unknown {
    /// As obstacles (the default).
    #[default]
    Occupied,
    /// As free space.
    Free,
}

/// ROS map_server's defaults for an image given without a YAML.
pub const DEFAULT_OCCUPIED_THRESH: f64 = 0.65;
/// ROS map_server's default free threshold.
pub const DEFAULT_FREE_THRESH: f64 = 0.196;

/// The fields of a ROS map YAML that sitgen reads.
#[derive(Debug, Deserialize)]
struct RosMapYaml {
    image: String,
    resolution: f64,
    #[serde(default)]
    negate: serde_yaml_ng::Value,
    #[serde(default = "default_occupied")]
    occupied_thresh: f64,
    #[serde(default = "default_free")]
    free_thresh: f64,
    #[serde(default)]
    origin: Option<Vec<f64>>,
}

/// A loaded map and, for a ROS map, its `origin` (x m, y m, yaw rad); zeros otherwise.
#[derive(Debug, Clone, PartialEq)]
pub struct LoadedMap {
    /// The map, in sitgen's frame.
    pub map: Map,
    /// Pose of the map's bottom-left corner in the file's frame.
    pub origin: [f64; 3],
}

fn default_occupied() -> f64 {
    DEFAULT_OCCUPIED_THRESH
}
fn default_free() -> f64 {
    DEFAULT_FREE_THRESH
}

/// Thresholds of the ROS trinary rule.
#[derive(Debug, Clone, Copy)]
pub struct Thresholds {
    /// Occupancy above which a cell is occupied.
    pub occupied: f64,
    /// Occupancy below which a cell is free.
    pub free: f64,
    /// Whether white is occupied.
    pub negate: bool,
}

impl Default for Thresholds {
    fn default() -> Self {
        Self {
            occupied: DEFAULT_OCCUPIED_THRESH,
            free: DEFAULT_FREE_THRESH,
            negate: false,
        }
    }
}

/// Load a map; `resolution_m` is used for formats that carry none. Errors name the file.
pub fn load_map(path: &Path, resolution_m: f64, unknown: Unknown) -> Result<Map, String> {
    load_map_with_origin(path, resolution_m, unknown).map(|loaded| loaded.map)
}

/// Load a map with its origin; see [`load_map`].
pub fn load_map_with_origin(
    path: &Path,
    resolution_m: f64,
    unknown: Unknown,
) -> Result<LoadedMap, String> {
    let at_zero = |map: Map| LoadedMap {
        map,
        origin: [0.0; 3],
    };
    let ext = path
        .extension()
        .map(|e| e.to_string_lossy().to_ascii_lowercase())
        .unwrap_or_default();
    let shown = path.display();
    match ext.as_str() {
        "yaml" | "yml" => load_ros_yaml(path, unknown),
        "png" | "pgm" => Ok(at_zero(Map {
            grid: read_trinary(path, Thresholds::default(), unknown)?,
            resolution_m,
        })),
        "map" => {
            let text =
                std::fs::read_to_string(path).map_err(|e| format!("cannot read {shown}: {e}"))?;
            Ok(at_zero(Map {
                grid: movingai::parse_map(&text).map_err(|e| format!("{shown}: {e}"))?,
                resolution_m,
            }))
        }
        _ => Err(format!(
            "{shown}: unknown map format; expected .yaml (ROS), .png, .pgm or .map (MovingAI)"
        )),
    }
}

fn load_ros_yaml(path: &Path, unknown: Unknown) -> Result<LoadedMap, String> {
    let shown = path.display();
    let text = std::fs::read_to_string(path).map_err(|e| format!("cannot read {shown}: {e}"))?;
    let yaml: RosMapYaml = serde_yaml_ng::from_str(&text).map_err(|e| format!("{shown}: {e}"))?;
    if yaml.resolution.is_nan() || yaml.resolution <= 0.0 {
        return Err(format!(
            "{shown}: resolution: {} is not positive",
            yaml.resolution
        ));
    }
    let negate = match &yaml.negate {
        serde_yaml_ng::Value::Null => false,
        serde_yaml_ng::Value::Bool(b) => *b,
        serde_yaml_ng::Value::Number(n) => n.as_i64() != Some(0),
        other => return Err(format!("{shown}: negate: expected 0 or 1, found {other:?}")),
    };
    for (field, value) in [
        ("occupied_thresh", yaml.occupied_thresh),
        ("free_thresh", yaml.free_thresh),
    ] {
        if !(0.0..=1.0).contains(&value) {
            return Err(format!("{shown}: {field}: {value} is not in [0, 1]"));
        }
    }
    // map_server's own rule: a cell cannot be both free and occupied.
    if yaml.free_thresh > yaml.occupied_thresh {
        return Err(format!(
            "{shown}: free_thresh {} is above occupied_thresh {}; expected free_thresh <= \
             occupied_thresh",
            yaml.free_thresh, yaml.occupied_thresh
        ));
    }
    let image = path.parent().unwrap_or(Path::new(".")).join(&yaml.image);
    let thresholds = Thresholds {
        occupied: yaml.occupied_thresh,
        free: yaml.free_thresh,
        negate,
    };
    let origin = match yaml.origin.as_deref() {
        None => [0.0; 3],
        Some(&[x, y, yaw]) => [x, y, yaw],
        Some(other) => {
            return Err(format!(
                "{shown}: origin: expected [x, y, yaw], found {} values",
                other.len()
            ))
        }
    };
    Ok(LoadedMap {
        map: Map {
            grid: read_trinary(&image, thresholds, unknown)?,
            resolution_m: yaml.resolution,
        },
        origin,
    })
}

/// Read an image by the ROS trinary rule.
pub fn read_trinary(path: &Path, t: Thresholds, unknown: Unknown) -> Result<OccupancyGrid, String> {
    let img = super::image::open_image(path)?;
    let channels = if img.color().has_color() { 3 } else { 1 };
    let rgb = img.to_rgb8();
    let cells = rgb
        .pixels()
        .map(|px| {
            let sum: f64 = px.0[..channels].iter().map(|&v| f64::from(v)).sum();
            let p = sum / channels as f64;
            let occ = if t.negate {
                p / 255.0
            } else {
                (255.0 - p) / 255.0
            };
            if occ > t.occupied {
                true
            } else if occ < t.free {
                false
            } else {
                unknown == Unknown::Occupied
            }
        })
        .collect();
    Ok(OccupancyGrid {
        rows: rgb.height() as usize,
        cols: rgb.width() as usize,
        cells,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::test_data::shared;

    #[test]
    fn ros_maps_read_with_their_thresholds() {
        let Some(depot) = shared("rosmaps/nav2_bringup/depot.yaml") else {
            eprintln!("SKIPPED: ../shared/data/rosmaps not found");
            return;
        };
        let map = load_map(&depot, 0.1, Unknown::Occupied).unwrap();
        assert_eq!(
            (map.grid.cols, map.grid.rows, map.resolution_m),
            (604, 307, 0.05)
        );
        // Grey 205 is free under depot's free_thresh 0.25, unknown under the default 0.196.
        let world = shared("rosmaps/nav2_bringup/turtlebot3_world.yaml").unwrap();
        let occupied = load_map(&world, 0.1, Unknown::Occupied).unwrap();
        let free = load_map(&world, 0.1, Unknown::Free).unwrap();
        assert!(occupied.grid.occupied_count() > free.grid.occupied_count());
        assert_eq!((occupied.grid.cols, occupied.grid.rows), (384, 384));
    }

    #[test]
    fn thresholds_out_of_range_inverted_or_nan_are_refused() {
        let dir = std::env::temp_dir().join(format!("sitgen-thresh-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let path = dir.join("m.yaml");
        for (occupied, free, expected) in [
            ("1.5", "0.2", "occupied_thresh: 1.5 is not in [0, 1]"),
            ("0.65", "-0.1", "free_thresh: -0.1 is not in [0, 1]"),
            (".nan", "0.2", "occupied_thresh: NaN is not in [0, 1]"),
            (
                "0.2",
                "0.65",
                "free_thresh 0.65 is above occupied_thresh 0.2",
            ),
        ] {
            std::fs::write(
                &path,
                format!(
                    "image: m.pgm\nresolution: 0.05\noccupied_thresh: {occupied}\n\
                     free_thresh: {free}\n"
                ),
            )
            .unwrap();
            let e = load_map(&path, 0.1, Unknown::Occupied).unwrap_err();
            assert!(e.contains(expected), "{e}");
            assert!(e.starts_with(&path.display().to_string()), "{e}");
        }
        std::fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    fn unknown_formats_and_missing_files_name_the_file() {
        let e = load_map(Path::new("/tmp/x.bmp"), 0.1, Unknown::Occupied).unwrap_err();
        assert!(e.starts_with("/tmp/x.bmp: unknown map format"), "{e}");
        let e = load_map(Path::new("/nonexistent/m.yaml"), 0.1, Unknown::Occupied).unwrap_err();
        assert!(e.starts_with("cannot read /nonexistent/m.yaml"), "{e}");
    }
}
