//! Situations: a map with robots and routes, complete and storable.
//!
//! A situation is everything a run needs and nothing more: the map (embedded, so the file
//! stays readable without the generator), each robot (body, start pose, waypoints, controller,
//! behaviour at the end of its route) and provenance (the resolved spec and seed that
//! regenerate it, the sitgen version, and a content hash). It is stored as JSON, with a JSON
//! Schema generated from these types in `schema/situation.schema.json`.
//!
//! **Map encoding.** One bit per cell, row-major from the top-left, most significant bit
//! first, zlib-compressed (level 9), then base64 (standard alphabet, padded).
//!
//! **Content hash.** `sha256:` and the hex SHA-256 of the compact JSON of `{map, robots}` (the
//! serialisation of [`Content`]), so two situations that would run the same have the same hash
//! whatever their provenance.

pub mod descriptors;

use std::io::{Read, Write};

use base64::Engine;
use schemars::JsonSchema;
use serde::{Deserialize, Serialize};
use sha2::{Digest, Sha256};

use crate::geometry::Body;
use crate::grid::{Map, OccupancyGrid};
use crate::mission::{self, AtEnd, ControllerSpec};
use crate::rng::{stream, ChoiceSource};
use crate::spec::{SituationSpec, SpecError};
use crate::terrain::{self, GenerationFailed};

/// The format tag of situation files this version writes and reads.
pub const FORMAT: &str = "sitgen.situation/1";

/// Most robots a situation may hold (the generator places at most 21).
pub const MAX_ROBOTS: usize = 100;

/// Most waypoints one robot's route may hold.
pub const MAX_WAYPOINTS: usize = 100_000;

/// The encoding tag of [`EmbeddedMap::data`].
pub const MAP_ENCODING: &str = "bits-msb-zlib-base64";

/// A complete situation.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct Situation {
    /// Always `sitgen.situation/1`.
    pub format: String,
    /// The map.
    pub map: EmbeddedMap,
    /// The robots; the agent first.
    pub robots: Vec<Robot>,
    /// Where the situation came from.
    pub provenance: Provenance,
}

/// The map, embedded and compressed.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct EmbeddedMap {
    /// Rows (y, row 0 at the top).
    pub rows: usize,
    /// Columns (x).
    pub cols: usize,
    /// Cell edge length, metres.
    pub resolution_m: f64,
    /// Always `bits-msb-zlib-base64`.
    pub encoding: String,
    /// The occupancy bits, encoded as `encoding` says.
    pub data: String,
}

/// A robot's part in the situation.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, JsonSchema)]
#[serde(rename_all = "snake_case")]
pub enum Role {
    /// Driven by the controller under test.
    Agent,
    /// A moving obstacle that avoids nothing.
    Peer,
}

/// A pose in the world frame (x east, y north, origin at the map's bottom-left corner).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct Pose {
    /// x, metres.
    pub x_m: f64,
    /// y, metres.
    pub y_m: f64,
    /// Heading, radians, counter-clockwise from east.
    pub heading_rad: f64,
}

/// One robot.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct Robot {
    /// Index in `robots`.
    pub id: u32,
    /// `agent` or `peer`.
    pub role: Role,
    /// Footprint.
    pub body: Body,
    /// Pose of the rotation centre at the start.
    pub start: Pose,
    /// Route after the start, [x, y] in metres.
    pub waypoints: Vec<[f64; 2]>,
    /// Controller and parameters.
    pub controller: ControllerSpec,
    /// What the robot does after the last waypoint.
    pub at_end: AtEnd,
}

/// Where a situation came from.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct Provenance {
    /// The resolved spec (presets applied, defaults filled).
    pub spec: SituationSpec,
    /// The master seed.
    pub seed: u64,
    /// Version of sitgen that generated it.
    pub sitgen_version: String,
    /// `sha256:` + hex digest of the map and robots.
    pub content_hash: String,
    /// For a situation shrunk from another (`sitgen shrink`), that one's content hash: the
    /// spec and seed above made the original, not this one.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub shrunk_from: Option<String>,
    /// For a situation a search made by changing another with a situation operator
    /// (`sitgen search --strategy mutation`), that one's content hash: the spec and seed above
    /// made its first ancestor.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub mutated_from: Option<String>,
}

