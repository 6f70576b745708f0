//! Terrain: the first stage of the pipeline, after Arnold & Alexander (2013) §3.
//!
//! A *source* makes a layer the size of the map (a scalar field, such as Perlin noise, or an
//! occupancy grid, such as cellular-automaton caves); *filters* then run in the order the spec
//! lists them (pipe and filter), each taking the layer the previous one produced. The chain
//! must end with an occupancy grid: a scalar field becomes one through `threshold` or
//! `coverage`. Which filter accepts which layer is checked before anything is generated.
//!
//! `coverage` is the paper's coverage constraint. The paper varied the threshold at random
//! until the occupied fraction was acceptable; here the threshold is found directly, and it
//! accounts for the filters after it, so the finished map meets the target (see
//! [`filters::coverage`]).

pub mod filters;
pub mod noise;
pub mod presets;
pub mod sources;

use std::path::Path;

use schemars::JsonSchema;
use serde::{Deserialize, Serialize};

use crate::error::{join, kind_tagged, SpecError};
use crate::grid::{Map, OccupancyGrid, ScalarField};
use crate::rng::ChoiceSource;

use filters::{
    Border, Coverage, Dilate, Erode, Invert, KeepLargestFreeRegion, Pixelise, RemoveIslands,
    Threshold,
};
use sources::{Caves, ImageSource, MapSource, Maze, Perlin, Rocks, Rooms};

/// Largest map the generator accepts, in cells ([`crate::grid::MAX_CELLS`]).
pub const MAX_CELLS: f64 = crate::grid::MAX_CELLS as f64;

/// Default map width and height, metres.
pub const DEFAULT_SIZE_M: f64 = 40.0;

/// How to generate the terrain map.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct TerrainSpec {
    /// Built-in preset to start from (`open_field`, `rocky_desert`, `caves`, `urban`, `maze`);
    /// the other fields given here override the preset's. Default: none.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub preset: Option<String>,
    /// Seed of the terrain's draws (noise offsets, cave fill, rooms, rocks, mazes). Default:
    /// the situation's seed. A search sets it to keep a map while the robots change.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub seed: Option<u64>,
    /// Map width (x, east), metres, in (0, 10000]. Default 40, or the image's width times
    /// `resolution_m` for an `image` source.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub width_m: Option<f64>,
    /// Map height (y, north), metres, in (0, 10000]. Default 40, or the image's height times
    /// `resolution_m` for an `image` source.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub height_m: Option<f64>,
    /// Cell edge length, metres per cell, in (0, 10]. Default 0.1.
    #[serde(default = "default_resolution_m")]
    pub resolution_m: f64,
    /// Where the map starts from. Default: Perlin noise with its defaults.
    #[serde(default)]
    pub source: SourceSpec,
    /// Filters applied in order to the source's layer. Default: none.
    #[serde(default)]
    pub filters: Vec<FilterSpec>,
}

fn default_resolution_m() -> f64 {
    0.1
}

impl Default for TerrainSpec {
    fn default() -> Self {
        Self {
            preset: None,
            seed: None,
            width_m: None,
            height_m: None,
            resolution_m: default_resolution_m(),
            source: SourceSpec::default(),
            filters: Vec::new(),
        }
    }
}

/// A terrain source: what the map starts from.
#[derive(Debug, Clone, PartialEq, Serialize, JsonSchema)]
#[serde(tag = "kind", rename_all = "snake_case")]
pub enum SourceSpec {
    /// Improved Perlin noise with octaves (a scalar field).
    Perlin(Perlin),
    /// Cellular-automaton caves (an occupancy grid).
    Caves(Caves),
    /// Rooms joined by corridors, or city blocks between streets (an occupancy grid).
    Rooms(Rooms),
    /// A maze of corridors (an occupancy grid).
    Maze(Maze),
    /// Scattered rocks: discs or convex polygons (an occupancy grid).
    Rocks(Rocks),
    /// A PNG or PGM image (a scalar field: dark = occupied).
    Image(ImageSource),
    /// A map file: ROS YAML, PNG/PGM or MovingAI `.map` (an occupancy grid).
    Map(MapSource),
}

kind_tagged!(SourceSpec, "source", {
    "perlin" => Perlin,
    "caves" => Caves,
    "rooms" => Rooms,
    "maze" => Maze,
    "rocks" => Rocks,
    "image" => Image,
    "map" => Map,
});

impl Default for SourceSpec {
    fn default() -> Self {
        Self::Perlin(Perlin::default())
    }
}

