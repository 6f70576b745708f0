//! ROS map_server map metadata (the YAML beside the image), and a situation's map exported
//! as map_server files.
//!
//! Convention (ROS `map_server`): `resolution` in m/cell; `origin` is the pose (x, y, yaw) of
//! the lower-left pixel in the map frame; with `negate: 0` a pixel's occupancy probability is
//! (255 − value) / 255, occupied above `occupied_thresh`, free below `free_thresh`. sitgen's
//! frame has its origin at the map's lower-left corner, so `origin` is [0, 0, 0].

use std::path::{Path, PathBuf};

use super::image::write_image;
use crate::grid::Map;
use crate::situation::Situation;

/// Occupancy probability above which ROS reads a pixel as occupied.
pub const OCCUPIED_THRESH: f64 = 0.65;
/// Occupancy probability below which ROS reads a pixel as free.
pub const FREE_THRESH: f64 = 0.196;

/// The map_server YAML text for `map` stored in the image file named `image`.
pub fn map_yaml(map: &Map, image: &str) -> String {
    // A JSON string is a valid YAML double-quoted scalar: safe for any file name.
    let image = serde_json::Value::from(image).to_string();
    format!(
        "image: {image}\nresolution: {}\norigin: [0.0, 0.0, 0.0]\nnegate: 0\noccupied_thresh: {OCCUPIED_THRESH}\nfree_thresh: {FREE_THRESH}\nmode: trinary\n",
        map.resolution_m
    )
}

/// Write the YAML for `map` to `yaml_path`, naming `image_path` relative to it when they share
/// a folder.
pub fn write_map_yaml(map: &Map, yaml_path: &Path, image_path: &Path) -> Result<(), String> {
    let image = if image_path.parent() == yaml_path.parent() {
        image_path
            .file_name()
            .map(|n| n.to_string_lossy().into_owned())
            .unwrap_or_default()
    } else {
        image_path.display().to_string()
    };
    std::fs::write(yaml_path, map_yaml(map, &image))
        .map_err(|e| format!("cannot write {}: {e}", yaml_path.display()))
}

/// Write the map as a ROS map_server PGM and YAML (`map.pgm`, `map.yaml`) into `dir`.
pub fn write_ros(situation: &Situation, dir: &Path) -> Result<Vec<PathBuf>, String> {
    let map = situation.map.decode().map_err(|e| e.to_string())?;
    std::fs::create_dir_all(dir).map_err(|e| format!("cannot create {}: {e}", dir.display()))?;
    let image = dir.join("map.pgm");
    let yaml = dir.join("map.yaml");
    write_image(&map.grid, &image)?;
    write_map_yaml(&map, &yaml, &image)?;
    Ok(vec![yaml, image])
}