/// What the content hash covers.
#[derive(Serialize)]
struct Content<'a> {
    map: &'a EmbeddedMap,
    robots: &'a [Robot],
}

impl EmbeddedMap {
    /// Encode a map.
    pub fn encode(map: &Map) -> Self {
        let g = &map.grid;
        let mut bits = vec![0u8; g.cells.len().div_ceil(8)];
        for (i, _) in g.cells.iter().enumerate().filter(|(_, &c)| c) {
            bits[i / 8] |= 0x80 >> (i % 8);
        }
        let mut z = flate2::write::ZlibEncoder::new(Vec::new(), flate2::Compression::best());
        z.write_all(&bits).expect("writing to memory");
        let packed = z.finish().expect("writing to memory");
        Self {
            rows: g.rows,
            cols: g.cols,
            resolution_m: map.resolution_m,
            encoding: MAP_ENCODING.into(),
            data: base64::engine::general_purpose::STANDARD.encode(packed),
        }
    }

    /// Decode the map; the error names the field.
    pub fn decode(&self) -> Result<Map, SpecError> {
        if self.encoding != MAP_ENCODING {
            return Err(SpecError::new(
                "map.encoding",
                format!(
                    "`{}` is not supported; expected `{MAP_ENCODING}`",
                    self.encoding
                ),
            ));
        }
        SpecError::check_positive("map.resolution_m", self.resolution_m, 10.0)?;
        let packed = base64::engine::general_purpose::STANDARD
            .decode(&self.data)
            .map_err(|e| SpecError::new("map.data", format!("not base64: {e}")))?;
        crate::grid::check_size(self.rows, self.cols).map_err(|e| SpecError::new("map", e))?;
        let n = self.rows * self.cols;
        // Inflate no more than the cells need (plus one byte to tell "too long"): a blob that
        // claims less than it holds is refused without being unpacked.
        let mut bits = Vec::with_capacity(n.div_ceil(8));
        flate2::read::ZlibDecoder::new(&packed[..])
            .take(n.div_ceil(8) as u64 + 1)
            .read_to_end(&mut bits)
            .map_err(|e| SpecError::new("map.data", format!("not zlib data: {e}")))?;
        if bits.len() != n.div_ceil(8) {
            return Err(SpecError::new(
                "map.data",
                format!(
                    "holds {}{} bytes; {} × {} cells need {}",
                    if bits.len() > n.div_ceil(8) {
                        "more than "
                    } else {
                        ""
                    },
                    bits.len().min(n.div_ceil(8)),
                    self.rows,
                    self.cols,
                    n.div_ceil(8)
                ),
            ));
        }
        let cells = (0..n)
            .map(|i| bits[i / 8] & (0x80 >> (i % 8)) != 0)
            .collect();
        Ok(Map {
            grid: OccupancyGrid {
                rows: self.rows,
                cols: self.cols,
                cells,
            },
            resolution_m: self.resolution_m,
        })
    }
}

impl Situation {
    /// Assemble a situation and compute its content hash.
    pub fn new(map: &Map, robots: Vec<Robot>, spec: SituationSpec, seed: u64) -> Self {
        let map = EmbeddedMap::encode(map);
        let mut s = Self {
            format: FORMAT.into(),
            map,
            robots,
            provenance: Provenance {
                spec,
                seed,
                sitgen_version: crate::VERSION.into(),
                content_hash: String::new(),
                shrunk_from: None,
                mutated_from: None,
            },
        };
        s.provenance.content_hash = s.content_hash();
        s
    }

    /// A situation shrunk from this one: `map` and `robots` in place of its own, the provenance
    /// kept and marked as shrunk from this one's content hash, and a content hash of its own.
    pub fn shrunk(&self, map: &Map, robots: Vec<Robot>) -> Self {
        let mut s = self.edited(map, robots);
        s.provenance.shrunk_from = Some(self.provenance.content_hash.clone());
        s
    }

