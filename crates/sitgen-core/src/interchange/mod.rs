//! Maps in and out of files: images (PNG/PGM) and ROS map_server YAML.

pub mod image;
pub mod ros;
