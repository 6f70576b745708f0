//! Terrain sources, one file each. Every file follows the same template: what the source
//! makes, why it is there, its parameters with units and defaults, and its source.

mod caves;
mod image;
mod map;
mod maze;
mod perlin;
mod rocks;
mod rooms;

pub use self::image::ImageSource;
pub use caves::Caves;
pub use map::{MapSource, UnknownCells};
pub use maze::Maze;
pub use perlin::Perlin;
pub use rocks::{RockShape, Rocks};
pub use rooms::{Rooms, RoomsLayout};