    /// `map` and `robots` in place of this one's, with its spec and seed: a situation they
    /// no longer make, which its caller marks with where it came from.
    fn edited(&self, map: &Map, robots: Vec<Robot>) -> Self {
        Self::new(
            map,
            robots,
            self.provenance.spec.clone(),
            self.provenance.seed,
        )
    }

    /// A situation a situation operator made from this one: `map` and `robots` in place of
    /// its own, the provenance kept and marked as mutated from this one's content hash.
    pub fn mutated(&self, map: &Map, robots: Vec<Robot>) -> Self {
        let mut s = self.edited(map, robots);
        s.provenance.shrunk_from = self.provenance.shrunk_from.clone();
        s.provenance.mutated_from = Some(self.provenance.content_hash.clone());
        s
    }

    /// The hash of the map and robots, as stored in provenance when generated.
    pub fn content_hash(&self) -> String {
        let content = serde_json::to_vec(&Content {
            map: &self.map,
            robots: &self.robots,
        })
        .expect("a situation serialises");
        let digest = Sha256::digest(&content);
        let hex: String = digest.iter().map(|b| format!("{b:02x}")).collect();
        format!("sha256:{hex}")
    }

    /// Check that the map and robots still give the recorded content hash: a situation edited
    /// by hand (or damaged) after it was generated no longer matches its provenance, so a run
    /// of it would be credited to a spec and seed that do not make it.
    pub fn check_content_hash(&self) -> Result<(), SpecError> {
        let now = self.content_hash();
        if now == self.provenance.content_hash {
            return Ok(());
        }
        Err(SpecError::new(
            "provenance.content_hash",
            format!(
                "the map and robots hash to {now}, not the recorded {}: the file was edited after it was generated",
                self.provenance.content_hash
            ),
        ))
    }

    /// Pretty JSON, as written to files.
    pub fn to_json(&self) -> String {
        let mut text = serde_json::to_string_pretty(self).expect("a situation serialises");
        text.push('\n');
        text
    }

    /// Read a situation from JSON; the error names the bad field.
    pub fn from_json(text: &str) -> Result<Self, SpecError> {
        let mut de = serde_json::Deserializer::from_str(text);
        let s: Situation = serde_path_to_error::deserialize(&mut de).map_err(|e| {
            if e.inner().is_syntax() || e.inner().is_eof() {
                return SpecError::new("", format!("not JSON: {}", e.inner()));
            }
            let path = e.path().to_string();
            let path = if path == "." { String::new() } else { path };
            SpecError::new(path, e.inner().to_string())
        })?;
        s.validate()?;
        Ok(s)
    }

    /// Check what types cannot: the format, the map, the robots' ids and roles, and that every
    /// route is usable — the agent has at least one waypoint, and every waypoint lies inside
    /// the map on a free cell (one inside an obstacle could never be reached, and the run
    /// would report a failure that is not the controller's). Where robots start is checked
    /// against the simulator's own collision test ([`crate::sim::World::check_start`]).
    pub fn validate(&self) -> Result<(), SpecError> {
        if self.format != FORMAT {
            return Err(SpecError::new(
                "format",
                format!("`{}` is not supported; expected `{FORMAT}`", self.format),
            ));
        }
        let map = self.map.decode()?;
        if self.robots.len() > MAX_ROBOTS {
            return Err(SpecError::new(
                "robots",
                format!("{} robots; at most {MAX_ROBOTS} allowed", self.robots.len()),
            ));
        }
        for (i, r) in self.robots.iter().enumerate() {
            let path = format!("robots[{i}]");
            if r.id as usize != i {
                return Err(SpecError::new(
                    format!("{path}.id"),
                    format!("{} must equal its index {i}", r.id),
                ));
            }
            let agent = r.role == Role::Agent;
            if agent != (i == 0) {
                return Err(SpecError::new(
                    format!("{path}.role"),
                    "the first robot, and only it, is the agent",
                ));
            }
            r.body.validate(&format!("{path}.body"))?;
            if r.waypoints.len() > MAX_WAYPOINTS {
                return Err(SpecError::new(
                    format!("{path}.waypoints"),
                    format!(
                        "{} waypoints; at most {MAX_WAYPOINTS} allowed",
                        r.waypoints.len()
                    ),
                ));
            }
            for (k, &[x, y]) in r.waypoints.iter().enumerate() {
                check_route_point(&map, &format!("{path}.waypoints[{k}]"), x, y)?;
            }
            if agent && r.waypoints.is_empty() {
                return Err(SpecError::new(
                    format!("{path}.waypoints"),
                    "the agent needs at least one waypoint (an empty route is completed at once)",
                ));
            }
        }
        if self.robots.is_empty() {
            return Err(SpecError::new("robots", "must hold at least the agent"));
        }
        Ok(())
    }
}