/// A terrain filter: one step of the chain.
#[derive(Debug, Clone, PartialEq, Serialize, JsonSchema)]
#[serde(tag = "kind", rename_all = "snake_case")]
pub enum FilterSpec {
    /// Average the layer over square blocks.
    Pixelise(Pixelise),
    /// Occupied where the field is at or above a value.
    Threshold(Threshold),
    /// Threshold (or grow/shrink obstacles) so the finished map has a target occupied fraction.
    Coverage(Coverage),
    /// Grow obstacles by a radius.
    Dilate(Dilate),
    /// Shrink obstacles by a radius.
    Erode(Erode),
    /// Swap occupied and free (or v → 1 − v on a field).
    Invert(Invert),
    /// Wall in the map's edges.
    Border(Border),
    /// Remove small obstacles.
    RemoveIslands(RemoveIslands),
    /// Fill every free region but the largest.
    KeepLargestFreeRegion(KeepLargestFreeRegion),
}

kind_tagged!(FilterSpec, "filter", {
    "pixelise" => Pixelise,
    "threshold" => Threshold,
    "coverage" => Coverage,
    "dilate" => Dilate,
    "erode" => Erode,
    "invert" => Invert,
    "border" => Border,
    "remove_islands" => RemoveIslands,
    "keep_largest_free_region" => KeepLargestFreeRegion,
});

/// What flows between filters.
#[derive(Debug, Clone, PartialEq)]
pub enum Layer {
    /// A scalar field, values in [0, 1] for the built-in sources.
    Field(ScalarField),
    /// An occupancy grid.
    Occupancy(OccupancyGrid),
}

/// The two kinds of [`Layer`], for checking a chain before running it.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum LayerKind {
    /// [`Layer::Field`].
    Field,
    /// [`Layer::Occupancy`].
    Occupancy,
}

impl LayerKind {
    fn describe(self) -> &'static str {
        match self {
            Self::Field => "a scalar field",
            Self::Occupancy => "an occupancy grid",
        }
    }
}

/// The map's size in cells and its resolution, as sources see it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Extent {
    /// Rows (y).
    pub rows: usize,
    /// Columns (x).
    pub cols: usize,
    /// Metres per cell.
    pub resolution_m: f64,
}

/// A terrain source. Each lives in its own file under `sources/`.
pub trait Source {
    /// Which layer it produces.
    fn output(&self) -> LayerKind;
    /// Check the parameters; `path` names the source in errors.
    fn validate(&self, path: &str) -> Result<(), SpecError>;
    /// Make the layer, drawing every random choice from `choices`.
    fn generate(&self, extent: Extent, choices: &mut ChoiceSource) -> Result<Layer, String>;
    /// Whether it draws random choices at all (drawing it again can change the layer).
    fn draws(&self) -> bool {
        true
    }
}

/// A terrain filter. Each lives in its own file under `filters/`.
pub trait Filter {
    /// Which layer kinds it accepts.
    fn accepts(&self, input: LayerKind) -> bool;
    /// Which layer it produces from `input`.
    fn output(&self, input: LayerKind) -> LayerKind {
        input
    }
    /// Check the parameters; `path` names the filter in errors.
    fn validate(&self, path: &str) -> Result<(), SpecError>;
    /// Apply to a layer it accepts.
    fn apply(&self, layer: Layer, resolution_m: f64) -> Layer;
}

impl SourceSpec {
    fn as_source(&self) -> &dyn Source {
        match self {
            Self::Perlin(s) => s,
            Self::Caves(s) => s,
            Self::Rooms(s) => s,
            Self::Maze(s) => s,
            Self::Rocks(s) => s,
            Self::Image(s) => s,
            Self::Map(s) => s,
        }
    }

    /// Make relative file paths relative to `dir` (the spec file's folder).
    pub fn resolve_paths(&mut self, dir: &Path) {
        match self {
            Self::Image(image) => image.resolve_path(dir),
            Self::Map(map) => map.resolve_path(dir),
            _ => {}
        }
    }
}

impl FilterSpec {
    fn as_filter(&self) -> &dyn Filter {
        match self {
            Self::Pixelise(f) => f,
            Self::Threshold(f) => f,
            Self::Coverage(f) => f,
            Self::Dilate(f) => f,
            Self::Erode(f) => f,
            Self::Invert(f) => f,
            Self::Border(f) => f,
            Self::RemoveIslands(f) => f,
            Self::KeepLargestFreeRegion(f) => f,
        }
    }
}