/// Check that a route point lies inside `map` on a free cell.
fn check_route_point(map: &Map, path: &str, x: f64, y: f64) -> Result<(), SpecError> {
    let (w, h) = (map.width_m(), map.height_m());
    if !(x > 0.0 && x < w && y > 0.0 && y < h) {
        return Err(SpecError::new(
            path,
            format!("({x:?}, {y:?}) is outside the map, (0, 0) to ({w}, {h}) m"),
        ));
    }
    let res = map.resolution_m;
    let col = ((x / res) as usize).min(map.grid.cols - 1);
    let row = map.grid.rows - 1 - ((y / res) as usize).min(map.grid.rows - 1);
    if map.grid.get(row, col) {
        return Err(SpecError::new(
            path,
            format!("({x:?}, {y:?}) is inside an obstacle; a route point must be on free ground"),
        ));
    }
    Ok(())
}

/// Generate the situation of `spec` with master seed `seed`: terrain from the `terrain`
/// stream, robot placement and the agent's route from `mission`, peers' routes from `peers`
/// (each stage from its own seed where the spec gives one).
pub fn generate(
    spec: &SituationSpec,
    seed: u64,
) -> Result<(Situation, terrain::Terrain), GenerationFailed> {
    generate_with_distances(spec, seed).map(|(situation, terrain, _)| (situation, terrain))
}

/// [`generate`], and the finished map's squared distance from each cell to its nearest
/// occupied cell ([`crate::grid::distance::squared_distance_to`], cells²): the routes are
/// planned on it and a run's world needs it again ([`crate::run::Run::with_distances`]), so a
/// campaign's job computes it once.
pub fn generate_with_distances(
    spec: &SituationSpec,
    seed: u64,
) -> Result<(Situation, terrain::Terrain, Vec<f64>), GenerationFailed> {
    let terrain_seed = spec.terrain.seed.unwrap_or(seed);
    let mission_seed = spec.mission.seed.unwrap_or(seed);
    let terrain = terrain::generate(
        &spec.terrain,
        &mut ChoiceSource::stream(terrain_seed, stream::TERRAIN),
    )?;
    let g = &terrain.map.grid;
    let to_occupied = crate::grid::distance::squared_distance_to(&g.cells, g.rows, g.cols);
    let robots = mission::generate(
        &terrain.map,
        &to_occupied,
        &spec.mission,
        &mut ChoiceSource::stream(mission_seed, stream::MISSION),
        &mut ChoiceSource::stream(mission_seed, stream::PEERS),
    )?;
    Ok((
        Situation::new(&terrain.map, robots, spec.clone(), seed),
        terrain,
        to_occupied,
    ))
}

/// The JSON Schema of [`Situation`], pretty-printed, as checked in under `schema/`.
pub fn json_schema() -> String {
    let schema = schemars::schema_for!(Situation);
    let mut text = serde_json::to_string_pretty(&schema).expect("a schema serialises");
    text.push('\n');
    text
}

#[cfg(test)]
mod tests;