impl TerrainSpec {
    /// Check sizes, every source and filter parameter, and that the chain fits together.
    pub fn validate(&self, path: &str) -> Result<(), SpecError> {
        SpecError::check_positive(&join(path, "resolution_m"), self.resolution_m, 10.0)?;
        for (name, value) in [("width_m", self.width_m), ("height_m", self.height_m)] {
            if let Some(v) = value {
                SpecError::check_positive(&join(path, name), v, 10_000.0)?;
            }
        }
        let (w, h) = (
            self.width_m.unwrap_or(DEFAULT_SIZE_M),
            self.height_m.unwrap_or(DEFAULT_SIZE_M),
        );
        let cells = (w / self.resolution_m).round() * (h / self.resolution_m).round();
        if cells > MAX_CELLS {
            return Err(SpecError::new(
                join(path, "resolution_m"),
                format!(
                    "{w} m × {h} m at {} m per cell is {cells:.0} cells; at most {MAX_CELLS:.0} allowed",
                    self.resolution_m
                ),
            ));
        }
        let source_path = join(path, "source");
        if let SourceSpec::Map(_) = self.source {
            for (name, value) in [("width_m", self.width_m), ("height_m", self.height_m)] {
                if value.is_some() {
                    return Err(SpecError::new(
                        join(path, name),
                        "a map source takes its size from the file; leave width_m and height_m out",
                    ));
                }
            }
        }
        let source = self.source.as_source();
        source.validate(&source_path)?;
        let mut kind = source.output();
        for (i, f) in self.filters.iter().enumerate() {
            let fpath = join(path, &format!("filters[{i}]"));
            let filter = f.as_filter();
            filter.validate(&fpath)?;
            if !filter.accepts(kind) {
                return Err(SpecError::new(
                    join(&fpath, "kind"),
                    format!(
                        "{} needs {} but gets {}; {}",
                        f.kind(),
                        match kind {
                            LayerKind::Field => LayerKind::Occupancy.describe(),
                            LayerKind::Occupancy => LayerKind::Field.describe(),
                        },
                        kind.describe(),
                        match kind {
                            LayerKind::Field => "put threshold or coverage before it",
                            LayerKind::Occupancy => "it must come before threshold or coverage",
                        }
                    ),
                ));
            }
            kind = filter.output(kind);
        }
        if kind == LayerKind::Field {
            return Err(SpecError::new(
                join(path, "filters"),
                format!(
                    "the chain ends with a scalar field from the {} source; add a threshold or coverage filter",
                    self.source.kind()
                ),
            ));
        }
        Ok(())
    }
}

/// What happened at one step of the chain, for the user and for provenance.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct StageReport {
    /// `source` or the filter's kind.
    pub stage: String,
    /// Occupied fraction after this stage, if it produced an occupancy grid.
    pub coverage: Option<f64>,
    /// The threshold a `coverage` filter chose.
    pub threshold: Option<f64>,
    /// How many thresholds a `coverage` filter tried.
    pub evaluations: Option<usize>,
}

/// A generated terrain map and how it came about.
#[derive(Debug, Clone, PartialEq)]
pub struct Terrain {
    /// The finished map.
    pub map: Map,
    /// One entry for the source and each filter, in order.
    pub stages: Vec<StageReport>,
    /// How many times the source was drawn (more than 1 when a coverage constraint could not
    /// be met by an earlier draw).
    pub attempts: usize,
}

/// How many times a source is drawn before a coverage constraint that no threshold can meet
/// fails generation. A later filter can make coverage jump (a cave passage closing off a
/// pocket that `keep_largest_free_region` then fills), so a few draws of a source miss a
/// tight target; drawing the source again, as the mission stage draws goals again, recovers.
pub const SOURCE_ATTEMPTS: usize = 8;

/// Why a valid spec produced no map.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("{path}: {reason}")]
pub struct GenerationFailed {
    /// The stage that failed (`terrain.source`, `terrain.filters[2]`).
    pub path: String,
    /// What went wrong.
    pub reason: String,
}

/// Generate the terrain of `spec` (already validated), drawing from `choices` (the terrain
/// stream of the situation's seed).
pub fn generate(
    spec: &TerrainSpec,
    choices: &mut ChoiceSource,
) -> Result<Terrain, GenerationFailed> {
    let extent = extent_of(spec).map_err(|reason| GenerationFailed {
        path: "terrain.source".into(),
        reason,
    })?;
    let source = spec.source.as_source();
    let mut attempt = 0;
    loop {
        attempt += 1;
        let layer = source
            .generate(extent, choices)
            .map_err(|reason| GenerationFailed {
                path: "terrain.source".into(),
                reason,
            })?;
        let mut stages = vec![stage_report("source", &layer)];
        match run_chain(&spec.filters, layer, extent.resolution_m, &mut stages) {
            Ok(grid) => {
                return Ok(Terrain {
                    map: Map {
                        grid,
                        resolution_m: extent.resolution_m,
                    },
                    stages,
                    attempts: attempt,
                })
            }
            // The chain fails only on a coverage constraint: draw the source again.
            Err(_) if attempt < SOURCE_ATTEMPTS && source.draws() => {}
            Err(mut failed) => {
                if attempt > 1 {
                    failed.reason =
                        format!("after {attempt} draws of the source: {}", failed.reason);
                }
                return Err(failed);
            }
        }
    }
}

/// The map's size in cells: from the spec, or from the image of an image source.
fn extent_of(spec: &TerrainSpec) -> Result<Extent, String> {
    let res = spec.resolution_m;
    let (w, h) = match (&spec.source, spec.width_m, spec.height_m) {
        (SourceSpec::Image(image), None, _) | (SourceSpec::Image(image), _, None) => {
            let (cols, rows) = image.pixel_size()?;
            (
                spec.width_m.unwrap_or(cols as f64 * res),
                spec.height_m.unwrap_or(rows as f64 * res),
            )
        }
        (_, w, h) => (w.unwrap_or(DEFAULT_SIZE_M), h.unwrap_or(DEFAULT_SIZE_M)),
    };
    let (rows, cols) = (
        crate::grid::cells_for(h, res, 1),
        crate::grid::cells_for(w, res, 1),
    );
    crate::grid::check_size(rows, cols)?;
    Ok(Extent {
        rows,
        cols,
        resolution_m: res,
    })
}

/// Apply `filters` to `layer` and return the finished occupancy grid, reporting each stage.
/// A `coverage` filter runs the rest of the chain itself, as many times as its search needs,
/// so that it is the finished map that meets the target.
fn run_chain(
    filters: &[FilterSpec],
    mut layer: Layer,
    resolution_m: f64,
    stages: &mut Vec<StageReport>,
) -> Result<OccupancyGrid, GenerationFailed> {
    for (i, f) in filters.iter().enumerate() {
        if let FilterSpec::Coverage(coverage) = f {
            let rest = &filters[i + 1..];
            let field = filters::coverage::level_field(layer, resolution_m);
            let found = coverage
                .search(&field, !rest.is_empty(), |grid| {
                    finish_chain(rest, grid, resolution_m)
                })
                .map_err(|reason| GenerationFailed {
                    path: format!("terrain.filters[{i}]"),
                    reason,
                })?;
            stages.push(StageReport {
                stage: "coverage".into(),
                coverage: Some(found.threshold_coverage),
                threshold: Some(found.threshold),
                evaluations: Some(found.evaluations),
            });
            stages.extend(found.rest);
            return Ok(found.finished);
        }
        layer = f.as_filter().apply(layer, resolution_m);
        stages.push(stage_report(f.kind(), &layer));
    }
    match layer {
        Layer::Occupancy(grid) => Ok(grid),
        Layer::Field(_) => unreachable!("validated chains end with an occupancy grid"),
    }
}

/// Apply `filters` (all taking occupancy grids) to `grid`, reporting each stage.
fn finish_chain(
    filters: &[FilterSpec],
    grid: OccupancyGrid,
    resolution_m: f64,
) -> (OccupancyGrid, Vec<StageReport>) {
    let mut layer = Layer::Occupancy(grid);
    let mut stages = Vec::with_capacity(filters.len());
    for f in filters {
        layer = f.as_filter().apply(layer, resolution_m);
        stages.push(stage_report(f.kind(), &layer));
    }
    match layer {
        Layer::Occupancy(grid) => (grid, stages),
        Layer::Field(_) => unreachable!("validated chains keep occupancy after coverage"),
    }
}

fn stage_report(stage: &str, layer: &Layer) -> StageReport {
    StageReport {
        stage: stage.into(),
        coverage: match layer {
            Layer::Occupancy(g) => Some(g.coverage()),
            Layer::Field(_) => None,
        },
        threshold: None,
        evaluations: None,
    }
}

#[cfg(test)]
mod tests;
